"""The PPO example (examples/train_ppo.py) for a few thousand steps, and its checkpoint as the
``ppo`` controller (docs/learning.md §8): the losses are finite, the checkpoint reloads to the
jitted network's actions, the controller holds its action over the env's shorter steps to the
same trajectory, runs in ``wip-bench compare``, survives a copy, and refuses what it cannot
drive."""

from __future__ import annotations

import copy
import json
import math
import os
import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.cli import main as bench_main
from controllers.learned import LearnedConfig, LearnedController, load_checkpoint
from controllers.registry import controller_names, default_controller_names, make_policy
from wip_gym.wrappers import ObservationNormalizer, RandomGoal

ROOT = Path(__file__).resolve().parents[1]
STEPS, NUM_ENVS, ROLLOUT = 3072, 4, 64


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short training run on WIP-v0 at a 10 ms control step (3,072 env steps, an
    evaluation every 1,024 on two 0.5 s episodes)."""
    out = tmp_path_factory.mktemp("ppo")
    command = [
        sys.executable,
        str(ROOT / "examples" / "train_ppo.py"),
        *("--env", "wip_gym/WIP-v0", "--frame-skip", "10", "--steps", str(STEPS)),
        *("--num-envs", str(NUM_ENVS), "--rollout", str(ROLLOUT), "--epochs", "2"),
        *("--minibatches", "2", "--eval-every", "1024", "--eval-seeds", "2"),
        *("--eval-duration", "0.5", "--goal-low", "-3", "-3", "--goal-high", "3", "3"),
        *("--plot", "--out", str(out)),
    ]
    environment = {**os.environ, "PYTHONPATH": str(ROOT), "MUJOCO_GL": "egl"}
    result = subprocess.run(command, capture_output=True, text=True, env=environment, cwd=ROOT)
    assert result.returncode == 0, result.stderr[-3000:]
    return out


def test_the_example_trains_with_finite_losses_and_writes_its_curve(run: Path) -> None:
    lines = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert len(lines) == STEPS // (NUM_ENVS * ROLLOUT)
    assert [line["env_steps"] for line in lines] == [
        (k + 1) * NUM_ENVS * ROLLOUT for k in range(len(lines))
    ]
    for line in lines:
        for key in ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction", "std"):
            assert math.isfinite(line[key]), (key, line)
    # the policy moved: its updates changed the log-probabilities of the collected actions
    assert any(line["approx_kl"] > 0.0 for line in lines)
    curve = json.loads((run / "curve.json").read_text())
    assert [point["env_steps"] for point in curve] == [1024, 2048, 3072]
    for point in curve:
        assert 0.0 <= point["success_rate"] <= 1.0 and len(point["final_goal_error_m"]) == 2
    assert (run / "curve.png").stat().st_size > 0
    meta = load_checkpoint(run / "checkpoint.npz").meta
    assert meta["env_id"] == "wip_gym/WIP-v0" and meta["control_dt"] == pytest.approx(0.01)
    assert meta["training"]["env_steps"] == STEPS


def test_the_checkpoint_reloads_to_the_jitted_networks_actions(run: Path) -> None:
    probe = np.load(run / "probe.npz")
    checkpoint = load_checkpoint(run / "checkpoint.npz")
    mean = checkpoint.mean_action(probe["observations"])
    # float32 weights in both; NumPy evaluates in float64
    np.testing.assert_allclose(mean, probe["mean_actions"], rtol=1e-4, atol=1e-6)
    # the controller from the raw observation of the same resets (the example's probes are
    # resets of its training env: a goal drawn in its box by the reset's seed)
    env = RandomGoal(gym.make("wip_gym/WIP-v0", frame_skip=10), (-3, -3), (3, 3))
    policy = make_policy("ppo", env, LearnedConfig(checkpoint=str(run / "checkpoint.npz")))
    limit = env.unwrapped.action_space.high.astype(float)
    for seed in range(len(mean)):
        obs, _ = env.reset(seed=seed)
        expected = np.clip(probe["mean_actions"][seed], -1, 1) * limit
        np.testing.assert_allclose(policy.action(obs), expected, rtol=1e-4, atol=1e-4)


def _trajectory(checkpoint: Path, frame_skip: int, policy_steps: int) -> np.ndarray:
    env = gym.make("wip_gym/WIP-v0", frame_skip=frame_skip, fall_angle=10.0)
    policy = make_policy("ppo", env, LearnedConfig(checkpoint=str(checkpoint)))
    assert policy.hold_steps == 10 // frame_skip
    obs, info = env.reset(seed=3)
    policy.reset(obs, info)
    states = [obs["qpos"]]
    for n in range(1, policy_steps * policy.hold_steps + 1):
        obs, *_ = env.step(policy(obs))
        if n % policy.hold_steps == 0:
            states.append(obs["qpos"])
    return np.array(states)


def test_the_controller_holds_its_action_on_the_1_ms_env_to_the_same_trajectory(
    run: Path,
) -> None:
    """Trained at 10 ms: on the 1 ms env it acts every 10 steps and holds the torque in
    between, which drives MuJoCo exactly as frame_skip=10 does."""
    checkpoint = run / "checkpoint.npz"
    held = _trajectory(checkpoint, 1, 50)
    skipped = _trajectory(checkpoint, 10, 50)
    np.testing.assert_array_equal(held, skipped)
    assert np.abs(held[-1] - held[0]).max() > 1e-3  # the robot moved


def test_the_controller_runs_in_compare_beside_the_model_based_ones(
    run: Path, tmp_path: Path
) -> None:
    code = bench_main(
        [
            "compare",
            *("--env", "wip_gym/WIP-v0", "--controllers", "ppo,decoupled"),
            *("--set", f"ppo.checkpoint={run / 'checkpoint.npz'}"),
            *("--episodes", "1", "--duration", "0.3", "--out", str(tmp_path)),
        ]
    )
    assert code == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert list(summary["controllers"]) == ["ppo", "decoupled"]
    ppo = summary["controllers"]["ppo"]
    assert ppo["config"]["checkpoint"] == str(run / "checkpoint.npz")
    assert set(ppo["counters"]) >= {"policy_clip_steps", "clipped_steps"}
    # the learned policy is named, never a default
    assert "ppo" in controller_names() and "ppo" not in default_controller_names()


def test_a_copied_controller_goes_on_as_the_original(run: Path) -> None:
    env = gym.make("wip_gym/WIP-v0")
    policy = make_policy("ppo", env, LearnedConfig(checkpoint=str(run / "checkpoint.npz")))
    obs, info = env.reset(seed=1)
    policy.reset(obs, info)
    for _ in range(15):  # mid-hold
        obs, *_ = env.step(policy(obs))
    for twin in (copy.deepcopy(policy), pickle.loads(pickle.dumps(policy))):
        a, b = copy.deepcopy(policy), twin
        state = obs
        for _ in range(25):
            action = a(state)
            np.testing.assert_array_equal(b(state), action)
            state, *_ = env.step(action)


def test_what_the_controller_refuses(run: Path) -> None:
    checkpoint = str(run / "checkpoint.npz")
    with pytest.raises(ValueError, match="observes"):  # another robot
        make_policy("ppo", gym.make("wip_gym/Planar-v0"), LearnedConfig(checkpoint=checkpoint))
    with pytest.raises(ValueError, match="must divide"):  # 3 ms does not divide 10 ms
        make_policy(
            "ppo", gym.make("wip_gym/WIP-v0", frame_skip=3), LearnedConfig(checkpoint=checkpoint)
        )
    with pytest.raises(ValueError, match="must divide"):  # a longer step than the policy's
        make_policy(
            "ppo", gym.make("wip_gym/WIP-v0", frame_skip=20), LearnedConfig(checkpoint=checkpoint)
        )
    with pytest.raises(ValueError, match="no checkpoint at"):
        make_policy("ppo", gym.make("wip_gym/WIP-v0"), LearnedConfig(checkpoint="/nonexistent"))
    with pytest.raises(ValueError, match="no shipped ppo checkpoint for wip_gym/Krang-v0"):
        make_policy("ppo", gym.make("wip_gym/Krang-v0"))
    with pytest.raises(ValueError, match="LearnedConfig"):
        LearnedController.for_env(gym.make("wip_gym/WIP-v0"), object())
    assert ObservationNormalizer.for_env(gym.make("wip_gym/WIP-v0")).size == 13


@pytest.mark.parametrize("env_id", ["wip_gym/Planar-v0", "wip_gym/WIP-v0"])
def test_the_shipped_policy_balances_and_ends_at_the_goal(env_id: str) -> None:
    """The checkpoint shipped for the env, as ``wip-bench compare`` runs it on the env's
    default task: it balances the 25 s and ends within 5 cm of the goal, slower than 5 cm/s
    (``success``), in at least 8 of 10 seeds (docs/learning.md §8). At a 10 ms env step: the
    policy's own, on which the 1 ms env's held actions give the same trajectory (above)."""
    from benchmarks.rollout import rollout
    from controllers.registry import default_config

    config = default_config("ppo")
    rows = [
        rollout(env_id, {"frame_skip": 10}, "ppo", config, seed, 25.0).metrics for seed in range(10)
    ]
    assert sum(r["success"] for r in rows) >= 8, [r["final_goal_error_m"] for r in rows]
    assert not any(r["fell"] for r in rows)
