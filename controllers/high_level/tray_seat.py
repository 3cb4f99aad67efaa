"""Where a free tray rests on the hands at this episode's pose (docs/upright.md §6).

A controller's nominal model welds a free tray where it rested on the hands when the env's
model was built (``controllers.policy.controller_model``). At each reset the env lets the tray
settle again on its supports at the noisy reset pose (``wip_gym.envs.base``,
``TraySettler``): on Krang the reset noise moves the two grippers' finger plates against each
other by a few mm, which turns the tray by 1 to 3 deg about its forward axis against the
nominal weld, as much as the friction angle of a cup at ``mu = 0.05``. The controller knows
the tray and the plates (the scenario's, ``TaskInfo.free_tray``), not how the contacts stand:
:class:`TraySeat` settles the tray on the plates of its own kinematics at the reset pose, as
the env does, then lets it sink for :data:`TRAY_SINK_TIME` into the plates of the whole scene
with the robot held still (the settler's fixed supports are stiffer than the arm's plates in
the scene: the tray sinks about 4 mm more, and turns by up to 0.7 deg, within 0.1 s), and
moves the nominal model's weld there, so that the tray frame the controller plans with is the
one the cup stands on.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
from numpy.typing import NDArray

from wip_gym.robot_model import RobotModel
from wip_gym.scene import (
    TRAY_RESET_MAX_SPEED,
    TRAY_RESET_SETTLE_TIME,
    SceneOptions,
    TraySettler,
    build_model,
    support_model,
)

Array = NDArray[np.float64]
TRAY_BODY = "tray"
#: how long the seated tray is then let sink into the supports of the whole scene with the
#: robot held still (s): MuJoCo's soft contacts on Krang's finger plates, whose constraint
#: regularisation takes the arm's inverse weight, give way about 4 mm more than on the
#: settler's fixed supports, within 0.1 s (docs/upright.md §6)
TRAY_SINK_TIME = 0.2


class TraySeat:
    """Re-seats the welded tray of ``robot``'s model on the supports of ``options`` (a free
    tray's scene options) at a pose (module docstring). The weld it starts each settling from
    is the model's at construction, as the env's from its build-time rest place."""

    def __init__(
        self, robot: RobotModel, options: SceneOptions, sink_s: float = TRAY_SINK_TIME
    ) -> None:
        if options.tray_attachment != "free":
            raise ValueError(f"a free tray's scene options, got {options.tray_attachment!r}")
        m = robot.model
        self.body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, TRAY_BODY)
        if self.body < 0:
            raise ValueError("the controller's model has no tray body to seat")
        self.mount = int(m.body_parentid[self.body])
        self.robot = robot
        self._pos = m.body_pos[self.body].copy()
        self._quat = m.body_quat[self.body].copy()
        self.model = support_model(options)
        self.data = mujoco.MjData(self.model)
        self.settler = TraySettler(self.model, options)
        self._mount = self.model.body(m.body(self.mount).name).id
        self._nq = robot.layout.nq
        if not (np.isfinite(sink_s) and sink_s >= 0):
            raise ValueError(f"sink_s must be finite and >= 0, got {sink_s!r}")
        # the whole scene (robot, plates, free tray, the cup lifted clear of it; the env's
        # solver settings come with the cup) for the sinking
        self.scene = build_model(dataclasses.replace(options, payload_mass=0.0))
        self.scene_data = mujoco.MjData(self.scene)
        joint = self.scene.joint(TRAY_BODY)
        self._tray_qpos, self._tray_dof = int(joint.qposadr[0]), int(joint.dofadr[0])
        self._sink_steps = round(sink_s / self.scene.opt.timestep)
        cup = mujoco.mj_name2id(self.scene, mujoco.mjtObj.mjOBJ_JOINT, "cup")
        self._cup_qpos = int(self.scene.jnt_qposadr[cup]) if cup >= 0 else None

    def seat(self, qpos: Array) -> tuple[Array, Array]:
        """Settle the tray on the supports at the robot pose ``qpos`` (the robot's ``nq``
        entries), let it sink (:meth:`_sink`) and weld it there in the robot's model; returns
        the weld ``(pos, quat)`` in the mount body's frame."""
        qpos = np.asarray(qpos, dtype=float)
        if qpos.shape != (self._nq,) or not np.all(np.isfinite(qpos)):
            raise ValueError(f"qpos must be {self._nq} finite numbers, got shape {qpos.shape}")
        d, body = self.data, self._mount
        d.qpos[: self._nq] = qpos
        mujoco.mj_kinematics(self.model, d)
        R = d.xmat[body].reshape(3, 3).copy()
        start = d.xpos[body] + R @ self._pos
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, d.xquat[body], self._quat)
        position, world_quat = self.settler.settle(
            d, start, quat, TRAY_RESET_SETTLE_TIME, TRAY_RESET_MAX_SPEED
        )
        position, world_quat = self._sink(qpos, position, world_quat)
        inverse, relative = np.zeros(4), np.zeros(4)
        mujoco.mju_negQuat(inverse, d.xquat[body])
        mujoco.mju_mulQuat(relative, inverse, world_quat)
        pos = R.T @ (position - d.xpos[body])
        m = self.robot.model
        m.body_pos[self.body] = pos
        m.body_quat[self.body] = relative
        return pos, relative

    def _sink(self, qpos: Array, position: Array, quat: Array) -> tuple[Array, Array]:
        """The tray's pose after ``sink_s`` in the whole scene from ``(position, quat)``
        (world), at rest, with the robot held at ``qpos``."""
        m, d, a = self.scene, self.scene_data, self._tray_qpos
        mujoco.mj_resetData(m, d)
        if self._cup_qpos is not None:
            d.qpos[self._cup_qpos + 2] += 5.0  # clear of the tray for the sinking's time
        d.qpos[a : a + 3] = position
        d.qpos[a + 3 : a + 7] = quat
        for _ in range(self._sink_steps):
            d.qpos[: self._nq] = qpos
            d.qvel[: self._tray_dof] = 0.0
            mujoco.mj_step(m, d)
        mujoco.mj_kinematics(m, d)
        return d.qpos[a : a + 3].copy(), d.qpos[a + 3 : a + 7].copy()
