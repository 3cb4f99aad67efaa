"""``unified-upright``: the unified controller that keeps the carried cup's balance.

The paper's controller (``controllers.hierarchical``) keeps the tray level, so the cup feels the
whole horizontal acceleration. This one follows the same plan and MPC, and adds three things to
the task QP (docs/upright.md):

1. **the cup's balance as constraints** (Heins and Schoellig, "Keep It Upright", 2023): the
   contact wrench the cup needs, from the tray's linear and angular acceleration and gravity,
   inside the friction pyramid of the planning coefficient and with its zero-moment point inside
   the cup's feet (``controllers.low_level.object_balance``). Weighted, they are soft with a
   stiff slack (``controllers.low_level.priority_qp``); strict, a level of their own under the
   balance, and the drive row and the hands' forward rows traded with the posture in the last
   level (``UprightConfig.strict_posture_rows``);
2. **a task on the cup's tangential specific force** at its place on the plate, toward zero
   (the tray tilted so that the plate's normal carries the motion's force), and a drive row
   that holds the axle's acceleration to the MPC's prediction (the base must not give up the
   plan's acceleration to level the cup);
3. **tray targets** that lead that tilt: each hand that holds the tray turns about the plate's
   centre toward the plan's acceleration ``lead`` ahead, corrected by the tray's drift over the
   axle (``controllers.high_level.tray_reference``).

Its object parameters (:class:`controllers.low_level.object_balance.CarriedObject`) default to
the scenario's declared cup: the env's ``cup_friction`` and the cup's nominal geometry; each can
be set apart from the truth (``--set unified-upright.carried.friction=0.091``). Without a cup
(no tray task) it is the unified controller with this config's weights.

Counters: ``object_active_steps`` (steps whose unconstrained minimiser broke a balance row, or
whose strict solution has one at its bound) and ``object_relaxed_steps`` (steps where a
balance row had to give: the torque or joint limits, or a higher level, left no solution that
meets it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Self

import gymnasium as gym
import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.hierarchical import HierarchicalConfig, HierarchicalController
from controllers.high_level.planning import PlanConfig
from controllers.high_level.receding_horizon import HighLevelConfig
from controllers.high_level.tray_reference import TrayGains, TrayReference, plan_acceleration
from controllers.high_level.tray_seat import TraySeat, add_tray_shares
from controllers.low_level.hand_pair import HandPair
from controllers.low_level.object_balance import CarriedObject, ObjectBalance
from controllers.low_level.object_tasks import (
    AxleAccelerationTask,
    ObjectBalanceConstraint,
    TangentialForceTask,
)
from controllers.low_level.priority_qp import PriorityStep
from controllers.low_level.task_stack import unwrap
from controllers.low_level.tasks import FramePositionTask, site_in_axle_frame
from controllers.policy import nominal_spec, task_info
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]
#: the site on the plate's top that the cup stands on (wip_gym/scene.py)
TRAY_TOP_SITE = "tray_top"
#: rows the strict stack may trade with the posture (``UprightConfig.strict_posture_rows``)
StrictPostureRow = Literal["drive", "hand_forward"]
STRICT_POSTURE_ROWS: tuple[StrictPostureRow, ...] = ("drive", "hand_forward")
#: a hand position task's row along the axle's forward axis (rows: forward, lateral, up)
FORWARD_ROW = 0


@dataclass(frozen=True)
class UprightConfig(HierarchicalConfig):
    """The hierarchical config with the cup-aware parts (module docstring). The low level's
    values below differ from the unified controller's; each was chosen on PlanarTray-v0's
    aggressive drive (docs/upright.md §3 gives the runs).

    Attributes:
        carried: what the controller is told about the cup (its friction None: the env's).
        tray: the tray targets' lead and outer-loop gains (one hand: PlanarTray-v0).
        two_hand_tray: the same with a tray held by two hands (Krang): lead 0.1 s, kp 4,
            kv 4. Without ``share_tray_weight`` the one hand's softer loop (kp 1, kv 1.5,
            lead 0.25) let Krang's body and free tray oscillate: in the paper's configuration
            at friction 0.05 it carried 4 of 10 (3 fell) where these carry 8; with it both
            carry 10 (docs/upright.md §6).
        tangential_weight: weight of the cup's tangential specific force (in g) toward zero.
        two_hand_tangential_weight: the same with a tray held by two hands (Krang): at 3000
            the task outweighed the hands' position tasks and walked both hands off their
            places, the body's oscillation growing until the tray fell (docs/upright.md §6).
        drive_weight: weight of the axle's acceleration toward the MPC's prediction (m/s^2).
        slack_weight: weight of a balance row's slack in the weighted QP (the rows are in units
            of the cup's weight: 1e6 makes a slack of 1e-3 cost as much as a 1 m/s^2 error of a
            weight-1 task).
        ee_position_weight: (forward, lateral, up) 0.1, 10, 10: the hand may move along the
            axle's forward axis, which the tray's tilt about the plate's centre needs.
        orientation_kp, orientation_kv: 400, 40: the tray follows its tilt target within
            about 0.1 s (the targets lead by ``tray.lead``, which covers this lag and the
            body's).
        hand_observer_bandwidth: None: the tilt targets move the hands on purpose; an
            observer of their unmodelled acceleration read that as a disturbance.
        seat_tray: a free tray: weld the nominal model's tray where it settles on the hand's
            supports at each reset pose (``controllers.high_level.tray_seat``).
        share_tray_weight: with ``seat_tray``, a free tray on two hands (Krang): the nominal
            model's tray weight divided between the hands as their supports carry it at the
            seat (``tray_seat.add_tray_shares``). Off, the nominal model hangs the whole tray on
            the left gripper, the right arm carries about half of it unmodelled and its hand
            sags 3 to 6 mm against the left, turning the tray 1 to 2.3 deg about the heading:
            at friction 0.05 in the paper's configuration 8 of 10 carried, on: 10 of 10
            (docs/upright.md §6).
        strict_posture_rows: with ``priority="strict"``, the rows met in the posture level,
            traded by their weights with the posture as the weighted QP trades them, instead of
            in the motion level: ``drive`` (the axle's acceleration toward the MPC's) and
            ``hand_forward`` (each hand's position along the axle's forward axis, whose weight
            0.1 lets the tilt hold the tray's place). In the motion level the theta row, the
            drive, the tangential force and the hand's height and tilt fix five of the planar
            robot's six accelerations exactly; the drive met to 0.01 m/s^2 folds the body (torso
            and shoulder over 1.2 and 1.7 rad at up to 8 rad/s) and the robot falls in 10 of 10
            seeds of the aggressive drive. With the drive alone moved, the forward row holds
            the hand over the axle exactly and the tray's tilt sets the axle's acceleration: it
            falls sooner (0.4 to 1.0 s). docs/upright.md §4 and §5.
        hand_pair_weight, hand_pair_kp, hand_pair_kv: with two hands under the tray (Krang),
            the second hand's pose relative to the first held at its reset value
            (``controllers.low_level.hand_pair``; 0: not held). docs/upright.md §6 measured
            them on KrangTray-v0 in the paper's configuration.
    """

    carried: CarriedObject = field(default_factory=CarriedObject)
    tray: TrayGains = field(default_factory=TrayGains)
    two_hand_tray: TrayGains = field(default_factory=lambda: TrayGains(lead=0.1, kp=4.0, kv=4.0))
    tangential_weight: float = 3000.0
    two_hand_tangential_weight: float = 300.0
    drive_weight: float = 10.0
    slack_weight: float = 1e6
    ee_position_weight: float | tuple[float, float, float] = (0.1, 10.0, 10.0)
    orientation_kp: float = 400.0
    orientation_kv: float = 40.0
    hand_observer_bandwidth: float | None = None
    seat_tray: bool = True
    share_tray_weight: bool = True
    strict_posture_rows: tuple[StrictPostureRow, ...] = STRICT_POSTURE_ROWS
    hand_pair_weight: float = 100.0
    hand_pair_kp: float = 400.0
    hand_pair_kv: float = 40.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in (
            "tangential_weight",
            "two_hand_tangential_weight",
            "drive_weight",
            "slack_weight",
            "hand_pair_weight",
            "hand_pair_kp",
            "hand_pair_kv",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        if self.slack_weight == 0:
            raise ValueError("slack_weight must be positive")
        unknown = set(self.strict_posture_rows) - set(STRICT_POSTURE_ROWS)
        if unknown:
            raise ValueError(
                f"strict_posture_rows: unknown {sorted(unknown)}; known: {STRICT_POSTURE_ROWS}"
            )

    @classmethod
    def paper(cls, tray_mode: Any = "level") -> UprightConfig:  # noqa: ARG003 - the signature
        """The paper's plan (``PlanConfig.paper()``) under this controller's own low level:
        the authors' low-level weights keep the tray level, which is what this controller
        does not do (docs/upright.md §5)."""
        return cls(high_level=HighLevelConfig(plan=PlanConfig.paper()))


class UprightController(HierarchicalController):
    """``unified-upright`` (module docstring)."""

    config_class = UprightConfig
    config: UprightConfig

    @classmethod
    def for_env(cls, env: gym.Env, config: Any = None) -> Self:
        """The hierarchical controller's, with a nominal model whose free tray's weight is
        shared by every hand under it (``UprightConfig.share_tray_weight``)."""
        config = cls.config_class() if config is None else config
        if not isinstance(config, cls.config_class):
            raise ValueError(
                f"{cls.__name__} needs a {cls.config_class.__name__}, got {type(config).__name__}"
            )
        task = task_info(env, config.model)
        if (
            task.free_tray is None
            or config.model != "nominal"
            or not (config.seat_tray and config.share_tray_weight)
        ):
            return super().for_env(env, config)
        spec = nominal_spec(env)
        add_tray_shares(spec, task.free_tray)
        return cls(RobotModel(spec.compile()), task, config)

    @property
    def name(self) -> str:
        return "unified-upright"

    def reset(self, observation: dict[str, Array], info: dict[str, Any]) -> None:
        if self.task.free_tray is not None and self.config.seat_tray:
            # the nominal weld where the env's tray settled at this reset pose (tray_seat)
            if getattr(self, "_seat", None) is None:
                self._seat = TraySeat(self.robot, self.task.free_tray)
            self._seat.seat(observation["qpos"][: self.robot.layout.nq])
        super().reset(observation, info)
        robot, cfg, m = self.robot, self.config, self.robot.model
        self._active = self._relaxed = 0
        self.priority_qp.slack_weight = cfg.slack_weight
        self.balance: ObjectBalance | None = None
        self.tray_reference: TrayReference | None = None
        self.hand_pair: HandPair | None = None
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, TRAY_TOP_SITE)
        if self.task.cup_friction is None or site < 0 or not self.orientation_tasks:
            return  # no cup on a tray: the unified controller with this config
        friction = cfg.carried.friction or self.task.cup_friction
        self.balance = ObjectBalance(robot, site, cfg.carried, friction)
        self._tray_site = site
        # the cup's rows as objects of the task QP, computed in its one-call step: the
        # tangential force and the drive as tasks, the balance rows as its last constraint
        # (with two hands, their pair's rows too)
        two_hands = len(self._sites) == 2
        weight = cfg.two_hand_tangential_weight if two_hands else cfg.tangential_weight
        self._drive = AxleAccelerationTask(cfg.drive_weight)
        self._qp_tasks = [
            *self.tasks,
            TangentialForceTask(self.balance, robot, weight),
            self._drive,
        ]
        if two_hands and cfg.hand_pair_weight > 0:
            left, right = self._sites
            self.hand_pair = HandPair(
                robot, left, right, cfg.hand_pair_weight, cfg.hand_pair_kp, cfg.hand_pair_kv
            )
            self._qp_tasks.append(self.hand_pair)
        self._qp_constraints = [*self.constraints, ObjectBalanceConstraint(self.balance, robot)]
        plate, plate_rotation, _, _ = site_in_axle_frame(robot, site)
        self._plate_reset = plate.copy()
        self._hands = [
            inner for inner, _ in map(unwrap, self.tasks) if isinstance(inner, FramePositionTask)
        ]
        # the strict stack's rows traded with the posture (UprightConfig.strict_posture_rows)
        demoted = cfg.strict_posture_rows
        self._posture_rows: list[tuple[Any, tuple[int, ...]]] = []
        if "drive" in demoted:
            self._posture_rows.append((self._drive, (0,)))
        if "hand_forward" in demoted:
            self._posture_rows += [(hand, (FORWARD_ROW,)) for hand in self._hands]
        self.tray_reference = TrayReference(
            plate,
            [task.target.copy() for task in self._hands],
            [rotation.copy() for rotation in self._orientation_reset],
            cfg.two_hand_tray if two_hands else cfg.tray,
            normal=plate_rotation[:, 2],
        )
        # the tray's targets at the MPC's rate (its acceleration changes no faster; the drift
        # loop's bandwidth, about 1 rad/s, is far below 100 Hz)
        self._tray_every = max(1, round(self.high_level.config.mpc.dt / self.task.control_dt))
        self._set_tray_targets(robot)

    def _set_tray_targets(self, robot: RobotModel) -> None:
        """Each hand's target from the plan's acceleration ``lead`` ahead and the plate's
        drift over the axle (``TrayReference.targets``)."""
        reference = self.tray_reference
        assert reference is not None
        plate, _, J_p, _ = site_in_axle_frame(robot, self._tray_site)
        now = self._step * self.task.control_dt
        assert self.plan is not None
        targets = reference.targets(
            plan_acceleration(self.plan, now + reference.gains.lead),
            plate - self._plate_reset,
            J_p @ robot.nu,
            reference.gains.level_fraction(now),
        )
        for (position, rotation), hand, orientation in zip(
            targets, self._hands, self.orientation_tasks, strict=True
        ):
            hand.target = position
            orientation.target = rotation

    def _set_references(self, robot: RobotModel) -> None:
        super()._set_references(robot)
        if self.tray_reference is not None and self._step % self._tray_every == 0:
            self._set_tray_targets(robot)

    def _solve(self, robot: RobotModel) -> PriorityStep:
        if self.balance is None:
            return super()._solve(robot)
        states = self.high_level.last_solution.predicted_states
        self._drive.target = (states[1, 3] - states[0, 3]) / self.high_level.config.mpc.dt
        step = self.priority_qp.solve(
            robot,
            self._qp_tasks,
            self._qp_constraints,
            self.config.priority,
            balance_rows=self.balance.rows_count,
            posture_rows=self._posture_rows,
        )
        self._active += step.active
        self._relaxed += step.relaxed
        return step

    def controller_counters(self) -> dict[str, float]:
        """The unified controller's counters, ``object_active_steps`` and
        ``object_relaxed_steps`` (module docstring)."""
        counters = super().controller_counters()
        counters["object_active_steps"] = float(getattr(self, "_active", 0))
        counters["object_relaxed_steps"] = float(getattr(self, "_relaxed", 0))
        return counters
