"""Record the default scenario's episodes, the reference of its seed-spread guard.

The default scenario is what ``make demo`` runs: ``wip-bench compare --env
wip_gym/PlanarTray-v0`` with every controller. :data:`COMMAND` runs it over :data:`EPISODES`
seeds, and ``tests/data/default_scenario.json`` keeps every episode's record except its timing
fields (``benchmarks.rollout.TIMING_FIELDS``), with the revision it was recorded at.
``tests/test_default_scenario_guard.py`` runs the same command and holds each controller's
metrics within their spread over those seeds.

In that scenario the MPC solves again from the measured state every 10 ms and hands the low
level a theta reference that starts there, so the theta task's error stays under 5e-5 rad and
its gains hardly move any metric (the theta task's Kp at 20 instead of 50 changes the RMS of
its error by 0.1 %). :func:`run_held_high_level` records the same env and the same seeds with
the low level alone in charge of the balance: ``unified`` with its high level's reference held
at the reset state's theta (at rest: no rate, no acceleration), pushed (:data:`HELD_PUSH`),
for :data:`HELD_STEPS` control steps; per seed, whether it fell and the theta task's largest
and last error. There the theta task's gains set the response: its error decays at about
``Kp / Kv`` per second.

Record again only when a change is meant to change the controllers' behaviour, and say why in
the commit: ``python -m tests.default_scenario_recording``.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

EPISODES = 5
SEED = 0
ENV_ID = "wip_gym/PlanarTray-v0"
#: the ``wip-bench`` arguments (``--out`` is added)
COMMAND = ("compare", "--env", ENV_ID, "--episodes", str(EPISODES), "--seed", str(SEED))
PATH = Path(__file__).resolve().parents[1] / "tests" / "data" / "default_scenario.json"
#: the low level alone (:func:`run_held_high_level`): the controller, its push (N, s, s: a
#: backward push at the torso, as docs/scenarios.md's) and its length in control steps
HELD_CONTROLLER = "unified"
HELD_PUSH = {"push_force": -100.0, "push_time": 0.2, "push_duration": 0.1}
HELD_STEPS = 2000


def run_default_scenario(jobs: int = 2) -> list[dict[str, Any]]:
    """The episodes of :data:`COMMAND` (``--jobs jobs``), their timing fields left out, in the
    order ``compare`` writes them."""
    from benchmarks.cli import main
    from benchmarks.rollout import without_timing

    with tempfile.TemporaryDirectory(prefix="wip-gym-default-") as out:
        code = main([*COMMAND, "--jobs", str(jobs), "--out", out])
        if code != 0:
            raise RuntimeError(f"wip-bench {' '.join(COMMAND)} exited with {code}")
        lines = (Path(out) / "episodes.jsonl").read_text().splitlines()
    episodes = [json.loads(line) for line in lines]
    return [without_timing(row) for row in episodes]


def run_held_high_level() -> list[dict[str, Any]]:
    """Per seed of the default scenario's, :data:`HELD_CONTROLLER` on :data:`ENV_ID` pushed
    (:data:`HELD_PUSH`) with its high level's reference held at the reset state's theta:
    ``fell`` (the env ended the episode) and the theta task's error (``robot.theta`` minus the
    held theta, the controller's ``theta_error``) at its largest and at the last step, in
    rows that :func:`run_default_scenario`'s comparison reads (``controller``, ``seed``, the
    outcome, the metrics, no counters)."""
    import wip_gym  # noqa: F401, PLC0415
    from controllers.high_level.receding_horizon import HighLevelSetpoint  # noqa: PLC0415
    from controllers.registry import make_policy  # noqa: PLC0415

    rows = []
    for seed in range(SEED, SEED + EPISODES):
        env = gym.make(ENV_ID, max_episode_steps=-1, **HELD_PUSH)
        try:
            obs, info = env.reset(seed=seed)
            policy: Any = make_policy(HELD_CONTROLLER, env)
            policy.reset(obs, info)
            held = HighLevelSetpoint(
                theta=policy.robot.theta, thetad=0.0, thdd=0.0, tau_0=0.0, mpc_index=0
            )
            policy.high_level.reference = lambda robot, held=held: held
            fell = False
            for _ in range(HELD_STEPS):
                obs, _, terminated, _, _ = env.step(policy(obs))
                if terminated:
                    fell = True
                    break
            error = np.abs(np.asarray(policy.diagnostics["theta_error"]))
        finally:
            env.close()
        rows.append(
            {
                "controller": f"{HELD_CONTROLLER}, high level held",
                "seed": seed,
                "fell": fell,
                "theta_error_peak_rad": float(error.max()),
                "theta_error_end_rad": float(error[-1]),
                "counters": {},
            }
        )
    return rows


def main() -> None:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    revision = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    record = {
        "command": "wip-bench " + " ".join(COMMAND),
        "revision": revision or "unknown",
        "episodes": run_default_scenario(),
        "high_level_held": {
            "controller": HELD_CONTROLLER,
            "push": HELD_PUSH,
            "steps": HELD_STEPS,
            "episodes": run_held_high_level(),
        },
    }
    PATH.parent.mkdir(parents=True, exist_ok=True)
    PATH.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {PATH} ({len(record['episodes'])} episodes at {record['revision']})")


if __name__ == "__main__":
    main()
