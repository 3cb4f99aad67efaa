"""Build the MuJoCo model of a task: robot + floor (+ tray, cup, payload), with ``MjSpec``.

The robot and scene files of ``assets/mjcf`` hold the robot, the floor, lights and the goal
marker. A tray task also needs a tray on the end effector, level at the reset pose, and a free
cup on it whose friction against the tray is set on an explicit contact pair (MuJoCo otherwise
combines two geoms' friction by taking the larger, so a cup setting alone would change
nothing). Those depend on the task's parameters, so they are added here.

Sizes and masses (docs/DESIGN.md §5, from the authors' demo, docs/AUTHORS_CONFIG.md §5.3): tray
0.30 x 0.20 m, 0.2 kg (rim included); cup radius 0.031 m, height 0.08 m, 0.05 kg; tray-cup
friction 0.3; the authors' rim is 5 mm high and 5 mm thick.

The tray is either **welded** to the hand (``tray_attachment="welded"``: a child body of the
hand, level at the reset pose) or **free** (``"free"``: a free body resting on the hand, its
contacts with the supports made by explicit pairs of friction ``tray_friction``, as the authors
simulated it). Supports of a free tray (:func:`tray_support_geoms`):

- planar7: the hand's box, whose tip face is the ``tray_mount`` site (0.08 x 0.12 m).
- krang: the four gripper finger plates of the authors' URDF (``l/rgPlate1,2``, 0.0001 kg each,
  dropped from ``krang.xml``; a 21 x 74 x 90 mm box each, from the plate mesh's bounds, at
  (-+0.07 left, -+0.06 right, 0, 0.127) in the gripper frame, reaching 0.127 to 0.217 m along
  the gripper's z toward the other gripper). At the authors' initial arm pose (our ``home``
  keyframe) their tips reach 3 cm under each side edge of the plate and their tops sit within a
  few mm of the plate's underside; the gripper boxes (0.08 x 0.112 x 0.2025) end 6 to 11 cm short
  of the plate, so the finger plates are what the authors' tray rests on. They are massless
  collision boxes here, added only to the free-tray model (the welded model is unchanged).

**Stiff pairs** (``STIFF_SOLREF``, ``STIFF_SOLIMP``; assets/mjcf/README.md, "Contacts of the
tray and the cup"): the cup's cylinder meets each rim wall (:func:`add_cup`), and a free tray's
plate and rim walls meet Krang's gripper boxes (:func:`tray_hand_geoms`), so that neither
passes into the other where they meet. The contacts a body rests on (the cup's feet on the
plate, a free tray on its supports) keep MuJoCo's default solver parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wip_gym.assets import mjcf_path
from wip_gym.robot_model import RobotModel
from wip_gym.robots import robot_spec

#: m/s^2, MuJoCo's default ``opt.gravity`` (0, 0, -9.81), which every model of the gym keeps
#: (tests/test_object_balance.py); what the controllers' models of a carried object assume
GRAVITY = 9.81
TRAY_HALF_SIZE = (0.15, 0.10, 0.005)  # 0.30 x 0.20 m plate, 1 cm thick
TRAY_MASS = 0.2  # the whole tray, rim included
TRAY_RIM_THICKNESS = 0.005  # the authors' rim wall (inner floor 0.29 x 0.19 m)
AUTHORS_TRAY_RIM = 0.005  # m, rim height of the authors' tray (docs/AUTHORS_CONFIG.md §5.3)
TRAY_ATTACHMENTS = ("welded", "free")
#: Krang's finger plates (the URDF's gPlate links): half sizes in the gripper frame, and the
#: centres (gripper frame) of the two plates of each gripper, from the plate mesh's bounds.
FINGER_HALF_SIZE = (0.0105, 0.037, 0.045)
FINGER_CENTRES = {
    "left_gripper": ((-0.06, 0.0, 0.172), (0.06, 0.0, 0.172)),
    "right_gripper": ((-0.05, 0.0, 0.172), (0.07, 0.0, 0.172)),
}
#: the constraint solver's tolerance in models with a cup. At MuJoCo's default (1e-8) the
#: Newton solver stops at about one iteration per step with the cup's 0.5 N contact forces
#: unconverged beside the robot's kN wheel forces: a cup on a still tray then jitters (a path
#: of 12 to 16 mm per second, a net creep of 1 to 1.5 mm/s, measured with the robot held
#: still). At 1e-12 that is gone (under 0.001 mm/s) at the same iteration count and step cost.
CUP_SOLVER_TOLERANCE = 1e-12
#: the general convex collider's tolerance (``ccd_tolerance``, m) in models with a rim, whose
#: cup-wall pairs (cylinder-box) are the scene's only pairs MuJoCo's GJK/EPA computes. A cup
#: leaning on a wall presses into it by about 0.1 um (at 1 m/s^2; less under less load), below
#: MuJoCo's default 1e-6: EPA may then stop on a face of the wrong normal, and multiccd build the
#: contact on the wall's far face (5 mm deep, facing away), which threw a cup resting on the rim
#: over it at 14 rad/s. Among 10000 poses of the cup 1 um either side of touching a wall
#: (tests/test_rim.py, ``test_cup_contact_with_a_wall_faces_the_wall``) the default gives 3
#: such poses on each robot, 1e-7 gives 8 whose contact faces away at the right depth, 1e-8 and
#: 1e-9 none; the collision's time is the same within the machine's noise (8.6 to 9.9 us for
#: the whole model with the cup on the wall).
RIM_CCD_TOLERANCE = 1e-9
#: time the free tray is let settle on its supports (robot held still) when the model is built
TRAY_SETTLE_TIME = 0.5
#: damping of the tray's free joint while it settles (N s/m and N m s/rad): its rocking
#: (inertia 0.0015 to 0.004 kg m^2) dies out in a few hundredths of a second
TRAY_SETTLE_DAMPING = 0.05
#: and at each reset, from its rest place on the hand (the noise moves the supports a little).
#: Measured over 100 Krang resets: median residual angular speed 5e-5 rad/s, at most 0.016
#: rad/s and 1 mm/s; only a fall (1 cm of drop) raises at reset. About 10 ms per reset.
TRAY_RESET_SETTLE_TIME = 0.5
TRAY_RESET_MAX_SPEED = float("inf")
CUP_RADIUS = 0.031
CUP_HALF_HEIGHT = 0.04
CUP_MASS = 0.05
CUP_FEET = 4  # spheres the cup stands on (see add_cup)
CUP_FOOT_RADIUS = 0.001
#: solref of the stiff pairs (the cup's wall on the rim, a free tray on Krang's grippers): the
#: shortest time constant MuJoCo takes at the 1 ms step (with refsafe on, solref[0] is raised to
#: two timesteps), critically damped (no rebound). A cup meeting the rim at 0.5 m/s reaches
#: 0.5 mm into it, a tenth of the wall's thickness (MuJoCo's default 0.02 s: 3.6 mm);
#: assets/mjcf/README.md ("Contacts of the tray and the cup") gives the measurements.
STIFF_SOLREF = (0.002, 1.0)
#: solimp of the stiff pairs: an impedance of 0.99 at any depth (dmin = dmax; MuJoCo's default
#: rises from 0.9 to 0.95 over the first mm); the wheels' 0.9999 changes none of the figures of
#: tools/rim_contact.py
STIFF_SOLIMP = (0.99, 0.99, 0.001, 0.5, 2.0)
PAYLOAD_RADIUS = 0.04  # a 8 cm sphere in the hand, for its inertia and its picture


@dataclass(frozen=True)
class SceneOptions:
    """What to build.

    Attributes:
        robot: ``wip``, ``planar7`` or ``krang``.
        tray: add a tray on the end effector (level at the reset pose).
        cup: add a free cup resting on the tray (needs ``tray``).
        cup_friction: tray-cup friction coefficient (set on the explicit contact pairs).
        tray_attachment: ``welded`` (a child body of the hand) or ``free`` (a free body resting
            on the hand's supports, see the module docstring).
        tray_rim: rim height (m) on the plate's edge, 0 for none; the authors' tray has 5 mm.
        tray_friction: friction of the tray-support contact pairs (free tray only).
        tray_weld: a welded tray's pose on the body of the ``tray_mount`` site, ``(x, y, z,
            qw, qx, qy, qz)`` (body frame); None: at the mount, level at the reset pose. A
            controller's nominal model of a free tray welds it where it rests on the hand (the
            free tray's ``tray_rest`` site, ``controllers.policy.controller_model``).
        payload_mass: mass (kg) of a payload body welded to the hand (``ee`` site).
        wheel_torque_limit: each wheel motor's torque limit (N m); 150 as in the authors'
            simulation, 63.6 for Krang's hardware (docs/AUTHORS_CONFIG.md §1.5).
    """

    robot: str
    tray: bool = False
    cup: bool = False
    cup_friction: float = 0.3
    payload_mass: float = 0.0
    wheel_torque_limit: float = 150.0
    tray_attachment: str = "welded"
    tray_rim: float = 0.0
    tray_friction: float = 0.3
    tray_weld: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        spec = robot_spec(self.robot)
        if (self.tray or self.cup) and not spec.tray_capable:
            raise ValueError(f"robot {self.robot!r} has no end effector for a tray")
        if self.cup and not self.tray:
            raise ValueError("a cup needs a tray")
        if self.tray_attachment not in TRAY_ATTACHMENTS:
            raise ValueError(
                f"tray_attachment must be one of {list(TRAY_ATTACHMENTS)}, "
                f"got {self.tray_attachment!r}"
            )
        if self.tray_weld is not None and (
            self.tray_attachment != "welded"
            or len(self.tray_weld) != 7
            or not np.all(np.isfinite(self.tray_weld))
        ):
            raise ValueError(
                "tray_weld must be a welded tray's finite (x, y, z, qw, qx, qy, qz), got "
                f"{self.tray_weld!r} with tray_attachment {self.tray_attachment!r}"
            )
        if not (np.isfinite(self.tray_rim) and 0.0 <= self.tray_rim <= 2 * CUP_HALF_HEIGHT):
            raise ValueError(
                f"tray_rim must be a height in m in [0, {2 * CUP_HALF_HEIGHT}] "
                f"(0: no rim, {AUTHORS_TRAY_RIM}: the authors' rim), got {self.tray_rim!r}"
            )
        for name in ("cup_friction", "payload_mass", "wheel_torque_limit", "tray_friction"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        for name in ("wheel_torque_limit", "cup_friction"):
            if getattr(self, name) == 0:  # friction use is tangential / (mu normal)
                raise ValueError(f"{name} must be positive")


def reset_qpos(model: mujoco.MjModel, robot: RobotModel | None = None) -> np.ndarray:
    """The robot's noise-free reset pose: the ``home`` keyframe (or all zeros) at the origin,
    heading 0, with the base pitched about the axle so the body CoM is exactly above it."""
    robot = robot or RobotModel(model)
    lay = robot.layout
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    qpos = model.key_qpos[key][: lay.nq].copy() if key >= 0 else model.qpos0[: lay.nq].copy()
    robot.update(qpos, np.zeros(lay.nv), dynamics=False)
    q = robot.q.copy()
    q[lay.index_x] = 0.0
    if lay.index_psi is not None:
        q[lay.index_psi] = 0.0
    # the body rotates rigidly about the axle with q1: subtracting theta puts the CoM above it
    q[lay.index_q1] -= robot.theta
    return robot.full_state(q, np.zeros(lay.n_min))[0]


def _tray_geom_names(rim: float) -> list[str]:
    """The tray's collision geoms: the plate, then the rim walls (if any)."""
    return ["tray"] + (["tray_rim_px", "tray_rim_nx", "tray_rim_py", "tray_rim_ny"] if rim else [])


def _add_tray(
    spec: mujoco.MjSpec,
    options: SceneOptions,
    quat: np.ndarray,
    world_pos: np.ndarray | None,
    body_pos: np.ndarray | None = None,
) -> None:
    """The plate (geom ``tray``), the rim walls and the ``tray_top`` site. Welded: a child of the
    mount site's body with orientation ``quat``, at the mount or at ``body_pos`` (that body's
    frame). Free (``world_pos`` given): a free body at ``world_pos`` with world orientation
    ``quat``."""
    hx, hy, hz = TRAY_HALF_SIZE
    rim, t = options.tray_rim, TRAY_RIM_THICKNESS
    walls = (
        [
            ("tray_rim_px", (t / 2, hy, rim / 2), (hx - t / 2, 0.0)),
            ("tray_rim_nx", (t / 2, hy, rim / 2), (-(hx - t / 2), 0.0)),
            ("tray_rim_py", (hx - t, t / 2, rim / 2), (0.0, hy - t / 2)),
            ("tray_rim_ny", (hx - t, t / 2, rim / 2), (0.0, -(hy - t / 2))),
        ]
        if rim > 0
        else []
    )
    volumes = [8 * hx * hy * hz] + [8 * a * b * c for _, (a, b, c), _ in walls]
    density = TRAY_MASS / sum(volumes)
    free = world_pos is not None
    if free:
        tray = spec.worldbody.add_body(name="tray", pos=world_pos, quat=quat)
        tray.add_freejoint(name="tray")
    else:
        mount = spec.site("tray_mount")
        place = mount.pos if body_pos is None else body_pos
        tray = mount.parent.add_body(name="tray", pos=place, quat=quat)
    # free: meets the floor like the cup (contype 4 never meets the robot's conaffinity 1 ...
    # nor the cup's); its supports and the cup only through explicit pairs
    contype, conaffinity = (4, 1) if free else (0, 0)
    tray.add_geom(
        name="tray",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=TRAY_HALF_SIZE,
        pos=[0.0, 0.0, hz],
        mass=TRAY_MASS if not walls else density * volumes[0],
        contype=contype,
        conaffinity=conaffinity,
        material="tray",
    )
    for (name, size, (x, y)), volume in zip(walls, volumes[1:], strict=True):
        tray.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=size,
            pos=[x, y, 2 * hz + rim / 2],
            mass=density * volume,
            contype=contype,
            conaffinity=conaffinity,
            material="tray",
        )
    tray.add_site(name="tray_top", pos=[0.0, 0.0, 2 * hz], size=[0.01] * 3)


def tray_support_geoms(robot: str) -> list[str]:
    """Names of the geoms a free tray rests on (see the module docstring)."""
    if robot == "krang":
        return [f"{body}_finger{i}" for body in FINGER_CENTRES for i in (1, 2)]
    if robot == "planar7":
        return ["hand"]
    raise ValueError(f"robot {robot!r} has no tray support; valid: ['krang', 'planar7']")


def _add_supports(spec: mujoco.MjSpec, options: SceneOptions) -> None:
    """Krang's finger plates: massless boxes that collide only through the tray pairs."""
    if options.robot == "krang":
        for body_name, centres in FINGER_CENTRES.items():
            body = spec.body(body_name)
            for i, centre in enumerate(centres, start=1):
                body.add_geom(
                    name=f"{body_name}_finger{i}",
                    type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=FINGER_HALF_SIZE,
                    pos=centre,
                    mass=0.0,
                    contype=0,
                    conaffinity=0,
                    material="dark",
                )


def tray_hand_geoms(robot: str) -> list[str]:
    """Names of the hand's geoms a free tray meets sideways, beside its supports: stiff pairs
    with the plate and every rim wall (:func:`_add_hand_pairs`).

    - krang: the two gripper boxes. Their tops stand 5 to 6 mm above the plate's underside, 6
      (right) and 11 cm (left) beyond the plate's side edges: a tray sliding that far along its
      y meets one with its edge.
    - planar7: none. The hand's box lies wholly under the plate (its tip face is the support,
      paired with the plate), 11 and 4 cm inside the plate's edges: nothing of it reaches the
      plate's edges or the rim."""
    if robot == "krang":
        return ["left_gripper", "right_gripper"]
    if robot == "planar7":
        return []
    raise ValueError(f"robot {robot!r} has no tray support; valid: ['krang', 'planar7']")


def _add_support_pairs(spec: mujoco.MjSpec, options: SceneOptions) -> None:
    """The tray-support contact pairs, friction ``tray_friction``."""
    mu = options.tray_friction
    for support in tray_support_geoms(options.robot):
        spec.add_pair(
            name=f"tray_{support}",
            geomname1="tray",
            geomname2=support,
            condim=3,
            friction=[mu, mu, 0.005, 0.0001, 0.0001],
        )


def _add_hand_pairs(spec: mujoco.MjSpec, options: SceneOptions) -> None:
    """Stiff pairs (``STIFF_SOLREF``, ``STIFF_SOLIMP``) of the free tray's plate and rim walls
    with the hand's geoms of :func:`tray_hand_geoms`, friction ``tray_friction``. The free tray
    settles at reset on its supports alone (:class:`TraySettler`), which these never touch
    there."""
    mu = options.tray_friction
    for hand in tray_hand_geoms(options.robot):
        for tray_geom in _tray_geom_names(options.tray_rim):
            spec.add_pair(
                name=f"{tray_geom}_{hand}",
                geomname1=tray_geom,
                geomname2=hand,
                condim=3,
                friction=[mu, mu, 0.005, 0.0001, 0.0001],
                solref=list(STIFF_SOLREF),
                solimp=list(STIFF_SOLIMP),
            )


def add_cup(spec: mujoco.MjSpec, friction: float, rim: float) -> None:
    """A free cup (body and joint ``cup``) and its contact pairs of friction ``friction`` with
    the tray's plate and, with a rim (``rim`` > 0), its rim walls. The spec must hold the tray's
    geoms and the ``cup`` material.

    The cylinder ``cup`` carries the mass and the picture and meets the floor (plane-cylinder,
    a primitive pair). On the plate the cup stands on ``CUP_FEET`` small spheres inside its base
    rim (geoms ``cup_foot<k>``), tangent to the base: sphere-box is a primitive pair, where
    the cylinder on the plate's box is MuJoCo's general convex collision (4 points with
    multiccd). Same statics and sliding (Coulomb on a plate), same footprint; the support
    polygon is the square inscribed in the foot circle, so the cup could tip at an acceleration
    of ``0.53 g`` across a diagonal (the cylinder at ``0.75 g``): with ``cup_friction`` below
    0.53 it slides before either can tip, as the cylinder does (tests/test_cup_metrics.py).

    The rim meets the cup's wall: the cylinder ``cup`` and each wall make a stiff pair
    (``STIFF_SOLREF``, ``STIFF_SOLIMP``; cylinder-box is MuJoCo's general convex collision, up to
    5 points with multiccd), so the cup stops at the wall's face and can tip over its top edge
    (tests/test_rim.py). The feet meet the plate only: a 1 mm foot sits at the foot of a wall,
    whose nearest face becomes its bottom once the foot's centre is inside, and a foot pair
    pushed the cup under the rim (assets/mjcf/README.md, "Contacts of the tray and the cup").
    Only the feet touch the plate, so the cup's friction use on the plate
    (``wip_gym.envs.base.friction_use``, over the plate's contacts with the cup's geoms) counts
    the feet and never a rim's push."""
    cup = spec.worldbody.add_body(name="cup", pos=[0.0, 0.0, 1.0])
    cup.add_freejoint(name="cup")
    cup.add_geom(
        name="cup",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[CUP_RADIUS, CUP_HALF_HEIGHT, 0.0],
        mass=CUP_MASS,
        contype=4,  # meets the floor (conaffinity 1), not the robot (contype 2)
        conaffinity=1,
        material="cup",
    )
    feet = [f"cup_foot{k}" for k in range(CUP_FEET)]
    centre = CUP_RADIUS - CUP_FOOT_RADIUS
    for k, name in enumerate(feet):
        angle = 2.0 * np.pi * k / CUP_FEET
        cup.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[CUP_FOOT_RADIUS, 0.0, 0.0],
            pos=[
                centre * np.cos(angle),
                centre * np.sin(angle),
                -(CUP_HALF_HEIGHT - CUP_FOOT_RADIUS),
            ],
            mass=0.0,
            contype=0,  # the tray's pairs only
            conaffinity=0,
            material="cup",
        )
    plate, *walls = _tray_geom_names(rim)
    for foot in feet:
        spec.add_pair(
            name=f"{plate}_{foot}",
            geomname1=plate,
            geomname2=foot,
            condim=3,
            friction=[friction, friction, 0.005, 0.0001, 0.0001],
        )
    for wall in walls:
        spec.add_pair(
            name=f"{wall}_cup",
            geomname1=wall,
            geomname2="cup",
            condim=3,
            friction=[friction, friction, 0.005, 0.0001, 0.0001],
            solref=list(STIFF_SOLREF),
            solimp=list(STIFF_SOLIMP),
        )


def _add_payload(spec: mujoco.MjSpec, mass: float) -> None:
    ee = spec.site("ee")
    inertia = 0.4 * mass * PAYLOAD_RADIUS**2
    payload = ee.parent.add_body(
        name="payload",
        pos=ee.pos,
        mass=mass,
        inertia=[inertia] * 3,
        explicitinertial=True,
    )
    payload.add_geom(
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[PAYLOAD_RADIUS, 0, 0],
        contype=0,
        conaffinity=0,
        mass=0.0,
        rgba=[0.4, 0.4, 0.4, 0.6 if mass > 0 else 0.0],
    )


def _level_quat(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The orientation, in the ``tray_mount`` site's body frame, of a level frame heading 0."""
    mount_body = model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tray_mount")]
    world_from_body = np.zeros(4)
    mujoco.mju_mat2Quat(world_from_body, data.xmat[mount_body])
    quat = np.zeros(4)
    mujoco.mju_negQuat(quat, world_from_body)  # body_from_world: level, heading 0
    return quat


def _robot_spec(options: SceneOptions) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(mjcf_path(robot_spec(options.robot).scene_file)))
    for name in ("wheel_left", "wheel_right"):
        spec.actuator(name).ctrlrange = [-options.wheel_torque_limit, options.wheel_torque_limit]
    if robot_spec(options.robot).tray_capable:
        _add_payload(spec, options.payload_mass)
    return spec


def _posed(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData, int]:
    """Compile, put the robot at its reset pose, run the kinematics; also the robot's nq."""
    model = spec.compile()
    data = mujoco.MjData(model)
    robot = RobotModel(model)
    pose = reset_qpos(model, robot)
    data.qpos[: len(pose)] = pose
    mujoco.mj_kinematics(model, data)
    return model, data, robot.layout.nq


def _add_rest_site(spec: mujoco.MjSpec, pos: np.ndarray, quat: np.ndarray) -> None:
    """``tray_rest``: the tray's nominal place (its body frame) on the mount site's body."""
    spec.site("tray_mount").parent.add_site(
        name="tray_rest", pos=pos, quat=quat, size=[0.01] * 3, group=4
    )


class TraySettler:
    """Lets a free tray come to rest on the supports of a posed robot: a standalone model
    (the task's options, tray and tray-support pairs) holds the support geoms still at their
    world poses while the tray settles. Built once per task model; :meth:`settle` per pose."""

    def __init__(self, model: mujoco.MjModel, options: SceneOptions) -> None:
        spec = mujoco.MjSpec()
        spec.add_material(name="tray")
        for name in ("timestep", "integrator", "cone", "impratio", "enableflags", "disableflags"):
            setattr(spec.option, name, getattr(model.opt, name))
        spec.option.gravity = model.opt.gravity
        spec.option.tolerance = CUP_SOLVER_TOLERANCE
        self._names = tray_support_geoms(options.robot)
        for name in self._names:  # mocap bodies: posed per call through data.mocap_*
            spec.worldbody.add_body(name=name, mocap=True).add_geom(
                name=name,
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=model.geom_size[model.geom(name).id],
                contype=0,
                conaffinity=0,
            )
        _add_tray(spec, options, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3))
        # damping (settling only) so that a tray rocking on two diagonal supports comes to rest
        # on three; the rest pose is a static equilibrium, which damping does not move
        spec.joint("tray").damping = [TRAY_SETTLE_DAMPING, 0.0, 0.0]  # (linear, poly terms)
        mu = options.tray_friction
        for name in self._names:
            spec.add_pair(
                geomname1="tray",
                geomname2=name,
                condim=3,
                friction=[mu, mu, 0.005, 0.0001, 0.0001],
            )
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self._task_geoms = [model.geom(name).id for name in self._names]
        self._geoms = [self.model.geom(name).id for name in self._names]
        self._mocap = [int(self.model.body_mocapid[self.model.body(n).id]) for n in self._names]
        self._tray_geom = self.model.geom("tray").id

    def settle(
        self,
        data: mujoco.MjData,
        position: np.ndarray,
        quat: np.ndarray,
        duration: float = TRAY_SETTLE_TIME,
        max_speed: float = 1e-3,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The tray's rest pose (world position, quaternion) on the supports of the task data
        ``data`` (kinematics done), starting at ``position``, ``quat`` lowered (or raised)
        along world z to just touch the highest support. Raises if it fell (dropped 1 cm) or
        still moves faster than ``max_speed`` (m/s, rad/s) after ``duration``."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        for task_geom, mocap in zip(self._task_geoms, self._mocap, strict=True):
            d.mocap_pos[mocap] = data.geom_xpos[task_geom]
            mujoco.mju_mat2Quat(d.mocap_quat[mocap], data.geom_xmat[task_geom])
        d.qpos[:3] = position
        d.qpos[3:7] = quat
        mujoco.mj_kinematics(m, d)
        d.qpos[2] -= min(
            mujoco.mj_geomDistance(m, d, self._tray_geom, g, 0.1, None) for g in self._geoms
        )
        start = float(d.qpos[2])
        mujoco.mj_step(m, d, nstep=round(duration / m.opt.timestep))
        speed = float(np.linalg.norm(d.qvel))
        if speed > max_speed or start - float(d.qpos[2]) > 0.01:
            raise RuntimeError(
                f"the free tray did not settle on its supports (speed {speed:.3g} m/s, "
                f"drop {start - float(d.qpos[2]):.3g} m)"
            )
        return d.qpos[:3].copy(), d.qpos[3:7].copy()


def support_model(options: SceneOptions) -> mujoco.MjModel:
    """The robot with a free tray's supports (Krang's finger plates, :func:`tray_support_geoms`)
    and no tray: with :class:`TraySettler` on it, a controller finds where the tray rests on
    the supports at a pose of its own kinematics, as the env places it at reset
    (``controllers.high_level.tray_seat``)."""
    spec = _robot_spec(options)
    _add_supports(spec, options)
    return spec.compile()


def _settled_free_tray(options: SceneOptions) -> mujoco.MjSpec:
    """The spec with a free tray resting on its supports at the robot's reset pose
    (:func:`_settle_on_supports`): its settled pose is the tray body's initial pose and the
    ``tray_rest`` site (relative to the mount body)."""
    spec = _robot_spec(options)
    _add_supports(spec, options)
    model, data, _ = _posed(spec)
    mount = data.site_xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tray_mount")]
    pos, quat = TraySettler(model, options).settle(data, mount, np.array([1.0, 0.0, 0.0, 0.0]))
    _add_tray(spec, options, quat, pos)
    _add_support_pairs(spec, options)
    _add_hand_pairs(spec, options)
    body = model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tray_mount")]
    rel_pos = data.xmat[body].reshape(3, 3).T @ (pos - data.xpos[body])
    inv, rel_quat = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inv, data.xquat[body])
    mujoco.mju_mulQuat(rel_quat, inv, quat)
    _add_rest_site(spec, rel_pos, rel_quat)
    return spec


def build_spec(options: SceneOptions) -> mujoco.MjSpec:
    """The ``MjSpec`` of the task (see :class:`SceneOptions`)."""
    if options.tray and options.tray_attachment == "free":
        spec = _settled_free_tray(options)
    elif options.tray and options.tray_weld is not None:
        spec = _robot_spec(options)
        pose = np.array(options.tray_weld, dtype=float)
        quat = pose[3:] / np.linalg.norm(pose[3:])
        _add_tray(spec, options, quat, None, body_pos=pose[:3])
        _add_rest_site(spec, pose[:3], quat)
    else:
        tray_quat = np.array([1.0, 0.0, 0.0, 0.0])
        # the tray must be level at the reset pose, which its own mass shifts slightly: iterate
        for _ in range(3 if options.tray else 1):
            spec = _robot_spec(options)
            if not options.tray:
                break
            _add_tray(spec, options, tray_quat, None)
            model, data, _ = _posed(spec)
            tray_quat = _level_quat(model, data)
        if options.tray:
            tray = spec.body("tray")
            _add_rest_site(spec, np.array(tray.pos), np.array(tray.quat))
    if options.cup:
        add_cup(spec, options.cup_friction, options.tray_rim)
        spec.option.tolerance = CUP_SOLVER_TOLERANCE
        if options.tray_rim > 0:
            spec.option.ccd_tolerance = RIM_CCD_TOLERANCE
    return spec


def build_model(options: SceneOptions) -> mujoco.MjModel:
    """Compile the task's model."""
    return build_spec(options).compile()
