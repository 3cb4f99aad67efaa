"""The carried object's rows as objects of the task QP (controllers/low_level/object_tasks.py).

Their compiled rows (``compiled_tasks.tangential_force_rows``, ``axle_acceleration_rows``,
``object_balance_rows``, in the one-call step) against the readable path and against
``ObjectBalance``, the reference held to MuJoCo by tests/test_object_balance.py, on random
states of both tray robots, on and off the rolling manifold, with the cup off the plate's
centre. And ``unified-upright``'s QP with the rows as objects (``PriorityQP.solve`` with
``balance_rows``) against the same QP with the rows as arrays (``ExtraRows``) at every step of
a closed-loop drive, weighted and strict (strict: the drive row a task in both, traded with the
posture as ``UprightConfig.strict_posture_rows`` says)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wip_gym  # noqa: F401
from benchmarks.overrides import resolve_run
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.object_balance import CarriedObject, ObjectBalance
from controllers.low_level.object_tasks import (
    AxleAccelerationTask,
    ObjectBalanceConstraint,
    TangentialForceTask,
)
from controllers.low_level.priority_qp import ExtraRows, PriorityQP
from controllers.low_level.task_qp import QPSettings, TaskQP
from controllers.registry import make_policy
from tests.robot_states import random_states, robot_at_reset

ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")


def _close(actual: np.ndarray, expected: np.ndarray, tol: float = 1e-12) -> None:
    scale = max(1.0, float(np.abs(expected).max())) if expected.size else 1.0
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=tol * scale)


@pytest.mark.parametrize("env_id", ENVS)
def test_compiled_rows_equal_the_readable_rows_and_the_object_balance(env_id: str) -> None:
    env, robot = robot_at_reset(env_id)
    model = robot.model
    site = model.site("tray_top").id
    balance = ObjectBalance(robot, site, CarriedObject(place=(0.03, -0.02)), friction=0.3)
    drive = AxleAccelerationTask(7.0)
    tasks = [TangentialForceTask(balance, robot, 30.0), drive]
    constraints = [ObjectBalanceConstraint(balance, robot)]
    low, high = model.actuator_ctrlrange.T.copy()
    compiled = TaskQP(robot, low, high, QPSettings())
    readable = TaskQP(robot, low, high, QPSettings(compiled_tasks=False))
    probe = MotionProbe(robot)
    rng = np.random.default_rng(4)
    for qpos, qvel in random_states(robot, rng, 8):
        robot.update(qpos, qvel)
        drive.target = float(rng.normal())
        kernels = []
        for qp in (compiled, readable):
            qp.assemble(robot, None, tasks, constraints)
            kernels.append(qp.kernel)
        assert compiled.compiled and not readable.compiled
        ours, theirs = kernels
        for name in ("J", "target", "jdot_nu", "w", "G", "constraint_bias"):
            _close(getattr(ours, name), getattr(theirs, name))
        for name in ("constraint_lower", "constraint_upper"):
            np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name))
        # the reference: ObjectBalance at the same state
        probe.update(robot)
        T, t = balance.tangential(robot, probe)
        G, b = balance.rows(robot, probe)
        _close(ours.J[:2], T)
        _close(ours.jdot_nu[:2], t)
        _close(ours.G, G)
        _close(ours.constraint_bias, b)
        assert np.all(ours.constraint_upper == 0.0) and np.all(ours.constraint_lower == -np.inf)
        assert ours.J[2, 0] == 1.0 and ours.target[2] == drive.target
        assert np.abs(t).max() > 1e-3 and np.abs(ours.jdot_nu[:2] - t).max() < 1e-9


#: how far the strict stack's answer may move with its rows' round-off: DAQP's lexicographic
#: solve (``priorities.RHO_SOFT`` regularisation) moved the actuators by up to 3e-5 of their
#: scale when a level's rows were only permuted, at this drive's first state
STRICT_ROUND_OFF = 1e-4


@pytest.mark.parametrize(
    ("priority", "seconds", "tol"), [("weighted", 1.5, 1e-7), ("strict", 0.15, STRICT_ROUND_OFF)]
)
def test_the_qp_with_the_rows_as_objects_equals_the_qp_with_the_rows_as_arrays(
    priority: str, seconds: float, tol: float
) -> None:
    """At every step of ``unified-upright``'s aggressive drive (PlanarTray-v0, friction 0.05,
    told 0.03 so that the balance rows bind): the step's answer (its rows computed in the
    one-call step, the balance rows its QP's last constraint rows) against the same QP with
    the rows as arrays from ``ObjectBalance`` (``ExtraRows``, the path it replaced), on a
    second task QP at the same state: equal to ``tol`` of the actuators' scale, relaxed at the
    same steps, and (weighted) active at the same steps."""
    overrides = {
        "env.goal": 1.0,
        "plan.horizon_s": 3.0,
        "plan.a_max": "none",
        "env.cup_friction": 0.05,
        "unified-upright.carried.friction": 0.03,
        "unified-upright.priority": priority,
    }
    spec = resolve_run("wip_gym/PlanarTray-v0", ["unified-upright"], None, overrides=overrides)
    env = gym.make("wip_gym/PlanarTray-v0", **spec.env_kwargs)
    observation, info = env.reset(seed=0)
    policy = make_policy("unified-upright", env, spec.configs["unified-upright"])
    policy.reset(observation, info)
    cfg, robot, balance = policy.config, policy.robot, policy.balance
    reference = PriorityQP(
        TaskQP(robot, policy.task.torque_low, policy.task.torque_high, cfg.qp), cfg.slack_weight
    )
    reference.qp.note_solved()
    solve = policy.priority_qp.solve
    counts = {"steps": 0, "active": 0}

    def checked(*args, **kwargs):
        step = solve(*args, **kwargs)
        probe = reference.qp.motion
        probe.update(robot)
        motion = balance.tray_motion(robot, probe)
        T, t = balance.tangential(robot, probe, motion)
        drive = policy._drive  # noqa: SLF001 - the drive row's task of this step
        if priority == "weighted":
            tasks, moved = policy.tasks, ()
            A = np.vstack([cfg.tangential_weight * T, np.eye(1, len(robot.nu))[0] * drive.weight])
            a = np.concatenate([cfg.tangential_weight * t, [-drive.weight * drive.target]])
        else:  # the drive a task, so that it can be in the posture level with the hand's row
            tasks, moved = [*policy.tasks, drive], policy._posture_rows  # noqa: SLF001
            A, a = cfg.tangential_weight * T, cfg.tangential_weight * t
        rows = ExtraRows((A, a), balance.rows(robot, probe, motion))
        expected = reference.solve(
            robot, tasks, policy.constraints, priority, rows, posture_rows=moved
        )
        ours, theirs = step.solution, expected.solution
        assert ours.solved and theirs.solved
        _close(ours.actuators, theirs.actuators, tol)
        _close(ours.nu_dot, theirs.nu_dot, tol)
        assert step.relaxed == expected.relaxed
        if priority == "weighted":  # strict: a row at its bound to 1e-9 counts as active
            assert step.active == expected.active
        counts["steps"] += 1
        counts["active"] += step.active
        return step

    policy.priority_qp.solve = checked
    for _ in range(int(round(seconds / env.unwrapped.dt))):
        observation, _, terminated, _, info = env.step(policy(observation))
        assert not terminated
    assert counts["steps"] == int(round(seconds / env.unwrapped.dt))
    assert counts["active"] > 0, counts  # the balance rows bound: the soft path was compared
