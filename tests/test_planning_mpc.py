"""The offline plan, the MPC and the ``decoupled-mpc`` policy."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.baselines.decoupled import DecoupledLQRController
from controllers.baselines.decoupled_mpc import DecoupledMPCController
from controllers.high_level.mpc import ModelPredictiveController, pack_inputs, unpack_inputs
from controllers.high_level.planning import PlanConfig, plan_to_goal
from controllers.policy import make_robot
from controllers.simplified.wipm import WIPMParams, params_from_lambda, planar_dynamics
from controllers.simplified.wipm_problem import wipm_state


def robot_state(env_id: str, **kwargs):
    env = gym.make(env_id, **kwargs)
    obs, _ = env.reset(seed=0)
    robot = make_robot(env, "nominal")
    robot.update(obs["qpos"], obs["qvel"])
    return env, robot, params_from_lambda(robot.wipm_parameters()), wipm_state(robot)


def test_planar_plan_arrives_within_bounds() -> None:
    env, robot, params, state = robot_state("wip_gym/PlanarTray-v0")
    plan = plan_to_goal(state, params, np.array([2.0, 0.0]), planar=True, cup_friction=0.3)
    assert plan.violations == ()
    assert plan.converged
    assert plan.a_max == pytest.approx(0.5 * 0.3 * 9.81)
    assert plan.peak_acceleration <= plan.a_max
    assert plan.peak_theta <= plan.theta_max
    assert plan.arrival_time is not None and plan.arrival_time <= 0.6 * 20.0
    final = plan.states[-1]
    assert abs(final[2] - 2.0) < 0.01 and np.abs(final[[0, 1, 3]]).max() < 0.01
    assert plan.states.shape == (2001, 4) and plan.controls.shape == (2000, 1)
    indices = (0, 1000, 2000, 2001, 5000)  # inside the plan, its last state, past its end
    for index in indices:
        np.testing.assert_array_equal(plan.state(index), plan.window(index, 1)[0])
    np.testing.assert_array_equal(
        plan.states_at(np.array(indices)), [plan.state(index) for index in indices]
    )


def test_3d_plan_turns_to_an_offset_goal() -> None:
    env, robot, params, state = robot_state("wip_gym/KrangTray-v0")
    plan = plan_to_goal(state, params, np.array([2.0, 1.0]), planar=False, cup_friction=0.3)
    assert plan.violations == (), plan.violations
    final = plan.states[-1]
    assert np.hypot(final[6] - 2.0, final[7] - 1.0) < 0.01
    assert np.abs(final[[2, 3, 4, 5]]).max() < 0.01
    # it faced the goal (bearing 0.46 rad) and drove about the straight distance forward (no
    # spin, no detour); a WIP's brief backward lurch before it leans forward is allowed
    assert 0.2 < final[1] < 0.7
    assert np.hypot(2.0, 1.0) < final[0] < 1.15 * np.hypot(2.0, 1.0)
    # past its end the plan is continued until it rests (tests/test_plan_end.py holds the
    # reference continuous there); x (the distance rolled) is no part of the 3-D goal, so at
    # rest the plan holds the x its continuation ends at (it used to drop to 0 there: a 2.3 m
    # step in the reference of every controller that tracks x); the rest of the rest state is
    # within the plan's arrival tolerance (1 cm, 1 cm/s) of where the plan ended
    before = plan.sample(plan.times[-1] - 1e-9)
    after = plan.sample(plan.reference_times[-1] + 1.0)
    assert after["x"] == plan.reference_states[-1, 0] == plan.goal_state[0]
    assert after["x"] == pytest.approx(before["x"], abs=0.01)
    for name in ("xd", "theta", "thetad", "psi", "X0", "Y0"):
        assert after[name] == pytest.approx(before[name], abs=0.01), name


def test_violations_are_reported() -> None:
    env, robot, params, state = robot_state("wip_gym/Planar-v0")
    tight = PlanConfig(a_max=0.05, horizon_s=4.0)  # cannot arrive 3 m away in 2.4 s so gently
    plan = plan_to_goal(state, params, np.array([3.0, 0.0]), planar=True, config=tight)
    assert any("arrives" in v or "acceleration" in v for v in plan.violations)


def test_plan_rejects_bad_inputs() -> None:
    env, robot, params, state = robot_state("wip_gym/Planar-v0")
    with pytest.raises(ValueError, match="state"):
        plan_to_goal(state[:3], params, np.array([2.0, 0.0]), planar=True)
    with pytest.raises(ValueError, match="goal"):
        plan_to_goal(state, params, np.array([np.nan, 0.0]), planar=True)


def test_mpc_on_the_plan_reproduces_it_and_warm_starts() -> None:
    env, robot, params, state = robot_state("wip_gym/Planar-v0")
    plan = plan_to_goal(state, params, np.array([2.0, 0.0]), planar=True)
    mpc = ModelPredictiveController(plan)
    # from a state on the plan, the MPC's prediction follows the plan's positions (its own
    # weights differ from the plan's, so rates may differ slightly)
    for index in (0, 100, 300):
        step = mpc.step(index, plan.states[index], params)
        assert step.accepted
        predicted, planned = step.predicted_states[:20], plan.states[index : index + 20]
        np.testing.assert_allclose(predicted[:, [0, 2]], planned[:, [0, 2]], atol=5e-3)
    # past the plan's continuation the reference is its rest state, the goal (planar):
    # standing still at the goal is optimal
    assert mpc.rejected == 0 and mpc.solves == 3
    np.testing.assert_array_equal(plan.rest_state, plan.goal_state)
    fresh = ModelPredictiveController(plan)
    end = fresh.step(len(plan.reference_times) + 50, plan.goal_state, params)
    assert abs(end.control[0]) < 1e-9
    np.testing.assert_allclose(end.predicted_states, np.tile(plan.goal_state, (101, 1)), atol=1e-9)


def test_decoupled_tracks_the_plan() -> None:
    """The decoupled controller's reference obeys the WIPM it was planned on: from its value at
    one knot, an explicit Euler step of ``planar_dynamics`` under the plan's ``thdd`` gives its
    value at the next knot (for knots across the drive); between knots it lies between them."""
    env = gym.make("wip_gym/Planar-v0", goal=2.0)
    obs, info = env.reset(seed=0)
    policy = DecoupledLQRController.for_env(env)
    policy.reset(obs, info)
    plan = policy.plan
    assert plan is not None
    params = params_from_lambda(policy.robot.wipm_parameters())
    dt = plan.dt

    def reference_state(t: float) -> np.ndarray:
        ref = policy.reference(t)
        return np.array([ref["theta"], ref["thetad"], ref["x"], ref["xd"]])

    for k in (0, 150, 300, 450, 900):
        start, end = reference_state(k * dt), reference_state((k + 1) * dt)
        stepped = start + dt * np.asarray(planar_dynamics(start, plan.controls[k, 0], params))
        np.testing.assert_allclose(end, stepped, rtol=1e-9, atol=1e-12)
        middle = reference_state((k + 0.5) * dt)
        assert np.all(middle >= np.minimum(start, end) - 1e-15)
        assert np.all(middle <= np.maximum(start, end) + 1e-15)
    assert abs(policy.reference(3.0)["theta"]) > 1e-3  # it leans to accelerate: not 0


def closed_loop(env_id: str, goal, seconds: float = 14.0) -> dict:
    env = gym.make(env_id, goal=goal)
    obs, info = env.reset(seed=0)
    policy = DecoupledMPCController.for_env(env)
    policy.reset(obs, info)
    assert policy.plan_violations == ()
    for _ in range(int(seconds / env.unwrapped.dt)):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, info
    assert policy.diagnostics["mpc_rejected"][-1] == 0
    return info


@pytest.mark.parametrize(
    ("env_id", "goal"),
    [
        ("wip_gym/WIP-v0", (2.5, 1.0)),
        ("wip_gym/WIP-v0", (2.5, -1.0)),
        ("wip_gym/Planar-v0", 2.5),
        ("wip_gym/Krang-v0", (2.5, 0.0)),
    ],
)
def test_decoupled_mpc_drives_to_the_goal_and_stops(env_id: str, goal) -> None:
    info = closed_loop(env_id, goal)
    assert info["goal_distance"] < 0.05
    assert abs(info["xd"]) < 0.05


def test_the_packed_host_inputs_unpack_to_the_step_arguments() -> None:
    """``pack_inputs`` puts the MPC step's host inputs in one vector (one transfer per step);
    ``unpack_inputs``, inside the compiled step, gives back the index, the flag, the state and
    every leaf of ``lambda(q)`` exactly, in their shapes."""
    rng = np.random.default_rng(3)
    params = WIPMParams(*rng.normal(size=3), rng.normal(size=(3, 3)), *rng.normal(size=7))
    state = rng.normal(size=8)
    plan_states, plan_controls = np.zeros((40, 8)), np.zeros((40, 2))
    for index, first in ((0, True), (1234, False)):
        host = pack_inputs(index, first, state, params)
        assert host.shape == (2 + 8 + 19,)
        i, f, s, p, *rest = jax.jit(unpack_inputs)(host, np.zeros(2), plan_states, plan_controls)
        assert int(i) == index and bool(f) is first
        np.testing.assert_array_equal(s, state)
        for name, ours, theirs in zip(WIPMParams._fields, p, params, strict=True):
            assert np.shape(ours) == np.shape(theirs), name
            np.testing.assert_array_equal(ours, theirs, err_msg=name)
        np.testing.assert_array_equal(rest[1], plan_states)
    # leaves of other kinds (0-d arrays, Python floats, nested lists, JAX arrays) pack the same
    others = WIPMParams(
        np.asarray(params[0]),
        float(params[1]),
        jnp.asarray(params[2]),
        params.inertia_body.tolist(),
        *(np.asarray(leaf) for leaf in params[4:]),
    )
    np.testing.assert_array_equal(
        pack_inputs(7, False, state, others), pack_inputs(7, False, state, params)
    )
    # a parameter leaf of another size is refused
    with pytest.raises(ValueError, match="WIPM parameter of 4 entries"):
        pack_inputs(0, True, state, params._replace(inertia_body=np.eye(2)))
    # a state of another length than the plan's is refused, not read as parameters
    with pytest.raises(ValueError, match="packed MPC inputs"):
        unpack_inputs(
            pack_inputs(0, True, state, params), np.zeros(2), plan_states[:, :4], plan_controls
        )


def test_the_mpc_refuses_a_state_of_another_length_than_its_plan() -> None:
    env, robot, params, state = robot_state("wip_gym/Planar-v0")
    plan = plan_to_goal(state, params, np.array([0.5, 0.0]), planar=True)
    mpc = ModelPredictiveController(plan)
    with pytest.raises(ValueError, match="MPC state must have shape"):
        mpc.step(0, np.zeros(8), params)


@pytest.mark.parametrize("env_id", ["wip_gym/Planar-v0", "wip_gym/Krang-v0"])
def test_inputs_of_the_robots_vector_are_the_packed_inputs(env_id: str) -> None:
    """``inputs_of(index, robot.wipm_inputs())`` and ``inputs_from(index, robot)`` (the high
    level's path) are ``inputs(index, state, params_from_robot(robot))`` to the bit, the index
    clamped alike and the first flag set until a solve; a vector of another length or dtype, a
    state not finite, or a robot of the other kind is refused."""
    from controllers.simplified.wipm import params_from_robot

    env, robot, params, state = robot_state(env_id)
    plan = plan_to_goal(state, params, np.array([0.5, 0.0]), planar=robot.layout.planar)
    mpc = ModelPredictiveController(plan)
    vector, reference = robot.wipm_inputs(), params_from_robot(robot)
    for solved in (False, True):
        for index in (-3, 0, 7, len(plan.states) + 50):
            host = mpc.inputs_of(index, vector)
            np.testing.assert_array_equal(host, mpc.inputs(index, state, reference))
            np.testing.assert_array_equal(mpc.inputs_from(index, robot), host)
            assert host[1] == (not solved)
        mpc.solve(host)
    # a robot of the other kind (planar against 3-D): its vector does not fit the plan's
    other_env, other_robot, *_ = robot_state(
        "wip_gym/Krang-v0" if robot.layout.planar else "wip_gym/Planar-v0"
    )
    with pytest.raises(ValueError, match="out must be"):
        mpc.inputs_from(0, other_robot)
    other_env.close()
    n = len(state)
    for bad in (vector[:-1], vector.astype(np.float32), list(vector), np.append(vector, 0.0)):
        with pytest.raises(ValueError, match="float64 vector of shape"):
            mpc.inputs_of(0, bad)  # type: ignore[arg-type]
    broken = vector.copy()
    broken[n - 1] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        mpc.inputs_of(0, broken)
    env.close()


def test_decoupled_mpc_packs_the_parameters_of_each_mpc_step() -> None:
    """``decoupled-mpc`` packs ``lambda(q)`` once per MPC step: at every control step its packed
    vector is that of the high level's current parameters (new at every MPC step)."""
    import gymnasium as gym

    from controllers.high_level.mpc import param_values
    from controllers.registry import make_policy

    env = gym.make("wip_gym/Krang-v0")
    observation, info = env.reset(seed=1)
    policy = make_policy("decoupled-mpc", env)
    policy.reset(observation, info)
    previous, packings = None, 0
    for _ in range(25):
        action = policy(observation)
        packed = policy._packed_params()
        packings += packed is not previous
        previous = packed
        np.testing.assert_array_equal(packed, param_values(policy.high_level.params))
        observation, *_ = env.step(action)
    env.close()
    assert packings == 3  # MPC steps at 0, 10 and 20 ms


def test_decoupled_mpc_command_equals_the_wipm_functions() -> None:
    """``decoupled-mpc``'s one jitted call per step (``lambda(q)`` packed by ``param_values``)
    gives the wheels' torques and the base's accelerations of ``inverse_dynamics`` and
    ``spatial_dynamics`` (planar: ``planar_inverse_dynamics``, ``planar_dynamics``) called with
    the parameters as they are, to round-off (XLA compiles the two forms apart)."""
    from controllers.baselines.decoupled_mpc import _planar_command_jit, _spatial_command_jit
    from controllers.high_level.mpc import param_values
    from controllers.simplified.wipm import (
        inverse_dynamics,
        planar_dynamics,
        planar_inverse_dynamics,
        spatial_dynamics,
    )

    rng = np.random.default_rng(8)
    params = WIPMParams(
        *np.abs(rng.normal(1.0, 0.2, size=3)),
        np.diag(rng.uniform(0.5, 2.0, size=3)) + 0.01 * rng.normal(size=(3, 3)),
        *np.abs(rng.normal(1.0, 0.2, size=7)),
    )
    packed = np.array(param_values(params))
    for _ in range(20):
        state, u = rng.normal(scale=0.3, size=8), rng.normal(size=2)
        tau_left, tau_right = inverse_dynamics(state, u, params)
        sdot = spatial_dynamics(state, u, params)
        expected = np.array([tau_left, tau_right, sdot[3], sdot[4]])
        got = np.asarray(_spatial_command_jit(state, u, packed))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
        planar_state, thdd = rng.normal(scale=0.3, size=4), float(rng.normal())
        expected = np.array(
            [
                planar_inverse_dynamics(planar_state, thdd, params),
                planar_dynamics(planar_state, thdd, params)[3],
            ]
        )
        got = np.asarray(_planar_command_jit(planar_state, thdd, packed))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


def test_plan_sample_is_np_interp_of_each_state() -> None:
    """``Plan.sample`` (``np.interp``'s arithmetic for all quantities at once) gives the floats
    of ``np.interp`` per quantity of the reference (the plan, then its continuation): at random
    times, at the grid's times and just after them, before the start (the first state), at the
    plan's end and in its continuation, and at and after the continuation's end (the rest
    state); NaN refused."""
    env, robot, params, state = robot_state("wip_gym/Krang-v0")
    plan = plan_to_goal(state, params, np.array([0.6, 0.2]), planar=False)
    times, states = plan.reference_times, plan.reference_states
    assert len(times) > len(plan.times)  # the plan is continued past its end
    np.testing.assert_array_equal(times[: len(plan.times)], plan.times)
    rng = np.random.default_rng(5)
    queries = [
        *rng.uniform(times[0], times[-1], size=300),
        *times[::37],
        *(times[:-1:41] + 1e-12),
        -0.5,
        float(plan.times[-1]),
        float(times[-1]),
        times[-1] + 1.0,
    ]
    for t in queries:
        if t >= times[-1]:
            expected = plan.rest_state
        else:
            expected = np.array([np.interp(t, times, column) for column in states.T])
        got = np.array(list(plan.sample(float(t)).values()))
        np.testing.assert_array_equal(got, expected, err_msg=f"t = {t!r}")
    with pytest.raises(ValueError, match="NaN"):
        plan.sample(float("nan"))
    # the plan's arrays are read-only: the rows sample keeps cannot go stale
    with pytest.raises(ValueError, match="read-only"):
        plan.states[0, 0] = 1.0
    # a plan with a non-finite state is read through np.interp itself (its NaN cases)
    states = plan.states.copy()
    states[5, 2] = np.nan
    broken = dataclasses.replace(plan, states=states)
    for t in (times[4], times[5], 0.5 * (times[4] + times[5]), times[6]):
        expected = np.array([np.interp(t, plan.times, column) for column in states.T])
        np.testing.assert_array_equal(np.array(list(broken.sample(float(t)).values())), expected)
