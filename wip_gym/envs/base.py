"""The common Gymnasium environment of every wip-gym robot and task (docs/DESIGN.md §6).

Subclasses (``wip_gym/envs/tasks.py``) fix the robot and whether there is a tray and a cup; the
class docstrings there hold the tables of spaces, rewards and arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces, utils
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
from numpy.typing import NDArray

from wip_gym.assets import mjcf_path
from wip_gym.camera import COMPUTED_CAMERAS
from wip_gym.display import require_display
from wip_gym.envs import measures as ms
from wip_gym.envs import step_reference
from wip_gym.envs.measures import (  # noqa: F401  (the cup's and tray's thresholds, here too)
    CUP_PLATE_GAP,
    CUP_UPRIGHT_DEG,
    TRAY_HAND_GAP,
    env_measures,
)
from wip_gym.envs.perturbations import Perturbations, Perturber, build_task_model
from wip_gym.envs.step_reference import friction_use  # noqa: F401  (its home was here)
from wip_gym.floor import FloorOptions
from wip_gym.overlay import OverlayValues, draw_overlay
from wip_gym.registration import EPISODE_SECONDS
from wip_gym.renderer import FrameRenderer
from wip_gym.robot_model import RobotModel
from wip_gym.robots import robot_spec
from wip_gym.scene import (
    CUP_HALF_HEIGHT,
    TRAY_HALF_SIZE,
    TRAY_RESET_MAX_SPEED,
    TRAY_RESET_SETTLE_TIME,
    SceneOptions,
    TraySettler,
    reset_qpos,
)

DEFAULT_CAMERA_CONFIG: dict[str, Any] = {}
#: how far the reset puts the wheels into the floor (m): enough for their contacts to carry
#: the robot from the first step (a contact exactly at distance 0 is not yet active)
WHEEL_RESET_DEPTH = 1e-6


def _goal_array(goal: Any, planar: bool) -> NDArray[np.float64]:
    arr = np.atleast_1d(np.asarray(goal, dtype=float))
    if arr.shape == (1,):
        arr = np.array([arr[0], 0.0])
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"goal must be a finite x or (x, y), got {goal!r}")
    if planar and arr[1] != 0.0:
        raise ValueError(f"a planar robot's goal has y = 0, got {goal!r}")
    return arr


def _check_time_limit(time_limit: Any) -> None:
    """``ValueError`` unless ``time_limit`` is None or a finite positive number of seconds."""
    if time_limit is None:
        return
    number = isinstance(time_limit, int | float | np.integer | np.floating)
    if isinstance(time_limit, bool) or not number or not (0.0 < time_limit < math.inf):
        raise ValueError(f"time_limit must be None or a positive number of s, got {time_limit!r}")


def _check_frame_skip(frame_skip: Any) -> None:
    """``ValueError`` unless ``frame_skip`` is a positive integer (``mj_step`` takes 0 or a
    negative count as no step at all); checked when the env is made and at the first step after
    it is assigned."""
    integer = isinstance(frame_skip, int | np.integer) and not isinstance(frame_skip, bool)
    if not integer or frame_skip < 1:
        raise ValueError(f"frame_skip must be a positive integer, got {frame_skip!r}")


#: the step info's reward terms, after the entries of :class:`StepLayout`
REWARD_TERMS = ("reward_progress", "reward_ctrl", "reward_fall", "reward_cup_loss")


def _cup_kept(values: list[float]) -> bool:
    """Whether the cup is kept at ``_measure``'s ``values``: on the tray (on the plate and
    upright), and the tray on the hand."""
    OUT = ms.OUT
    return (
        values[OUT.cup_on_plate] != 0.0
        and values[OUT.cup_upright] != 0.0
        and values[OUT.tray_on_hand] != 0.0
    )


@dataclass(frozen=True)
class StepLayout:
    """Where a step's info and observation are (``WIPEnv.step_layout``), for the native
    vector env (docs/vector.md §3). The info's entries (:data:`REWARD_TERMS` after them in a
    step's; a reset's has the same but those) are entries of ``WIPEnv._block``
    (``wip_gym.envs.measures.OUT``): Python floats (key, entry), flags (key, entries: True
    where every listed entry is nonzero; a reset's ``fallen`` is False) and float64 arrays
    (key, start, length); ``keys`` in the info's order. The observation is ``state`` (the
    keys of ``WIPEnv._state_views``' arrays), ``goal`` (``WIPEnv.goal``) and ``measured``
    (entries of ``_block``: key, start, length)."""

    floats: tuple[tuple[str, int], ...]
    flags: tuple[tuple[str, tuple[int, ...]], ...]
    arrays: tuple[tuple[str, int, int], ...]
    keys: tuple[str, ...]
    state: tuple[str, ...]
    goal: str
    measured: tuple[tuple[str, int, int], ...]


class WIPEnv(MujocoEnv, utils.EzPickle):
    """A WIP robot on flat ground driving to a goal, optionally carrying a cup on a tray.

    See the task classes in ``wip_gym.envs.tasks`` for the documentation tables.
    """

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"]}
    #: the actuators' torques (N m) between their control limits (float32, as MujocoEnv sets)
    action_space: spaces.Box[np.float32]
    observation_space: spaces.Dict

    def __init__(
        self,
        robot: str,
        tray: bool = False,
        goal: float | tuple[float, float] = 2.0,
        cup_friction: float = 0.3,
        payload_mass: float = 0.0,
        payload_time: float = 0.0,
        push_force: float = 0.0,
        push_time: float = 1.0,
        push_duration: float = 0.1,
        reset_noise_scale: float = 0.01,
        mass_randomization: float = 0.0,
        wheel_torque_limit: float = 150.0,
        tray_attachment: str = "welded",
        tray_rim: float = 0.0,
        tray_friction: float = 0.3,
        terminate_on_cup_loss: bool = True,
        fall_angle: float = 0.8,
        progress_weight: float = 1.0,
        ctrl_cost_weight: float = 0.1,
        fall_penalty: float = 10.0,
        cup_loss_penalty: float = 10.0,
        frame_skip: int = 1,
        time_limit: float | None = EPISODE_SECONDS,
        sensor_noise: float = 0.0,
        obs_delay_steps: int = 0,
        obs_delay_jitter_steps: int = 0,
        action_delay_steps: int = 0,
        action_delay_jitter_steps: int = 0,
        actuator_lag_s: float = 0.0,
        joint_lag_s: float | None = None,
        torque_noise: float = 0.0,
        com_offset: float = 0.0,
        inertia_randomization: float = 0.0,
        joint_damping: float = 0.0,
        joint_friction: float = 0.0,
        floor_friction: float | tuple[float, float] = 1.0,
        floor_slope_deg: float = 0.0,
        bump_height: float = 0.0,
        bump_spacing: float = 1.0,
        bump_width: float = 0.1,
        width: int = 480,
        height: int = 320,
        **kwargs: Any,
    ) -> None:
        # pickled once, here, by keyword: a task class fixes ``robot`` and ``tray`` itself
        arguments = {k: v for k, v in locals().items() if k not in ("self", "kwargs")}
        if type(self) is not WIPEnv:
            arguments = {k: v for k, v in arguments.items() if k not in ("robot", "tray")}
        utils.EzPickle.__init__(self, **arguments, **kwargs)
        self._spec = robot_spec(robot)
        self._goal = _goal_array(goal, self._spec.planar)
        for name, value in (
            ("payload_time", payload_time),
            ("push_time", push_time),
            ("push_duration", push_duration),
            ("reset_noise_scale", reset_noise_scale),
            ("fall_angle", fall_angle),
            ("ctrl_cost_weight", ctrl_cost_weight),
            ("fall_penalty", fall_penalty),
            ("cup_loss_penalty", cup_loss_penalty),
        ):
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not np.isfinite(push_force):
            raise ValueError(f"push_force must be finite, got {push_force}")
        if not 0.0 <= mass_randomization < 1.0:
            raise ValueError(f"mass_randomization must be in [0, 1), got {mass_randomization}")
        _check_frame_skip(frame_skip)
        _check_time_limit(time_limit)
        # the robot as hardware sees it (wip_gym.envs.perturbations; docs/realism.md)
        self._perturbations = Perturbations(
            sensor_noise=sensor_noise,
            obs_delay_steps=obs_delay_steps,
            obs_delay_jitter_steps=obs_delay_jitter_steps,
            action_delay_steps=action_delay_steps,
            action_delay_jitter_steps=action_delay_jitter_steps,
            actuator_lag_s=actuator_lag_s,
            joint_lag_s=joint_lag_s,
            torque_noise=torque_noise,
            com_offset=com_offset,
            inertia_randomization=inertia_randomization,
            joint_damping=joint_damping,
            joint_friction=joint_friction,
            floor_friction=tuple(floor_friction)  # type: ignore[arg-type]
            if isinstance(floor_friction, list | tuple)
            else floor_friction,
            floor=FloorOptions(floor_slope_deg, bump_height, bump_spacing, bump_width),
        )
        self._scene = SceneOptions(
            robot=robot,
            tray=tray,
            cup=tray,
            cup_friction=cup_friction,
            payload_mass=payload_mass,
            wheel_torque_limit=wheel_torque_limit,
            tray_attachment=tray_attachment,
            tray_rim=float(tray_rim),
            tray_friction=float(tray_friction),
        )
        if not tray and (tray_attachment, tray_rim, tray_friction) != ("welded", 0.0, 0.3):
            raise ValueError(
                f"tray_attachment, tray_rim and tray_friction need a tray task, got "
                f"{tray_attachment!r}, {tray_rim!r}, {tray_friction!r} on robot {robot!r}"
            )
        self._arguments: dict[str, Any] = {
            "goal": tuple(float(v) for v in self._goal)
            if not self._spec.planar
            else float(self._goal[0]),
            "cup_friction": float(cup_friction),
            "payload_mass": payload_mass,
            "payload_time": payload_time,
            "push_force": push_force,
            "push_time": push_time,
            "push_duration": push_duration,
            "reset_noise_scale": reset_noise_scale,
            "mass_randomization": mass_randomization,
            "wheel_torque_limit": wheel_torque_limit,
            "tray_attachment": tray_attachment,
            "tray_rim": float(tray_rim),
            "tray_friction": float(tray_friction),
            "terminate_on_cup_loss": terminate_on_cup_loss,
            "fall_angle": fall_angle,
            "progress_weight": progress_weight,
            "ctrl_cost_weight": ctrl_cost_weight,
            "fall_penalty": fall_penalty,
            "cup_loss_penalty": cup_loss_penalty,
            "frame_skip": int(frame_skip),
            "time_limit": None if time_limit is None else float(time_limit),
            "sensor_noise": sensor_noise,
            "obs_delay_steps": obs_delay_steps,
            "obs_delay_jitter_steps": obs_delay_jitter_steps,
            "action_delay_steps": action_delay_steps,
            "action_delay_jitter_steps": action_delay_jitter_steps,
            "actuator_lag_s": actuator_lag_s,
            "joint_lag_s": joint_lag_s,
            "torque_noise": torque_noise,
            "com_offset": com_offset,
            "inertia_randomization": inertia_randomization,
            "joint_damping": joint_damping,
            "joint_friction": joint_friction,
            "floor_friction": self._perturbations.floor_friction,
            "floor_slope_deg": floor_slope_deg,
            "bump_height": bump_height,
            "bump_spacing": bump_spacing,
            "bump_width": bump_width,
        }
        self._tray = tray
        self._free_tray = tray and tray_attachment == "free"
        self._payload_mass = payload_mass
        self._scratch_data: tuple[mujoco.MjModel, mujoco.MjData] | None = None  # _set_const
        self._payload_time = payload_time
        self._push = (push_force, push_time, push_duration)
        self._reset_noise_scale = reset_noise_scale
        self._mass_randomization = mass_randomization
        self._terminate_on_cup_loss = terminate_on_cup_loss
        self._fall_angle = fall_angle
        self._weights = (progress_weight, ctrl_cost_weight, fall_penalty, cup_loss_penalty)
        self._time_limit = None if time_limit is None else float(time_limit)
        # the make-time goal; reset(options={"goal": ...}) sets another for one episode
        self._default_goal = self._goal.copy()

        if kwargs.get("render_mode") == "human":  # a window: GLFW aborts the process without one
            require_display("render_mode='human'")
        # render(): the camera (wip_gym.camera: "follow", "tray" or an MJCF camera) and overlay
        self._render_camera = kwargs.pop("camera_name", None) or "follow"
        self._render_overlay = bool(kwargs.pop("render_overlay", False))
        self._frame_renderer: FrameRenderer | None = None
        MujocoEnv.__init__(
            self,
            str(mjcf_path(self._spec.scene_file)),
            frame_skip,
            observation_space=None,
            default_camera_config=DEFAULT_CAMERA_CONFIG,
            width=width,
            height=height,
            # render() below draws rgb/depth through its own renderer; an MJCF camera's id is
            # also Gymnasium's (mujoco_renderer.camera_id, e.g. for projecting points)
            camera_name=None if self._render_camera in COMPUTED_CAMERAS else self._render_camera,
            **kwargs,
        )
        self.metadata = {
            "render_modes": ["human", "rgb_array", "depth_array"],
            "render_fps": int(np.round(1.0 / self.dt)),
        }
        self.robot = RobotModel(self.model)
        lay = self.robot.layout
        self._layout = lay
        self._planar = lay.planar
        self._nq, self._nv = lay.nq, lay.nv
        obs: dict[str, spaces.Space[Any]] = {
            "qpos": spaces.Box(-np.inf, np.inf, (lay.nq,), np.float64),
            "qvel": spaces.Box(-np.inf, np.inf, (lay.nv,), np.float64),
            "goal": spaces.Box(-np.inf, np.inf, (2,), np.float64),
        }
        if tray:
            obs["cup_pose"] = spaces.Box(-np.inf, np.inf, (7,), np.float64)
        self.observation_space = spaces.Dict(obs)
        m = self.model
        self._robot_bodies = np.array(
            [b for b in range(m.nbody) if m.body_rootid[b] == lay.base_body]
        )
        self._nominal_mass = m.body_mass.copy()
        self._nominal_inertia = m.body_inertia.copy()
        self._push_body = m.body(self._spec.push_body).id
        self._goal_site = m.site("goal").id
        self._floor = m.geom("floor").id
        wheel_geoms = {m.geom("wheel_left").id, m.geom("wheel_right").id}
        self._body_geoms = np.array(
            [
                g
                for g in range(m.ngeom)
                if m.geom_bodyid[g] in self._robot_bodies
                and g not in wheel_geoms
                and (m.geom_contype[g] or m.geom_conaffinity[g])
            ]
        )
        self._body_geom_set = frozenset(self._body_geoms.tolist())
        self._ee_site = m.site("ee").id if self._spec.tray_capable else -1
        if tray:
            self._tray_body = m.body("tray").id
            self._cup_body = m.body("cup").id
            self._cup_qpos = m.jnt_qposadr[m.joint("cup").id]
            self._cup_dof = m.jnt_dofadr[m.joint("cup").id]
            self._cup_geom = m.geom("cup").id
            self._cup_geoms = frozenset(np.flatnonzero(m.geom_bodyid == self._cup_body).tolist())
            self._tray_geom = m.geom("tray").id
            self._cup_friction = float(cup_friction)
            rest = m.site("tray_rest").id
            self._tray_rest_site = rest
            self._tray_mount_body = int(m.site_bodyid[rest])
            self._tray_rest_pos = m.site_pos[rest].copy()
            self._tray_rest_quat = m.site_quat[rest].copy()
        if self._free_tray:
            tray_joint = m.joint("tray").id
            self._tray_qpos = m.jnt_qposadr[tray_joint]
            self._tray_dof = m.jnt_dofadr[tray_joint]
            self._tray_settler = TraySettler(m, self._scene)
        if payload_mass > 0:
            self._payload_body = m.body("payload").id
        self._perturber = Perturber(
            self._perturbations,
            m,
            lay,
            self.dt,
            self._robot_bodies,
            m.body("payload").id if self._spec.tray_capable else -1,
        )
        # the step's hooks run only for a perturbation that acts there
        self._perturb_model = self._perturbations.active
        self._perturb_action = self._perturbations.on_action
        self._perturb_observation = self._perturbations.on_observation
        self._action_low = self.action_space.low.astype(np.float64)
        self._action_high = self.action_space.high.astype(np.float64)
        # made once: the accepted band (limits +- 1e-6 of the range) and the reward's scale
        tol = 1e-6 * (self._action_high - self._action_low)
        self._action_band = (self._action_low - tol, self._action_high + tol)
        self._action_scale = np.maximum(np.abs(self._action_high), 1e-12)
        self._prev_distance = 0.0
        self._ee_reference = np.zeros(3)
        self._cup_lost = False
        self._islands_switched_on = False  # by a cup's loss, until the next reset
        self._payload_attached = True
        # made once for step(): plain Python numbers and the views of the arrays it reads
        self._goal_xy = (float(self._goal[0]), float(self._goal[1]))
        # the accepted band and the reward's scale, rows of one table (action_effort)
        self._action_table = np.array([*self._action_band, self._action_scale])
        # the parameters of the step's measures (wip_gym.envs.measures) and its results
        INT, FLOAT = ms.INT, ms.FLOAT
        ints = np.zeros(ms.N_INTS + m.ngeom, dtype=np.int64)
        ints[INT.base] = lay.base_body
        ints[INT.wheel_left], ints[INT.wheel_right] = lay.wheel_bodies
        ints[INT.planar] = lay.planar
        ints[INT.root_qpos], ints[INT.root_dof] = lay.root_qpos, lay.root_dof
        ints[INT.qpos_left], ints[INT.qpos_right] = lay.wheel_qpos
        ints[INT.dof_left], ints[INT.dof_right] = lay.wheel_dof
        ints[INT.ee_site] = self._ee_site
        ints[INT.floor] = self._floor
        ints[ms.N_INTS + self._body_geoms] |= ms.GEOM_FALL
        floats = np.zeros(ms.N_FLOATS)
        floats[FLOAT.wheel_radius] = lay.wheel_radius
        floats[FLOAT.goal : FLOAT.goal + 2] = self._goal_xy
        floats[FLOAT.fall_angle] = fall_angle
        if tray:
            ints[INT.tray], ints[INT.free_tray] = 1, self._free_tray
            ints[INT.tray_body], ints[INT.cup_body] = self._tray_body, self._cup_body
            ints[INT.rest_site], ints[INT.tray_geom] = self._tray_rest_site, self._tray_geom
            ints[ms.N_INTS + np.array(sorted(self._cup_geoms))] |= ms.GEOM_CUP
            floats[FLOAT.cup_friction] = self._cup_friction
        self._measure_ints, self._measure_floats = ints, floats
        self._measures = np.zeros(ms.N_OUT)
        self._measures[ms.OUT.cos_psi] = 1.0  # heading 0 until the first measure
        self._block = self._measures.copy()
        self._values = self._measures.tolist()
        self._action_shape = self.action_space.shape
        # step() applies a push or a payload only while one can still come (reset_model)
        self._events_due = push_force != 0.0
        # the fast path (compiled, wip_gym.envs.measures) or the readable one
        # (wip_gym.envs.step_reference), as the robot model took
        self._fast = self.robot.fast_path
        self._action_effort = ms.action_effort if self._fast else step_reference.action_effort
        ms.compile_once(self._fast)
        self._bind_views()

    def _bind_views(self) -> None:
        """Keep the views of the model's and data's arrays that ``step`` reads (a view stays
        valid while its MjData or MjModel lives; made again if the env gets new ones)."""
        m, d = self.model, self.data
        self._views_of = (m, d)
        self._view_robot_qpos, self._view_robot_qvel = d.qpos[: self._nq], d.qvel[: self._nv]
        self._view_xmat = d.xmat
        self._view_push = d.xfrc_applied[self._push_body]
        # do_simulation checks frame_skip and makes _step_dt for it at the next step (-1: none
        # checked yet; frame_skip may have been assigned since the env was made)
        self._frames_bound = -1
        self._measure_table = (
            ms.env_table(m, d, self._measure_ints, self._measure_floats, self._measures)
            if self._fast
            else None
        )

    # ----------------------------------------------------------------- model
    def _initialize_simulation(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        model = build_task_model(self._scene, self._perturbations, self._goal_xy_of_task())
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, self.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, self.height)
        return model, mujoco.MjData(model)

    def _goal_xy_of_task(self) -> tuple[float, float]:
        return (float(self._goal[0]), float(self._goal[1]))

    @property
    def perturbations(self) -> Perturbations:
        """The perturbation arguments in effect (docs/realism.md)."""
        return self._perturbations

    @property
    def perturber(self) -> Perturber:
        """The perturbations at run time (its ``sensors`` hold the last observation's
        errors)."""
        return self._perturber

    @property
    def scene_options(self) -> SceneOptions:
        """What the model was built from (a controller builds its nominal model from it)."""
        return self._scene

    @property
    def goal(self) -> NDArray[np.float64]:
        """The goal ``(X, Y)`` in world (planar: ``(x, 0)``)."""
        return self._goal.copy()

    @property
    def push(self) -> tuple[float, float, float]:
        """``(force N, start s, duration s)`` of the push along the heading."""
        return self._push

    @property
    def reset_noise_scale(self) -> float:
        return self._reset_noise_scale

    @property
    def cup_friction(self) -> float | None:
        """Tray-cup friction coefficient, or None without a cup."""
        return self._cup_friction if self._tray else None

    @property
    def tray_attachment(self) -> str | None:
        """``welded`` or ``free``, None without a tray."""
        return self._scene.tray_attachment if self._tray else None

    @property
    def tray_rim(self) -> float | None:
        """Rim height of the tray (m), None without a tray."""
        return self._scene.tray_rim if self._tray else None

    @property
    def tray_friction(self) -> float | None:
        """Friction of the free tray's contacts with its supports (also reported when welded,
        where it has no effect), None without a tray."""
        return self._scene.tray_friction if self._tray else None

    @property
    def arguments(self) -> dict[str, Any]:
        """Every env argument in effect (defaults included), by name, as ``gymnasium.make``
        takes it (render arguments excluded)."""
        return dict(self._arguments)

    @property
    def time_limit(self) -> float | None:
        """The episode's time limit in simulated seconds (None: none); ``step`` reports
        ``truncated`` at the first step that reaches it."""
        return self._time_limit

    # ----------------------------------------------------------------- reset
    # MujocoEnv types observations as one array; ours is the Dict space's dict
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float64]], dict[str, Any]]:
        """Gymnasium's reset; ``options={"goal": x or (X, Y)}`` sets the goal of this episode
        (a reset without it goes back to the goal the env was made with). ``ValueError`` for
        another option or a goal the robot cannot have (a planar robot's goal has y = 0)."""
        goal = self._default_goal
        if options:
            unknown = sorted(set(options) - {"goal"})
            if unknown:
                raise ValueError(f"unknown reset options {unknown}; valid: ['goal']")
            goal = _goal_array(options["goal"], self._spec.planar)
        self._set_goal(goal)
        return super().reset(seed=seed, options=options)

    def _set_goal(self, goal: NDArray[np.float64]) -> None:
        """The goal the observation, the reward and the info measure from (``reset`` places
        its marker)."""
        self._goal = goal.copy()
        self._goal_xy = (float(goal[0]), float(goal[1]))
        self._measure_floats[ms.FLOAT.goal : ms.FLOAT.goal + 2] = self._goal_xy

    def reset_model(self) -> dict[str, NDArray[np.float64]]:  # type: ignore[override]
        m, d, lay = self.model, self.data, self.robot.layout
        rng = self.np_random
        self._solve_by_islands(False)  # as built again, before any of the reset's physics
        if self._perturb_model:  # the perturbations' own streams seeded (none drawn from rng)
            self._perturber.begin_episode(rng, self.np_random_seed)
        m.body_mass[:] = self._nominal_mass
        m.body_inertia[:] = self._nominal_inertia
        if self._mass_randomization > 0:
            scale = 1.0 + rng.uniform(
                -self._mass_randomization, self._mass_randomization, len(self._robot_bodies)
            )
            m.body_mass[self._robot_bodies] *= scale
            m.body_inertia[self._robot_bodies] *= scale[:, None]
        if self._perturb_model:
            self._perturber.perturb_model(m)
        self._payload_attached = self._payload_mass <= 0 or self._payload_time <= 0.0
        self._events_due = self._push[0] != 0.0 or not self._payload_attached
        if self._payload_mass > 0 and not self._payload_attached:
            m.body_mass[self._payload_body] = 0.0
            m.body_inertia[self._payload_body] = 0.0
        self._set_const()

        qpos0 = reset_qpos(m, self.robot)
        self.robot.update(qpos0, np.zeros(lay.nv), dynamics=False)
        q = self.robot.q.copy()
        nu = np.zeros(lay.n_min)
        s = self._reset_noise_scale
        first = lay.index_q1
        q[first:] += rng.uniform(-s, s, lay.n_min - first)
        nu[first:] += rng.uniform(-s, s, lay.n_min - first)
        qpos_robot, qvel_robot = self.robot.full_state(q, nu)
        # the wheels WHEEL_RESET_DEPTH into the floor, as the cup into the tray below: at
        # distance 0 their contacts carry no force at the reset, and the robot dropped onto
        # its wheels in the first step (17 to 20 mm/s down, a bounce of the wheels' contact
        # that shook the tray)
        qpos_robot[lay.root_qpos + (1 if lay.planar else 2)] -= WHEEL_RESET_DEPTH
        qpos = self.init_qpos.copy()
        qvel = np.zeros(m.nv)
        qpos[: lay.nq] = qpos_robot
        qvel[: lay.nv] = qvel_robot
        if self._perturb_model:
            self._perturber.place_on_floor(qpos)
        if self._tray:
            if self._free_tray:
                self._place_free_tray(qpos)
            d.qpos[:] = qpos
            mujoco.mj_kinematics(m, d)
            top = d.xpos[self._tray_body] + d.xmat[self._tray_body].reshape(3, 3) @ np.array(
                # 1 micron into the tray: a contact exactly at distance 0 is not yet active
                [0.0, 0.0, 2 * TRAY_HALF_SIZE[2] + CUP_HALF_HEIGHT - 1e-6]
            )
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, d.xmat[self._tray_body])
            qpos[self._cup_qpos : self._cup_qpos + 3] = top
            qpos[self._cup_qpos + 3 : self._cup_qpos + 7] = quat
            if self._free_tray:
                self._move_with_hand(qpos, qvel)
        self.set_state(qpos, qvel)
        m.site_pos[self._goal_site, :2] = self._goal
        d.xfrc_applied[:] = 0.0
        values = self._measure()
        self._prev_distance = values[ms.OUT.goal_distance]
        self._set_ee_reference(self._ee_in_axle_frame())
        # _measure found ee_error from the previous reference: from this one it is 0
        error = ms.OUT.ee_error
        self._measures[error] = self._block[error] = values[error] = 0.0
        self._cup_lost = False
        if self._perturb_observation:
            return self._perturber.observe(self._get_obs(), first=True)
        return self._get_obs()

    def _set_const(self) -> None:
        """``mj_setConst`` on the model (its constants for the masses and inertias now). It
        overwrites the data it is given (``qpos`` reset to ``qpos0``), so it gets a scratch
        MjData of the env's own, made once per model: making one at every reset took 0.4 ms
        of PlanarTray-v0's 0.6 ms reset. The constants do not depend on the scratch data's
        contents (``tests/test_envs.py`` holds them equal to a fresh data's)."""
        m = self.model
        scratch = self._scratch_data
        if scratch is None or scratch[0] is not m:
            scratch = (m, mujoco.MjData(m))
            self._scratch_data = scratch
        mujoco.mj_setConst(m, scratch[1])

    def _move_with_hand(self, qpos: NDArray[np.float64], qvel: NDArray[np.float64]) -> None:
        """Give the free tray and the cup (in ``qvel``) the velocity they would have welded to
        the hand at the reset state, so that the reset's velocity noise does not start them
        sliding on the hand (a welded tray moves with it by construction)."""
        m, d = self.model, self.data
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        body = self._tray_mount_body
        velocity = np.zeros(6)  # (angular, linear) at the body's origin, world frame
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
        omega, linear = velocity[:3], velocity[3:]
        for moved, dof in ((self._tray_body, self._tray_dof), (self._cup_body, self._cup_dof)):
            arm = d.xpos[moved] - d.xpos[body]
            qvel[dof : dof + 3] = linear + np.cross(omega, arm)
            qvel[dof + 3 : dof + 6] = d.xmat[moved].reshape(3, 3).T @ omega

    def _place_free_tray(self, qpos: NDArray[np.float64]) -> None:
        """Put the free tray (in ``qpos``) at rest on the supports of the robot pose in
        ``qpos``: from its rest place on the hand (the ``tray_rest`` site, found when the model
        was built) it settles for ``TRAY_RESET_SETTLE_TIME`` with the robot still (the reset
        noise moves Krang's grippers relative to each other by a few mm)."""
        m, d = self.model, self.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        body = self._tray_mount_body
        position = d.xpos[body] + d.xmat[body].reshape(3, 3) @ self._tray_rest_pos
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, d.xquat[body], self._tray_rest_quat)
        position, quat = self._tray_settler.settle(
            d, position, quat, TRAY_RESET_SETTLE_TIME, TRAY_RESET_MAX_SPEED
        )
        a = self._tray_qpos
        qpos[a : a + 3] = position
        qpos[a + 3 : a + 7] = quat

    def _get_reset_info(self) -> dict[str, Any]:
        values = self._values  # reset_model's _measure
        info = self._info(values, fallen=False)
        if self._tray:
            self._tray_entries(info, values)
        return info

    # ------------------------------------------------------------------ step
    # MujocoEnv types observations as one array and info as floats; ours are dicts of arrays
    def step(  # type: ignore[override]
        self, action: NDArray[np.floating]
    ) -> tuple[dict[str, NDArray[np.float64]], float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self._action_shape:
            a = self._check_action(a)
        reward, progress, ctrl, fall, cup_loss, terminated, truncated = self._advance(a)
        info = self._step_info(progress, ctrl, fall, cup_loss)
        if self.render_mode == "human":
            self.render()
        obs = self._get_obs()
        if self._perturb_observation:  # what the sensors report, when it arrives
            obs = self._perturber.observe(obs)
        return obs, reward, terminated, truncated, info

    def _advance(self, a: NDArray[np.float64]) -> tuple[float, Any, Any, Any, Any, bool, bool]:
        """The step without its observation and info (``step`` is this and them; the native
        vector env calls it and reads the batch's rows itself, docs/vector.md §3): the action
        ``a`` (float64 of the action's shape) checked, the physics, the measures (kept as
        ``_values``, ``_block``), the cup's loss; returns the reward, its terms (progress,
        ctrl, fall, cup loss), terminated and truncated."""
        # the action's check and its ctrl cost, one compiled call (_check_action explains a
        # rejected action)
        effort = self._action_effort(a, self._action_table)
        if effort != effort:  # NaN: a torque beyond the band, or NaN
            a = self._check_action(a)
            effort = float(np.sum(np.square(a / self._action_scale)))
        if self._events_due:
            self._apply_events()
        if self._perturb_action:  # the torques applied: delayed, noisy (docs/realism.md)
            a = self._perturber.actuate(a)
        self.do_simulation(a, self.frame_skip)
        values = self._measure()
        OUT = ms.OUT
        fallen = values[OUT.fallen] != 0.0
        newly_lost = False
        if self._tray:
            kept = _cup_kept(values)
            newly_lost = not kept and not self._cup_lost
            self._cup_lost = self._cup_lost or not kept
            if newly_lost:
                self._solve_by_islands(True)
        distance = values[OUT.goal_distance]
        progress_w, ctrl_w, fall_pen, cup_pen = self._weights
        progress = progress_w * (self._prev_distance - distance)
        ctrl = -ctrl_w * effort * self._step_dt
        fall = -fall_pen if fallen else 0.0
        cup_loss = -cup_pen if newly_lost else 0.0
        self._prev_distance = distance
        terminated = bool(fallen or (self._tray and self._terminate_on_cup_loss and self._cup_lost))
        # the time limit in simulated seconds, whatever frame_skip is (half a MuJoCo step of
        # margin for the sum of the steps' rounding)
        limit = self._time_limit
        truncated = limit is not None and self.data.time >= limit - 0.5 * self.model.opt.timestep
        reward = float(progress + ctrl + fall + cup_loss)
        return reward, progress, ctrl, fall, cup_loss, terminated, truncated

    def _step_info(self, progress: Any, ctrl: Any, fall: Any, cup_loss: Any) -> dict[str, Any]:
        """The info of the step :meth:`_advance` made, with its reward terms."""
        values = self._values
        info = self._info(values, values[ms.OUT.fallen] != 0.0)
        if self._tray:
            self._tray_entries(info, values)
        info["reward_progress"] = progress
        info["reward_ctrl"] = ctrl
        info["reward_fall"] = fall
        info["reward_cup_loss"] = cup_loss
        return info

    def _solve_by_islands(self, cup_lost: bool) -> None:
        """Constraint islands, off in the models (assets/mjcf/README.md: while the cup rides the
        tray a scene is one island, where solving by islands gives the same bits for more
        work), are switched on from a cup's loss to the next reset: the cup (or the free tray)
        on the floor is an island of its own, and one joint solve stops when the robot's
        forces have converged, leaving the cup's up to 1e-4 m/s off where the solve by islands
        converges each. Only the island flag is touched, only if it
        is set at the loss, and only what this switched on is switched off at the reset: a
        user's own setting stands. ``model.opt`` shows the change."""
        bit = int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
        opt = self.model.opt
        if cup_lost:
            if opt.disableflags & bit:
                opt.disableflags &= ~bit
                self._islands_switched_on = True
        elif self._islands_switched_on:
            opt.disableflags |= bit
            self._islands_switched_on = False

    def _apply_events(self) -> None:
        """Before a step: the push on (its force along the heading at the step's start) or off
        (zeroed) on its body; a payload due in the hand put there. Only an env with a push
        (``push_force != 0``) writes its body's ``xfrc_applied``; others leave it to the user."""
        if self._views_of[1] is not self.data or self._views_of[0] is not self.model:
            self._bind_views()
        m, t = self.model, self.data.time
        force, start, duration = self._push
        if force != 0.0:
            push = self._view_push
            push[:] = 0.0
            if start <= t < start + duration:
                push[:3] = (
                    force * self._values[ms.OUT.cos_psi],
                    force * self._values[ms.OUT.sin_psi],
                    0,
                )
        if not self._payload_attached and t >= self._payload_time:
            m.body_mass[self._payload_body] = self._payload_mass
            m.body_inertia[self._payload_body] = self._nominal_inertia[self._payload_body]
            self._set_const()
            self._payload_attached = True
            self._events_due = force != 0.0

    def do_simulation(self, ctrl: NDArray[np.float64], n_frames: int) -> None:
        """``n_frames`` MuJoCo steps with the (validated) torques ``ctrl``. Unlike Gymnasium's,
        it does not run ``mj_rnePostConstraint`` after them: ``data.cfrc_int``/``cfrc_ext``
        are not computed (no observation, reward or info uses them); call it to read them."""
        if n_frames != self._frames_bound:  # frame_skip assigned since: checked, dt made again
            _check_frame_skip(n_frames)
            self._frames_bound = int(n_frames)
            self._step_dt = float(self.model.opt.timestep) * n_frames
        self.data.ctrl[:] = ctrl
        mujoco.mj_step(self.model, self.data, n_frames)

    def _check_action(self, action: Any) -> NDArray[np.float64]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise ValueError(
                f"action must have shape {self.action_space.shape} (one torque per actuator: "
                f"{[self.model.actuator(i).name for i in range(self.model.nu)]}), got {a.shape}"
            )
        low, high = self._action_band
        if ((a >= low) & (a <= high)).all():  # also false for NaN
            return a
        if not np.isfinite(a).all():
            raise ValueError(
                f"action contains NaN or inf at indices {np.flatnonzero(~np.isfinite(a))}"
            )
        outside = (a < low) | (a > high)
        if outside.any():
            bad = {
                self.model.actuator(i).name: (float(a[i]), float(self._action_high[i]))
                for i in np.flatnonzero(outside)
            }
            raise ValueError(f"action beyond the torque limits (value, limit): {bad}")
        return a

    # ------------------------------------------------------------- measures
    def _measure(self) -> list[float]:
        """The step's numbers for the current ``qpos``/``qvel``, from MuJoCo's own kinematics
        and subtree quantities on the env's data (``mj_step`` leaves its kinematics at the state
        before the step) and its contacts, into ``_measures`` (``wip_gym.envs.measures.OUT``:
        heading ``psi``, ``psid``, ``x``, ``xd`` (the minimal coordinates of ``RobotModel``),
        the axle position, ``theta``, ``thetad`` of the body CoM (wheels excluded) about the
        axle in the heading frame (``RobotModel.theta``), the goal distance, the fall, the end
        effector's drift, a tray task's cup and tray): on the fast path one compiled call,
        ``env_measures``; on the readable one ``step_reference.measures``, their definition.
        Returned as floats and kept as ``_values``; ``_block`` is a fresh copy of
        ``_measures`` whose slices are the step's array-valued info and observation entries
        (one allocation for all of them)."""
        if self._views_of[1] is not self.data or self._views_of[0] is not self.model:
            self._bind_views()
        out = self._measures
        if self._measure_table is not None:
            env_measures(self._measure_table.rows, self.data.ncon)
        else:
            step_reference.measures(
                self.model, self.data, self._measure_ints, self._measure_floats, out
            )
        return self._keep_measures()

    def _keep_measures(self) -> list[float]:
        """``_block`` and ``_values`` made from ``_measures`` (:meth:`_measure`'s last part;
        the native vector env's compiled steps leave it to the vector env,
        ``wip_gym.vector.compiled``)."""
        self._block = block = self._measures.copy()
        self._values = values = block.tolist()
        return values

    def _goal_distance(self) -> float:
        """The axle's distance to the goal at the last ``_measure`` (planar: along x)."""
        return self._values[ms.OUT.goal_distance]

    def _ee_in_axle_frame(self) -> NDArray[np.float64]:
        """The end effector in the axle frame at the last ``_measure`` (zeros without one)."""
        if self._ee_site < 0:
            return np.zeros(3)
        return self._measures[ms.OUT.ee : ms.OUT.ee + 3].copy()

    def _set_ee_reference(self, reference: NDArray[np.float64]) -> None:
        """The end effector's place (axle frame) that ``ee_error`` is measured from."""
        self._ee_reference = reference
        self._measure_floats[ms.FLOAT.ee_reference : ms.FLOAT.ee_reference + 3] = reference

    def _cup_friction_use(self) -> float:
        """The cup's friction use on the plate now (see :func:`friction_use`)."""
        return friction_use(
            self.model, self.data, self._cup_geoms, self._tray_geom, self._cup_friction
        )

    def _tray_tilt_deg(self) -> float:
        z = self._view_xmat.item(self._tray_body, 8)  # the normal's world z
        return math.degrees(math.acos(min(1.0, max(-1.0, z))))

    def _info(
        self, values: list[float] | None = None, fallen: bool | None = None
    ) -> dict[str, Any]:
        """The robot's info from ``_measure``'s ``values`` (the last if None; ``fallen``: as
        found there if None); a tray task's entries are added by ``_tray_entries``."""
        if values is None:
            values = self._values
        if fallen is None:
            fallen = values[ms.OUT.fallen] != 0.0
        info: dict[str, Any] = {
            "x": values[ms.OUT.x],
            "xd": values[ms.OUT.xd],
            "theta": values[ms.OUT.theta],
            "thetad": values[ms.OUT.thetad],
            "axle_position": self._block[ms.OUT.axle : ms.OUT.axle + 3],
            "goal_distance": values[ms.OUT.goal_distance],
            "fallen": fallen,
        }
        if not self._planar:
            info["psi"] = values[ms.OUT.psi]
            info["psid"] = values[ms.OUT.psid]
        if self._ee_site >= 0:
            info["ee_error"] = values[ms.OUT.ee_error]
        return info

    def _tray_entries(self, info: dict[str, Any], values: list[float]) -> None:
        """Add the tray task's info entries from ``_measure``'s ``values``."""
        OUT, block = ms.OUT, self._block
        tilt, tray_tilt = values[OUT.cup_tilt_deg], values[OUT.tray_tilt_deg]
        upright, on_plate = values[OUT.cup_upright] != 0.0, values[OUT.cup_on_plate] != 0.0
        on_hand, use = values[OUT.tray_on_hand] != 0.0, values[OUT.cup_friction_use]
        on_tray = on_plate and upright
        info.update(
            tray_tilt_deg=tray_tilt,
            cup_offset=block[ms.OUT.cup_pose : ms.OUT.cup_pose + 3],
            cup_tilt_deg=tilt,
            cup_upright=upright,
            cup_on_plate=on_plate,
            cup_on_tray=on_tray,
            cup_friction_use=use,
            tray_offset=block[ms.OUT.tray_offset : ms.OUT.tray_offset + 3],
            tray_on_hand=on_hand,
        )

    def step_layout(self) -> StepLayout | None:
        """Where every entry of this env's step and reset infos and observations is (what
        :meth:`_info`, :meth:`_tray_entries` and :meth:`_get_obs` read), for the native vector
        env's batching (docs/vector.md §3); None if an entry's type may vary from step to step
        (a reward weight not a float: ``-fall_penalty`` of an int is an int) or the
        observation is not read from the data (an observation perturbation): there that
        vector env batches the dicts themselves."""
        progress_w, ctrl_w, fall_pen, cup_pen = self._weights
        if self._perturb_observation or not (
            type(progress_w) in (int, float)
            and type(ctrl_w) in (int, float)
            and type(fall_pen) is float
            and type(cup_pen) is float
        ):
            return None
        OUT = ms.OUT
        entries: list[tuple[str, str, tuple[int, ...]]] = [
            ("x", "float", (OUT.x,)),
            ("xd", "float", (OUT.xd,)),
            ("theta", "float", (OUT.theta,)),
            ("thetad", "float", (OUT.thetad,)),
            ("axle_position", "array", (OUT.axle, 3)),
            ("goal_distance", "float", (OUT.goal_distance,)),
            ("fallen", "flag", (OUT.fallen,)),
        ]
        if not self._planar:
            entries += [("psi", "float", (OUT.psi,)), ("psid", "float", (OUT.psid,))]
        if self._ee_site >= 0:
            entries.append(("ee_error", "float", (OUT.ee_error,)))
        if self._tray:
            entries += [
                ("tray_tilt_deg", "float", (OUT.tray_tilt_deg,)),
                ("cup_offset", "array", (OUT.cup_pose, 3)),
                ("cup_tilt_deg", "float", (OUT.cup_tilt_deg,)),
                ("cup_upright", "flag", (OUT.cup_upright,)),
                ("cup_on_plate", "flag", (OUT.cup_on_plate,)),
                ("cup_on_tray", "flag", (OUT.cup_on_plate, OUT.cup_upright)),
                ("cup_friction_use", "float", (OUT.cup_friction_use,)),
                ("tray_offset", "array", (OUT.tray_offset, 3)),
                ("tray_on_hand", "flag", (OUT.tray_on_hand,)),
            ]
        return StepLayout(
            floats=tuple((key, where[0]) for key, kind, where in entries if kind == "float"),
            flags=tuple((key, where) for key, kind, where in entries if kind == "flag"),
            arrays=tuple(
                (key, where[0], where[1]) for key, kind, where in entries if kind == "array"
            ),
            keys=tuple(key for key, _, _ in entries),
            state=("qpos", "qvel"),
            goal="goal",
            measured=(("cup_pose", OUT.cup_pose, 7),) if self._tray else (),
        )

    def _state_views(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The robot's ``qpos`` and ``qvel``, which :meth:`_get_obs` copies (views of the
        data, read at once: the next step or reset overwrites them)."""
        return self._view_robot_qpos, self._view_robot_qvel

    def _measure_into(self, row: NDArray[np.float64]) -> None:
        """Keep the measures (``_measures``, ``wip_gym.envs.measures.OUT``) in ``row`` from
        now on (a C-contiguous float64 vector of ``N_OUT``, a row of the native vector env's
        batch, which writes no copy of them then): their values copied there, the compiled
        measures' table made again for it. The step's results are the same."""
        if row.shape != self._measures.shape or row.dtype != np.float64:
            raise ValueError(f"expected a float64 vector of {self._measures.shape}, got {row}")
        if not row.flags.c_contiguous:
            raise ValueError("the measures' row must be C-contiguous")
        row[:] = self._measures
        self._measures = row
        self._bind_views()

    def _get_obs(self) -> dict[str, NDArray[np.float64]]:
        """The observation at the last ``_measure`` (fresh arrays, none shared with the info)."""
        obs = {
            "qpos": self._view_robot_qpos.copy(),
            "qvel": self._view_robot_qvel.copy(),
            "goal": self._goal.copy(),
        }
        if self._tray:
            obs["cup_pose"] = self._block[ms.OUT.cup_pose : ms.OUT.cup_pose + 7].copy()
        return obs

    # ------------------------------------------------------------- rendering
    # (wip_gym.camera frames the robot; wip_gym.overlay draws the task's numbers when asked)
    @property
    def payload_visible(self) -> bool:
        """The payload is drawn only once it is in the hand (``payload_time``)."""
        return self._payload_mass > 0 and self._payload_attached

    def render_hidden_geoms(self) -> list[int]:
        """Geoms left out of the picture now: a payload not yet in the hand."""
        if self._payload_mass > 0 and not self._payload_attached:
            body = self._payload_body
            return [g for g in range(self.model.ngeom) if self.model.geom_bodyid[g] == body]
        return []

    def overlay_values(self) -> OverlayValues:
        """The overlay's numbers for the current state."""
        return OverlayValues(
            time=float(self.data.time),
            goal_distance=self._goal_distance(),
            tray_tilt_deg=self._tray_tilt_deg() if self._tray else None,
            friction_use=self._cup_friction_use() if self._tray else None,
            cup_lost=self._cup_lost,
        )

    def render(self) -> Any:
        """``rgb_array``/``depth_array``: a frame through ``camera_name`` (default ``follow``,
        the robot framed from its side; ``tray``: the tray and cup close up), with the overlay
        if the env was made with ``render_overlay=True``. ``human``: Gymnasium's viewer."""
        if self.render_mode not in ("rgb_array", "depth_array"):
            return super().render()
        if self._frame_renderer is None:
            self._frame_renderer = FrameRenderer(
                self.model, self.width, self.height, camera=self._render_camera
            )
        hidden = self.render_hidden_geoms()
        if self.render_mode == "depth_array":
            return self._frame_renderer.render(self.data, hidden, depth=True)
        frame = self._frame_renderer.render(self.data, hidden)
        if self._render_overlay:
            frame = draw_overlay(frame, self.overlay_values())
        return frame

    def close(self) -> None:
        if self._frame_renderer is not None:
            self._frame_renderer.close()
            self._frame_renderer = None
        super().close()


def wip_env(env: gym.Env[Any, Any]) -> WIPEnv:
    """The wip-gym env under ``env``'s wrappers; ``ValueError`` for any other env."""
    base = env.unwrapped
    if not isinstance(base, WIPEnv):
        raise ValueError(f"expected a wip-gym env (a WIPEnv), got {type(base).__name__}")
    return base
