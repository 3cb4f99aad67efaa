"""The robot as hardware sees it: sensor noise, delays, actuator lag, torque noise, model error
and the floor's shape, as env arguments, every one off by default (docs/realism.md).

:class:`Perturbations` holds the settings (the env arguments, with their units); the env calls
a :class:`Perturber` at the step's boundaries only:

* when the model is built (:func:`build_task_model`): the floor's slope and bumps
  (``wip_gym.floor``) and the actuators' first-order lag (MuJoCo's own activation dynamics);
* at each reset (:meth:`Perturber.begin_episode`, :meth:`Perturber.perturb_model`,
  :meth:`Perturber.place_on_floor`): the streams seeded, the delay lines emptied, the model
  errors drawn, the wheels put on the slope;
* per step, the action before the simulation (:meth:`Perturber.actuate`: the action delay
  line, then the torque noise) and the observation after it (:meth:`Perturber.observe`: the
  sensors, ``wip_gym.envs.sensors``, then the observation delay line).

Each family draws from a random stream of its own, seeded from the reset's seed (the env's
``np_random_seed``) and a tag: the env's own stream (the reset noise, ``mass_randomization``)
is never drawn from here, so the same seed gives the same true initial state with any
perturbation on or off, and switching one family on does not change another's draws. With
every argument at its default nothing here runs and the env is today's to the bit.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.envs.draws import Draws
from wip_gym.envs.sensors import SensorModel, Sensors
from wip_gym.floor import FloorOptions, axle_lift, check_start_clear, shape_floor
from wip_gym.robot_model import RobotLayout
from wip_gym.scene import SceneOptions, build_model, build_spec

Array = NDArray[np.float64]

#: the first word of every perturbation stream's spawn key ("real"), then the family's tag
STREAM_KEY = 0x7265616C
SENSOR_STREAM, OBS_DELAY_STREAM, ACTION_DELAY_STREAM, TORQUE_STREAM, MODEL_STREAM = 1, 2, 3, 4, 5
WHEEL_ACTUATORS = ("wheel_left", "wheel_right")


def _number(name: str, value: Any, low: float = 0.0, below: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value < low or (below is not None and value >= below):
        bound = f"in [{low}, {below})" if below is not None else f">= {low}"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return value


def _steps(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ValueError(f"{name} must be an integer number of control steps >= 0, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class Perturbations:
    """The perturbation env arguments (docs/realism.md for each one's realistic value and its
    source). Every default is off: the env as it was.

    Attributes:
        sensor_noise: scale on the sensors' documented standard deviations, biases and encoder
            steps (``wip_gym.envs.sensors.SensorModel``); 0 for the exact state.
        obs_delay_steps: control steps by which the observation is late.
        obs_delay_jitter_steps: each step's observation delay is ``obs_delay_steps + U{0..j}``.
        action_delay_steps: control steps by which the action is applied late (zero torque
            before the first action arrives).
        action_delay_jitter_steps: each step's action delay is ``action_delay_steps + U{0..j}``.
        actuator_lag_s: time constant (s) of a first-order lag on every actuator's torque.
        joint_lag_s: the body joints' own time constant (s); None: ``actuator_lag_s``.
        torque_noise: standard deviation of white torque noise per control step, as a fraction
            of each actuator's torque limit.
        com_offset: each link's CoM moved by ``U(-c, c)`` (m) per axis per reset (wheels and
            payload excepted).
        inertia_randomization: each link's inertia scaled by ``1 + U(-f, f)`` per reset.
        joint_damping: viscous damping added to every actuated joint, ``U(0, d)`` (N m s/rad)
            per reset.
        joint_friction: dry friction (MuJoCo ``frictionloss``) added to every actuated joint,
            ``U(0, f)`` (N m) per reset.
        floor_friction: the wheel-floor friction coefficient, or a range ``(low, high)`` drawn
            uniformly per reset; 1.0 (the models' value) by default.
        floor: the floor's slope and bumps (``wip_gym.floor.FloorOptions``).
    """

    sensor_noise: float = 0.0
    obs_delay_steps: int = 0
    obs_delay_jitter_steps: int = 0
    action_delay_steps: int = 0
    action_delay_jitter_steps: int = 0
    actuator_lag_s: float = 0.0
    joint_lag_s: float | None = None
    torque_noise: float = 0.0
    com_offset: float = 0.0
    inertia_randomization: float = 0.0
    joint_damping: float = 0.0
    joint_friction: float = 0.0
    floor_friction: float | tuple[float, float] = 1.0
    floor: FloorOptions = field(default_factory=FloorOptions)

    def __post_init__(self) -> None:
        _number("sensor_noise", self.sensor_noise)
        for name in (
            "obs_delay_steps",
            "obs_delay_jitter_steps",
            "action_delay_steps",
            "action_delay_jitter_steps",
        ):
            _steps(name, getattr(self, name))
        _number("actuator_lag_s", self.actuator_lag_s)
        if self.joint_lag_s is not None:
            _number("joint_lag_s", self.joint_lag_s)
        _number("torque_noise", self.torque_noise)
        _number("com_offset", self.com_offset)
        _number("inertia_randomization", self.inertia_randomization, below=1.0)
        _number("joint_damping", self.joint_damping)
        _number("joint_friction", self.joint_friction)
        low, high = self.floor_friction_range
        if not (0.0 < low <= high and math.isfinite(high)):
            raise ValueError(
                f"floor_friction must be a coefficient > 0 or a range (low, high) with "
                f"0 < low <= high, got {self.floor_friction!r}"
            )

    @property
    def floor_friction_range(self) -> tuple[float, float]:
        value = self.floor_friction
        if isinstance(value, tuple | list):
            if len(value) != 2:
                raise ValueError(f"floor_friction as a range is (low, high), got {value!r}")
            return (
                _number("floor_friction", value[0], low=-math.inf),
                _number("floor_friction", value[1], low=-math.inf),
            )
        number = _number("floor_friction", value, low=-math.inf)
        return (number, number)

    @property
    def wheel_lag_s(self) -> float:
        return self.actuator_lag_s

    @property
    def body_lag_s(self) -> float:
        return self.actuator_lag_s if self.joint_lag_s is None else self.joint_lag_s

    @property
    def shapes_model(self) -> bool:
        """Whether the compiled model differs from the task's (a lag or a floor shape)."""
        return self.wheel_lag_s > 0 or self.body_lag_s > 0 or not self.floor.flat

    @property
    def draws_model(self) -> bool:
        """Whether the reset changes the model's parameters (a model error)."""
        return (
            self.com_offset > 0
            or self.inertia_randomization > 0
            or self.joint_damping > 0
            or self.joint_friction > 0
            or self.floor_friction_range != (1.0, 1.0)
        )

    @property
    def on_observation(self) -> bool:
        return self.sensor_noise > 0 or self.obs_delay_steps > 0 or self.obs_delay_jitter_steps > 0

    @property
    def on_action(self) -> bool:
        return (
            self.action_delay_steps > 0
            or self.action_delay_jitter_steps > 0
            or self.torque_noise > 0
        )

    @property
    def active(self) -> bool:
        return self.shapes_model or self.draws_model or self.on_observation or self.on_action


def add_actuator_lag(spec: mujoco.MjSpec, wheel_lag_s: float, body_lag_s: float) -> None:
    """A first-order lag on each actuator's torque: MuJoCo's ``filterexact`` activation
    dynamics (``act' = (ctrl - act) / tau``, integrated exactly over each physics step) with
    ``actearly``, so the torque applied over a step is the filter's value at the step's end
    (``tau -> 0`` gives the command itself, with no step of delay). Actuators with a time
    constant of 0 are left as they are. The activation starts at 0 at each reset (zero
    torque)."""
    for actuator in spec.actuators:
        tau = wheel_lag_s if actuator.name in WHEEL_ACTUATORS else body_lag_s
        if tau > 0:
            actuator.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT
            actuator.dynprm = [tau] + [0.0] * (len(actuator.dynprm) - 1)
            actuator.actearly = True


def build_task_model(
    scene: SceneOptions, perturbations: Perturbations, goal: tuple[float, float]
) -> mujoco.MjModel:
    """The task's model: ``wip_gym.scene.build_model`` itself when nothing perturbs the model's
    structure, else its spec with the floor shaped and the actuator lag added."""
    if not perturbations.shapes_model:
        return build_model(scene)
    spec = build_spec(scene)
    shape_floor(spec, perturbations.floor, goal)
    add_actuator_lag(spec, perturbations.wheel_lag_s, perturbations.body_lag_s)
    return spec.compile()


class DelayLine:
    """Items come out ``delay + U{0..jitter}`` pushes after they went in (each push draws its
    own delay from ``rng`` when ``jitter > 0``, so items may come out of order, as re-ordered
    bus replies do); before that, the line's initial item."""

    def __init__(self, delay: int, jitter: int) -> None:
        self.delay, self.jitter = delay, jitter
        self._items: deque[Any] = deque(maxlen=delay + jitter + 1)
        self._jitter: Draws | None = None
        #: the delay of the last item pushed out (control steps)
        self.last_delay = delay

    def reset(self, initial: Any, rng: np.random.Generator | None) -> None:
        """Fill the line with ``initial``; ``rng``: the stream of the jitter."""
        self._items.clear()
        self._items.extend([initial] * (self.delay + self.jitter + 1))
        high = self.jitter + 1
        self._jitter = (
            Draws(rng, lambda r, n: r.integers(0, high, n))
            if self.jitter and rng is not None
            else None
        )

    def push(self, item: Any) -> Any:
        """Put ``item`` in; return the one due now."""
        self._items.appendleft(item)
        delay = self.delay
        if self._jitter is not None:
            delay += self._jitter()
        self.last_delay = delay
        return self._items[delay]


def _stream(entropy: Any, spawn_key: tuple[int, ...], tag: int) -> np.random.Generator:
    return np.random.default_rng(
        np.random.SeedSequence(entropy, spawn_key=(*spawn_key, STREAM_KEY, tag))
    )


class Perturber:
    """The env's perturbations at run time (see the module docstring). Made once per env, on
    its model, with the robot's ``layout``, the control step ``dt`` and ``robot_bodies``
    (every body of the robot's tree); ``payload_body`` (or -1) is left out of the model
    errors."""

    def __init__(
        self,
        settings: Perturbations,
        model: mujoco.MjModel,
        layout: RobotLayout,
        dt: float,
        robot_bodies: NDArray[np.int64],
        payload_body: int = -1,
        sensor_model: SensorModel | None = None,
    ) -> None:
        self.settings = settings
        self.layout = layout
        self.dt = dt
        s = settings
        check_start_clear(s.floor, layout.wheel_radius)
        self._lift = axle_lift(s.floor, layout.wheel_radius)
        self._axle_height_qpos = layout.root_qpos + (1 if layout.planar else 2)
        self.sensors = (
            Sensors(layout, (sensor_model or SensorModel()).scaled(s.sensor_noise, dt), dt)
            if s.sensor_noise > 0
            else None
        )
        self._obs_line = DelayLine(s.obs_delay_steps, s.obs_delay_jitter_steps)
        self._obs_delayed = s.obs_delay_steps > 0 or s.obs_delay_jitter_steps > 0
        self._action_line = DelayLine(s.action_delay_steps, s.action_delay_jitter_steps)
        self._torque_sigma = s.torque_noise * np.maximum(
            np.abs(model.actuator_ctrlrange[:, 0]), np.abs(model.actuator_ctrlrange[:, 1])
        )
        self._ctrl_low = model.actuator_ctrlrange[:, 0].copy()
        self._ctrl_high = model.actuator_ctrlrange[:, 1].copy()
        self._zero_action = np.zeros(model.nu)
        # the model errors' bodies, joints and geoms, and their nominal values
        bodies = [int(b) for b in robot_bodies if int(b) != payload_body]
        self._inertia_bodies = np.array(bodies, dtype=np.int64)
        self._com_bodies = np.array(
            [b for b in bodies if b not in layout.wheel_bodies], dtype=np.int64
        )
        self._dofs = np.array([*layout.wheel_dof, *layout.body_dof], dtype=np.int64)
        self._wheel_geoms = np.array(
            [model.geom(name).id for name in ("wheel_left", "wheel_right")], dtype=np.int64
        )
        self._nominal_ipos = model.body_ipos.copy()
        self._nominal_damping = model.dof_damping.copy()
        self._nominal_frictionloss = model.dof_frictionloss.copy()
        self._nominal_friction = model.geom_friction.copy()
        self._seeded_from: np.random.Generator | None = None
        self._torque_draws: Draws | None = None
        self._streams: dict[int, np.random.Generator] = {}

    # ------------------------------------------------------------------ reset
    def begin_episode(self, env_rng: np.random.Generator, env_seed: int) -> None:
        """At each reset, before anything is drawn: seed the streams again when the env's
        generator is a new one (``reset(seed=...)``, or the first reset), from ``env_seed``
        (its ``np_random_seed``; -1 when the user set the generator: then from the
        generator's own seed sequence); nothing is drawn from ``env_rng``."""
        if env_rng is not self._seeded_from:
            if env_seed >= 0:
                entropy: Any = env_seed
                key: tuple[int, ...] = ()
            else:
                sequence = env_rng.bit_generator.seed_seq
                if not isinstance(sequence, np.random.SeedSequence):
                    raise ValueError(
                        "the env's generator has no seed sequence to seed the perturbations "
                        "from: reset it with a seed"
                    )
                entropy, key = sequence.entropy, tuple(sequence.spawn_key)
            tags = (
                SENSOR_STREAM,
                OBS_DELAY_STREAM,
                ACTION_DELAY_STREAM,
                TORQUE_STREAM,
                MODEL_STREAM,
            )
            self._streams = {tag: _stream(entropy, key, tag) for tag in tags}
            self._seeded_from = env_rng
        self._action_line.reset(self._zero_action, self._streams[ACTION_DELAY_STREAM])
        nu = len(self._zero_action)
        self._torque_draws = (
            Draws(self._streams[TORQUE_STREAM], lambda r, n: r.standard_normal((n, nu)))
            if self.settings.torque_noise > 0
            else None
        )

    def perturb_model(self, model: mujoco.MjModel) -> None:
        """Draw the episode's model errors into ``model`` (after the env has restored and
        randomised the link masses and inertias; before ``mj_setConst``). Nothing when no
        model error is on."""
        s = self.settings
        if not s.draws_model:
            return
        rng = self._streams[MODEL_STREAM]
        if s.com_offset > 0:
            bodies = self._com_bodies
            model.body_ipos[bodies] = self._nominal_ipos[bodies] + rng.uniform(
                -s.com_offset, s.com_offset, (len(bodies), 3)
            )
        if s.inertia_randomization > 0:
            f = s.inertia_randomization
            bodies = self._inertia_bodies
            model.body_inertia[bodies] *= 1.0 + rng.uniform(-f, f, len(bodies))[:, None]
        dofs = self._dofs
        if s.joint_damping > 0:
            model.dof_damping[dofs] = self._nominal_damping[dofs] + rng.uniform(
                0.0, s.joint_damping, len(dofs)
            )
        if s.joint_friction > 0:
            model.dof_frictionloss[dofs] = self._nominal_frictionloss[dofs] + rng.uniform(
                0.0, s.joint_friction, len(dofs)
            )
        low, high = s.floor_friction_range
        if (low, high) != (1.0, 1.0):
            mu = low if low == high else float(rng.uniform(low, high))
            model.geom_friction[self._wheel_geoms, 0] = mu

    def place_on_floor(self, qpos: Array) -> None:
        """Raise the reset pose's axle (in ``qpos``) onto a sloped floor."""
        if self._lift:
            qpos[self._axle_height_qpos] += self._lift

    # ------------------------------------------------------------------- step
    def actuate(self, action: Array) -> Array:
        """The torques applied this step for the policy's ``action``: the action delay line's
        output, plus the torque noise, saturated at the actuators' limits (the motor cannot
        give more; only the noise can reach past them, the policy's action is checked)."""
        applied = self._action_line.push(action.copy())  # the caller may reuse its array
        if self._torque_draws is not None:
            noise = np.array(self._torque_draws())
            applied = np.clip(applied + noise * self._torque_sigma, self._ctrl_low, self._ctrl_high)
        return np.asarray(applied, dtype=np.float64)

    def observe(self, observation: dict[str, Array], first: bool = False) -> dict[str, Array]:
        """What the policy receives for the true ``observation``: sensed (``sensor_noise``),
        then through the observation delay line. ``first``: the reset's observation (it fills
        the line: until the first delayed observation arrives the policy sees it)."""
        sensed = observation
        if self.sensors is not None:
            if first:
                self.sensors.begin(
                    self._streams[SENSOR_STREAM], observation["qpos"], observation["qvel"]
                )
            qpos, qvel = self.sensors.sense(observation["qpos"], observation["qvel"], first)
            sensed = {**observation, "qpos": qpos, "qvel": qvel}
        if not self._obs_delayed:  # the sensed observation's arrays are fresh already
            return sensed
        if first:
            self._obs_line.reset(sensed, self._streams[OBS_DELAY_STREAM])
            return _copy(sensed)
        return _copy(self._obs_line.push(sensed))


def _copy(observation: dict[str, Array]) -> dict[str, Array]:
    """Fresh arrays (an observation handed out twice by the delay line must not share them)."""
    return {key: value.copy() for key, value in observation.items()}
