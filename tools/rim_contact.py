"""Measure how the tray's rim meets the cup, for the model's contact and the variants it was
chosen against (assets/mjcf/README.md, "Contacts of the tray and the cup").

    python -m tools.rim_contact [--variants stiff mujoco-default ...] [--cost]

The scene: the task's tray (``wip_gym.scene._add_tray``: the plate and the 5 mm rim) fixed in
world, level, and the task's cup (``wip_gym.scene.add_cup``: its cylinder and feet on the
plate), with the options of the task model (``KrangTray-v0`` with the rim). Only the cup's
contact with the rim walls changes between variants:

- ``stiff``: the model's, the cylinder paired with each wall (``STIFF_SOLREF``,
  ``STIFF_SOLIMP``); checked equal to the task model's pairs.
- ``mujoco-default``: the same pairs at MuJoCo's default solref (0.02, 1) and solimp (0.9,
  0.95, 0.001, 0.5, 2).
- ``solimp-0.9999``: the stiff pairs with the wheels' impedance, 0.9999.
- ``feet``: the four 1 mm feet paired with each wall at MuJoCo's defaults, no cylinder pair.
- ``spheres``: a ring of 16 spheres of 2.5 mm at the foot of the cup's wall (sphere-box, a
  primitive pair), stiff pairs with each wall.
- ``capsules``: a ring of 8 upright capsules of 3 mm along the lowest 2 cm of the wall
  (capsule-box, a primitive pair), stiff pairs with each wall.

Figures, per variant: the reach (mm) of the cup's wall, from its bottom up to the rim's height,
past the rim's inner face when it meets the rim at 0.25, 0.5 and 1.0 m/s: the largest over 8
phases of arrival (launched from 1 mm short of the wall to one step's travel more), read 50 ms;
and the launch speed from which it falls over (its tilt passes 90 deg within 1 s: over the
rim's edge, or through the wall where the reach says it passes; bisection to 2 mm/s) at rest
and at a sustained 1.5 m/s^2 toward the rim (gravity turned), cup friction 0.05, beside the
speed from which a rigid cup tips over the edge (``tests/test_rim.py``: ``impact_energy``).
About 20 s a variant.

``--cost``: what the model's rim contact costs while it acts. On ``KrangTray-v0`` with the rim
(welded and free), robot held still, gravity turned for 1.5 m/s^2 along the tray's x, friction
0.05 (the cup slides into the rim and leans on it), the state before each of 1500 steps is
recorded and a bare ``mj_step`` replayed from each (as ``wip-bench profile`` times its floor),
in the unit of ``benchmarks.speed.yardstick`` timed in bursts between them: the medians over
the steps where the cup slides on the plate and where it touches the rim.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np

from benchmarks.speed.yardstick import ReferenceStep
from wip_gym.scene import (
    AUTHORS_TRAY_RIM,
    CUP_FEET,
    CUP_HALF_HEIGHT,
    CUP_RADIUS,
    STIFF_SOLIMP,
    STIFF_SOLREF,
    TRAY_HALF_SIZE,
    TRAY_RIM_THICKNESS,
    SceneOptions,
    _add_tray,
    _tray_geom_names,
    add_cup,
    build_model,
)

G = 9.81
FRICTION = 0.05
SPEEDS = (0.25, 0.5, 1.0)
PHASES = 8
GAP = 0.001  # m short of the wall at the launch
MUJOCO_SOLREF = (0.02, 1.0)
MUJOCO_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
OPTION_FIELDS = (
    "timestep",
    "integrator",
    "cone",
    "impratio",
    "enableflags",
    "disableflags",
    "ccd_tolerance",
)


def _pairs(spec: mujoco.MjSpec, geoms: list[str], solref: tuple, solimp: tuple) -> None:
    for wall in _tray_geom_names(AUTHORS_TRAY_RIM)[1:]:
        for geom in geoms:
            spec.add_pair(
                name=f"{wall}_{geom}",
                geomname1=wall,
                geomname2=geom,
                condim=3,
                friction=[FRICTION, FRICTION, 0.005, 0.0001, 0.0001],
                solref=list(solref),
                solimp=list(solimp),
            )


def _ring(spec: mujoco.MjSpec, kind: str, count: int, radius: float) -> list[str]:
    cup, names = spec.body("cup"), []
    centre = CUP_RADIUS - radius
    for k in range(count):
        angle = 2.0 * math.pi * k / count
        x, y = centre * math.cos(angle), centre * math.sin(angle)
        name = f"cup_ring{k}"
        common = {"name": name, "mass": 0.0, "contype": 0, "conaffinity": 0}
        if kind == "sphere":
            cup.add_geom(
                type=mujoco.mjtGeom.mjGEOM_SPHERE,
                size=[radius, 0.0, 0.0],
                pos=[x, y, -CUP_HALF_HEIGHT + radius],
                **common,
            )
        else:
            bottom, top = -CUP_HALF_HEIGHT + radius, -CUP_HALF_HEIGHT + 0.02 - radius
            cup.add_geom(
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                size=[radius, 0.0, 0.0],
                fromto=[x, y, bottom, x, y, top],
                **common,
            )
        names.append(name)
    return names


VARIANTS: dict[str, Callable[[mujoco.MjSpec], None]] = {
    "stiff": lambda s: _pairs(s, ["cup"], STIFF_SOLREF, STIFF_SOLIMP),
    "mujoco-default": lambda s: _pairs(s, ["cup"], MUJOCO_SOLREF, MUJOCO_SOLIMP),
    "solimp-0.9999": lambda s: _pairs(s, ["cup"], STIFF_SOLREF, (0.9999, 0.9999, 0.001, 0.5, 2)),
    "feet": lambda s: _pairs(
        s, [f"cup_foot{k}" for k in range(CUP_FEET)], MUJOCO_SOLREF, MUJOCO_SOLIMP
    ),
    "spheres": lambda s: _pairs(s, _ring(s, "sphere", 16, 0.0025), STIFF_SOLREF, STIFF_SOLIMP),
    "capsules": lambda s: _pairs(s, _ring(s, "capsule", 8, 0.003), STIFF_SOLREF, STIFF_SOLIMP),
}


def build(variant: str, task: mujoco.MjModel) -> mujoco.MjModel:
    """The still tray and the cup, with ``task``'s options and the variant's rim contact."""
    spec = mujoco.MjSpec()
    for name in OPTION_FIELDS:
        setattr(spec.option, name, getattr(task.opt, name))
    spec.option.tolerance = task.opt.tolerance
    spec.add_material(name="tray")
    spec.add_material(name="cup")
    spec.worldbody.add_site(name="tray_mount")
    options = SceneOptions("krang", tray=True, tray_rim=AUTHORS_TRAY_RIM)
    _add_tray(spec, options, np.array([1.0, 0.0, 0.0, 0.0]), None)
    add_cup(spec, FRICTION, 0.0)  # the cup and its feet on the plate
    VARIANTS[variant](spec)
    spec.geom("cup").contype = spec.geom("cup").conaffinity = 0  # no floor here
    return spec.compile()


def _check_stiff_is_the_model(model: mujoco.MjModel, task: mujoco.MjModel) -> None:
    for wall in _tray_geom_names(AUTHORS_TRAY_RIM)[1:]:
        mine, theirs = model.pair(f"{wall}_cup"), task.pair(f"{wall}_cup")
        for field in ("solref", "solimp", "friction", "margin", "gap", "dim"):
            if not np.array_equal(getattr(mine, field), getattr(theirs, field)):
                raise AssertionError(f"{wall}: {field} differs from the task model's")


def _reach(data: mujoco.MjData, cup: int) -> float:
    """How far the cup's wall (bottom up to the rim's height) reaches past the +x rim's face."""
    axis = data.xmat[cup].reshape(3, 3)[:, 2]
    bottom = data.xpos[cup] - CUP_HALF_HEIGHT * axis
    across = math.sqrt(max(0.0, 1.0 - axis[0] ** 2))
    reach = max(bottom[0] + height * axis[0] for height in (0.0, AUTHORS_TRAY_RIM))
    return reach + CUP_RADIUS * across - (TRAY_HALF_SIZE[0] - TRAY_RIM_THICKNESS)


def _launch(
    model: mujoco.MjModel, speed: float, gap: float, acceleration: float = 0.0
) -> mujoco.MjData:
    model.opt.gravity[:] = (acceleration, 0.0, -G)
    data = mujoco.MjData(model)
    x = TRAY_HALF_SIZE[0] - TRAY_RIM_THICKNESS - CUP_RADIUS - gap
    data.qpos[:3] = (x, 0.0, 2 * TRAY_HALF_SIZE[2] + CUP_HALF_HEIGHT - 1e-6)
    data.qvel[0] = speed
    return data


def deepest_reach(model: mujoco.MjModel, speed: float) -> float:
    """The largest reach (m) over ``PHASES`` phases of arrival at ``speed``, read 50 ms."""
    cup, worst = model.body("cup").id, -math.inf
    for phase in range(PHASES):
        data = _launch(model, speed, GAP + speed * model.opt.timestep * phase / PHASES)
        for _ in range(round(0.05 / model.opt.timestep)):
            mujoco.mj_step(model, data)
            mujoco.mj_kinematics(model, data)
            worst = max(worst, _reach(data, cup))
    return worst


def tips(model: mujoco.MjModel, speed: float, acceleration: float) -> bool:
    data = _launch(model, speed, GAP, acceleration)
    cup = model.body("cup").id
    for _ in range(round(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
        if data.xmat[cup][8] < 0.0:  # its axis past horizontal
            return True
    return False


def tipping_speed(model: mujoco.MjModel, acceleration: float) -> float:
    low, high = 0.2, 1.5
    while high - low > 0.002:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if tips(model, middle, acceleration) else (middle, high)
    return 0.5 * (low + high)


def rigid_tipping_speed(acceleration: float) -> float:
    """The rigid cup's (tests/test_rim.py: tipping_energy, impact_energy), at the wall."""
    pivot = CUP_HALF_HEIGHT - AUTHORS_TRAY_RIM
    energy = (
        math.hypot(CUP_RADIUS, pivot) * math.hypot(acceleration, G)
        - G * pivot
        - acceleration * CUP_RADIUS
    )
    k2 = (3 * CUP_RADIUS**2 + (2 * CUP_HALF_HEIGHT) ** 2) / 12 + CUP_RADIUS**2 + pivot**2
    return math.sqrt(2 * k2 * energy) / pivot


def contact_cost(attachment: str) -> tuple[float, float]:
    """Median bare ``mj_step`` (units) of the steps where the cup slides and where it touches
    the rim (see ``--cost`` in the module docstring)."""
    env = gym.make(
        "wip_gym/KrangTray-v0",
        tray_rim=AUTHORS_TRAY_RIM,
        tray_attachment=attachment,
        cup_friction=FRICTION,
        reset_noise_scale=0.0,
        terminate_on_cup_loss=False,
    )
    env.reset(seed=0)
    base = env.unwrapped
    m, d = base.model, base.data
    nq, nv = base.robot.layout.nq, base.robot.layout.nv
    held = d.qpos[:nq].copy()
    m.dof_armature[:nv] = 1e6  # the robot held (the harness of tests/test_rim.py)
    m.opt.gravity[:] = d.xmat[m.body("tray").id].reshape(3, 3) @ np.array([1.5, 0.0, -G])
    walls = {m.geom(name).id for name in _tray_geom_names(AUTHORS_TRAY_RIM)[1:]}
    cup = set(np.flatnonzero(m.geom_bodyid == m.body("cup").id).tolist())
    kind = mujoco.mjtState.mjSTATE_INTEGRATION
    states, touching = [], []
    for _ in range(1500):
        d.qpos[:nq] = held
        d.qvel[:nv] = 0.0
        mujoco.mj_forward(m, d)
        d.qfrc_applied[:nv] = d.qfrc_bias[:nv]
        state = np.zeros(mujoco.mj_stateSize(m, kind))
        mujoco.mj_getState(m, d, state, kind)
        states.append(state)
        mujoco.mj_step(m, d)
        pairs = [set(d.contact.geom[i].tolist()) for i in range(d.ncon)]
        touching.append(any(p & walls and p & cup for p in pairs))
    unit, scratch, times = ReferenceStep(), mujoco.MjData(m), []
    units = unit.burst(100)
    for k, state in enumerate(states):
        mujoco.mj_setState(m, scratch, state, kind)
        start = time.perf_counter()
        mujoco.mj_step(m, scratch)
        times.append(time.perf_counter() - start)
        if (k + 1) % 100 == 0:
            units += unit.burst(20)
    reference = float(np.median(units))
    steps, rim = np.array(times[100:]) / reference, np.array(touching[100:])
    return float(np.median(steps[~rim])), float(np.median(steps[rim]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--cost", action="store_true", help="the rim contact's cost instead")
    args = parser.parse_args()
    if args.cost:
        print("| KrangTray-v0, rim | bare mj_step (units): cup sliding | cup on the rim |")
        print("|---|---|---|")
        for attachment in ("welded", "free"):
            sliding, on_rim = contact_cost(attachment)
            print(f"| {attachment} | {sliding:.2f} | {on_rim:.2f} |", flush=True)
        return
    task = build_model(
        SceneOptions("krang", tray=True, cup=True, cup_friction=FRICTION, tray_rim=AUTHORS_TRAY_RIM)
    )
    rigid = [rigid_tipping_speed(a) for a in (0.0, 1.5)]
    print(
        "| rim contact | reach (mm) at " + ", ".join(f"{v}" for v in SPEEDS) + " m/s "
        f"| falls over from (m/s) at rest, at 1.5 m/s^2 (a rigid cup tips from {rigid[0]:.3f}, "
        f"{rigid[1]:.3f}) |"
    )
    print("|---|---|---|")
    for variant in args.variants:
        model = build(variant, task)
        if variant == "stiff":
            _check_stiff_is_the_model(model, task)
        reach = [deepest_reach(model, v) * 1e3 for v in SPEEDS]
        speeds = [tipping_speed(model, a) for a in (0.0, 1.5)]
        print(
            f"| {variant} | " + " / ".join(f"{r:.2f}" for r in reach) + " | "
            f"{speeds[0]:.3f}, {speeds[1]:.3f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
