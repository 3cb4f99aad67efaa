"""Verify wip-gym on every MuJoCo release of pyproject's range (a maintainer's tool, not shipped).

For each release it makes a scratch virtual environment, installs the project's wheel and that
MuJoCo release in it, and runs, from outside the repository (so that the installed wheel is
what is imported):

1. the C-declaration checks, ``tests/test_mujoco_c.py`` (the installed ``mujoco.h`` declares
   every C function as ``wip_gym.mujoco_c.DECLARATIONS`` does; each, called from compiled code,
   gives what the bindings give);
2. a smoke of every env with every registered controller (``ppo`` where a checkpoint is
   shipped), ``--steps`` control steps each from
   a seeded reset, on the path the release gets (the compiled fast path where
   ``wip_gym.mujoco_c.VERIFIED_RELEASES`` holds it), then on the readable path
   (``WIP_GYM_FAST_PATH=0``) for a fifth of the steps: every action finite, no exception.

It prints one row per release: whether the fast path runs there, the checks, the smokes. The
scratch environments reuse this interpreter's other packages (numba, JAX, ProxQP, Gymnasium:
the versions constraints.txt pins) through a ``.pth`` file, after their own site-packages,
which hold the wheel and the MuJoCo release: what differs between the rows is MuJoCo alone.
CPU heavy (each environment compiles the numba caches anew): about 5 min a release.

    python tools/verify_mujoco_releases.py [--releases 3.10 3.11 ...] [--steps 300]
"""

from __future__ import annotations

import argparse
import os
import shutil
import site
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
RELEASES = ("3.10", "3.11", "3.12", "3.13", "3.14", "3.15", "3.16", "3.17")

SMOKE = textwrap.dedent(
    """
    import os, sys, time
    import numpy as np, gymnasium as gym
    import mujoco
    import wip_gym
    from controllers.optimizer import jax_setup
    jax_setup.configure()
    from controllers.learned import shipped_checkpoint
    from controllers.registry import controller_names, make_policy
    from wip_gym import mujoco_c
    steps = int(sys.argv[1])
    assert "site-packages" in wip_gym.__file__, wip_gym.__file__  # the installed wheel
    fast = mujoco_c.fast_path()
    runs = 0
    for env_id in wip_gym.ENV_IDS:
        for name in controller_names():
            if name == "ppo":  # a learned policy runs where a checkpoint is shipped
                try:
                    shipped_checkpoint(env_id)
                except ValueError:
                    continue
            env = gym.make(env_id)
            obs, info = env.reset(seed=0)
            policy = make_policy(name, env)
            policy.reset(obs, info)
            for _ in range(steps):
                action = policy(obs)
                assert np.isfinite(action).all(), (env_id, name)
                obs, _, terminated, _, info = env.step(action)
                if terminated:
                    break
            assert env.unwrapped.robot.fast_path == fast
            getattr(getattr(policy, "high_level", None), "close", lambda: None)()
            env.close()
            runs += 1
    print(f"RESULT mujoco {mujoco.__version__} fast {fast} runs {runs}")
    """
)


def _run(command: list[str], cwd: Path, env: dict[str, str]) -> tuple[bool, str]:
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    return done.returncode == 0, done.stdout + done.stderr


def _wheel(work: Path) -> Path:
    """The project's wheel, built once into ``work``."""
    dist = work / "dist"
    shutil.rmtree(dist, ignore_errors=True)
    ok, log = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w",
         str(dist), str(REPOSITORY)],
        work,
        dict(os.environ),
    )  # fmt: skip
    if not ok:
        raise SystemExit(f"the wheel did not build:\n{log}")
    return next(dist.glob("wip_gym-*.whl"))


def _environment(work: Path, release: str, wheel: Path) -> Path:
    """A scratch venv with the wheel and MuJoCo ``release`` in its own site-packages, this
    interpreter's other packages after them."""
    venv = work / f"venv-{release}"
    shutil.rmtree(venv, ignore_errors=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    own = subprocess.run(
        [str(python), "-c", "import site; print(site.getsitepackages()[0])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    shared = [p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir()]
    shared += [p for p in site.getsitepackages() if p not in shared]
    Path(own, "wip_gym_shared.pth").write_text("\n".join(shared) + "\n")
    subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--no-deps", str(wheel),
         f"mujoco=={release}.*"],
        check=True,
    )  # fmt: skip
    return python


def _checks(work: Path) -> Path:
    """The C-declaration checks, copied out of the repository (with the module they import)."""
    checks = work / "checks"
    shutil.rmtree(checks, ignore_errors=True)
    checks.mkdir()
    for name in ("test_mujoco_c.py", "dynamics_reference.py"):
        shutil.copy(REPOSITORY / "tests" / name, checks / name)
    return checks


def verify(release: str, work: Path, wheel: Path, steps: int) -> dict[str, str]:
    python = _environment(work, release, wheel)
    checks = _checks(work)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "WIP_GYM_FAST_PATH")}
    env.setdefault("MUJOCO_GL", "egl")
    env["NUMBA_CACHE_DIR"] = str(work / f"numba-{release}")
    row = {"release": release}
    ok, log = _run(
        [str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(checks),
         str(checks / "test_mujoco_c.py")],
        checks,
        env,
    )  # fmt: skip
    row["checks"] = "pass" if ok else "FAIL"
    if not ok:
        print(log[-3000:])
    script = work / "smoke.py"
    script.write_text(SMOKE)
    for label, extra, count in (("fast", {}, steps), ("readable", {"WIP_GYM_FAST_PATH": "0"}, 0)):
        count = count or max(steps // 5, 20)
        ok, log = _run([str(python), str(script), str(count)], work, env | extra)
        result = [line for line in log.splitlines() if line.startswith("RESULT")]
        if ok and result:
            words = result[0].split()
            row["version"] = words[2]
            if label == "fast":
                row["fast path"] = words[4]
            row[f"smoke ({label})"] = f"{words[6]} runs x {count} steps"
        else:
            row[f"smoke ({label})"] = "FAIL"
            print(log[-3000:])
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--releases", nargs="*", default=list(RELEASES))
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--work", type=Path, default=None, help="scratch directory (a new one)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="wip-gym-releases-"))
    work.mkdir(parents=True, exist_ok=True)
    wheel = _wheel(work)
    rows = []
    for release in args.releases:
        row = verify(release, work, wheel, args.steps)
        rows.append(row)
        print(row, flush=True)
    columns = ["release", "version", "fast path", "checks", "smoke (fast)", "smoke (readable)"]
    print("\n| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(row.get(c, "-") for c in columns) + " |")
    failed = [r for r in rows if "FAIL" in r.values()]
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
