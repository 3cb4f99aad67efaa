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

**The tray's weight on every hand that carries it.** A kinematic tree cannot close the loop
through the tray: the nominal model hangs the whole tray on its mount (Krang's left gripper),
while the free tray rests on the finger plates of both grippers. The right arm then carries
about half the tray's weight unmodelled, and its hand sags under it against the left one (3 to
6 mm on KrangTray-v0 in the paper's configuration, turning the tray 1 to 2.3 deg about the
heading against the nominal weld: docs/upright.md §6). With :func:`add_tray_shares` the nominal
model holds one more body per support body beside the mount (``tray_share_<body>``, no geoms);
at each seat :class:`TraySeat` measures how the settled tray's weight divides between the
support bodies (the vertical contact forces at the end of the sinking) and gives each share
body that fraction of the tray's mass and inertia, welded where the tray sits, the tray body
the rest, each part's centre of mass above its supports' centre of pressure: while the hands
keep their relative pose the parts' mass and centre of mass are the tray's, and each arm
carries the tray's weight where its supports do (tests/test_hand_pair.py holds the arms'
gravity torques to the env's, the tray's contact forces included).
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
    tray_support_geoms,
)

Array = NDArray[np.float64]
TRAY_BODY = "tray"
#: how long the seated tray is then let sink into the supports of the whole scene with the
#: robot held still (s): MuJoCo's soft contacts on Krang's finger plates, whose constraint
#: regularisation takes the arm's inverse weight, give way about 4 mm more than on the
#: settler's fixed supports, within 0.1 s (docs/upright.md §6)
TRAY_SINK_TIME = 0.2
#: the name of the body that carries a support body's share of the tray (:func:`add_tray_shares`)
TRAY_SHARE_PREFIX = "tray_share_"
#: the mount site of the tray (wip_gym/scene.py)
TRAY_MOUNT_SITE = "tray_mount"


def tray_share_bodies(options: SceneOptions) -> list[str]:
    """The bodies that hold a free tray's supports (``wip_gym.scene.tray_support_geoms``) other
    than the tray's mount body, in the supports' order: Krang's right gripper; none on
    planar7, whose one support is on the mount's body."""
    model = support_model(options)
    mount = model.body(int(model.site_bodyid[model.site(TRAY_MOUNT_SITE).id])).name
    names: list[str] = []
    for geom in tray_support_geoms(options.robot):
        body = model.body(int(model.geom_bodyid[model.geom(geom).id])).name
        if body != mount and body not in names:
            names.append(body)
    return names


def add_tray_shares(spec: mujoco.MjSpec, options: SceneOptions) -> list[str]:
    """Add to a nominal model's spec (a welded tray) one body per :func:`tray_share_bodies`
    body, ``TRAY_SHARE_PREFIX + <body>``, a child of it without geoms; :meth:`TraySeat.seat`
    gives it its share of the tray's mass at each reset (module docstring). Its mass until then
    is a placeholder (1e-9 kg). Returns the added bodies' names."""
    if options.tray_attachment != "free":
        raise ValueError(f"a free tray's scene options, got {options.tray_attachment!r}")
    names = []
    for body in tray_share_bodies(options):
        name = TRAY_SHARE_PREFIX + body
        spec.body(body).add_body(name=name, mass=1e-9, inertia=[1e-12] * 3, explicitinertial=True)
        names.append(name)
    return names


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
        #: the tray's mass and inertia (principal moments) in the model at construction
        self.tray_mass = float(m.body_mass[self.body])
        self._inertia = m.body_inertia[self.body].copy()
        self._ipos = m.body_ipos[self.body].copy()
        self._iquat = m.body_iquat[self.body].copy()
        # the share bodies of the robot's model (add_tray_shares) and their parents
        self._shares = [
            (b, int(m.body_parentid[b]))
            for b in range(m.nbody)
            if m.body(b).name.startswith(TRAY_SHARE_PREFIX)
        ]
        #: the fraction of the tray's weight each body carries at the last seat (by body name:
        #: the mount's and each share body's parent's); the mount's alone without share bodies
        self.fractions: dict[str, float] = {m.body(self.mount).name: 1.0}
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
        self._scene_tray_geom = self.scene.geom(TRAY_BODY).id
        # each support geom of the scene and the name of the body that holds it
        self._scene_supports = {
            self.scene.geom(g).id: self.scene.body(int(self.scene.geom(g).bodyid[0])).name
            for g in tray_support_geoms(options.robot)
        }
        for share, parent in self._shares:
            if m.body(parent).name not in self._scene_supports.values():
                raise ValueError(f"{m.body(share).name!r} is on a body that holds no support")

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
        if self._shares:
            self._share_weight(position, world_quat)
        return pos, relative

    def _share_weight(self, position: Array, quat: Array) -> None:
        """Divide the tray's mass and inertia between the tray body and the share bodies as the
        supports of each body carry its weight at the end of the sinking (:meth:`loads`): each
        part's mass the fraction of the weight its body's supports carry, its centre of mass on
        the vertical through their centre of pressure at the height of the tray's own (so that
        the parts' centre of mass is the tray's, and each arm carries its weight where its
        supports do), its inertia that fraction of the tray's; each share body welded where the
        tray sits (``position``, ``quat``: world) on its parent at this pose (the support
        model's data, posed by :meth:`seat`). Then the subtree masses."""
        loads, centres = self.loads()
        total = sum(loads.values())
        if not total > 0:
            raise RuntimeError("the seated tray rests on no support")
        m, d = self.robot.model, self.data
        self.fractions = {name: load / total for name, load in loads.items()}
        flat = np.zeros(9)
        mujoco.mju_quat2Mat(flat, quat)
        R_tray = flat.reshape(3, 3)
        com = position + R_tray @ self._ipos

        def part(name: str) -> tuple[float, Array]:
            """The fraction of the tray a body carries, its centre of mass in the tray frame."""
            fraction = self.fractions.get(name, 0.0)
            if fraction <= 0.0:
                return 0.0, self._ipos.copy()
            point = centres[name].copy()
            point[2] = com[2]
            return fraction, R_tray.T @ (point - position)

        for share, parent in self._shares:
            name = m.body(parent).name
            fraction, ipos = part(name)
            frame = self.model.body(name).id
            R = d.xmat[frame].reshape(3, 3)
            m.body_pos[share] = R.T @ (position - d.xpos[frame])
            inverse = np.zeros(4)
            mujoco.mju_negQuat(inverse, d.xquat[frame])
            mujoco.mju_mulQuat(m.body_quat[share], inverse, quat)
            m.body_mass[share] = fraction * self.tray_mass
            m.body_inertia[share] = fraction * self._inertia
            m.body_ipos[share] = ipos
            m.body_iquat[share] = self._iquat
            m.body_sameframe[share] = 0  # the compiler's shortcut (xipos = xpos) no longer holds
        fraction, ipos = part(m.body(self.mount).name)
        m.body_mass[self.body] = fraction * self.tray_mass
        m.body_inertia[self.body] = fraction * self._inertia
        m.body_ipos[self.body] = ipos
        m.body_sameframe[self.body] = 0
        subtree = m.body_mass.copy()
        for b in range(m.nbody - 1, 0, -1):  # a body's parent comes before it
            subtree[m.body_parentid[b]] += subtree[b]
        m.body_subtreemass[:] = subtree

    def loads(self) -> tuple[dict[str, float], dict[str, Array]]:
        """Per body that holds supports (by name), in the whole scene's data as the last
        :meth:`seat` left it (at rest, the robot held): the upward force (N) its supports give
        the tray (the vertical components of their contact forces on it), and the centre of
        pressure of those forces (world; the tray's centre of mass where there are none)."""
        m, d = self.scene, self.scene_data
        names = set(self._scene_supports.values())
        loads = dict.fromkeys(names, 0.0)
        moments = {name: np.zeros(3) for name in names}
        force = np.zeros(6)
        for i in range(d.ncon):
            contact = d.contact[i]
            geoms = (int(contact.geom[0]), int(contact.geom[1]))
            if self._scene_tray_geom not in geoms:
                continue
            other = geoms[1] if geoms[0] == self._scene_tray_geom else geoms[0]
            if other not in self._scene_supports:
                continue
            mujoco.mj_contactForce(m, d, i, force)
            # the force geom 1 puts on geom 2, in world (the frame's rows are its axes)
            world = contact.frame.reshape(3, 3).T @ force[:3]
            up = float((world if geoms[1] == self._scene_tray_geom else -world)[2])
            name = self._scene_supports[other]
            loads[name] += up
            moments[name] += up * contact.pos
        tray = self.scene.body(TRAY_BODY).id
        centres = {
            name: moments[name] / loads[name] if loads[name] > 0 else d.xipos[tray].copy()
            for name in names
        }
        return loads, centres

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
        d.qpos[: self._nq] = qpos
        d.qvel[: self._tray_dof] = 0.0
        mujoco.mj_forward(m, d)  # the kinematics, and the contact forces for loads()
        return d.qpos[a : a + 3].copy(), d.qpos[a + 3 : a + 7].copy()
