"""Compute the `home` keyframe of assets/mjcf/planar7.xml and write it into the file.

The tray-carrying pose is chosen by hand (constants below); what is computed:

* elbow and wrist, so that the forearm and the hand have the chosen absolute pitches (the hand
  straight up: the ``ee`` site frame is then world-aligned and a tray on it is level);
* root_pitch, so that the body CoM (everything but the wheels) is exactly over the axle: the body
  turns rigidly about the axle with root_pitch, so subtracting ``theta = atan2(X_com, Z_com)``
  from it zeroes theta. Elbow and wrist depend on root_pitch, so the two steps are iterated to a
  fixed point (the arm is light: a few iterations reach machine precision).

Usage::

    python tools/build_planar7_mjcf.py          # rewrite the keyframe, print the pose summary
    python tools/build_planar7_mjcf.py --check  # exit 1 if the file's keyframe is out of date
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import mujoco
import numpy as np

MJCF = Path(__file__).resolve().parents[1] / "assets" / "mjcf" / "planar7.xml"

# The chosen pose (rad; signs: positive leans a link forward, see planar7.xml):
SPINE = 1.9  # waist folded forward (Krang's tray pose: 1.986, docs/AUTHORS_CONFIG.md §1.6)
TORSO = -0.55  # torso tipped back on the spine so it leans only ~0.4 rad forward
SHOULDER = -0.45  # upper arm hanging nearly straight down, slightly forward
FOREARM_PITCH = -1.35  # forearm absolute pitch: 0.22 rad below horizontal (-pi/2), forward
HAND_PITCH = -math.pi  # hand absolute pitch: pointing straight up (its tip carries the tray)
WHEEL_RADIUS = 0.25  # root_z: the axle at the wheel radius

JOINTS = (
    "root_x",
    "root_z",
    "root_pitch",
    "wheel_left",
    "wheel_right",
    "spine",
    "torso",
    "shoulder",
    "elbow",
    "wrist",
)
KEY_PATTERN = re.compile(r'(<key name="home" qpos=")([^"]*)(")')


def body_com_theta(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[float, np.ndarray]:
    """``theta`` and the body CoM (wheels excluded) relative to the axle, in world axes."""
    base = model.body("base").id
    wheels = {model.body("wheel_left").id, model.body("wheel_right").id}
    ids = [b for b in range(model.nbody) if model.body_rootid[b] == base and b not in wheels]
    masses = model.body_mass[ids]
    com = masses @ data.xipos[ids] / masses.sum() - data.xpos[base]
    return math.atan2(com[0], com[2]), com


def solve_home(model: mujoco.MjModel) -> np.ndarray:
    """The home qpos (see the module docstring)."""
    data = mujoco.MjData(model)
    adr = {name: int(model.joint(name).qposadr[0]) for name in JOINTS}
    qpos = np.zeros(model.nq)
    qpos[adr["root_z"]] = WHEEL_RADIUS
    qpos[adr["spine"]] = SPINE
    qpos[adr["torso"]] = TORSO
    qpos[adr["shoulder"]] = SHOULDER
    q1 = 0.0
    for _ in range(100):
        qpos[adr["root_pitch"]] = q1
        qpos[adr["elbow"]] = FOREARM_PITCH - (q1 + SPINE + TORSO + SHOULDER)
        qpos[adr["wrist"]] = HAND_PITCH - FOREARM_PITCH
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        theta, _ = body_com_theta(model, data)
        q1 -= theta
        if abs(theta) < 1e-15:
            break
    else:
        raise RuntimeError("home pose iteration did not converge")
    return qpos


def format_qpos(qpos: np.ndarray) -> str:
    """Shortest round-trip text of each number (exact as a double)."""
    return " ".join(repr(float(v)) if v != 0 else "0" for v in qpos)


def summary(model: mujoco.MjModel, qpos: np.ndarray) -> str:
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    theta, com = body_com_theta(model, data)
    ee = data.site("ee").xpos
    axle = data.body("base").xpos
    gravity = data.qfrc_bias[[int(model.joint(n).dofadr[0]) for n in JOINTS[5:]]]
    lines = [
        f"total mass {model.body_subtreemass[model.body('base').id]:.2f} kg",
        "home qpos " + " ".join(f"{n}={v:+.4f}" for n, v in zip(JOINTS, qpos, strict=True)),
        f"theta {theta:.2e}; body CoM {com[2]:.4f} m above the axle",
        f"ee {ee[2]:.4f} m above the floor, {ee[0] - axle[0]:.4f} m ahead of the axle",
        "gravity torques (spine..wrist) " + " ".join(f"{t:.1f}" for t in gravity),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check the keyframe")
    args = parser.parse_args(argv)
    model = mujoco.MjModel.from_xml_path(str(MJCF))
    qpos = solve_home(model)
    text = MJCF.read_text()
    if KEY_PATTERN.search(text) is None:
        raise SystemExit(f'no <key name="home" qpos=...> in {MJCF}')
    new_text = KEY_PATTERN.sub(lambda m: m.group(1) + format_qpos(qpos) + m.group(3), text)
    print(summary(model, qpos))
    if args.check:
        if new_text != text:
            print(f"{MJCF.name}: home keyframe out of date", file=sys.stderr)
            return 1
        return 0
    MJCF.write_text(new_text)
    print(f"wrote {MJCF}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
