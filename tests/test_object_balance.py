"""The carried object's balance rows (controllers/low_level/object_balance.py) against MuJoCo.

The wrench a cup needs to move with the tray is checked three ways on random states that turn,
pitch and move every joint: the point's velocity and drift against central differences of
MuJoCo's kinematics, the whole wrench against MuJoCo's inverse dynamics of the env's cup placed
on the tray and moving with it (contacts off: what the plate must give), and the rows' algebra
against the geometry they encode (friction ratio, zero-moment point in the support polygon).
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import wip_gym  # noqa: F401
from controllers.low_level.motion_probe import MotionProbe
from controllers.low_level.object_balance import (
    GRAVITY,
    CarriedObject,
    ObjectBalance,
    cylinder_inertia_per_mass,
)
from tests.robot_states import robot_at_reset
from wip_gym.robot_model import RobotModel
from wip_gym.scene import CUP_HALF_HEIGHT, CUP_MASS, CUP_RADIUS

ENVS = ("wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0")


def _random_state(robot: RobotModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A minimal state near the reset pose that turns, pitches and moves every joint."""
    q = robot.q + rng.uniform(-0.3, 0.3, robot.layout.n_min)
    nu = rng.uniform(-1.0, 1.0, robot.layout.n_min)
    return q, nu


def _setup(env_id: str, place: tuple[float, float] = (0.0, 0.0)):
    env, robot = robot_at_reset(env_id)
    model = robot.model
    site = model.site("tray_top").id
    balance = ObjectBalance(robot, site, CarriedObject(place=place), friction=0.3)
    return env, model, robot, site, balance


def _cup_point(robot: RobotModel, site: int, offset: np.ndarray) -> np.ndarray:
    d = robot.data
    return d.site_xpos[site] + d.site_xmat[site].reshape(3, 3) @ offset


@pytest.mark.parametrize("env_id", ENVS)
def test_the_centre_of_mass_acceleration_equals_differences_of_mujoco_kinematics(env_id):
    env, model, robot, site, balance = _setup(env_id, place=(0.03, -0.02))
    probe = MotionProbe(robot)
    other = RobotModel(model)
    rng = np.random.default_rng(1)
    offset = np.array([0.03, -0.02, CUP_HALF_HEIGHT])
    for _ in range(5):
        q, nu = _random_state(robot, rng)
        xy = rng.uniform(-1, 1, 2)
        qpos, qvel = robot.full_state(q, nu, xy)
        robot.update(qpos, qvel)
        probe.update(robot)
        W, w = balance.wrench(robot, probe)
        R = robot.data.site_xmat[site].reshape(3, 3)
        # W nu_dot + w - R^T g_vec / g is R^T a_c / g: its nu_dot part is R^T J_c / g
        eps = 1e-6
        heading = 0.0 if robot.layout.planar else robot.psi
        step = eps * nu[0] * np.array([np.cos(heading), np.sin(heading)])
        points, velocities = [], []
        for sign in (1.0, -1.0):
            qp, qv = robot.full_state(q + sign * eps * nu, nu, xy + sign * step)
            other.update(qp, qv, dynamics=False)
            points.append(_cup_point(other, site, offset))
            motion = balance.tray_motion(other, probe)
            velocities.append(R.T @ balance._point(motion, offset)[0] @ nu)  # J_c nu
        velocity = (points[0] - points[1]) / (2 * eps)
        np.testing.assert_allclose(W[:3] @ nu * GRAVITY, R.T @ velocity, rtol=1e-6, atol=1e-7)
        # the drift: d/dt (J_c nu) at fixed nu, in the tray frame of this state
        drift = (velocities[0] - velocities[1]) / (2 * eps)
        gravity_part = R.T @ np.array([0.0, 0.0, GRAVITY]) / GRAVITY
        assert np.abs(drift).max() > 0.05  # the states move: the drift is not trivially zero
        np.testing.assert_allclose((w[:3] - gravity_part) * GRAVITY, drift, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("env_id", ENVS)
def test_the_wrench_equals_mujoco_inverse_dynamics_of_the_cup_on_the_tray(env_id):
    env, model, robot, site, balance = _setup(env_id)
    probe = MotionProbe(robot)
    data = mujoco.MjData(model)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    cup = model.body("cup").id
    joint = model.joint("cup").id
    qa, va = model.jnt_qposadr[joint], model.jnt_dofadr[joint]
    lay = robot.layout
    rng = np.random.default_rng(2)
    assert model.body_mass[cup] == pytest.approx(CUP_MASS)
    np.testing.assert_allclose(
        model.body_inertia[cup] / CUP_MASS,
        cylinder_inertia_per_mass(CUP_RADIUS, 2 * CUP_HALF_HEIGHT),
        rtol=1e-9,
    )
    for _ in range(5):
        q, nu = _random_state(robot, rng)
        qpos, qvel = robot.full_state(q, nu, rng.uniform(-1, 1, 2))
        robot.update(qpos, qvel)
        probe.update(robot)
        nu_dot = rng.uniform(-3.0, 3.0, lay.n_min)
        W, w = balance.wrench(robot, probe)
        wrench = W @ nu_dot + w
        # the cup placed on the plate, moving with the tray: its centre of mass's acceleration
        # and the tray's angular acceleration from the same rows' kinematics (checked against
        # MuJoCo's by the test above), then MuJoCo's inverse dynamics of the cup alone
        R = robot.data.site_xmat[site].reshape(3, 3)
        motion = balance.tray_motion(robot, probe)
        J_c, d_c = balance._point(motion, np.array([0.0, 0.0, CUP_HALF_HEIGHT]))
        J_r, omega_drift = motion.J_r, motion.omega_drift
        data.qpos[: lay.nq] = qpos
        data.qvel[: lay.nv] = qvel
        data.qpos[qa : qa + 3] = robot.data.site_xpos[site] + R @ [0.0, 0.0, CUP_HALF_HEIGHT]
        mujoco.mju_mat2Quat(data.qpos[qa + 3 : qa + 7], R.reshape(-1))
        data.qvel[va : va + 3] = J_c @ robot.nu
        data.qvel[va + 3 : va + 6] = R.T @ (J_r @ robot.nu)  # a free joint's: body frame
        data.qacc[:] = 0.0
        data.qacc[va : va + 3] = J_c @ nu_dot + d_c
        data.qacc[va + 3 : va + 6] = R.T @ (J_r @ nu_dot + omega_drift)
        mujoco.mj_inverse(model, data)
        force = data.qfrc_inverse[va : va + 3]  # world, at the centre of mass
        torque = data.qfrc_inverse[va + 3 : va + 6]  # body (= tray) frame
        weight = CUP_MASS * GRAVITY
        np.testing.assert_allclose(wrench[:3], R.T @ force / weight, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(wrench[3:], torque / weight, rtol=1e-9, atol=1e-12)
        # the torque part is exercised (a cup's inertia per unit weight is ~4e-5 m s^2)
        assert np.abs(wrench[3:]).max() > 1e-6


def _zero_moment_point(wrench: np.ndarray, h: float) -> np.ndarray:
    f, tau = wrench[:3], wrench[3:]
    return np.array([-(h * f[0] + tau[1]), tau[0] - h * f[1]]) / f[2]


def _inside(point: np.ndarray, polygon: np.ndarray) -> bool:
    for i, v in enumerate(polygon):
        e = polygon[(i + 1) % len(polygon)] - v
        if e[0] * (point[1] - v[1]) - e[1] * (point[0] - v[0]) < 0:
            return False
    return True


def test_the_rows_say_what_their_geometry_says():
    """On random wrenches, each row's sign agrees with the friction ratio, the normal force and
    the zero-moment point's place, computed directly."""
    env, model, robot, site, _ = _setup("wip_gym/PlanarTray-v0")
    carried = CarriedObject(support=((0.03, -0.02), (0.01, 0.04), (-0.02, 0.01), (-0.01, -0.03)))
    balance = ObjectBalance(robot, site, carried, friction=0.3)
    mu = balance.planning_friction
    polygon = np.array(carried.support)
    rng = np.random.default_rng(3)
    agree = {"friction": 0, "contact": 0, "tipping": 0}
    for _ in range(2000):
        wrench = np.concatenate(
            [rng.uniform(-0.5, 0.5, 2), rng.uniform(0.05, 2, 1), rng.uniform(-0.05, 0.05, 3)]
        )
        values = balance._wrench_rows @ wrench + balance._constants
        friction_ok = abs(wrench[0]) + abs(wrench[1]) <= mu * wrench[2]
        assert (values[:4] <= 0).all() == friction_ok
        assert (values[4] <= 0) == (wrench[2] >= carried.min_normal)
        zmp = _zero_moment_point(wrench, carried.com_height)
        assert (values[5:] <= 0).all() == _inside(zmp, polygon)
        agree["friction"] += friction_ok
        agree["contact"] += bool(values[4] <= 0)
        agree["tipping"] += _inside(zmp, polygon)
    assert all(0 < n < 2000 for n in agree.values())  # both sides of every condition were met


def test_a_support_that_does_not_hold_the_centre_of_mass_is_refused():
    with pytest.raises(ValueError, match="counter-clockwise"):
        CarriedObject(support=((0.01, 0.0), (0.02, 0.0), (0.02, 0.01)))
    with pytest.raises(ValueError, match="counter-clockwise"):  # clockwise
        CarriedObject(support=((0.03, 0.0), (0.0, -0.03), (-0.03, 0.0), (0.0, 0.03)))
    with pytest.raises(ValueError, match="friction"):
        CarriedObject(friction=0.0)
    with pytest.raises(ValueError, match="margin"):
        CarriedObject(margin=1.0)


@pytest.mark.parametrize(
    "env_id",
    ["wip_gym/WIP-v0", "wip_gym/Planar-v0", "wip_gym/PlanarTray-v0", "wip_gym/KrangTray-v0"],
)
def test_every_model_keeps_the_gravity_the_rows_assume(env_id):
    """The rows divide by ``wip_gym.scene.GRAVITY``: every model's ``opt.gravity`` is it."""
    model = gym.make(env_id).unwrapped.model
    np.testing.assert_array_equal(model.opt.gravity, [0.0, 0.0, -GRAVITY])
