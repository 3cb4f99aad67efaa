"""The envs' time limit in simulated seconds, whatever ``frame_skip`` is, with Gymnasium's
``max_episode_steps`` still usable on top; and the goal of one episode set at its reset
(docs/learning.md §4)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import wip_gym
from wip_gym.registration import EPISODE_SECONDS


def _first_truncation(env: gym.Env, steps: int) -> int | None:
    """Zero torques (the robot falls and lies on the floor: the time limit does not care) for at
    most ``steps`` steps; the 1-based index of the first truncated step, None if none."""
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape)
    for n in range(1, steps + 1):
        *_, truncated, _ = env.step(action)
        if truncated:
            return n
    return None


@pytest.mark.parametrize(("frame_skip", "steps"), [(10, 2500), (1, 25000), (7, 3572)])
def test_an_episode_is_truncated_after_25_simulated_seconds(frame_skip: int, steps: int) -> None:
    """2,500 steps at 10 ms, 25,000 at 1 ms; at 7 ms the first step whose end reaches 25 s
    (3,572 x 7 ms = 25.004 s; 3,571 steps are 24.997 s)."""
    env = gym.make("wip_gym/WIP-v0", frame_skip=frame_skip)
    assert _first_truncation(env, steps + 5) == steps
    assert math.isclose(env.unwrapped.data.time, steps * frame_skip * 1e-3, abs_tol=1e-9)
    # the next episode starts its clock again
    assert _first_truncation(env, steps + 5) == steps
    env.close()


def test_the_specs_register_no_step_count_and_the_env_its_limit() -> None:
    for env_id in wip_gym.ENV_IDS:
        assert gym.spec(env_id).max_episode_steps is None, env_id
    env = gym.make("wip_gym/Planar-v0", frame_skip=10)
    assert env.unwrapped.time_limit == EPISODE_SECONDS == 25.0
    assert env.unwrapped.arguments["time_limit"] == 25.0
    env.close()


def test_max_episode_steps_still_adds_a_time_limit_and_minus_one_none() -> None:
    shorter = gym.make("wip_gym/WIP-v0", frame_skip=10, max_episode_steps=100)
    assert _first_truncation(shorter, 200) == 100
    # a longer TimeLimit: the env's own 25 s come first
    longer = gym.make("wip_gym/WIP-v0", frame_skip=10, max_episode_steps=3000)
    assert _first_truncation(longer, 3100) == 2500
    # neither: the episode runs on
    unlimited = gym.make("wip_gym/WIP-v0", frame_skip=10, max_episode_steps=-1, time_limit=None)
    assert _first_truncation(unlimited, 2600) is None
    assert math.isclose(unlimited.unwrapped.data.time, 26.0, abs_tol=1e-9)
    one_second = gym.make("wip_gym/WIP-v0", frame_skip=10, time_limit=1.0)
    assert _first_truncation(one_second, 200) == 100


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, "25", True])
def test_a_bad_time_limit_raises(bad: object) -> None:
    with pytest.raises(ValueError, match="time_limit must be None or a positive number"):
        gym.make("wip_gym/WIP-v0", time_limit=bad)


def test_a_reset_option_sets_the_goal_of_one_episode() -> None:
    env = gym.make("wip_gym/WIP-v0")
    base = env.unwrapped
    obs, info = env.reset(seed=3, options={"goal": (1.0, -2.0)})
    np.testing.assert_array_equal(obs["goal"], [1.0, -2.0])
    axle = info["axle_position"]
    assert info["goal_distance"] == pytest.approx(math.hypot(1.0 - axle[0], -2.0 - axle[1]))
    np.testing.assert_array_equal(base.model.site_pos[base.model.site("goal").id, :2], [1, -2])
    np.testing.assert_array_equal(base.goal, [1.0, -2.0])
    # the reward's progress is measured to this goal
    obs, _, _, _, step_info = env.step(np.full(2, 20.0))
    assert step_info["reward_progress"] == pytest.approx(
        info["goal_distance"] - step_info["goal_distance"], abs=1e-15
    )
    axle = step_info["axle_position"]
    assert step_info["goal_distance"] == pytest.approx(math.hypot(1.0 - axle[0], -2.0 - axle[1]))
    # a reset without it: the goal the env was made with
    obs, info = env.reset(seed=3)
    np.testing.assert_array_equal(obs["goal"], [2.0, 0.0])
    env.close()


def test_a_reset_with_the_default_goal_as_option_is_the_same_episode() -> None:
    def run(options: dict | None) -> list[np.ndarray]:
        env = gym.make("wip_gym/Planar-v0")
        obs, info = env.reset(seed=5, options=options)
        trace = [np.concatenate([obs["qpos"], obs["qvel"], obs["goal"], [info["goal_distance"]]])]
        for _ in range(50):
            obs, reward, *_, info = env.step(np.full(env.action_space.shape, 1.0))
            trace.append(np.concatenate([obs["qpos"], obs["qvel"], [reward, info["theta"]]]))
        env.close()
        return trace

    np.testing.assert_array_equal(np.concatenate(run(None)), np.concatenate(run({"goal": 2.0})))


def test_bad_reset_options_raise() -> None:
    planar = gym.make("wip_gym/Planar-v0")
    planar.reset(seed=0, options={"goal": 1.5})
    with pytest.raises(ValueError, match="a planar robot's goal has y = 0"):
        planar.reset(seed=0, options={"goal": (1.0, 1.0)})
    with pytest.raises(ValueError, match="unknown reset options"):
        planar.reset(seed=0, options={"target": 1.0})
    with pytest.raises(ValueError, match="goal must be a finite"):
        planar.reset(seed=0, options={"goal": math.nan})


def test_the_vector_env_truncates_in_seconds_as_the_single_env() -> None:
    """``gym.make_vec`` (the native vector env, docs/vector.md) adds no step count: each sub-env
    truncates at its own ``time_limit``, at the step the single env does, and resets after it."""
    vec = gym.make_vec("wip_gym/WIP-v0", num_envs=2, frame_skip=10, time_limit=0.05)
    assert type(vec).__name__ == "WIPDriveVectorEnv"
    single = gym.make("wip_gym/WIP-v0", frame_skip=10, time_limit=0.05)
    assert _first_truncation(single, 10) == 5
    vec.reset(seed=0)
    zeros = np.zeros(vec.action_space.shape)
    for _ in range(4):
        _, _, terminated, truncated, _ = vec.step(zeros)
        assert not truncated.any() and not terminated.any()
    _, _, terminated, truncated, _ = vec.step(zeros)
    assert truncated.all() and not terminated.any()
    # next-step autoreset: the clock starts again
    vec.step(zeros)
    assert [env.unwrapped.data.time for env in vec.envs] == [0.0, 0.0]
    vec.close()
    single.close()
