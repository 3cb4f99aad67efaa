"""Minimal-coordinate dynamics (paper eq. ``dyn``) against MuJoCo, for every robot.

Two levels: (1) MuJoCo's rigid-body dynamics with the rolling constraints imposed
exactly (a KKT solve, tests/dynamics_reference.py): round-off; (2) ``mj_forward`` with the wheels
rolling on the floor through MuJoCo's soft contacts: the contact's softness.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from dynamics_reference import (
    constrained_accelerations,
    random_minimal_state,
    sample_contact_states,
)

import wip_gym  # noqa: F401  (registers the envs)
from wip_gym.assets import mjcf_path
from wip_gym.robot_model import RobotModel
from wip_gym.small_linalg import (
    matmul_pattern,
    matmul_transposed_pattern,
    matvec_transposed_pattern,
    small_matmul,
    small_matvec,
)
from wip_gym.wheel_torques import generalized_to_wheel, wheel_to_generalized

ROBOTS = ["wip", "planar7", "krang"]


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request: pytest.FixtureRequest) -> RobotModel:
    model = mujoco.MjModel.from_xml_path(str(mjcf_path(f"scene_{request.param}.xml")))
    return RobotModel(model)


def test_layout_counts(robot: RobotModel) -> None:
    lay = robot.layout
    expected = {"wip": 3, "planar7": 7, "krang": 19}[
        robot.model.names.split(b"\0")[0].decode().split()[0]
    ]
    assert lay.n_min == expected
    assert lay.wheel_radius == pytest.approx(0.25)
    assert lay.nv == robot.model.nv


def test_full_state_round_trip(robot: RobotModel) -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q, nu))
        np.testing.assert_allclose(robot.q, q, atol=1e-12)
        np.testing.assert_allclose(robot.nu, nu, atol=1e-12)


def test_wipm_state_is_the_minimal_state_the_pitch_and_the_axle(robot: RobotModel) -> None:
    """``RobotModel.wipm_state`` (read from the compiled update's scalars) is, bit for bit, the
    state composed from the public accessors, on random states off the home pose."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        q, nu = random_minimal_state(robot, rng)
        axle_xy = rng.uniform(-3.0, 3.0, size=2)
        robot.update(*robot.full_state(q, nu, axle_xy))
        q_now, nu_now, axle = robot.q, robot.nu, robot.axle_position
        if robot.layout.planar:
            expected = [robot.theta, robot.thetad, q_now[0], nu_now[0]]
        else:
            expected = [
                *(q_now[0], q_now[1], robot.theta),
                *(nu_now[0], nu_now[1], robot.thetad),
                *(axle[0], axle[1]),
            ]
        state = robot.wipm_state()
        assert state.dtype == np.float64
        np.testing.assert_array_equal(state, np.array(expected))
        state[0] += 1.0  # a new array: the robot's state is not changed through it
        np.testing.assert_array_equal(robot.wipm_state(), np.array(expected))


def test_dynamics_equal_exact_constrained_dynamics(robot: RobotModel) -> None:
    """Level 1: A nu_dot + h = B tau reproduces MuJoCo's constrained dynamics to 1e-9."""
    rng = np.random.default_rng(1)
    model = robot.model
    worst = 0.0
    for _ in range(20):
        q, nu = random_minimal_state(robot, rng)
        qpos, qvel = robot.full_state(q, nu)
        ctrl = rng.uniform(-1, 1, model.nu) * model.actuator_ctrlrange[:, 1]
        robot.update(qpos, qvel)
        nu_dot = robot.accelerations(ctrl)
        reference = constrained_accelerations(model, qpos, qvel, ctrl, robot)
        qacc = robot.full_accelerations(nu_dot)
        worst = max(worst, np.linalg.norm(qacc - reference) / np.linalg.norm(reference))
        assert np.linalg.norm(qacc - reference) <= 1e-9 * np.linalg.norm(reference)
        # and the equation itself, in minimal coordinates
        nu_dot_ref = np.linalg.lstsq(robot.J_tf, reference - robot.Jdot_tf_nu, rcond=None)[0]
        residual = robot.A @ nu_dot_ref + robot.h - robot.B @ ctrl
        assert np.linalg.norm(residual) <= 1e-9 * np.linalg.norm(robot.B @ ctrl - robot.h)
    print(f"exact level: worst relative error {worst:.1e}")


def test_dynamics_match_mujoco_contact(robot: RobotModel) -> None:
    """Level 2: against mj_forward with the wheels on the floor through contact.

    Per sample: ``||a - a_mj|| / max(||a_mj||, 1)`` on the minimal accelerations (MuJoCo's qacc
    mapped back through J_tf); median under 2e-3, max under 2e-2. In 3-D the heading rate is
    zero here: MuJoCo's contacts are velocity-level (``J qacc = a_ref``, the ``Jdot qvel`` term of
    the rolling constraint is left to the reference's damping), so while turning the instantaneous
    accelerations lack the wheels' centripetal terms until a small side slip builds up; see
    test_turning_contact_difference_is_the_omitted_term.
    """
    rng = np.random.default_rng(2)
    errors = []
    for qpos, qvel, ctrl, data in sample_contact_states(
        robot, robot.model, rng, 100, turning=False
    ):
        robot.update(qpos, qvel)
        nu_dot = robot.accelerations(ctrl)
        nu_dot_mj = np.linalg.lstsq(robot.J_tf, data.qacc - robot.Jdot_tf_nu, rcond=None)[0]
        errors.append(np.linalg.norm(nu_dot - nu_dot_mj) / max(np.linalg.norm(nu_dot_mj), 1.0))
    errors = np.array(errors)
    print(f"contact level: median {np.median(errors):.1e}, max {errors.max():.1e}")
    assert np.median(errors) < 2e-3, np.median(errors)
    assert errors.max() < 2e-2, errors.max()


def test_turning_contact_difference_is_the_omitted_term() -> None:
    """While turning, MuJoCo's instantaneous contact accelerations differ from the rigid rolling
    ones by the constraint's ``Jdot qvel`` (MuJoCo imposes ``J qacc = a_ref``): imposing the
    rolling constraint as ``G a = 0`` instead of ``G a = -Gdot v`` in the KKT referee reproduces
    mj_forward to the contact's softness."""
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_wip.xml")))
    robot = RobotModel(model)
    rng = np.random.default_rng(3)
    exact_errors, velocity_level_errors = [], []
    for qpos, qvel, ctrl, data in sample_contact_states(robot, model, rng, 30, turning=True):
        exact = constrained_accelerations(model, qpos, qvel, ctrl, robot)
        velocity_level = constrained_accelerations(model, qpos, qvel, ctrl, robot, with_jdot=False)
        scale = max(np.linalg.norm(data.qacc), 1.0)
        exact_errors.append(np.linalg.norm(exact - data.qacc) / scale)
        velocity_level_errors.append(np.linalg.norm(velocity_level - data.qacc) / scale)
    assert np.median(velocity_level_errors) < 2e-3
    assert np.median(exact_errors) > 5 * np.median(velocity_level_errors)


def _contact_point_jacobian(robot: RobotModel, wheel: int) -> np.ndarray:
    model, data = robot.model, robot.data
    jacp = np.zeros((3, model.nv))
    point = data.xpos[wheel] - np.array([0.0, 0.0, robot.layout.wheel_radius])
    mujoco.mj_jac(model, data, jacp, None, point, wheel)
    return jacp


def test_transform_keeps_wheels_rolling_without_slip(robot: RobotModel) -> None:
    rng = np.random.default_rng(4)
    for _ in range(10):
        q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q, nu))
        qvel = robot.J_tf @ robot.nu
        for wheel in robot.layout.wheel_bodies:
            velocity = _contact_point_jacobian(robot, wheel) @ qvel
            assert np.linalg.norm(velocity) < 1e-12 * max(1.0, np.linalg.norm(qvel))


def test_jdot_tf_and_thetad_match_finite_differences(robot: RobotModel) -> None:
    rng = np.random.default_rng(5)
    eps = 1e-6
    for _ in range(10):
        q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q, nu))
        jdot_nu = robot.Jdot_tf_nu.copy()
        thetad = robot.thetad
        sides = []
        for sign in (1.0, -1.0):
            robot.update(*robot.full_state(q + sign * eps * nu, nu))
            sides.append((robot.J_tf @ nu, robot.theta))
        fd_jdot = (sides[0][0] - sides[1][0]) / (2 * eps)
        fd_thetad = (sides[0][1] - sides[1][1]) / (2 * eps)
        np.testing.assert_allclose(jdot_nu, fd_jdot, atol=1e-7 * max(1.0, np.abs(fd_jdot).max()))
        assert thetad == pytest.approx(fd_thetad, abs=1e-7)


def test_wheel_torque_map_matches_mujoco_actuation(robot: RobotModel) -> None:
    """B's wheel columns put (tau_L + tau_R) / r on x, tau_0 on psi and tau_1 on q1."""
    lay = robot.layout
    rng = np.random.default_rng(6)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    for _ in range(5):
        tau_left, tau_right = rng.uniform(-150, 150, 2)
        ctrl = np.zeros(robot.model.nu)
        ctrl[lay.wheel_actuators[0]] = tau_left
        ctrl[lay.wheel_actuators[1]] = tau_right
        generalized = robot.B @ ctrl
        tau_0, tau_1 = wheel_to_generalized(
            tau_left, tau_right, lay.wheel_radius, lay.wheel_separation
        )
        assert generalized[lay.index_x] == pytest.approx(-tau_1 / lay.wheel_radius)
        assert generalized[lay.index_q1] == pytest.approx(tau_1)
        if lay.index_psi is not None:
            assert generalized[lay.index_psi] == pytest.approx(tau_0)
        others = np.delete(
            generalized,
            [lay.index_x, lay.index_q1] + ([lay.index_psi] if lay.index_psi is not None else []),
        )
        np.testing.assert_allclose(others, 0.0, atol=1e-12)
        back = generalized_to_wheel(tau_0, tau_1, lay.wheel_radius, lay.wheel_separation)
        np.testing.assert_allclose(back, (tau_left, tau_right), rtol=1e-12)


def test_wip_lambda_gives_back_the_body() -> None:
    """For the one-link wip, lambda(q) is the body's own mass, CoM distance and axle inertia."""
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_wip.xml")))
    robot = RobotModel(model)
    base = robot.layout.base_body
    mass = model.body_mass[base]
    com_local = model.body_ipos[base]
    inertia_com_y = model.body_inertia[base][1]  # diagonal inertial, axes aligned with base
    distance = np.hypot(com_local[0], com_local[2])
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, nu = random_minimal_state(robot, rng)
        robot.update(*robot.full_state(q, nu))
        params = robot.wipm_parameters()
        assert params.body_mass == pytest.approx(mass, rel=1e-12)
        assert params.com_distance == pytest.approx(distance, rel=1e-12)
        assert params.pitch_inertia == pytest.approx(inertia_com_y + mass * distance**2, rel=1e-12)
        assert params.inertia_axle[1, 1] == pytest.approx(params.pitch_inertia, rel=1e-12)
        assert params.theta == pytest.approx(
            q[robot.layout.index_q1] + np.arctan2(com_local[0], com_local[2]), abs=1e-12
        )
        assert params.wheel_mass == pytest.approx(4.66)
        assert params.wheel_inertia == pytest.approx(0.102)


def test_pitch_inertia_is_the_axle_component_of_the_body_inertia(robot: RobotModel) -> None:
    rng = np.random.default_rng(8)
    q, nu = random_minimal_state(robot, rng)
    robot.update(*robot.full_state(q, nu))
    params = robot.wipm_parameters()
    assert params.inertia_axle[1, 1] == pytest.approx(params.pitch_inertia, rel=1e-10)


def test_bad_state_raises(robot: RobotModel) -> None:
    lay = robot.layout
    with pytest.raises(ValueError, match="shape"):
        robot.update(np.zeros(lay.nq + 1), np.zeros(lay.nv))
    with pytest.raises(ValueError, match="NaN"):
        robot.update(np.full(lay.nq, np.nan), np.zeros(lay.nv))
    # a refused state leaves the last one as it was
    qpos, qvel = robot.full_state(*random_minimal_state(robot, np.random.default_rng(9)))
    robot.update(qpos, qvel)
    held = [robot.q, robot.nu, robot.data.qpos, robot.data.qvel, robot.data.xpos]
    held += list(robot.update_buffers().values())
    before = [a.copy() for a in held]
    bad = qvel.copy()
    bad[-1] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        robot.update(qpos, bad)
    for array, value in zip(held, before, strict=True):
        np.testing.assert_array_equal(array, value)


def _states_on_and_off_the_manifold(
    robot: RobotModel, seed: int, count: int = 6
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Random full states: every other one on the rolling manifold (``full_state``), the rest
    moved off it (position by 1e-4, velocity by 1e-2, the base quaternion normalised)."""
    rng = np.random.default_rng(seed)
    for k in range(count):
        qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
        if k % 2:
            qpos = qpos + 1e-4 * rng.normal(size=qpos.shape)
            qvel = qvel + 1e-2 * rng.normal(size=qvel.shape)
            if not robot.layout.planar:
                qpos[3:7] /= np.linalg.norm(qpos[3:7])
        yield qpos, qvel


def _com_jacobian_less_origin(robot: RobotModel, mass: float) -> np.ndarray:
    """The body CoM's (wheels excluded, of ``mass``) world Jacobian less the base origin's,
    over MuJoCo's dofs, at the robot's last update, as ``RobotModel`` computed it before the
    compiled kernel: the base subtree's CoM Jacobian times its mass, less each wheel's,
    divided by ``mass`` (NumPy's elementwise operations, in that order)."""
    m, d, lay = robot.model, robot.data, robot.layout
    base = lay.base_body
    jacp, jac_wheel, jac_origin = (np.zeros((3, m.nv)) for _ in range(3))
    mujoco.mj_jacSubtreeCom(m, d, jacp, base)
    Jc = jacp * m.body_subtreemass[base]
    for w in lay.wheel_bodies:
        mujoco.mj_jac(m, d, jac_wheel, None, d.xipos[w], w)
        Jc -= m.body_mass[w] * jac_wheel
    Jc /= mass
    mujoco.mj_jac(m, d, jac_origin, None, d.xpos[base], base)
    return Jc - jac_origin


def test_compiled_arithmetic_equals_numpy(robot: RobotModel) -> None:
    """``wip_gym.minimal_kernels`` against the NumPy expressions it replaced, on random
    states on and off the rolling manifold: ``A``, ``h``, ``B`` of eq. ``dyn``, the body CoM in
    the axle frame, its Jacobian, ``theta``, ``thetad`` and ``J_theta``."""
    m, d, lay = robot.model, robot.data, robot.layout
    for qpos, qvel in _states_on_and_off_the_manifold(robot, seed=17):
        robot.update(qpos, qvel)
        J = robot.J_tf
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        bias = np.zeros(m.nv)
        mujoco.mj_rne(m, d, 0, bias)
        scale = max(1.0, float(np.abs(M).max()))
        np.testing.assert_allclose(robot.A, J.T @ M @ J, rtol=0, atol=1e-12 * scale)
        h = J.T @ (M @ robot.Jdot_tf_nu + bias - d.qfrc_passive)
        np.testing.assert_allclose(robot.h, h, rtol=0, atol=1e-12 * max(1.0, np.abs(h).max()))
        S = np.zeros((m.nv, m.nu))
        for a in range(m.nu):
            S[m.jnt_dofadr[m.actuator_trnid[a, 0]], a] = m.actuator_gear[a, 0]
        np.testing.assert_allclose(robot.B, J.T @ S, rtol=0, atol=1e-12)
        # the body CoM, as RobotModel computed it before the compiled kernel
        ids = np.array(lay.body_bodies)
        masses = m.body_mass[ids]
        mass = masses.sum()
        origin = d.xpos[lay.base_body]
        Rt = robot.heading_rotation.T
        rel = Rt @ (masses @ d.xipos[ids] / mass - origin)
        J_rel = Rt @ (_com_jacobian_less_origin(robot, mass) @ J)
        if not lay.planar:
            J_rel[0, 1] += rel[1]
            J_rel[1, 1] -= rel[0]
        X, Z = rel[0], rel[2]
        J_theta = (Z * J_rel[0] - X * J_rel[2]) / (X * X + Z * Z)
        np.testing.assert_allclose(robot.body_mass, mass, rtol=1e-15)
        np.testing.assert_allclose(robot.com, rel, rtol=0, atol=1e-14)
        np.testing.assert_allclose(robot.J_com, J_rel, rtol=0, atol=1e-13)
        assert robot.theta == pytest.approx(np.arctan2(X, Z), abs=1e-14)
        np.testing.assert_allclose(robot.J_theta, J_theta, rtol=0, atol=1e-12)
        assert robot.thetad == pytest.approx(float(J_theta @ robot.nu), abs=1e-12)


def test_dynamics_in_place_equal_the_pattern_products_to_the_bit(robot: RobotModel) -> None:
    """``minimal_dynamics_into`` (rows of ``J^T M`` by the mass matrix's symmetry, the
    nonzero entries of ``Jdot_tf nu`` only, into the update's buffers) adds the same terms in
    the same order as ``small_linalg``'s pattern products it replaced, and ``body_com_into``
    the same operations as the update's arithmetic before it wrote in place: ``A``, ``h``,
    ``B``, the CoM, its Jacobian, ``J_theta``, the mass, ``theta`` and ``thetad`` equal to the
    bit, on random states on and off the rolling manifold. (``_M``, ``_bias``, ``_S``: the
    update's own mass matrix, bias and actuator map buffers.)"""
    d, lay = robot.data, robot.layout
    for qpos, qvel in _states_on_and_off_the_manifold(robot, seed=23):
        robot.update(qpos, qvel)
        M, J, pattern = robot._M, robot.J_tf, robot.J_tf_pattern
        assert np.array_equal(M, M.T)  # what the rows of J^T M rely on
        A = matmul_transposed_pattern(J, pattern, matmul_pattern(M, J, pattern))
        y = small_matvec(M, robot.Jdot_tf_nu) + robot._bias - d.qfrc_passive
        np.testing.assert_array_equal(robot.A, A)
        np.testing.assert_array_equal(robot.h, matvec_transposed_pattern(J, pattern, y))
        np.testing.assert_array_equal(robot.B, matmul_transposed_pattern(J, pattern, robot._S))
        # the body's CoM as the update computed it before writing in place, operation for
        # operation (NumPy's elementwise arithmetic is the same IEEE arithmetic)
        m, base = robot.model, lay.base_body
        ids = np.array(lay.body_bodies)
        mass = 0.0
        for i in ids:
            mass += float(m.body_mass[i])
        world = np.zeros(3)
        for i in ids:
            for a in range(3):
                world[a] += m.body_mass[i] * d.xipos[i, a]
        world /= mass
        offset = world - d.xpos[base]
        J_rel = matmul_pattern(_com_jacobian_less_origin(robot, mass), J, pattern)
        if lay.planar:
            com = offset
        else:
            c, s = robot.heading_rotation[0, 0], robot.heading_rotation[1, 0]
            ox, oy = offset[0], offset[1]
            com = np.array([c * ox + s * oy, -s * ox + c * oy, offset[2]])
            J_rel = np.array([c * J_rel[0] + s * J_rel[1], -s * J_rel[0] + c * J_rel[1], J_rel[2]])
            J_rel[0, 1] += com[1]
            J_rel[1, 1] -= com[0]
        X, Z = com[0], com[2]
        J_theta = (Z * J_rel[0] - X * J_rel[2]) / (X * X + Z * Z)
        thetad = 0.0
        for i in range(len(J_theta)):
            thetad += J_theta[i] * robot.nu[i]
        np.testing.assert_array_equal(robot.com, com)
        np.testing.assert_array_equal(robot.J_com, J_rel)
        np.testing.assert_array_equal(robot.J_theta, J_theta)
        assert (robot.body_mass, robot.theta, robot.thetad) == (mass, math.atan2(X, Z), thetad)


@pytest.mark.parametrize("source", [*ROBOTS, "wip_gym/KrangTray-v0", "wip_gym/PlanarTray-v0"])
def test_transform_jacobian_is_nonzero_only_in_its_pattern(source: str) -> None:
    """``J_tf_pattern``, which the compiled products with ``J_tf`` visit, holds every nonzero
    entry of ``J_tf`` at random states, on and off the rolling manifold (a random base
    orientation: headings and pitches of every quadrant, roll), of every robot and of the tray
    envs' models (a cup's free joint among the dofs); each entry once, each nonzero at some
    state (no wasted work), column by column, int64, read-only."""
    if source in ROBOTS:
        robot = RobotModel(mujoco.MjModel.from_xml_path(str(mjcf_path(f"scene_{source}.xml"))))
    else:
        env = gym.make(source)
        robot = RobotModel(env.unwrapped.model)
        env.close()
    rng = np.random.default_rng(23)
    pattern = robot.J_tf_pattern
    assert pattern.dtype == np.int64 and pattern.ndim == 2 and pattern.shape[0] == 2
    rows, columns = pattern
    shape = (robot.model.nv, robot.layout.n_min)
    assert np.unique(rows * shape[1] + columns).size == rows.size
    outside = np.ones(shape, dtype=bool)
    outside[rows, columns] = False
    seen = np.zeros(shape, dtype=bool)
    lay = robot.layout
    for k in range(40):
        q, nu = random_minimal_state(robot, rng)
        qpos, qvel = robot.full_state(q, nu)
        if k % 2:
            qpos = qpos + 1e-2 * rng.normal(size=qpos.shape)
            qvel = qvel + rng.normal(size=qvel.shape)
            if not lay.planar:
                quat = qpos[lay.root_qpos + 3 : lay.root_qpos + 7]
                quat[:] = rng.normal(size=4)
                quat /= np.linalg.norm(quat)
        robot.update(qpos, qvel)
        assert not robot.J_tf[outside].any()
        seen |= robot.J_tf != 0.0
    assert seen[rows, columns].all()
    assert (np.diff(columns) >= 0).all()
    with pytest.raises(ValueError, match="read-only"):
        robot.J_tf_pattern[0, 0] = 1


def test_model_and_data_are_fixed(robot: RobotModel) -> None:
    """A robot model's MuJoCo model and data cannot be swapped (its compiled calls hold views
    and addresses of their buffers)."""
    with pytest.raises(AttributeError):
        robot.model = robot.model  # type: ignore[misc]
    with pytest.raises(AttributeError):
        robot.data = mujoco.MjData(robot.model)  # type: ignore[misc]


def test_pattern_products_equal_dense_products() -> None:
    """``wip_gym.small_linalg``'s products over a sparsity pattern against NumPy's dense
    products, on a random matrix with zeros outside its pattern (and the pattern's columns in
    any order, repeated columns included); its loops for small operands likewise."""
    rng = np.random.default_rng(5)
    S = np.zeros((24, 19))
    rows, columns = rng.integers(0, 24, 40), rng.integers(0, 19, 40)
    S[rows, columns] = rng.normal(size=40)
    pattern = np.array(np.nonzero(S), dtype=np.int64)[:, rng.permutation(np.count_nonzero(S))]
    pattern = np.ascontiguousarray(pattern)
    pattern.flags.writeable = False  # as RobotModel.J_tf_pattern: the signature it runs with
    A, B, x = rng.normal(size=(7, 24)), rng.normal(size=(24, 5)), rng.normal(size=24)
    np.testing.assert_allclose(matmul_pattern(A, S, pattern), A @ S, rtol=0, atol=1e-13)
    np.testing.assert_allclose(
        matmul_transposed_pattern(S, pattern, B), S.T @ B, rtol=0, atol=1e-13
    )
    np.testing.assert_allclose(
        matvec_transposed_pattern(S, pattern, x), S.T @ x, rtol=0, atol=1e-13
    )
    # and the loops for small operands
    y, R = rng.normal(size=19), rng.normal(size=(3, 7))
    np.testing.assert_allclose(small_matvec(S, y), S @ y, rtol=0, atol=1e-13)
    np.testing.assert_allclose(small_matmul(R, A), R @ A, rtol=0, atol=1e-13)


def test_body_inertia_about_the_axle_equals_the_sum_over_bodies(robot: RobotModel) -> None:
    """``body_inertia_about_axle`` (compiled) against the parallel-axis sum written with
    NumPy, on random states; its pitch entry is ``A[q1, q1]`` (eq. ``dyn``'s inertia)."""
    m, d, lay = robot.model, robot.data, robot.layout
    rng = np.random.default_rng(23)
    for _ in range(4):
        robot.update(*robot.full_state(*random_minimal_state(robot, rng)))
        ids = np.array(lay.body_bodies)
        Rh = robot.heading_rotation
        rot = np.einsum("ji,njk->nik", Rh, d.ximat[ids].reshape(-1, 3, 3))  # Rh^T R_i
        inertia = np.einsum("nij,nj,nkj->ik", rot, m.body_inertia[ids], rot)
        p = (d.xipos[ids] - d.xpos[lay.base_body]) @ Rh
        outer = np.einsum("ni,nj->nij", p, p)
        squares = np.einsum("ni,ni->n", p, p)[:, None, None] * np.eye(3)
        inertia += np.einsum("n,nij->ij", m.body_mass[ids], squares - outer)
        np.testing.assert_allclose(robot.body_inertia_about_axle(), inertia, rtol=0, atol=1e-12)
        pitch = robot.body_inertia_about_axle()[1, 1]
        assert pitch == pytest.approx(robot.A[lay.index_q1, lay.index_q1], rel=1e-10)


def test_the_readable_update_equals_the_fast_one_to_the_bit(robot: RobotModel) -> None:
    """A model made with the fast path switched off (``wip_gym.mujoco_c.set_fast_path``) updates
    through MuJoCo's Python bindings: every output, the WIPM's inputs and MuJoCo's data equal
    the fast path's to the bit, on and off the rolling manifold, with and without dynamics."""
    from wip_gym import mujoco_c

    assert robot.fast_path
    mujoco_c.set_fast_path(False)
    try:
        readable = RobotModel(robot.model)
    finally:
        mujoco_c.set_fast_path(None)
    assert not readable.fast_path
    assert RobotModel(robot.model).fast_path  # the default again
    for k, (qpos, qvel) in enumerate(_states_on_and_off_the_manifold(robot, 31)):
        dynamics = k != 3
        for model in (robot, readable):
            model.update(qpos, qvel, dynamics=dynamics)
        outputs = [lambda r: r.q, lambda r: r.nu, lambda r: r.J_tf, lambda r: r.Jdot_tf_nu]
        outputs += [lambda r: r.com, lambda r: r.J_com, lambda r: r.J_theta]
        outputs += [lambda r: r.update_scalars(), lambda r: r.wipm_inputs()]
        outputs += [lambda r: r.data.xpos, lambda r: r.data.qvel, lambda r: r.data.cdof]
        if dynamics:
            outputs += [lambda r: r.A, lambda r: r.h, lambda r: r.B]
        for output in outputs:
            np.testing.assert_array_equal(output(readable), output(robot))
        assert readable.has_dynamics is dynamics
    with pytest.raises(ValueError, match="NaN or inf"):
        readable.update(np.full(robot.layout.nq, np.nan), np.zeros(robot.layout.nv))
