"""The MPC run beside the control loop (``HighLevelConfig.mpc_delay_steps``): the solve from
step ``k``'s state is used from step ``k + d`` on, whatever the machine's speed."""

from __future__ import annotations

import copy
import dataclasses
import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.high_level.mpc import ModelPredictiveController, MPCStep, params_from_vector
from controllers.high_level.receding_horizon import HighLevel, HighLevelConfig
from controllers.high_level.solve_thread import SolveThread
from controllers.low_level.compiled_step import rows_and_kernel
from controllers.low_level.kernel import kernel_step
from wip_gym.envs.measures import env_measures
from wip_gym.minimal_kernels import robot_update_at, wipm_inputs_into

STEPS = 45


def _run(delay: int) -> tuple[np.ndarray, list[Any], list[Any], HierarchicalController]:
    """``STEPS`` steps of PlanarTray; the actions, the MPC solution in use at each step, and
    every MPC call ``(index, state, params, solution)`` in the order made."""
    env = gym.make("wip_gym/PlanarTray-v0", max_episode_steps=-1)
    obs, info = env.reset(seed=4)
    config = HierarchicalConfig(high_level=HighLevelConfig(mpc_delay_steps=delay))
    policy = HierarchicalController.for_env(env, config)
    policy.reset(obs, info)
    mpc = policy.high_level.mpc
    calls: list[Any] = []
    inputs_from, run, take = mpc.inputs_from, mpc.run, mpc.take
    n = len(policy.plan.states[0])

    # a solve is its inputs (on the control thread), the compiled step on those inputs (in the
    # MPC's thread when delayed) and its outputs taken (on the control thread), one at a time
    def recorded_inputs(index: int, robot: Any) -> np.ndarray:
        assert all(call[3] is not None for call in calls), "inputs made before the last solve"
        host = inputs_from(index, robot)
        state, params = host[2 : 2 + n].copy(), params_from_vector(host[2 + n :].copy())
        calls.append([index, state, params, None, host, None])
        return host

    def recorded_run(host: np.ndarray) -> Any:
        outputs = run(host)
        (call,) = [call for call in calls if call[4] is host]
        call[5] = outputs
        return outputs

    def recorded_take(outputs: Any) -> MPCStep:
        solution = take(outputs)
        (call,) = [call for call in calls if call[5] is outputs]
        call[3] = solution
        return solution

    mpc.inputs_from = recorded_inputs  # type: ignore[method-assign]
    mpc.run = recorded_run  # type: ignore[method-assign]
    mpc.take = recorded_take  # type: ignore[method-assign]
    actions, in_use = [], []
    for _ in range(STEPS):
        action = policy(obs)
        actions.append(action)
        in_use.append(policy.high_level.last_solution)
        obs, *_ = env.step(action)
    env.close()
    return np.array(actions), in_use, calls, policy


def test_delayed_solutions_are_the_solves_of_d_steps_before() -> None:
    delay = 4
    actions, in_use, calls, policy = _run(delay)
    # one solve per 10 steps; step k uses the one started at the last tick at least d steps
    # before it (the first solve, at step 0, is synchronous)
    assert [index for index, *_ in calls] == [0, 1, 2, 3, 4]
    for k, solution in enumerate(in_use):
        tick = 0 if k < 10 + delay else (k - delay) // 10
        assert solution is calls[tick][3], k
    # the same solves made synchronously in the same order give the same solutions
    replay = ModelPredictiveController(policy.plan, policy.config.high_level.mpc)
    for index, state, params, solution, *_ in calls:
        again = replay.step(index, state, params)
        np.testing.assert_array_equal(again.predicted_states, solution.predicted_states)
        np.testing.assert_array_equal(again.predicted_controls, solution.predicted_controls)
    repeat, *_ = _run(delay)
    np.testing.assert_array_equal(actions, repeat)  # deterministic: no timing leaks in
    synchronous, *_ = _run(0)
    np.testing.assert_array_equal(actions[:10], synchronous[:10])
    assert np.abs(actions[10:] - synchronous[10:]).max() > 1e-6  # then an older prediction


def test_reset_with_a_solve_pending_and_rejections_counted_in_use() -> None:
    actions, in_use, calls, policy = _run(3)
    high_level = policy.high_level
    used = {id(solution): solution for solution in in_use}  # every solution taken into use
    assert high_level.rejections == sum(not s.accepted for s in used.values())
    env = gym.make("wip_gym/PlanarTray-v0", max_episode_steps=-1)
    obs, info = env.reset(seed=1)
    for _ in range(10):  # until a tick's solve is pending
        obs, *_ = env.step(policy(obs))
        if high_level._pending is not None:
            break
    assert high_level._pending is not None
    policy.reset(obs, info)
    assert high_level._pending is None and high_level.rejections == 0
    high_level.close()
    env.close()


def test_delay_is_validated_and_a_pending_solve_survives_pickling() -> None:
    with pytest.raises(ValueError, match="mpc_delay_steps"):
        HighLevel(HighLevelConfig(mpc_delay_steps=10), 1e-3)
    with pytest.raises(ValueError, match="mpc_delay_steps"):
        HighLevel(dataclasses.replace(HighLevelConfig(), mpc_delay_steps=-1), 1e-3)
    short = dataclasses.replace(HighLevelConfig().mpc, horizon_s=0.01)
    with pytest.raises(ValueError, match="at least 2 steps"):
        HighLevel(HighLevelConfig(mpc=short, mpc_delay_steps=3), 1e-3)
    high_level = HighLevel(HighLevelConfig(mpc_delay_steps=3), 1e-3)
    outputs = (np.arange(5.0), np.ones((2, 1)))
    thread = SolveThread("test-mpc")
    thread.submit(lambda: outputs)
    high_level._thread, high_level._pending = thread, (thread, 20)
    copy = pickle.loads(pickle.dumps(high_level))
    assert copy._thread is None and copy.config.mpc_delay_steps == 3
    assert copy._pending is not None and copy._pending[1] == 20
    (kept,) = copy._pending[0].result()[:1]
    np.testing.assert_array_equal(kept, np.arange(5.0))
    # the original keeps the outputs too, to take them at the same step
    assert high_level._pending is not None and high_level._pending[0].result() is outputs
    assert not thread.running
    thread.close()


def test_the_control_loops_compiled_calls_release_the_gil() -> None:
    """A delayed MPC's thread needs the GIL to start its solve and to take its result; the
    control thread holds it through Python and gives it up only in calls that release it
    (MuJoCo's ``mj_step``, and these compiled calls). Held through them, the solve took 1.4 to
    1.7 ms in its thread (0.85 to 0.97 ms since) and was often not done ``d = 5`` steps later."""
    kernels = (robot_update_at, rows_and_kernel, kernel_step, env_measures)
    for kernel in (*kernels, wipm_inputs_into):
        assert kernel.targetoptions.get("nogil") is True, kernel.__name__


@pytest.mark.parametrize("pickled", [False, True])
def test_a_copy_with_a_solve_pending_goes_on_as_the_original(pickled: bool) -> None:
    """A controller deep-copied or pickled while a solve runs beside its loop takes the same
    solution at the same step: on the same observations, the copy's next actions are the
    original's to the bit."""
    env = gym.make("wip_gym/PlanarTray-v0", max_episode_steps=-1)
    obs, info = env.reset(seed=5)
    config = HierarchicalConfig(high_level=HighLevelConfig(mpc_delay_steps=3))
    policy = HierarchicalController.for_env(env, config)
    policy.reset(obs, info)
    for _ in range(11):  # the tick at step 10 started a solve
        obs, *_ = env.step(policy(obs))
    assert policy.high_level._pending is not None
    twin = pickle.loads(pickle.dumps(policy)) if pickled else copy.deepcopy(policy)
    assert twin.high_level._thread is None and twin.high_level._pending is not None
    for k in range(25):  # both on the same observations
        action = policy(obs)
        np.testing.assert_array_equal(twin(obs), action, err_msg=f"step {k}")
        obs, *_ = env.step(action)
    policy.high_level.close()
    twin.high_level.close()
    env.close()


def test_a_failed_solve_is_raised_where_it_is_taken_and_the_thread_ends() -> None:
    """The solve's error is raised by the step that takes it, also after a copy made while it
    ran (kept, not lost); ``close`` ends the thread even then."""
    high_level = HighLevel(HighLevelConfig(mpc_delay_steps=3), 1e-3)

    def fail(*_: Any) -> None:
        raise FloatingPointError("the solve diverged")

    thread = SolveThread("test-mpc-fail")
    high_level._thread = thread
    thread.submit(fail)
    high_level._pending = (thread, 0)
    twin = copy.deepcopy(high_level)
    with pytest.raises(FloatingPointError, match="diverged"):
        twin._wait_pending()
    assert twin._pending is None
    with pytest.raises(FloatingPointError, match="diverged"):
        high_level.close()
    assert high_level._thread is None and not thread._thread.is_alive()


class _Interrupted:
    """A pending solve whose first wait is interrupted (``KeyboardInterrupt``), as by Ctrl-C."""

    def __init__(self, thread: SolveThread) -> None:
        self.thread, self.interrupted = thread, False

    def result(self) -> Any:
        if not self.interrupted:
            self.interrupted = True
            raise KeyboardInterrupt
        return self.thread.result()


def test_an_interrupted_wait_keeps_the_solve_and_reset_or_close_drain_it() -> None:
    """A wait interrupted by ``KeyboardInterrupt`` leaves the solve pending (a later wait takes
    it); ``_discard_pending`` (reset) drains a job left running with nothing pending; ``close``
    after an interrupted wait leaves nothing pending and can be called again."""
    high_level = HighLevel(HighLevelConfig(mpc_delay_steps=3), 1e-3)
    thread = SolveThread("test-mpc-interrupted")
    high_level._thread = thread
    thread.submit(lambda: 1)
    source = _Interrupted(thread)
    high_level._pending = (source, 0)  # type: ignore[assignment]
    with pytest.raises(KeyboardInterrupt):
        high_level._wait_pending()
    assert high_level._pending == (source, 0) and thread.running
    high_level._pending = None  # as if the interrupt had come between the submit and its record
    high_level._discard_pending()
    assert not thread.running
    # close interrupted while waiting: the thread ends, nothing stays pending, close again is fine
    thread.submit(lambda: 2)
    high_level._pending = (thread, 0)
    thread_result = thread.result

    def interrupted_result() -> Any:
        raise KeyboardInterrupt

    thread.result = interrupted_result  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        high_level.close()
    thread.result = thread_result  # type: ignore[method-assign]
    assert high_level._thread is None and high_level._pending is None
    assert not thread._thread.is_alive()
    high_level.close()
