"""The WIPM (controllers/simplified/wipm.py) against MuJoCo.

The ``wip`` robot is one rigid body on two wheels: the WIPM is exact for it. Level 1: MuJoCo's
rigid-body dynamics with the rolling constraints imposed exactly (a KKT solve,
tests/dynamics_reference.py), to round-off; level 2: ``mj_forward`` with the wheels rolling on
the floor through MuJoCo's soft contacts, to the contact's softness. A "skewed" wip (its CoM
moved ahead and sideways, its inertia tensor rotated off the axes) exercises the lateral CoM, the
products of inertia and the rotation of ``lambda(q)``'s inertia into the CoM frame.
"""

from __future__ import annotations

import copy
import pickle

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from dynamics_reference import (
    constrained_accelerations,
    random_minimal_state,
    sample_contact_states,
)

from controllers.high_level.mpc import param_values
from controllers.simplified import wipm
from wip_gym.assets import mjcf_path
from wip_gym.minimal_kernels import robot_update_at, wipm_values
from wip_gym.robot_model import WIPM_SCALARS, RobotModel
from wip_gym.wheel_torques import generalized_to_wheel, wheel_to_generalized

spatial_torque_dynamics = jax.jit(wipm.spatial_torque_dynamics)
spatial_dynamics = jax.jit(wipm.spatial_dynamics)
inverse_dynamics = jax.jit(wipm.inverse_dynamics)
planar_dynamics = jax.jit(wipm.planar_dynamics)
planar_torque_dynamics = jax.jit(wipm.planar_torque_dynamics)
planar_inverse_dynamics = jax.jit(wipm.planar_inverse_dynamics)
linearize = jax.jit(wipm.linearize, static_argnums=0)


def _paper_printed_planar_dynamics(
    s: jax.Array, u: jax.Array, params: wipm.WIPMParams
) -> jax.Array:
    """The paper's eq. ``WIPdyn`` AS PRINTED (wrong; docs/ERRATA.md §1).

    ``xdd = (g sin th - R sin th thd^2 - (beta + cos th) u) / (alpha + cos th)`` with the printed
    ``alpha = R/(M L) (M + m_w + I_w/R^2)`` and ``beta = I/(M L)`` (``m_w``, ``I_w`` of both
    wheels). Same state and control as ``wipm.planar_dynamics``.
    """
    s = jnp.asarray(s)
    thdd = jnp.reshape(jnp.asarray(u), (-1,))[0]
    th, thd, xd = s[0], s[1], s[3]
    R, g = params.wheel_radius, params.gravity
    alpha, beta = wipm._planar_alpha_beta(params)
    c, sn = jnp.cos(th), jnp.sin(th)
    xdd = (g * sn - R * sn * thd**2 - (beta + c) * thdd) / (alpha + c)
    return jnp.stack([thd, thdd, xd, xdd])


paper_printed_planar_dynamics = jax.jit(_paper_printed_planar_dynamics)


def _wip_model(skewed: bool = False) -> mujoco.MjModel:
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_wip.xml")))
    if skewed:
        base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base")
        model.body_ipos[base] = (0.07, 0.04, 0.30)
        quat = np.array([0.9, 0.2, -0.3, 0.25])
        model.body_iquat[base] = quat / np.linalg.norm(quat)
        model.body_inertia[base] = (21.0, 15.0, 9.0)
    return model


@pytest.fixture(scope="module")
def wip() -> RobotModel:
    return RobotModel(_wip_model())


def _spatial_state(robot: RobotModel) -> np.ndarray:
    """WIPM state ``[x, psi, theta, xd, psid, thetad, X0, Y0]`` of the robot's last update."""
    x, psi = robot.q[0], robot.q[1]
    xd, psid = robot.nu[0], robot.nu[1]
    X0, Y0 = robot.axle_position[:2]
    return np.array([x, psi, robot.theta, xd, psid, robot.thetad, X0, Y0])


def _minimal_accelerations(robot: RobotModel, qacc: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(robot.J_tf, qacc - robot.Jdot_tf_nu, rcond=None)[0]


def _wheel_ctrl(robot: RobotModel, tau_left: float, tau_right: float) -> np.ndarray:
    ctrl = np.zeros(robot.model.nu)
    ctrl[robot.layout.wheel_actuators[0]] = tau_left
    ctrl[robot.layout.wheel_actuators[1]] = tau_right
    return ctrl


# ------------------------------------------------------------------------- level 1, 3-D
@pytest.mark.parametrize("skewed", [False, True], ids=["wip", "wip_skewed"])
def test_spatial_wipm_equals_exact_constrained_dynamics(skewed: bool) -> None:
    """Level 1 (round-off), turning states included: the 3-D WIPM with the wheel torques as
    input gives MuJoCo's constrained accelerations; with ``u = [thdd, tau_0]`` it gives the same
    ``xdd``, ``psidd``; and the inverse dynamics return the applied wheel torques."""
    model = _wip_model(skewed)
    robot = RobotModel(model)
    lay = robot.layout
    rng = np.random.default_rng(10)
    worst = {"torque": 0.0, "thdd": 0.0, "inverse": 0.0}
    for _ in range(30):
        q, nu = random_minimal_state(robot, rng, turning=True)
        nu[1] = rng.normal() * 1.5  # turning fast enough for the centripetal terms to matter
        qpos, qvel = robot.full_state(q, nu)
        tau_left, tau_right = rng.uniform(-150.0, 150.0, 2)
        ctrl = _wheel_ctrl(robot, tau_left, tau_right)
        robot.update(qpos, qvel)
        reference = _minimal_accelerations(
            robot, constrained_accelerations(model, qpos, qvel, ctrl, robot)
        )  # [xdd, psidd, q1dd]; theta = q1 + const on a rigid body, so thdd = q1dd
        params = wipm.params_from_lambda(robot.wipm_parameters())
        s = _spatial_state(robot)
        scale = np.linalg.norm(reference)

        sdot = np.asarray(spatial_torque_dynamics(s, np.array([tau_left, tau_right]), params))
        np.testing.assert_allclose(sdot[:3], s[3:6], rtol=0, atol=0)
        c, sn = np.cos(s[1]), np.sin(s[1])
        np.testing.assert_allclose(sdot[6:], [s[3] * c, s[3] * sn], rtol=1e-14, atol=1e-14)
        error = np.linalg.norm(sdot[3:6] - reference) / scale
        worst["torque"] = max(worst["torque"], error)
        assert error < 1e-9, error

        tau_0, _ = wheel_to_generalized(tau_left, tau_right, lay.wheel_radius, lay.wheel_separation)
        u = np.array([reference[2], tau_0])
        sdot_u = np.asarray(spatial_dynamics(s, u, params))
        error = np.linalg.norm(sdot_u[3:6] - reference) / scale
        worst["thdd"] = max(worst["thdd"], error)
        assert error < 1e-9, error

        tau = np.array(inverse_dynamics(s, u, params))
        error = np.linalg.norm(tau - [tau_left, tau_right]) / np.linalg.norm([tau_left, tau_right])
        worst["inverse"] = max(worst["inverse"], error)
        assert error < 1e-9, error
    print(f"level 1 ({'skewed' if skewed else 'wip'}): worst relative errors {worst}")


def test_inverse_dynamics_uses_the_wheel_torque_map_of_wip_gym(wip: RobotModel) -> None:
    """The torque split of inverse_dynamics is wip_gym.wheel_torques' (docs/ERRATA.md §3
    convention)."""
    rng = np.random.default_rng(11)
    q, nu = random_minimal_state(wip, rng)
    wip.update(*wip.full_state(q, nu))
    params = wipm.params_from_lambda(wip.wipm_parameters())
    s = _spatial_state(wip)
    A, h, B = (np.asarray(m) for m in jax.jit(wipm.spatial_equations)(s, params))
    for _ in range(5):
        u = np.array([rng.normal() * 3.0, rng.normal() * 50.0])
        tau_left, tau_right = inverse_dynamics(s, u, params)
        nu_dot = np.asarray(spatial_dynamics(s, u, params))[3:6]
        tau_1 = A[2] @ nu_dot + h[2]
        expected = generalized_to_wheel(
            u[1], tau_1, wip.layout.wheel_radius, wip.layout.wheel_separation
        )
        np.testing.assert_allclose([tau_left, tau_right], expected, rtol=1e-12)
        # and the three rows hold with these torques
        residual = A @ nu_dot + h - B @ np.array([tau_left, tau_right])
        assert np.linalg.norm(residual) < 1e-9 * np.linalg.norm(h)


# ----------------------------------------------------------------------- level 1, planar
def _planar_samples(robot: RobotModel, count: int, seed: int) -> list[tuple]:
    """``(s_planar, tau_w, params, [xdd, thdd] of MuJoCo)`` with psi = psid = 0, tau_L = tau_R."""
    rng = np.random.default_rng(seed)
    model = robot.model
    samples = []
    for _ in range(count):
        q, nu = random_minimal_state(robot, rng, turning=False)
        q[1], nu[1] = 0.0, 0.0
        qpos, qvel = robot.full_state(q, nu)
        tau = rng.uniform(-150.0, 150.0)
        ctrl = _wheel_ctrl(robot, tau, tau)
        robot.update(qpos, qvel)
        xdd, psidd, q1dd = _minimal_accelerations(
            robot, constrained_accelerations(model, qpos, qvel, ctrl, robot)
        )
        assert abs(psidd) < 1e-9 * (abs(xdd) + abs(q1dd))  # a symmetric robot goes straight
        s = np.array([robot.theta, robot.thetad, robot.q[0], robot.nu[0]])
        params = wipm.params_from_lambda(robot.wipm_parameters())
        samples.append((s, 2.0 * tau, params, np.array([xdd, q1dd])))
    return samples


@pytest.fixture(scope="module")
def planar_samples(wip: RobotModel) -> list[tuple]:
    return _planar_samples(wip, 40, seed=12)


def test_planar_wipm_equals_exact_constrained_dynamics(planar_samples: list[tuple]) -> None:
    """docs/ERRATA.md §1's zero dynamics (u = MuJoCo's thdd) give MuJoCo's xdd, and the two rows
    with the torque give (thdd, xdd) from tau_w, both to round-off."""
    worst_zero, worst_torque = 0.0, 0.0
    for s, tau_w, params, (xdd, thdd) in planar_samples:
        scale = np.hypot(xdd, thdd)
        sdot = np.asarray(planar_dynamics(s, thdd, params))
        np.testing.assert_allclose(sdot[[0, 2]], s[[1, 3]], rtol=0, atol=0)
        assert sdot[1] == thdd
        worst_zero = max(worst_zero, abs(sdot[3] - xdd) / scale)
        assert abs(sdot[3] - xdd) < 1e-9 * scale
        sdot = np.asarray(planar_torque_dynamics(s, tau_w, params))
        error = np.hypot(sdot[1] - thdd, sdot[3] - xdd) / scale
        worst_torque = max(worst_torque, error)
        assert error < 1e-9, error
        tau_back = float(planar_inverse_dynamics(s, thdd, params))
        assert tau_back == pytest.approx(tau_w, rel=1e-9, abs=1e-9)
    print(f"planar level 1: zero dynamics {worst_zero:.1e}, torque form {worst_torque:.1e}")


def test_paper_printed_planar_form_is_wrong(planar_samples: list[tuple]) -> None:
    """The printed eq. WIPdyn misses MuJoCo's xdd by orders of magnitude more than
    docs/ERRATA.md §1's."""
    printed, corrected = [], []
    for s, _, params, (xdd, thdd) in planar_samples:
        scale = max(abs(xdd), 1.0)
        printed.append(abs(float(paper_printed_planar_dynamics(s, thdd, params)[3]) - xdd) / scale)
        corrected.append(abs(float(planar_dynamics(s, thdd, params)[3]) - xdd) / scale)
    printed_median = float(np.median(printed))
    corrected_worst = max(float(np.max(corrected)), 1e-16)
    print(
        f"xdd relative error: printed median {printed_median:.2e} (max {np.max(printed):.2e}), "
        f"corrected median {np.median(corrected):.1e} (max {np.max(corrected):.1e})"
    )
    assert printed_median > 1e-1
    assert printed_median > 100.0 * corrected_worst
    assert np.median(printed) > 100.0 * np.median(corrected)


# ------------------------------------------------------------------------ level 2, contact
def test_spatial_wipm_matches_mujoco_contact(wip: RobotModel) -> None:
    """Level 2: against mj_forward with the wheels on the floor (MuJoCo's soft contacts)."""
    model = wip.model
    lay = wip.layout
    rng = np.random.default_rng(13)
    errors = []
    for qpos, qvel, ctrl, data in sample_contact_states(wip, model, rng, 100, turning=False):
        wip.update(qpos, qvel)
        params = wipm.params_from_lambda(wip.wipm_parameters())
        tau = ctrl[list(lay.wheel_actuators)]
        nu_dot = np.asarray(spatial_torque_dynamics(_spatial_state(wip), tau, params))[3:6]
        nu_dot_mj = _minimal_accelerations(wip, data.qacc)
        errors.append(np.linalg.norm(nu_dot - nu_dot_mj) / max(np.linalg.norm(nu_dot_mj), 1.0))
    errors = np.array(errors)
    print(f"contact level: median {np.median(errors):.1e}, max {errors.max():.1e}")
    assert np.median(errors) < 2e-3, np.median(errors)
    assert errors.max() < 2e-2, errors.max()


# ------------------------------------------------------------------------- linearisation
def _finite_difference(f, s: np.ndarray, u: np.ndarray, params, eps: float = 1e-6):
    """Central differences of ``f(s, u, params)`` (a jitted dynamics)."""
    columns = []
    for x, index in ((s, 0), (u, 1)):
        derivative = np.zeros((s.size, x.size))
        for j in range(x.size):
            step = np.zeros(x.size)
            step[j] = eps
            plus = [s, u]
            minus = [s, u]
            plus[index] = x + step
            minus[index] = x - step
            derivative[:, j] = (np.asarray(f(*plus, params)) - np.asarray(f(*minus, params))) / (
                2 * eps
            )
        columns.append(derivative)
    return columns


@pytest.mark.parametrize(
    "name", ["planar_dynamics", "planar_torque_dynamics", "spatial_dynamics", "spatial_torque"]
)
def test_linearize_matches_finite_differences(wip: RobotModel, name: str) -> None:
    """``linearize`` (jax.jacfwd) against central differences; ``discretize`` is explicit Euler
    and its Jacobians are ``I + dt A``, ``dt B``."""
    rng = np.random.default_rng(14)
    q, nu = random_minimal_state(wip, rng)
    wip.update(*wip.full_state(q, nu))
    params = wipm.params_from_lambda(wip.wipm_parameters())
    s3 = _spatial_state(wip)
    s2 = np.array([s3[2], s3[5], s3[0], s3[3]])
    dynamics, jitted, s, u = {
        "planar_dynamics": (wipm.planar_dynamics, planar_dynamics, s2, np.array([1.3])),
        "planar_torque_dynamics": (
            wipm.planar_torque_dynamics,
            planar_torque_dynamics,
            s2,
            np.array([40.0]),
        ),
        "spatial_dynamics": (wipm.spatial_dynamics, spatial_dynamics, s3, np.array([1.3, 20.0])),
        "spatial_torque": (
            wipm.spatial_torque_dynamics,
            spatial_torque_dynamics,
            s3,
            np.array([30.0, -50.0]),
        ),
    }[name]
    A, B = (np.asarray(m) for m in linearize(dynamics, s, u, params))
    A_fd, B_fd = _finite_difference(jitted, s, u, params)
    assert A.shape == (s.size, s.size) and B.shape == (s.size, u.size)
    scale = max(1.0, np.abs(A_fd).max(), np.abs(B_fd).max())
    np.testing.assert_allclose(A, A_fd, atol=1e-6 * scale)
    np.testing.assert_allclose(B, B_fd, atol=1e-6 * scale)
    dt = 0.01
    step = wipm.discretize(jitted, dt)
    np.testing.assert_allclose(
        np.asarray(step(s, u, params)), s + dt * np.asarray(jitted(s, u, params)), rtol=1e-14
    )
    if name == "planar_torque_dynamics":  # (compiling each Euler map costs time: one suffices)
        A_d, B_d = (np.asarray(m) for m in linearize(wipm.discretize(dynamics, dt), s, u, params))
        np.testing.assert_allclose(A_d, np.eye(s.size) + dt * A, atol=1e-12 * scale)
        np.testing.assert_allclose(B_d, dt * B, atol=1e-12 * scale)


def test_balance_is_an_unstable_controllable_pendulum(wip: RobotModel) -> None:
    """At balance (theta = 0, all rates 0) the torque-driven planar WIPM has an unstable
    eigenvalue (an inverted pendulum) and is controllable from the wheel torque."""
    wip.update(*wip.full_state(np.zeros(3), np.zeros(3)))
    params = wipm.params_from_lambda(wip.wipm_parameters())
    A, B = (np.asarray(m) for m in linearize(wipm.planar_torque_dynamics, np.zeros(4), 0.0, params))
    eigenvalues = np.linalg.eigvals(A)
    print(f"balance eigenvalues: {np.sort_complex(eigenvalues)}")
    assert eigenvalues.real.max() > 1.0  # sqrt(g/L)-like, a few 1/s
    controllability = np.hstack([np.linalg.matrix_power(A, k) @ B for k in range(4)])
    assert np.linalg.matrix_rank(controllability) == 4
    # and the zero dynamics with u = thdd is controllable too (x, xd reachable through theta)
    A, B = (np.asarray(m) for m in linearize(wipm.planar_dynamics, np.zeros(4), 0.0, params))
    controllability = np.hstack([np.linalg.matrix_power(A, k) @ B for k in range(4)])
    assert np.linalg.matrix_rank(controllability) == 4


# --------------------------------------------------------------------------- parameters
def test_params_from_lambda_on_krang() -> None:
    """On Krang at ``home``: the pitch inertia is A[q1, q1], and the rotation into the CoM frame
    puts the CoM at (0, com_lateral, com_distance)."""
    model = mujoco.MjModel.from_xml_path(str(mjcf_path("scene_krang.xml")))
    robot = RobotModel(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    states = [(model.key_qpos[key][: robot.layout.nq], np.zeros(robot.layout.nv))]
    rng = np.random.default_rng(15)
    for _ in range(3):
        states.append(robot.full_state(*random_minimal_state(robot, rng)))
    for qpos, qvel in states:
        robot.update(qpos, qvel)
        lam = robot.wipm_parameters()
        params = wipm.params_from_lambda(lam)
        inertia_body = np.asarray(params.inertia_body)
        assert inertia_body[1, 1] == pytest.approx(lam.pitch_inertia, rel=1e-12)
        assert inertia_body[1, 1] == pytest.approx(robot.A[2, 2], rel=1e-12)
        np.testing.assert_allclose(inertia_body, inertia_body.T, atol=1e-14)
        rot = np.asarray(wipm.rotation_y(lam.theta))
        com_B = rot.T @ lam.com
        np.testing.assert_allclose(
            com_B, [0.0, float(params.com_lateral), float(params.com_distance)], atol=1e-12
        )
        # rotating back gives lambda's axle-frame tensor
        np.testing.assert_allclose(rot @ inertia_body @ rot.T, lam.inertia_axle, atol=1e-12)
        assert float(params.wheel_mass) == pytest.approx(4.66)
        assert float(params.wheel_damping) == pytest.approx(0.5)


def test_wrong_inertia_rotation_breaks_the_skewed_wip() -> None:
    """The sign of the rotation in params_from_lambda matters: rotating the other way (I_B =
    Ry(theta) I_axle Ry(theta)^T) misses MuJoCo's accelerations on the skewed wip."""
    model = _wip_model(skewed=True)
    robot = RobotModel(model)
    rng = np.random.default_rng(16)
    q, nu = random_minimal_state(robot, rng)
    qpos, qvel = robot.full_state(q, nu)
    ctrl = _wheel_ctrl(robot, 60.0, -20.0)
    robot.update(qpos, qvel)
    reference = _minimal_accelerations(
        robot, constrained_accelerations(model, qpos, qvel, ctrl, robot)
    )
    lam = robot.wipm_parameters()
    params = wipm.params_from_lambda(lam)
    rot = np.asarray(wipm.rotation_y(lam.theta))
    wrong = params._replace(inertia_body=jnp.asarray(rot @ np.asarray(lam.inertia_axle) @ rot.T))
    s = _spatial_state(robot)
    tau = np.array([60.0, -20.0])
    right_error = np.linalg.norm(
        np.asarray(spatial_torque_dynamics(s, tau, params))[3:6] - reference
    )
    wrong_error = np.linalg.norm(
        np.asarray(spatial_torque_dynamics(s, tau, wrong))[3:6] - reference
    )
    scale = np.linalg.norm(reference)
    assert right_error < 1e-9 * scale
    assert wrong_error > 1e-3 * scale


# ------------------------------------------------ parameters from the robot, one compiled call
def _robot(name: str) -> RobotModel:
    if name == "wip-skewed":
        return RobotModel(_wip_model(skewed=True))
    return RobotModel(mujoco.MjModel.from_xml_path(str(mjcf_path(f"scene_{name}.xml"))))


# the fields computed with the same arithmetic on both paths (copies): equal to the bit; the
# others come from NumPy's (BLAS) matrix products on the reference path, or from hypot, whose
# numba and NumPy versions need not be the same libm call on every platform
_BIT_EQUAL = set(wipm.WIPMParams._fields) - {
    "inertia_body",
    "wheel_inertia",
    "wheel_inertia_transverse",
    "com_distance",
}


def _assert_same_params(fast: wipm.WIPMParams, reference: wipm.WIPMParams) -> None:
    """``fast`` has ``reference``'s leaves (NumPy float64 scalars, a 3x3 float64 array: what
    the jitted MPC step is traced for) and its values: to the bit where the arithmetic is the
    same, else to 1e-12 of the largest entry."""
    for name, a, b in zip(wipm.WIPMParams._fields, fast, reference, strict=True):
        assert type(a) is type(b), (name, type(a), type(b))
        assert np.shape(a) == np.shape(b) and np.asarray(a).dtype == np.asarray(b).dtype, name
        if name in _BIT_EQUAL:
            assert a == b, (name, a, b)
        else:
            scale = float(np.abs(b).max())
            np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * scale, err_msg=name)
    assert type(reference.body_mass) is np.float64
    assert type(reference.inertia_body) is np.ndarray and reference.inertia_body.shape == (3, 3)


def test_wipm_scalars_are_the_params_fields() -> None:
    fields = list(wipm.WIPMParams._fields)
    fields.remove("inertia_body")
    assert tuple(fields) == WIPM_SCALARS
    assert wipm.WIPMParams._fields.index("inertia_body") == 3  # params_from_robot's unpacking


@pytest.mark.parametrize("name", ["wip", "wip-skewed", "planar7", "krang"])
def test_params_from_robot_equals_params_from_lambda(name: str) -> None:
    """The one compiled call the MPC makes per step gives ``params_from_lambda`` of
    ``wipm_parameters()`` on random states (turning, with the body joints anywhere in their
    range), with or without the update's dynamics."""
    robot = _robot(name)
    rng = np.random.default_rng(31)
    for k in range(12):
        qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
        robot.update(qpos, qvel)
        reference = wipm.params_from_lambda(robot.wipm_parameters())
        _assert_same_params(wipm.params_from_robot(robot), reference)
        if k % 3 == 0:
            robot.update(qpos, qvel, dynamics=False)
            _assert_same_params(wipm.params_from_robot(robot), reference)


@pytest.mark.parametrize("name", ["wip", "wip-skewed", "planar7", "krang"])
def test_wipm_inputs_are_the_state_and_the_packed_params(name: str) -> None:
    """``RobotModel.wipm_inputs``, the MPC's one call per step, is ``wipm_state()`` then
    ``param_values(params_from_robot(robot))``, to the bit, on random states (turning, with and
    without the update's dynamics) and after the model changed; a new vector each call."""
    robot = _robot(name)
    rng = np.random.default_rng(35)
    n = 4 if robot.layout.planar else 8
    for k in range(8):
        qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
        robot.update(qpos, qvel, dynamics=k % 2 == 0)
        if k == 5 and name != "wip-skewed":
            before = robot.wipm_inputs()
            _change_model(robot.model, robot, rng)
            assert not np.array_equal(robot.wipm_inputs()[n:], before[n:])
        vector = robot.wipm_inputs()
        expected = [*robot.wipm_state(), *param_values(wipm.params_from_robot(robot))]
        assert vector.dtype == np.float64 and vector.shape == (n + 19,)
        np.testing.assert_array_equal(vector, np.array(expected))
        assert robot.wipm_inputs() is not vector
        into = np.full(n + 21, np.nan)
        assert robot.wipm_inputs(into[2:]) is not None  # written in place, in a view
        np.testing.assert_array_equal(into[2:], vector)
        assert np.isnan(into[:2]).all()
    for bad in (
        np.empty(n + 18),
        np.empty(n + 19, dtype=np.float32),
        np.empty(2 * (n + 19))[::2],
        np.empty(n + 19).reshape(1, -1),
        list(range(n + 19)),
    ):
        with pytest.raises(ValueError, match="out must be"):
            robot.wipm_inputs(bad)  # type: ignore[arg-type]
    frozen = np.empty(n + 19)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="out must be"):
        robot.wipm_inputs(frozen)


def _change_model(model: mujoco.MjModel, robot: RobotModel, rng: np.random.Generator) -> None:
    """What an env may change between two MPC steps: a payload's mass and inertia, a
    randomised wheel (mass, inertia, its inertial frame), its damping, gravity."""
    lay = robot.layout
    body = lay.body_bodies[-1]
    model.body_mass[body] += rng.uniform(0.5, 2.0)
    model.body_inertia[body] *= rng.uniform(1.1, 1.5, 3)
    wheel = lay.wheel_bodies[0]
    model.body_mass[wheel] *= rng.uniform(1.1, 1.5)
    model.body_inertia[wheel] = (0.09, 0.11, 0.08) * rng.uniform(1.0, 1.2, 3)
    quat = rng.normal(size=4)
    model.body_iquat[wheel] = quat / np.linalg.norm(quat)
    model.dof_damping[lay.wheel_dof[0]] += rng.uniform(0.1, 1.0)
    model.opt.gravity[2] -= rng.uniform(0.1, 0.5)


@pytest.mark.parametrize("name", ["wip", "planar7", "krang"])
def test_params_from_robot_reads_the_model_at_each_call(name: str) -> None:
    """Nothing of the model is cached: after a change of masses, inertias, the wheel's frame,
    its damping and gravity, the next call gives the new values (before the next update, the
    body mass, CoM and theta are the last update's, as on the reference path)."""
    robot = _robot(name)
    rng = np.random.default_rng(32)
    qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
    robot.update(qpos, qvel)
    before = wipm.params_from_robot(robot)
    for _ in range(3):
        _change_model(robot.model, robot, rng)
        changed = wipm.params_from_robot(robot)
        _assert_same_params(changed, wipm.params_from_lambda(robot.wipm_parameters()))
        robot.update(qpos, qvel)
        updated = wipm.params_from_robot(robot)
        _assert_same_params(updated, wipm.params_from_lambda(robot.wipm_parameters()))
        for field in ("wheel_mass", "wheel_inertia", "wheel_damping", "gravity"):
            assert getattr(changed, field) != getattr(before, field), field
        assert not np.allclose(changed.inertia_body, before.inertia_body, rtol=1e-6)
        assert changed.body_mass == before.body_mass  # the update's, until the next update
        assert updated.body_mass > before.body_mass
        before = updated


def test_params_from_robot_after_pickling_and_copying() -> None:
    """An unpickled (or deep-copied) robot model reads its own MuJoCo model, not the original's:
    its address table is made again with its views (``RobotModel.__setstate__``)."""
    robot = _robot("krang")
    rng = np.random.default_rng(33)
    qpos, qvel = robot.full_state(*random_minimal_state(robot, rng))
    robot.update(qpos, qvel)
    original = wipm.params_from_robot(robot)
    compiled = (robot_update_at, wipm_values)
    signatures = [len(function.signatures) for function in compiled]
    for twin in (pickle.loads(pickle.dumps(robot)), copy.deepcopy(robot)):
        assert twin.model is not robot.model
        # read-only again (NumPy's copies are writable): no second compiled signature
        assert not twin.J_tf_pattern.flags.writeable
        assert not twin.heading_rotation.flags.writeable
        _assert_same_params(wipm.params_from_robot(twin), original)
        twin.update(qpos, qvel)
        assert [len(function.signatures) for function in compiled] == signatures
        _change_model(twin.model, twin, rng)
        twin.update(qpos, qvel)
        _assert_same_params(
            wipm.params_from_robot(twin), wipm.params_from_lambda(twin.wipm_parameters())
        )
        assert wipm.params_from_robot(twin).wheel_mass != original.wheel_mass
        _assert_same_params(wipm.params_from_robot(robot), original)  # the original untouched


def test_params_from_robot_does_not_retrace_a_jitted_step() -> None:
    """A jitted function of the parameters (the MPC step) traced on ``params_from_lambda``'s
    is not traced again for ``params_from_robot``'s."""
    traces = []

    @jax.jit
    def f(params: wipm.WIPMParams) -> jax.Array:
        traces.append(1)
        return sum(jnp.sum(jnp.asarray(leaf)) for leaf in params)

    robot = _robot("krang")
    robot.update(*robot.full_state(*random_minimal_state(robot, np.random.default_rng(34))))
    f(wipm.params_from_lambda(robot.wipm_parameters()))
    f(wipm.params_from_robot(robot))
    assert len(traces) == 1


# ------------------------------------------------------------------------------ damping
def test_wheel_damping_cancels_from_the_zero_dynamics_only(wip: RobotModel) -> None:
    """Damping acts on the wheels' rotation relative to the body, like the motor torque: it
    cancels out of ``R * (x row) + (th row)`` (planar_dynamics) but not out of the torque form."""
    rng = np.random.default_rng(17)
    q, nu = random_minimal_state(wip, rng, turning=False)
    wip.update(*wip.full_state(q, nu))
    base = wipm.params_from_lambda(wip.wipm_parameters())
    R = float(base.wheel_radius)
    s = np.array([0.2, -0.7, 0.0, 1.5])  # relative wheel rate xd/R - thd = 6.7 rad/s
    relative = s[3] / R - s[1]
    zero_dynamics, torque_form, inverse = [], [], []
    for damping in (0.0, 0.5, 5.0):
        params = base._replace(wheel_damping=jnp.asarray(damping))
        zero_dynamics.append(np.asarray(planar_dynamics(s, 2.0, params)))
        torque_form.append(np.asarray(planar_torque_dynamics(s, 40.0, params)))
        inverse.append(float(planar_inverse_dynamics(s, 2.0, params)))
    np.testing.assert_array_equal(zero_dynamics[0], zero_dynamics[1])
    np.testing.assert_array_equal(zero_dynamics[0], zero_dynamics[2])
    # damping 5 at 6.7 rad/s on two wheels is a 67 N m torque: thdd changes by order 1 rad/s^2
    assert abs(torque_form[2][1] - torque_form[0][1]) > 0.1
    assert abs(torque_form[2][3] - torque_form[0][3]) > 0.01
    # it acts exactly like a wheel torque -2 d (xd/R - thd): equivalent inputs give equal rates
    equivalent = np.asarray(
        planar_torque_dynamics(s, 40.0 - 2 * 5.0 * relative, base._replace(wheel_damping=0.0))
    )
    np.testing.assert_allclose(torque_form[2], equivalent, rtol=1e-12, atol=1e-12)
    # and the torque that realises a thdd grows by exactly the damping torque
    assert inverse[2] - inverse[0] == pytest.approx(2 * 5.0 * relative, rel=1e-12)
    print(
        f"damping 0 -> 5 N m s/rad: zero dynamics change 0, torque-form thdd change "
        f"{torque_form[2][1] - torque_form[0][1]:.3f} rad/s^2"
    )


# ------------------------------------------------------------------- closed form vs Kane
def _random_params(rng: np.random.Generator) -> wipm.WIPMParams:
    """Random WIPM parameters: lateral CoM, a rotated (non-diagonal) body inertia about the
    axle, damped wheels."""
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    inertia = rotation @ np.diag(rng.uniform(0.5, 25.0, 3)) @ rotation.T
    values = (
        rng.uniform(5.0, 150.0),  # body_mass
        rng.uniform(0.1, 1.0),  # com_distance
        rng.normal() * 0.1,  # com_lateral
        0.5 * (inertia + inertia.T),  # inertia_body
        rng.uniform(0.5, 5.0),  # wheel_mass
        rng.uniform(0.01, 0.5),  # wheel_inertia
        rng.uniform(0.01, 0.3),  # wheel_inertia_transverse
        rng.uniform(0.0, 5.0),  # wheel_damping
        rng.uniform(0.1, 0.4),  # wheel_radius
        rng.uniform(0.3, 1.0),  # wheel_separation
        rng.uniform(9.0, 10.0),  # gravity
    )
    return wipm.WIPMParams(*(jnp.asarray(v, dtype=jnp.float64) for v in values))


def _random_batch(count: int, seed: int) -> tuple[np.ndarray, wipm.WIPMParams]:
    """``count`` random turning states (any pitch, fast rates) with their own parameters."""
    rng = np.random.default_rng(seed)
    states = rng.normal(size=(count, 8)) * np.array([3.0, 3.0, 0.8, 2.0, 2.0, 2.0, 5.0, 5.0])
    params = [_random_params(rng) for _ in range(count)]
    return states, jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *params)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_closed_form_equals_kane() -> None:
    """The closed-form ``spatial_equations`` (what the dynamics use) and the Kane derivation
    agree to round-off on random turning states and parameters (lateral CoM, products of
    inertia, damping), and so do the dynamics and inverse dynamics solved from either; ``A`` is
    symmetric and the equations do not depend on ``x``, ``psi``, ``X0``, ``Y0``."""
    count = 200
    states, params = _random_batch(count, seed=20)
    closed = jax.jit(jax.vmap(wipm.spatial_equations))
    kane = jax.jit(jax.vmap(wipm.spatial_equations_kane))
    A, h, B = (np.asarray(m) for m in closed(states, params))
    A_k, h_k, B_k = (np.asarray(m) for m in kane(states, params))
    worst = {"A": 0.0, "h": 0.0, "B": 0.0}
    for i in range(count):
        worst["A"] = max(worst["A"], _relative(A[i], A_k[i]))
        worst["h"] = max(worst["h"], _relative(h[i], h_k[i]))
        worst["B"] = max(worst["B"], _relative(B[i], B_k[i]))
    print(f"closed form vs Kane: worst relative differences {worst}")
    assert max(worst.values()) < 1e-12, worst
    np.testing.assert_array_equal(A, np.swapaxes(A, 1, 2))
    moved = states.copy()
    moved[:, [0, 1, 6, 7]] = np.random.default_rng(21).normal(size=(count, 4)) * 10.0
    A_m, h_m, _ = (np.asarray(m) for m in closed(moved, params))
    np.testing.assert_array_equal(A_m, A)
    np.testing.assert_array_equal(h_m, h)

    # the dynamics built on the closed form against dense solves of Kane's equations
    rng = np.random.default_rng(22)
    tau = rng.uniform(-150.0, 150.0, (count, 2))
    u = np.stack([rng.normal(size=count) * 3.0, rng.normal(size=count) * 50.0], axis=1)
    torque_sdot = np.asarray(jax.jit(jax.vmap(wipm.spatial_torque_dynamics))(states, tau, params))
    sdot = np.asarray(jax.jit(jax.vmap(wipm.spatial_dynamics))(states, u, params))
    tau_back = np.stack(jax.jit(jax.vmap(wipm.inverse_dynamics))(states, u, params), axis=1)
    for i in range(count):
        nu_dot = np.linalg.solve(A_k[i], B_k[i] @ tau[i] - h_k[i])
        assert _relative(torque_sdot[i, 3:6], nu_dot) < 1e-12
        # u = [thdd, tau_0]: B tau = [-tau_1/R, tau_0, tau_1]; unknowns [xdd, psidd, tau_1]
        R, sep = float(params.wheel_radius[i]), float(params.wheel_separation[i])
        system = np.column_stack([A_k[i][:, :2], [1.0 / R, 0.0, -1.0]])
        rhs = np.array([0.0, u[i, 1], 0.0]) - h_k[i] - A_k[i][:, 2] * u[i, 0]
        xdd, psidd, tau_1 = np.linalg.solve(system, rhs)
        assert _relative(sdot[i, 3:6], np.array([xdd, psidd, u[i, 0]])) < 1e-12
        expected = generalized_to_wheel(u[i, 1], tau_1, R, sep)
        assert _relative(tau_back[i], np.asarray(expected)) < 1e-12


def test_closed_form_derivatives_equal_kane() -> None:
    """The state Jacobians of ``A`` and ``h`` (what the DDP differentiates) agree too."""
    states, params = _random_batch(50, seed=23)

    def jacobian(equations):  # noqa: ANN001, ANN202
        return jax.jit(jax.vmap(jax.jacfwd(lambda s, p: equations(s, p)[:2])))

    ours = jacobian(wipm.spatial_equations)(states, params)
    reference = jacobian(wipm.spatial_equations_kane)(states, params)
    for name, a, b in zip(("dA/ds", "dh/ds"), ours, reference, strict=True):
        a, b = np.asarray(a), np.asarray(b)
        worst = max(_relative(a[i], b[i]) for i in range(len(b)))
        print(f"{name}: worst relative difference {worst:.1e}")
        assert worst < 1e-12, (name, worst)
