"""The native vector env (wip_gym/vector, docs/vector.md): the single env N times, bit for bit,
through autoresets, with Gymnasium's vector conventions; its info batching against Gymnasium's
own; errors; close."""

from __future__ import annotations

import gc
import json
import threading
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.wrappers.vector import RecordEpisodeStatistics

import wip_gym
from benchmarks.speed import vector_env as vector_bench
from wip_gym.vector import WIPVectorEnv
from wip_gym.vector.infos import InfoBatcher

# quick ends: a small fall angle (terminations) and a short time limit (truncations)
QUICK_ENDS: dict[str, Any] = {"fall_angle": 0.1, "mass_randomization": 0.1}
QUICK_STEPS = 60


def assert_same(a: Any, b: Any, path: str = "") -> None:
    """Equal to the bit, with the same types, dtypes and shapes (dicts: the same keys)."""
    if isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{k}]")
    elif isinstance(a, dict):
        assert isinstance(b, dict), path
        assert set(a) == set(b), (path, sorted(set(a) ^ set(b)))
        for key in a:
            assert_same(a[key], b[key], f"{path}/{key}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), path
        assert (a.dtype, a.shape) == (b.dtype, b.shape), (path, a.dtype, b.dtype, a.shape, b.shape)
        if a.dtype == object:
            for x, y in zip(a, b, strict=True):
                assert_same(x, y, path + "[]")
        else:
            np.testing.assert_array_equal(a, b, err_msg=path, strict=True)
    else:
        assert type(a) is type(b), (path, type(a), type(b))
        assert a == b or (a != a and b != b), (path, a, b)


def random_actions(space: gym.spaces.Box, steps: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    return rng.uniform(0.3 * low, 0.3 * high, (steps, *space.shape))


@pytest.mark.parametrize("env_id", list(wip_gym.ENV_IDS))
def test_make_vec_makes_the_native_vector_env(env_id: str) -> None:
    vec = gym.make_vec(env_id, num_envs=3)
    single = gym.make(env_id)
    assert isinstance(vec, WIPVectorEnv) and vec.num_envs == 3
    assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert vec.single_observation_space == single.observation_space
    assert vec.single_action_space == single.action_space
    assert vec.observation_space == gym.vector.utils.batch_space(single.observation_space, 3)
    assert vec.action_space == gym.vector.utils.batch_space(single.action_space, 3)
    assert vec.spec is not None and vec.spec.id == env_id
    observation, info = vec.reset(seed=0)
    assert observation in vec.observation_space
    assert all(v.dtype == np.float64 and v.shape[0] == 3 for v in observation.values())
    observation, reward, terminated, truncated, info = vec.step(np.zeros(vec.action_space.shape))
    assert observation in vec.observation_space
    assert reward.dtype == np.float64 and reward.shape == (3,)
    assert terminated.dtype == truncated.dtype == np.bool_ and terminated.shape == (3,)
    for key, value in info.items():
        assert isinstance(value, np.ndarray) and value.shape[0] == 3, key
        if key.startswith("_"):
            assert value.dtype == np.bool_ and value.all() and key[1:] in info
        else:
            assert "_" + key in info
    vec.close()
    single.close()


def run_pair(
    env_id: str,
    mode: AutoresetMode,
    threads: int,
    steps: int = 300,
    limit: dict[str, Any] | None = None,
) -> tuple[int, int]:
    """The native vector env against Gymnasium's SyncVectorEnv of the same envs, step by step,
    to the bit (observations, rewards, ends, every info key, dtype and mask, final_obs and
    final_info); the numbers of terminations and truncations seen. ``limit``: how the
    episodes are cut short (default: ``max_episode_steps``, a ``TimeLimit`` counted beside
    the sub-env)."""
    limit = {"max_episode_steps": QUICK_STEPS} if limit is None else limit
    sync = gym.make_vec(
        env_id,
        num_envs=4,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": mode},
        **limit,
        **QUICK_ENDS,
    )
    native = gym.make_vec(
        env_id, num_envs=4, autoreset_mode=mode, num_threads=threads, **limit, **QUICK_ENDS
    )
    assert isinstance(sync, SyncVectorEnv) and isinstance(native, WIPVectorEnv)
    assert native.num_threads == threads
    assert native.metadata["autoreset_mode"] is mode
    assert_same(sync.reset(seed=5), native.reset(seed=5))
    terminations = truncations = 0
    for action in random_actions(native.action_space, steps):
        expected, got = sync.step(action), native.step(action)
        assert_same(expected, got)
        terminations += int(expected[2].sum())
        truncations += int(expected[3].sum())
        if mode is AutoresetMode.DISABLED and (expected[2] | expected[3]).any():
            mask = expected[2] | expected[3]
            assert_same(
                sync.reset(options={"reset_mask": mask.copy()}),
                native.reset(options={"reset_mask": mask.copy()}),
            )
    sync.close()
    native.close()
    return terminations, truncations


@pytest.mark.parametrize("mode", list(AutoresetMode))
@pytest.mark.parametrize("threads", [1, 2])
def test_equals_sync_vector_env_bit_for_bit(mode: AutoresetMode, threads: int) -> None:
    terminations, truncations = run_pair("wip_gym/PlanarTray-v0", mode, threads)
    assert terminations > 0 and truncations > 0  # the autoresets were exercised


def test_equals_sync_vector_env_in_3d() -> None:
    terminations, truncations = run_pair("wip_gym/WIP-v0", AutoresetMode.SAME_STEP, 2, 200)
    assert terminations + truncations > 0


@pytest.mark.parametrize(
    "env_id", ["wip_gym/Planar-v0", "wip_gym/Krang-v0", "wip_gym/KrangTray-v0"]
)
@pytest.mark.parametrize("threads", [1, 2])
def test_every_env_equals_sync_vector_env_on_the_fast_path(env_id: str, threads: int) -> None:
    """The fast path (each sub-env's _advance, the infos from its measures, wip_gym/vector/
    columns.py) for every observation and info layout: 2-D and 3-D, with and without a
    tray and an end effector; the episodes cut by the env's own time limit (no step count
    beside it: one thread steps the sub-envs in a plain loop)."""
    probe = gym.make_vec(env_id, num_envs=2, **QUICK_ENDS)
    assert probe.unwrapped._sub.fast
    probe.close()
    terminations, truncations = run_pair(
        env_id, AutoresetMode.NEXT_STEP, threads, 100, limit={"time_limit": 0.03}
    )
    assert truncations > 0  # and the steps after: every sub-env reset at once


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_every_sub_env_ending_at_once_equals_sync_vector_env(mode: AutoresetMode) -> None:
    """All sub-envs truncated in the same step and reset together (a step whose info has no
    reward terms at all, next-step; final infos for every sub-env, same-step)."""
    sync = gym.make_vec(
        "wip_gym/WIP-v0",
        num_envs=3,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": mode},
        max_episode_steps=3,
    )
    native = gym.make_vec("wip_gym/WIP-v0", num_envs=3, autoreset_mode=mode, max_episode_steps=3)
    assert native.unwrapped._sub.fast
    assert_same(sync.reset(seed=2), native.reset(seed=2))
    zeros = np.zeros(native.action_space.shape)
    for k in range(8):
        expected, got = sync.step(zeros), native.step(zeros)
        assert_same(expected, got)
        if k == 3 and mode is AutoresetMode.NEXT_STEP:
            assert "reward_progress" not in got[4]
    sync.close()
    native.close()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"fall_penalty": 10},  # an int penalty: the info's reward_fall is an int when it falls
        {"sensor_noise": 0.01},  # an observation perturbation: the observation is not the data
    ],
)
def test_the_dict_path_where_the_fast_one_does_not_apply(kwargs: dict[str, Any]) -> None:
    """Sub-envs whose infos' types may vary or whose observation is perturbed are stepped
    through their own step() and the dicts batched, still equal to SyncVectorEnv's."""
    sync = gym.make_vec(
        "wip_gym/Planar-v0",
        num_envs=3,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
        max_episode_steps=QUICK_STEPS,
        **QUICK_ENDS,
        **kwargs,
    )
    native = gym.make_vec(
        "wip_gym/Planar-v0",
        num_envs=3,
        autoreset_mode=AutoresetMode.SAME_STEP,
        max_episode_steps=QUICK_STEPS,
        **QUICK_ENDS,
        **kwargs,
    )
    assert not native.unwrapped._sub.fast
    assert_same(sync.reset(seed=4), native.reset(seed=4))
    ends = 0
    for action in random_actions(native.action_space, 80):
        expected, got = sync.step(action), native.step(action)
        assert_same(expected, got)
        ends += int((expected[2] | expected[3]).sum())
    assert ends > 0
    sync.close()
    native.close()


def test_sub_env_i_is_the_single_env_with_seed_s_plus_i() -> None:
    """Sub-env i against gym.make(id) reset with seed S + i, stepped with its actions and reset
    (unseeded) at the step after it ends, as the next-step autoreset does."""
    env_id, n, seed = "wip_gym/PlanarTray-v0", 3, 11
    native = gym.make_vec(env_id, num_envs=n, max_episode_steps=QUICK_STEPS, **QUICK_ENDS)
    singles = [gym.make(env_id, max_episode_steps=QUICK_STEPS, **QUICK_ENDS) for _ in range(n)]
    observation, info = native.reset(seed=seed)
    ended = [False] * n
    for i, single in enumerate(singles):
        own, own_info = single.reset(seed=seed + i)
        for key in own:
            assert_same(observation[key][i], own[key])
        for key, value in own_info.items():
            assert_same(np.asarray(info[key][i]), np.asarray(value))
    resets = 0
    for action in random_actions(native.action_space, 250, seed=3):
        observation, reward, terminated, truncated, info = native.step(action)
        for i, single in enumerate(singles):
            if ended[i]:
                own, own_info = single.reset()
                own_reward, own_terminated, own_truncated = 0.0, False, False
                resets += 1
            else:
                own, own_reward, own_terminated, own_truncated, own_info = single.step(action[i])
            ended[i] = own_terminated or own_truncated
            for key in own:
                assert_same(observation[key][i], own[key])
            assert reward[i] == own_reward and terminated[i] == own_terminated
            assert truncated[i] == own_truncated
            for key, value in own_info.items():
                assert info["_" + key][i], key
                assert_same(np.asarray(info[key][i]), np.asarray(value))
    assert resets > 0
    native.close()


def test_max_episode_steps_is_the_single_envs() -> None:
    registered = gym.spec("wip_gym/WIP-v0").max_episode_steps
    default = gym.make_vec("wip_gym/WIP-v0", num_envs=2)
    assert [env.spec.max_episode_steps for env in default.envs] == [registered] * 2
    short = gym.make_vec("wip_gym/WIP-v0", num_envs=2, max_episode_steps=5)
    short.reset(seed=0)
    zeros = np.zeros(short.action_space.shape)
    for _ in range(4):
        assert not short.step(zeros)[3].any()
    assert short.step(zeros)[3].all()
    default.close()
    short.close()


def test_observations_are_fresh_arrays_unless_copy_is_false() -> None:
    vec = gym.make_vec("wip_gym/PlanarTray-v0", num_envs=2)
    first, _ = vec.reset(seed=0)
    second = vec.step(np.zeros(vec.action_space.shape))[0]
    assert not np.shares_memory(first["qpos"], second["qpos"])
    shared = gym.make_vec("wip_gym/PlanarTray-v0", num_envs=2, copy=False)
    first, _ = shared.reset(seed=0)
    shared_second = shared.step(np.zeros(shared.action_space.shape))[0]
    assert first["qpos"] is shared_second["qpos"]
    assert_same(second, shared_second)  # the same values written into the buffers
    vec.close()
    shared.close()


def test_bad_input_raises() -> None:
    vec = gym.make_vec("wip_gym/Planar-v0", num_envs=2)
    zeros = np.zeros(vec.action_space.shape)
    with pytest.raises(ResetNeeded):
        vec.step(zeros)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((3, zeros.shape[1])))
    bad = zeros.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="sub-env 1: .*NaN"):
        vec.step(bad)
    with pytest.raises(ValueError, match="seed"):
        vec.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="reset_mask"):
        vec.reset(options={"reset_mask": np.zeros(2, dtype=bool)})
    vec.close()
    with pytest.raises(ValueError, match="render_mode='rgb_array'"):
        gym.make_vec("wip_gym/Planar-v0", num_envs=2, render_mode="human")
    with pytest.raises(ValueError, match="autoreset_mode"):
        gym.make_vec("wip_gym/Planar-v0", num_envs=2, autoreset_mode="Later")
    with pytest.raises(ValueError, match="num_envs"):
        WIPVectorEnv("wip_gym/Planar-v0", 0)
    disabled = gym.make_vec(
        "wip_gym/Planar-v0", num_envs=2, autoreset_mode="Disabled", max_episode_steps=1
    )
    disabled.reset(seed=0)
    disabled.step(zeros)
    with pytest.raises(RuntimeError, match="reset_mask"):
        disabled.step(zeros)
    disabled.close()


def test_close_stops_the_threads_and_closes_the_sub_envs() -> None:
    """With compiled steps a vector env of T threads has T - 1 of the compiled steps' team;
    closing (or collecting) it stops them."""
    before = threading.active_count()
    vec = gym.make_vec("wip_gym/WIP-v0", num_envs=4, num_threads=3)
    assert vec.unwrapped._sub.compiled is not None
    assert threading.active_count() == before + 2
    vec.reset(seed=0)
    vec.step(np.zeros(vec.action_space.shape))
    envs = vec.envs
    vec.close()
    assert vec.closed and threading.active_count() == before
    assert all(env.unwrapped.mujoco_renderer._viewers == {} for env in envs)
    vec.close()  # again: nothing to do
    # an env never closed stops its threads when it is collected
    forgotten = gym.make_vec("wip_gym/WIP-v0", num_envs=2, num_threads=2)
    assert threading.active_count() == before + 1
    del forgotten
    gc.collect()
    assert threading.active_count() == before


def test_rgb_frames_and_gymnasium_vector_wrappers() -> None:
    vec = RecordEpisodeStatistics(
        gym.make_vec(
            "wip_gym/Planar-v0",
            num_envs=2,
            render_mode="rgb_array",
            width=64,
            height=48,
            max_episode_steps=3,
        )
    )
    vec.reset(seed=0)
    frames = vec.render()
    assert len(frames) == 2 and frames[0].shape == (48, 64, 3)
    zeros = np.zeros(vec.action_space.shape)
    for _ in range(3):
        _, _, _, truncated, info = vec.step(zeros)
    assert truncated.all() and info["_episode"].all()
    np.testing.assert_array_equal(info["episode"]["l"], [3, 3])
    vec.close()


def test_the_benchmark_runs_and_reports_ratios(tmp_path: Path) -> None:
    """The speed benchmark's plumbing (no timing is asserted: speed is measured in
    benchmarks/, docs/vector.md §3)."""
    out = tmp_path / "bench.json"
    flags = ["--env", "wip_gym/WIP-v0", "--action", "zero", "--num-envs", "2", "--rounds", "2"]
    flags += ["--block", "0.05", "--contenders", "native", "sync", "--json", str(out)]
    results = vector_bench.main(flags)
    (result,) = json.loads(out.read_text())
    assert result == json.loads(json.dumps(results[0]))
    assert set(result["wall"]["ratio_to_single"]) == {"native", "sync"}
    assert all(r > 0 for r in result["wall"]["ratio_to_single"].values())
    assert len(result["wall"]["steps_per_s"]["single"]) == 1  # the warm-up round dropped
    split = vector_bench.gil_split("wip_gym/WIP-v0", 2, steps=20)
    assert 0 < split["native_compiled_us"] < split["native_us"]


# ---------------------------------------------------------------------- the info batching
class _Gymnasium(gym.vector.VectorEnv):  # type: ignore[type-arg]
    """Only for its ``_add_info``: Gymnasium's batching rule."""

    def __init__(self, n: int) -> None:
        self.num_envs = n


def gymnasium_batch(infos: list[dict[str, Any] | None], finals: Any = ()) -> dict[str, Any]:
    reference, out = _Gymnasium(len(infos)), {}
    ended = {i: (o, f) for i, o, f in finals}
    for i, info in enumerate(infos):
        if i in ended:
            out = reference._add_info(out, {"final_obs": ended[i][0], "final_info": ended[i][1]}, i)
        if info is not None:
            out = reference._add_info(out, info, i)
    return out


def batcher_batch(
    batcher: InfoBatcher, infos: list[dict[str, Any] | None], finals: Any = ()
) -> dict[str, Any]:
    for i, info in enumerate(infos):
        batcher.write(i, info)
    return batcher.batch(infos, finals)


def step_info(k: float) -> dict[str, Any]:
    return {
        "x": k,
        "fallen": k > 1,
        "count": int(k),
        "single": np.float32(k),
        "axle": np.array([k, 2 * k, 3 * k]),
        "flags": np.array([k > 0, k > 2]),
    }


def test_info_batcher_equals_gymnasiums_add_info() -> None:
    n = 4
    host = _Gymnasium(n)
    batcher = InfoBatcher(n, host._add_info)
    cases: list[tuple[list[dict[str, Any] | None], Any]] = [
        ([step_info(k) for k in range(n)], ()),  # first: a layout is taken
        ([step_info(k + 0.5) for k in range(n)], ()),  # the common step
        ([step_info(1.0), {"x": 0.0}, step_info(2.0), step_info(3.0)], ()),  # a reset's info
        ([{"x": 0.0}, step_info(1.0), step_info(2.0), step_info(3.0)], ()),  # the first resets
        ([step_info(1.0), None, step_info(2.0), step_info(3.0)], ()),  # no info from one
        (
            [step_info(1.0), {"x": 0.0}, step_info(2.0), step_info(3.0)],
            [(1, {"obs": np.zeros(2)}, step_info(9.0))],  # a same-step autoreset
        ),
        ([step_info(1.0), {**step_info(2.0), "x": True}, step_info(3.0), step_info(4.0)], ()),
        ([{**step_info(1.0), "x": 1}, step_info(2.0), step_info(3.0), step_info(4.0)], ()),
        ([{**step_info(1.0), "axle": np.zeros(2)}, *[step_info(k) for k in range(3)]], ()),
        ([step_info(1.0), {**step_info(2.0), "axle": np.zeros(1)}, *[step_info(0.0)] * 2], ()),
        ([{**step_info(k), "nested": {"a": k}} for k in range(n)], ()),
        ([{**step_info(k), "name": "wip"} for k in range(n)], ()),
        ([step_info(k + 7) for k in range(n)], ()),  # back to the common step
        ([{} for _ in range(n)], ()),
    ]
    for infos, finals in cases:
        try:
            expected = gymnasium_batch(infos, finals)
        except ValueError:  # arrays that do not broadcast: ours raises too
            with pytest.raises(ValueError):
                batcher_batch(batcher, infos, finals)
            continue
        assert_same(expected, batcher_batch(batcher, infos, finals))
    # after a step of other keys the layout is taken again, and the next step goes the fast
    # way: its masks are rows of one block (fresh and writable, as Gymnasium's)
    for k in range(2):
        common = [step_info(j + 0.25 * k) for j in range(n)]
        got = batcher_batch(batcher, common)
        assert_same(gymnasium_batch(common), got)
    assert got["_x"].base is got["_fallen"].base is not None and got["_x"].flags.writeable


@pytest.mark.parametrize(
    ("env_id", "events"),
    [
        ("wip_gym/PlanarTray-v0", {}),  # cup losses
        ("wip_gym/Planar-v0", {"payload_mass": 2.0, "payload_time": 0.02}),  # a payload due
    ],
)
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_steps_and_advance_mixed_equal_sync_vector_env(
    env_id: str, events: dict[str, Any], threads: int
) -> None:
    """A sub-env takes the compiled step (wip_gym/vector/compiled.py) except while an event
    is due (a payload until it is in the hand), at its first step and whenever its data
    changed: through payloads, falls, cup losses and time limits, the mixture equals
    SyncVectorEnv to the bit; both ways were taken. An action rejected in the compiled call
    raises the lowest sub-env's error, as ``_advance`` does, and the other sub-envs step."""
    kwargs: dict[str, Any] = {"max_episode_steps": QUICK_STEPS, **events, **QUICK_ENDS}
    sync = gym.make_vec(env_id, num_envs=4, vectorization_mode="sync", **kwargs)
    native = gym.make_vec(env_id, num_envs=4, num_threads=threads, **kwargs)
    compiled = native.unwrapped._sub.compiled
    assert compiled is not None
    assert_same(sync.reset(seed=9), native.reset(seed=9))
    steps = ends = lost = 0
    for action in random_actions(native.action_space, 200):
        expected, got = sync.step(action), native.step(action)
        assert_same(expected, got)
        info, none = got[4], np.zeros(4, dtype=np.bool_)
        steps += int(info.get("_reward_progress", none).sum())  # absent: every one reset
        ends += int((expected[2] | expected[3]).sum())
        lost += int((info.get("reward_cup_loss", none) < 0).sum())
    assert ends > 0
    assert lost > 0 or "Tray" not in env_id
    # the first steps (and, with a payload, those until it is in the hand) took _advance
    assert 0 < compiled.steps < steps - (60 if events else 0)
    action = np.zeros(native.action_space.shape)
    action[3, 0] = action[1, 0] = np.nan
    times = [env.unwrapped.data.time for env in native.envs]
    with pytest.raises(ValueError, match="sub-env 1: .*NaN"):
        native.step(action)
    moved = [env.unwrapped.data.time > t for env, t in zip(native.envs, times, strict=True)]
    assert moved == [True, False, True, False]
    sync.close()
    native.close()


@pytest.mark.parametrize("threads", [1, 2])
def test_the_fast_path_without_compiled_steps_equals_sync_vector_env(threads: int) -> None:
    """Sub-envs whose torques are perturbed (``Perturber.actuate`` is Python) keep their
    ``_advance`` on the fast path (their infos from the measures, their state copied from
    their views), still equal to SyncVectorEnv's."""
    probe = gym.make_vec("wip_gym/PlanarTray-v0", num_envs=2, torque_noise=0.05)
    assert probe.unwrapped._sub.fast and probe.unwrapped._sub.compiled is None
    probe.close()
    terminations, truncations = run_pair(
        "wip_gym/PlanarTray-v0",
        AutoresetMode.SAME_STEP,
        threads,
        150,
        limit={"max_episode_steps": QUICK_STEPS, "torque_noise": 0.05},
    )
    assert terminations + truncations > 0
