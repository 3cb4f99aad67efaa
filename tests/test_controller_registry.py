"""The controller registry, the presets, the plan's acceleration cap, the policy base's counted
clip and counters, and every registered controller on the tray envs (short episodes)."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from numpy.typing import NDArray

import wip_gym  # noqa: F401
from controllers import HierarchicalConfig, HierarchicalController, PlanConfig, PolicyBase
from controllers.baselines.decoupled import DecoupledConfig, DecoupledLQRConfig
from controllers.baselines.decoupled_mpc import DecoupledMPCConfig
from controllers.hierarchical import authors_joint_weights
from controllers.high_level.planning import plan_to_goal
from controllers.policy import ClipCounter, ModelChoice, Policy, make_robot
from controllers.registry import (
    _REGISTRY,
    controller_names,
    default_config,
    make_policy,
    register,
)
from controllers.simplified.wipm import params_from_lambda
from controllers.simplified.wipm_problem import wipm_state
from wip_gym.wheel_torques import wheel_to_generalized

NAMES = ["decoupled", "decoupled-lqr", "decoupled-mpc", "unified", "unified-waiter"]
BASE_COUNTERS = {"clipped_steps", "max_clip_excess", "actuator_limit_steps"}
EXPECTED_COUNTERS = {
    "decoupled": BASE_COUNTERS
    | {"plan_violations", "plan_converged", "max_joint_deviation_rad"}
    | {"spin_current_clamped_steps", "wheel_current_clamped_steps"},
    "decoupled-lqr": BASE_COUNTERS
    | {"plan_violations", "plan_converged", "max_joint_deviation_rad"},
    "decoupled-mpc": BASE_COUNTERS
    | {"plan_violations", "plan_converged", "max_joint_deviation_rad", "mpc_rejections"},
    "unified": BASE_COUNTERS
    | {"plan_violations", "plan_converged", "qp_fallbacks", "qp_failures", "mpc_rejections"},
}
EXPECTED_COUNTERS["unified-waiter"] = EXPECTED_COUNTERS["unified"]


# ------------------------------------------------------------------------------- registry
def test_the_registered_names() -> None:
    assert controller_names()[: len(NAMES)] == NAMES


def test_default_config_applies_the_names_fields() -> None:
    assert default_config("unified").tray_mode == "level"
    assert default_config("unified-waiter").tray_mode == "specific_force"
    assert isinstance(default_config("decoupled"), DecoupledConfig)
    assert isinstance(default_config("decoupled-lqr"), DecoupledLQRConfig)
    assert isinstance(default_config("decoupled-mpc"), DecoupledMPCConfig)
    assert default_config("unified-waiter", "paper").tray_mode == "specific_force"


def test_unknown_names_and_presets_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown controller 'lqr'.*decoupled-lqr"):
        default_config("lqr")
    with pytest.raises(ValueError, match="unknown preset 'authors'.*paper"):
        default_config("unified", "authors")
    env = gym.make("wip_gym/WIP-v0")
    with pytest.raises(ValueError, match="unknown controller"):
        make_policy("nope", env)
    with pytest.raises(ValueError, match="needs a HierarchicalConfig"):
        make_policy("unified", env, DecoupledConfig())


# -------------------------------------------------------------------------------- presets
def test_plan_preset_is_the_authors_plan() -> None:
    paper, ours = PlanConfig.paper(), PlanConfig()
    assert paper.a_max == "none" and ours.a_max == "cup_safe"
    assert (paper.q_theta, paper.q_thetad, paper.q_position, paper.q_speed) == (1.0, 0.1, 0.1, 0.1)
    assert (paper.r_control, paper.r_rate, paper.q_terminal) == (0.01, 0.01, 1e4)
    assert paper.r_rate != ours.r_rate and paper.q_position != ours.q_position


def test_hierarchical_preset_is_the_authors_low_level() -> None:
    paper, ours = HierarchicalConfig.paper(), HierarchicalConfig()
    assert paper.ee_position_weight == (0.0, 1.0, 10.0) and ours.ee_position_weight == 10.0
    assert paper.theta_weight == 10.0 and ours.theta_weight == 100.0
    assert paper.hand_observer_bandwidth is None and ours.hand_observer_bandwidth is not None
    assert paper.spin_source == "mpc_tau_0" and ours.spin_source == "heading_task"
    assert paper.posture_weight == "authors" and paper.speed_regularization_kv == 10.0
    assert ours.speed_regularization_kv is None
    assert paper.high_level.plan == PlanConfig.paper()


@pytest.mark.parametrize("name", NAMES)
def test_every_controller_has_the_paper_preset(name: str) -> None:
    paper = default_config(name, "paper")
    assert paper != default_config(name)
    plan = paper.plan if hasattr(paper, "plan") else paper.high_level.plan
    assert plan == PlanConfig.paper()


def test_bad_configs_are_refused() -> None:
    for bad in ("fast", -1.0, 0.0, float("nan"), True):
        with pytest.raises(ValueError, match="a_max"):
            PlanConfig(a_max=bad)
    with pytest.raises(ValueError, match="spin_source"):
        HierarchicalConfig(spin_source="wheels")
    with pytest.raises(ValueError, match="ee_position_weight"):
        HierarchicalConfig(ee_position_weight=(1.0, 2.0))
    with pytest.raises(ValueError, match="gains_amps"):
        DecoupledConfig(gains_amps=(1.0, 2.0))


# ------------------------------------------------------------------------ the plan's a_max
@pytest.fixture(scope="module")
def planar_start() -> tuple[Any, Any, NDArray[np.float64]]:
    env = gym.make("wip_gym/PlanarTray-v0", goal=2.0)
    obs, _ = env.reset(seed=0)
    robot = make_robot(env, "nominal")
    robot.update(obs["qpos"], obs["qvel"])
    return wipm_state(robot), params_from_lambda(robot.wipm_parameters()), env.unwrapped.goal


def _plan(start: tuple, a_max: Any) -> Any:
    state, params, goal = start
    config = PlanConfig(a_max=a_max)
    return plan_to_goal(state, params, goal, planar=True, cup_friction=0.3, config=config)


def test_a_max_spellings_bound_the_plans_acceleration(planar_start: tuple) -> None:
    cup_safe = 0.5 * 0.3 * 9.81
    plan = _plan(planar_start, "cup_safe")
    assert plan.a_max == pytest.approx(cup_safe)
    assert plan.peak_acceleration <= cup_safe and plan.violations == ()
    slow = _plan(planar_start, 0.8)
    assert slow.a_max == 0.8 and slow.peak_acceleration <= 0.8 and slow.violations == ()
    assert slow.peak_acceleration < plan.peak_acceleration
    free = _plan(planar_start, "none")
    assert free.a_max == float("inf")
    assert free.peak_acceleration > cup_safe  # without the cap the plan drives harder
    # the cap no longer depends on the cup's friction when given in m/s^2
    assert PlanConfig(a_max=0.8).acceleration_bound(0.1) == 0.8
    assert PlanConfig().acceleration_bound(0.1) == pytest.approx(0.5 * 0.1 * 9.81)
    assert PlanConfig().acceleration_bound(None) == PlanConfig().default_a_max


# --------------------------------------------------------------- registering a controller
@dataclass(frozen=True)
class ToyConfig:
    model: ModelChoice = "nominal"
    excess: float = 0.0


class ToyController(PolicyBase):
    """Zero wheel torque, and the first joint pushed ``excess`` past its upper bound."""

    config_class = ToyConfig
    registry_name = "toy"

    def reset(self, observation: dict[str, NDArray[np.float64]], info: dict[str, Any]) -> None:
        self.begin_episode()

    def __call__(self, observation: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]:
        joints = np.zeros(len(self.robot.layout.joint_actuators))
        first = self.robot.layout.joint_actuators[0]
        joints[0] = self.task.torque_high[first] + self.config.excess
        action = self.finish(self.assemble((0.0, 0.0), joints))
        self._recorder.record(torque=action)
        self._step += 1
        return action


@pytest.fixture
def toy_registered():  # noqa: ANN201
    register("toy", ToyController, ToyConfig, excess=7.5)
    yield
    _REGISTRY.pop("toy")


def test_a_registered_controller_runs_through_make_policy(toy_registered: None) -> None:
    assert "toy" in controller_names()
    assert default_config("toy") == ToyConfig(excess=7.5)
    env = gym.make("wip_gym/Planar-v0")
    policy = make_policy("toy", env)
    assert isinstance(policy, Policy) and policy.name == "toy"
    obs, info = env.reset(seed=0)
    policy.reset(obs, info)
    for _ in range(5):
        action = policy(obs)
        obs, *_ = env.step(action)
    first = policy.robot.layout.joint_actuators[0]
    assert action[first] == env.action_space.high[first]  # clipped to the bound
    counters = policy.counters
    assert counters["clipped_steps"] == 5
    assert counters["max_clip_excess"] == pytest.approx(7.5)
    assert counters["actuator_limit_steps"] == 5
    policy.reset(obs, info)  # counters start afresh every episode
    assert policy.counters["clipped_steps"] == 0


def test_register_refuses_unknown_fields() -> None:
    with pytest.raises(ValueError, match="no fields"):
        register("toy2", ToyController, ToyConfig, gain=1.0)
    assert "toy2" not in controller_names()


def test_clip_counter_counts_and_refuses_non_finite_actions() -> None:
    counter = ClipCounter(np.array([-1.0, -2.0]), np.array([1.0, 2.0]))
    np.testing.assert_array_equal(counter.clip(np.array([0.5, -1.0])), [0.5, -1.0])
    given = np.array([1.25, -2.5])
    clipped = counter.clip(given)
    np.testing.assert_array_equal(clipped, [1.0, -2.0])
    np.testing.assert_array_equal(given, [1.25, -2.5])  # clipped in a copy
    assert clipped is not given
    assert counter.counters == {
        "clipped_steps": 1.0,
        "max_clip_excess": 0.5,
        "actuator_limit_steps": 1.0,
    }
    with pytest.raises(ValueError, match=r"non-finite action: \[nan +5\.\]"):
        counter.clip(np.array([np.nan, 5.0]))  # the values given, not the clipped copy
    with pytest.raises(ValueError, match="shape"):
        counter.clip(np.zeros(3))
    # its bounds are not assignable (the compiled clip reads them with the shape checked once)
    with pytest.raises(AttributeError):
        counter.high = np.array([1.0])  # type: ignore[misc]
    with pytest.raises(ValueError, match="two 1-D arrays of one length"):
        ClipCounter(np.zeros((2, 2)), np.ones((2, 2)))
    with pytest.raises(ValueError, match="ordered"):
        ClipCounter(np.array([1.0, -2.0]), np.array([-1.0, 2.0]))
    # the bounds given, shared: a change of their values in place reaches the clip
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    shared = ClipCounter(low, high)
    high[0] = 0.5
    np.testing.assert_array_equal(shared.clip(np.array([0.75, 0.0])), [0.5, 0.0])


# ------------------------------------------------------------- every controller, closed loop
SECONDS = 3.0
ENVS = {"wip_gym/PlanarTray-v0": 2.0, "wip_gym/KrangTray-v0": (2.0, 0.0)}


def run(env_id: str, name: str, seconds: float = SECONDS) -> tuple[Any, dict, float]:
    env = gym.make(env_id, goal=ENVS[env_id])
    obs, info = env.reset(seed=0)
    policy = make_policy(name, env)
    policy.reset(obs, info)
    start = info["goal_distance"]
    for _ in range(int(round(seconds / env.unwrapped.dt))):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, (name, env_id, info)
    return policy, info, start


@pytest.mark.parametrize("env_id", list(ENVS))
@pytest.mark.parametrize("name", NAMES)
def test_every_controller_balances_and_heads_for_the_goal(env_id: str, name: str) -> None:
    policy, info, start = run(env_id, name)
    assert not info["fallen"] and abs(info["theta"]) < 0.3
    assert info["goal_distance"] < 0.5 * start  # more than half way in 3 s
    assert info["cup_on_tray"]
    counters = policy.counters
    assert set(counters) == EXPECTED_COUNTERS[name]
    assert counters["plan_violations"] == 0 and counters["plan_converged"] == 1.0
    assert counters.get("qp_fallbacks", 0) == 0 and counters.get("mpc_rejections", 0) == 0
    diagnostics = policy.diagnostics
    if name == "decoupled":  # Krang 2014 balances about theta = 0 while the plan leans
        assert np.all(diagnostics["theta_ref"] == 0.0) and np.all(diagnostics["thetad_ref"] == 0.0)
        assert policy.plan.peak_theta > 0.05
    if "max_joint_deviation_rad" in counters:
        assert counters["max_joint_deviation_rad"] == pytest.approx(
            diagnostics["joint_deviation"].max()
        )
    if name == "decoupled-mpc":  # held nearly as locked: under a milliradian
        assert counters["max_joint_deviation_rad"] < 1e-3


def test_decoupled_mpc_holds_the_body_stiffer_than_the_joint_pd() -> None:
    """The computed torque keeps the joints closer to locked than the 5 Hz PD of the LQR
    baseline on the same plan."""
    mpc, _, _ = run("wip_gym/PlanarTray-v0", "decoupled-mpc", 1.5)
    pd, _, _ = run("wip_gym/PlanarTray-v0", "decoupled-lqr", 1.5)
    assert mpc.counters["max_joint_deviation_rad"] < 0.1 * pd.counters["max_joint_deviation_rad"]


def test_paper_preset_turns_with_the_mpcs_tau_0() -> None:
    """3-D, no heading task: the MPC's tau_0 alone turns Krang toward a goal to its left."""
    env = gym.make("wip_gym/KrangTray-v0", goal=(2.0, 1.0))
    obs, info = env.reset(seed=0)
    policy = HierarchicalController.for_env(env, HierarchicalConfig.paper())
    policy.reset(obs, info)
    assert policy.spin_task is None
    assert not any(task.name == "spin" for task in policy.tasks)
    for _ in range(2500):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, info
    assert info["psi"] > 0.15  # toward the bearing atan2(1, 2) = 0.46
    # the applied wheel torques carry exactly the MPC's tau_0 (no step was clipped)
    diagnostics, lay = policy.diagnostics, policy.robot.layout
    assert policy.counters["clipped_steps"] == 0
    wl, wr = lay.wheel_actuators
    torque = diagnostics["torque"]
    tau_0, _ = wheel_to_generalized(
        torque[:, wl], torque[:, wr], lay.wheel_radius, lay.wheel_separation
    )
    np.testing.assert_allclose(tau_0, diagnostics["tau_0"], rtol=0.0, atol=1e-9)
    assert np.abs(diagnostics["tau_0"]).max() > 1.0


def test_authors_joint_weights_follow_the_joint_names() -> None:
    env = gym.make("wip_gym/KrangTray-v0")
    robot = make_robot(env, "nominal")
    posture, speed = authors_joint_weights(robot)
    arm_posture = [10.0, 10.0, 10.0, 10.0, 5.0, 5.0, 5.0]
    # waist, torso, left arm j1..j7, right arm j1..j7
    np.testing.assert_array_equal(posture, [0.0, 1.0, *arm_posture, *arm_posture])
    np.testing.assert_array_equal(speed, [10.0, 10.0, *[1.0] * 14])
    planar = make_robot(gym.make("wip_gym/PlanarTray-v0"), "nominal")
    posture, speed = authors_joint_weights(planar)  # spine, torso, shoulder, elbow, wrist
    np.testing.assert_array_equal(posture, [0.0, 1.0, 10.0, 10.0, 5.0])
    np.testing.assert_array_equal(speed, [10.0, 10.0, 1.0, 1.0, 1.0])


def test_controllers_exports_the_policies_without_starting_jax() -> None:
    """``import controllers`` and the registry leave JAX alone; the paper's controller is
    importable from the package (a fresh process: this one has JAX already)."""
    code = (
        "import sys\n"
        "import controllers\n"
        "from controllers import Policy, controller_names, make_policy\n"
        "assert 'jax' not in sys.modules, 'jax imported'\n"
        "from controllers import HierarchicalConfig, HierarchicalController\n"
        "assert HierarchicalController.config_class is HierarchicalConfig\n"
        "assert set(controllers.__all__) <= set(dir(controllers))\n"
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300
    )
    assert result.returncode == 0, result.stderr


def test_decoupled_turns_toward_an_off_axis_goal() -> None:
    """Krang 2014 with our heading gain follows the plan's turn (3-D, goal to the left)."""
    env = gym.make("wip_gym/KrangTray-v0", goal=(2.0, 1.5))
    obs, info = env.reset(seed=0)
    policy = make_policy("decoupled", env)
    policy.reset(obs, info)
    start = info["goal_distance"]
    for _ in range(3000):
        obs, _, terminated, _, info = env.step(policy(obs))
        assert not terminated, info
    diagnostics = policy.diagnostics
    assert np.abs(diagnostics["psi"] - diagnostics["psi_ref"]).max() < 0.25
    assert info["psi"] > 0.3  # the plan turns to the bearing atan2(1.5, 2) = 0.64
    assert info["goal_distance"] < 0.5 * start
