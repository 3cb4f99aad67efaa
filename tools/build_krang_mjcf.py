"""Generate ``assets/mjcf/krang.xml``: Golem Krang (19 DOF, kinect dropped) for wip-gym.

Every number comes from KrangOld.urdf as summarised in docs/AUTHORS_CONFIG.md §1.2-1.6
(masses, CoM offsets, inertias, joint origins/axes/limits, collision boxes, torque limits,
initial pose) and from the URDF's collision-box origins. The URDF's own rounded angles (3.1416,
3.14, 1.5708, 4.7124) are kept verbatim, so the kinematics are those DART simulated.

Conventions (``assets/mjcf/README.md``):

* Our frame: x forward, y left, z up. The URDF ``Base`` frame has x along the axle pointing to the
  robot's right, y up the body and z backward, so the joint-less body ``base_link`` (welded to the
  root body ``base``) carries the fixed rotation URDF x -> -y, URDF y -> +z, URDF z -> -x. The
  URDF Base link (inertial, collision box) and the whole chain below it live in that frame, with
  the URDF numbers unchanged.
* A URDF joint ``origin xyz rpy`` becomes a body ``pos`` and ``quat`` (rpy is fixed-axis
  roll-pitch-yaw, R = Rz(yaw) Ry(pitch) Rx(roll)); the joint ``axis`` is in the child frame in
  both formats. Inertias are about the CoM in link axes: MJCF ``fullinertia``.
* The base pitch of the ``home`` keyframe (rotation about our +y, positive leans forward) is
  computed with MuJoCo so that the body CoM (all bodies except the wheels) is above the axle.
  It equals the paper code's ``qBase`` (its base orientation is Rx(pi/2) Ry(-pi/2) Rx(-qBase),
  i.e. a rotation by +qBase about our +y).

Run ``python tools/build_krang_mjcf.py`` from anywhere; it overwrites ``assets/mjcf/krang.xml``
and prints the derived numbers (home pitch, CoM distance, end-effector positions).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

Vec3 = tuple[float, float, float]

REPO = Path(__file__).resolve().parents[1]
MJCF_DIR = REPO / "assets" / "mjcf"
OUT_PATH = MJCF_DIR / "krang.xml"

# --------------------------------------------------------------------------------------------
# Numbers (docs/AUTHORS_CONFIG.md §1.2-1.6, KrangOld.urdf)
# --------------------------------------------------------------------------------------------

#: Rotation taking URDF Base-frame vectors to our base frame (columns: URDF x, y, z axes).
R_BASE_FROM_URDF = np.array(
    [
        [0.0, 0.0, -1.0],  # our x (forward) = -URDF z
        [-1.0, 0.0, 0.0],  # our y (left)    = -URDF x
        [0.0, 1.0, 0.0],  # our z (up)      = +URDF y
    ]
)

BASE_HEIGHT = 0.25  # axle height = the controllers' wheel radius
WHEEL_RADIUS = 0.25  # controllers' R (the URDF collision mesh is 0.2675)
WHEEL_HALF_TRACK = 0.34  # controllers' L/2 = 0.68/2 (URDF: -0.354 / +0.361, asymmetric)
WHEEL_MASS = 4.66
#: URDF wheel inertia ixx iyy izz = 0.102019 0.0832724 0.086493 (axle = URDF x). In our axes:
#: x <- URDF z, y <- URDF x (axial), z <- URDF y. Products (<= 0.0071) dropped: a round wheel.
WHEEL_DIAGINERTIA: Vec3 = (0.086493, 0.102019, 0.0832724)
WHEEL_TORQUE_LIMIT = 150.0  # per wheel: |tauL + tauR| <= 300 (docs/AUTHORS_CONFIG.md §1.5)

#: Home pose (13b defaultInit.txt first line); waist -4.2976 reduced mod 2 pi.
HOME_WAIST = 1.98558
HOME_TORSO = 0.053232
HOME_LEFT: tuple[float, ...] = (
    -1.36631,
    -0.495357,
    0.969689,
    -1.55801,
    -0.421576,
    -1.27307,
    -1.35663,
)
HOME_RIGHT: tuple[float, ...] = (1.2217, 0.606397, -0.91889, 1.50091, 0.516969, 1.31059, 1.26479)

#: Torque limits (13b controlParams.cfg tauLim): waist, torso, arm J1..J7.
WAIST_TORQUE = 740.0
TORSO_TORQUE = 370.0
ARM_TORQUES: tuple[float, ...] = (370.0, 370.0, 175.0, 175.0, 40.0, 40.0, 9.5)

#: Tray frame (docs/AUTHORS_CONFIG.md §5.3): left-gripper pose x R_local, then this offset in
#: that frame.
TRAY_R_LOCAL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
TRAY_OFFSET = np.array([0.0, -0.286303, 0.04])


@dataclass(frozen=True)
class Link:
    """One URDF link turned into an MJCF body (joint = the URDF joint from its parent).

    Attributes:
        body: our body name.
        joint: our joint name (None: welded).
        xyz, rpy: URDF joint origin in the parent link frame.
        axis: URDF joint axis in the child frame.
        limits: joint position limits (rad).
        mass, com: link mass and CoM offset in the link frame.
        inertia: ixx iyy izz ixy ixz iyz about the CoM in link axes.
        box: collision box full extents; box_xyz, box_rpy its origin in the link frame.
        material: material of the collision box.
    """

    body: str
    joint: str | None
    xyz: Vec3
    rpy: Vec3
    axis: Vec3
    limits: tuple[float, float]
    mass: float
    com: Vec3
    inertia: tuple[float, float, float, float, float, float]
    box: Vec3
    box_xyz: Vec3
    box_rpy: Vec3 = (0.0, 0.0, 0.0)
    material: str = "link"


# URDF Base link (placed by base_link's fixed rotation; no joint).
BASE_LINK = Link(
    body="base_link",
    joint=None,
    xyz=(0.0, 0.0, 0.0),
    rpy=(0.0, 0.0, 0.0),
    axis=(1.0, 0.0, 0.0),
    limits=(0.0, 0.0),
    mass=75.767,
    com=(-0.000628, 0.001940, 0.076721),
    inertia=(2.9427, 2.4034, 1.2335, 0.0001, 0.0037, -0.0113),
    box=(0.7165, 0.71048, 0.32860),
    box_xyz=(0.00225, 0.2097395, 0.0063),
    material="dark",
)

SPINE = Link(
    body="spine",
    joint="waist",
    xyz=(0.026, 0.499, -0.091),
    rpy=(0.0, 0.0, 0.0),
    axis=(-1.0, 0.0, 0.0),
    limits=(0.0, 2.7),
    mass=14.006,
    com=(-0.051222, 0.000345, 0.080526),
    inertia=(0.5601, 0.53, 0.2328, 0.0003, 0.1548, -0.006),
    box=(0.2340, 0.59430, 0.24097),
    box_xyz=(-0.026, 0.230150, 0.053887),
    material="body",
)

TORSO = Link(
    body="torso",
    joint="torso",
    xyz=(-0.0285, 0.584, 0.1088),
    rpy=(0.0, 3.1416, 0.0),
    axis=(0.0, -1.0, 0.0),
    limits=(-0.8, 0.8),
    mass=6.533,
    com=(0.0, 0.076445, -0.005972),
    inertia=(0.1003, 0.0214, 0.0987, 0.0, 0.0, 0.0),
    box=(0.2815, 0.23, 0.22611),
    box_xyz=(0.0012875, 0.0582, -0.0280530),
    material="body",
)

# Arm link numbers shared by both arms: mass, CoM, inertia, collision box (size, origin).
_ARM_INERTIAL: tuple[tuple[float, Vec3, tuple[float, float, float, float, float, float]], ...] = (
    (7.35, (0.0217, -0.0691, 0.0), (0.0381, 0.0187, 0.0430, 0.0104, 0.0, 0.0)),
    (6.1405, (0.0269, -0.0548, 0.0), (0.0320, 0.0134, 0.0350, 0.0097, 0.0, 0.0)),
    (4.531, (0.0188, -0.00619, 0.0), (0.0180, 0.0084, 0.0204, 0.005, 0.0, 0.0)),
    (3.2245, (0.0238, -0.0484, 0.0), (0.0133, 0.0049, 0.0145, 0.004, 0.0, 0.0)),
    (2.318, (0.0166, -0.0494, 0.0), (0.0063, 0.0029, 0.0072, 0.0017, 0.0, 0.0)),
    (2.318, (0.0232, -0.0377, 0.0), (0.0071, 0.0029, 0.008, 0.0020, 0.0, 0.0)),
    (2.3838, (0.0, 0.0, 0.1055), (0.0104, 0.0108, 0.0027, 0.0, 0.0, 0.0)),
)
_ARM_BOXES: tuple[tuple[Vec3, Vec3], ...] = (
    ((0.16, 0.29367, 0.13188), (0.015, -0.080866, 0.0)),
    ((0.14591, 0.24658, 0.13), (0.017042, -0.058309, 0.0)),
    ((0.13800, 0.26217, 0.11189), (0.014000, -0.075113, 0.0)),
    ((0.12960, 0.2141, 0.11), (0.018200, -0.052050, 0.0)),
    ((0.117977, 0.204179, 0.089915), (0.0145115, -0.0571105, 0.0000425)),
    ((0.111977, 0.185277, 0.089), (0.0175015, -0.0481615, 0.0)),
    ((0.08, 0.112, 0.2025), (0.0, 0.0, 0.0)),  # gripper origin differs per side (below)
)
_ARM_AXES: tuple[Vec3, ...] = (
    (0.0, -1.0, 0.0),
    (-1.0, 0.0, 0.0),
    (0.0, -1.0, 0.0),
    (-1.0, 0.0, 0.0),
    (0.0, -1.0, 0.0),
    (-1.0, 0.0, 0.0),
    (0.0, 0.0, -1.0),
)
_ARM_XYZ: tuple[Vec3, ...] = (
    (0.0, 0.0, 0.0),
    (0.0, -0.328, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, -0.2765, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, -0.200, 0.0),
)  # joints 2..7
_BEND = 2.094  # J2, J4, J6 limits
_ROT = 4.7124  # J3, J5, J7 limits


def arm_links(side: str) -> list[Link]:
    """The seven links of one arm (``side`` = ``left`` or ``right``), URDF numbers verbatim.

    The two arms differ in LJ1/RJ1 (origin, rpy, limit), LJ4/RJ4 rpy (pi,pi,0 vs -pi,pi,0), the
    L5 collision-box rpy (-1.57 0 0 on the left only) and the gripper box z (-/+0.02615).
    """
    left = side == "left"
    j1_xyz: Vec3 = (0.2823, 0.0845, 0.0) if left else (-0.2823, 0.0845, 0.0)
    j1_rpy: Vec3 = (0.0, 3.1416, -1.5708) if left else (0.0, 0.0, 1.5708)
    j1_lim = 3.1416 if left else _ROT
    rpys: list[Vec3] = [
        j1_rpy,
        (3.14, 3.14, 0.0),
        (-3.1416, -3.1416, 0.0),
        (3.1416, 3.1416, 0.0) if left else (-3.1416, 3.1416, 0.0),
        (3.1416, 3.1416, 0.0),
        (0.0, 0.0, 3.1416),
        (1.5708, 4.7124, 0.0),
    ]
    xyzs: list[Vec3] = [j1_xyz, *_ARM_XYZ]
    lims = (j1_lim, _BEND, _ROT, _BEND, _ROT, _BEND, _ROT)
    links = []
    for i in range(7):
        mass, com, inertia = _ARM_INERTIAL[i]
        box, box_xyz = _ARM_BOXES[i]
        box_rpy: Vec3 = (0.0, 0.0, 0.0)
        if i == 4 and left:
            box_rpy = (-1.57, 0.0, 0.0)
        if i == 6:
            box_xyz = (0.0, 0.0, -0.02615 if left else 0.02615)
            box_rpy = (0.0, 0.0, 1.5708)
        links.append(
            Link(
                body=f"{side}_{i + 1}" if i < 6 else f"{side}_gripper",
                joint=f"{side}_j{i + 1}",
                xyz=xyzs[i],
                rpy=rpys[i],
                axis=_ARM_AXES[i],
                limits=(-lims[i], lims[i]),
                mass=mass,
                com=com,
                inertia=inertia,
                box=box,
                box_xyz=box_xyz,
                box_rpy=box_rpy,
                material="gripper" if i == 6 else "link",
            )
        )
    return links


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------


def rpy_matrix(rpy: Vec3) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr = math.cos(r), math.sin(r)
    cp, sp = math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def mat_to_quat(mat: np.ndarray) -> np.ndarray:
    """Unit quaternion (w x y z, w >= 0) of a rotation matrix, via ``mju_mat2Quat``."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, dtype=float).ravel())
    quat /= np.linalg.norm(quat)
    return -quat if quat[0] < 0 else quat


def pitch_quat(pitch: float) -> np.ndarray:
    """Quaternion (w x y z) of a rotation by ``pitch`` about +y."""
    return np.array([math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0])


def fmt(values: np.ndarray | tuple[float, ...] | list[float]) -> str:
    """Space-separated numbers, 12 significant digits, round-off below 1e-12 printed as 0."""
    out = []
    for v in np.asarray(values, dtype=float).ravel():
        v = 0.0 if abs(v) < 1e-12 else float(v)
        out.append(f"{v:.12g}")
    return " ".join(out)


# --------------------------------------------------------------------------------------------
# XML
# --------------------------------------------------------------------------------------------

HEADER = """<!--
  krang: Golem Krang, 19 DOF after the rolling constraints (x, heading, base pitch, waist, torso,
  7 left-arm joints, 7 right-arm joints) driven by 18 torque motors (2 wheels + 16 body
  joints; the wheels drive x, heading and pitch together).
  GENERATED by tools/build_krang_mjcf.py: do not edit, change the generator and rerun it.

  Source: KrangOld.urdf, the model the paper's simulation (13b) loads, via
  docs/AUTHORS_CONFIG.md §1.2-1.6 (masses, CoM offsets, inertias about the CoM in link axes,
  joint origins/axes/limits, collision boxes) plus the URDF's collision-box origins. The URDF's
  rounded angles (3.1416, 3.14, 1.5708, 4.7124) are kept as written.
  Choices:
  - The kinect (0.705 kg, head joint) and the 4 gripper plates (0.0001 kg each) are dropped.
  - Wheels: radius 0.25 and separation 0.68 (+-0.34), the numbers every controller uses; the
    URDF has a 0.2675 m mesh at -0.354 / +0.361 (asymmetric). Wheel inertia from the URDF wheel
    link (axial 0.102019 about our y), its small products of inertia dropped (a round wheel).
  - Body joints: URDF position limits, no damping (the paper's controller added 0.5 N m s/rad
    on the arms and disabled their limits; we keep the robot's limits and no damping).
  - Torque limits: 13b tauLim (waist 740, torso 370, arm 370 370 175 175 40 40 9.5) and
    +-150 N m per wheel (|tauL + tauR| <= 300).
  Conventions (assets/mjcf/README.md): x forward, y left, z up; `base` has its origin at the axle
  midpoint. The URDF Base frame (x along the axle to the robot's right, y up the body, z
  backward) is the welded body `base_link`: URDF x -> -y, y -> +z, z -> -x. Everything from the
  URDF Base link down is in URDF numbers inside it (body pos/quat = joint origin xyz/rpy, rpy
  fixed-axis R = Rz Ry Rx; joint axis in the child frame; fullinertia = ixx iyy izz ixy ixz iyz).
  Keyframe `home`: the paper's initial pose; the base pitch (about +y, positive leans forward;
  it equals 13b's qBase) puts the body CoM (all but the wheels) over the axle: {pitch:.6f} rad.
  Sites: `ee` / `ee_right` = left / right gripper body origins (the controller's EE frames);
  `tray_mount` = the demo's tray frame origin (docs/AUTHORS_CONFIG.md §5.3) in the left-gripper
  frame.
-->
"""


def _link_xml(link: Link, indent: str, children: str, extra: str = "") -> str:
    """One body: pos/quat from the URDF joint origin, hinge, inertial, collision box."""
    quat = mat_to_quat(rpy_matrix(link.rpy))
    lines = [f'{indent}<body name="{link.body}" pos="{fmt(link.xyz)}" quat="{fmt(quat)}">']
    sub = indent + "  "
    if link.joint is not None:
        lines.append(
            f'{sub}<joint name="{link.joint}" axis="{fmt(link.axis)}" range="{fmt(link.limits)}"/>'
        )
    lines.append(
        f'{sub}<inertial pos="{fmt(link.com)}" mass="{fmt((link.mass,))}" '
        f'fullinertia="{fmt(link.inertia)}"/>'
    )
    half = np.asarray(link.box) / 2
    box_quat = mat_to_quat(rpy_matrix(link.box_rpy))
    quat_attr = "" if np.allclose(box_quat, [1, 0, 0, 0]) else f' quat="{fmt(box_quat)}"'
    lines.append(
        f'{sub}<geom name="{link.body}" type="box" size="{fmt(half)}" pos="{fmt(link.box_xyz)}"'
        f'{quat_attr} material="{link.material}"/>'
    )
    if extra:
        lines.append(extra)
    if children:
        lines.append(children)
    lines.append(f"{indent}</body>")
    return "\n".join(lines)


def _arm_xml(side: str, indent: str, tray_pos: np.ndarray) -> str:
    """Nested bodies of one arm, with the end-effector sites on the gripper."""
    links = arm_links(side)
    depth = [indent + "  " * i for i in range(len(links))]
    sub = depth[-1] + "  "
    if side == "left":
        extra = (
            f'{sub}<site name="ee" pos="0 0 0" size="0.02"/>\n'
            f"{sub}<!-- tray frame origin (docs/AUTHORS_CONFIG.md §5.3): "
            "R_local @ (0, -0.286303, 0.04) -->\n"
            f'{sub}<site name="tray_mount" pos="{fmt(tray_pos)}" size="0.015"/>'
        )
    else:
        extra = f'{sub}<site name="ee_right" pos="0 0 0" size="0.02"/>'
    xml = _link_xml(links[-1], depth[-1], "", extra)
    for i in range(len(links) - 2, -1, -1):
        xml = _link_xml(links[i], depth[i], xml)
    return xml


def _wheel_xml(name: str, y: float, indent: str) -> str:
    """A wheel body per the contract (classes from common.xml)."""
    sub = indent + "  "
    return "\n".join(
        [
            f'{indent}<body name="{name}" pos="0 {fmt((y,))} 0" childclass="wheel">',
            f'{sub}<joint name="{name}"/>',
            f'{sub}<inertial pos="0 0 0" mass="{fmt((WHEEL_MASS,))}" '
            f'diaginertia="{fmt(WHEEL_DIAGINERTIA)}"/>',
            f'{sub}<geom name="{name}" class="wheel_collision"/>',
            f'{sub}<geom class="wheel_visual"/>',
            f"{indent}</body>",
        ]
    )


def actuated_joints() -> list[str]:
    """Actuated joints in contract order: wheels, then body joints in tree order."""
    arms = [f"{s}_j{i}" for s in ("left", "right") for i in range(1, 8)]
    return ["wheel_left", "wheel_right", "waist", "torso", *arms]


def torque_limits() -> list[float]:
    """Torque limit of every actuated joint, in ``actuated_joints()`` order."""
    return [WAIST_TORQUE, TORSO_TORQUE, *ARM_TORQUES, *ARM_TORQUES]


def home_joint_qpos() -> list[float]:
    """Joint part of the home qpos (wheels, waist, torso, left arm, right arm)."""
    return [0.0, 0.0, HOME_WAIST, HOME_TORSO, *HOME_LEFT, *HOME_RIGHT]


def build_xml(pitch: float, tray_pos: np.ndarray) -> str:
    """The complete krang.xml text for a given home base pitch and tray_mount position."""
    i2, i3, i4 = ("  " * k for k in (3, 4, 5))
    base_quat = mat_to_quat(R_BASE_FROM_URDF)
    arms = _arm_xml("left", i4 + "  ", tray_pos) + "\n" + _arm_xml("right", i4 + "  ", tray_pos)
    torso = _link_xml(TORSO, i4, arms)
    spine = _link_xml(SPINE, i3, torso)
    base_link = _link_xml(BASE_LINK, i2, spine).replace(
        '<body name="base_link" pos="0 0 0" quat="1 0 0 0">',
        "<!-- the URDF Base frame: URDF x -> -y, y -> +z, z -> -x -->\n"
        f'{i2}<body name="base_link" quat="{fmt(base_quat)}">',
    )
    qpos = [0.0, 0.0, BASE_HEIGHT, *pitch_quat(pitch), *home_joint_qpos()]
    motors = []
    limits = [WHEEL_TORQUE_LIMIT] * 2 + torque_limits()
    for joint, limit in zip(actuated_joints(), limits, strict=True):
        motors.append(
            f'    <motor name="{joint}" joint="{joint}" ctrlrange="{fmt((-limit, limit))}"/>'
        )
    body = f"""<mujoco model="krang">
  <compiler angle="radian" autolimits="true"/>
  <include file="common.xml"/>

  <worldbody>
    <body name="base" pos="0 0 {fmt((BASE_HEIGHT,))}" childclass="robot">
      <freejoint name="root"/>
      <camera name="track" mode="trackcom" pos="1.0 -5.5 1.2" xyaxes="1 0 0 0 0.2 1"/>
      <!-- wheels at +-0.34 (the controllers' separation 0.68, not the URDF's -0.354/+0.361) -->
{_wheel_xml("wheel_left", WHEEL_HALF_TRACK, i2)}
{_wheel_xml("wheel_right", -WHEEL_HALF_TRACK, i2)}
{base_link}
    </body>
  </worldbody>

  <actuator>
{chr(10).join(motors)}
  </actuator>

  <keyframe>
    <!-- the paper's initial pose; base pitch {pitch:.9f} rad puts the body CoM over the axle -->
    <key name="home" qpos="{fmt(qpos)}"/>
  </keyframe>
</mujoco>
"""
    return HEADER.format(pitch=pitch) + body


# --------------------------------------------------------------------------------------------
# Derived numbers (MuJoCo)
# --------------------------------------------------------------------------------------------


def load(xml: str) -> mujoco.MjModel:
    """Compile krang.xml text (common.xml is read from the assets directory)."""
    assets = {"common.xml": (MJCF_DIR / "common.xml").read_bytes()}
    return mujoco.MjModel.from_xml_string(xml, assets)


def body_com_in_axle_frame(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """CoM of all bodies but the wheels, relative to the axle midpoint (world axes)."""
    wheels = {model.body(n).id for n in ("wheel_left", "wheel_right")}
    ids = [b for b in range(1, model.nbody) if b not in wheels]
    mass = model.body_mass[ids]
    com = (mass[:, None] * data.xipos[ids]).sum(axis=0) / mass.sum()
    return com - data.xpos[model.body("base").id]


def home_data(model: mujoco.MjModel, pitch: float) -> mujoco.MjData:
    """Forward kinematics at the home joint angles with the given base pitch."""
    data = mujoco.MjData(model)
    data.qpos[:] = [0.0, 0.0, BASE_HEIGHT, *pitch_quat(pitch), *home_joint_qpos()]
    mujoco.mj_kinematics(model, data)
    return data


def compute_home_pitch(model: mujoco.MjModel) -> float:
    """Base pitch putting the body CoM over the axle: minus atan2(X_com, Z_com) at pitch 0."""
    com = body_com_in_axle_frame(model, home_data(model, 0.0))
    return -math.atan2(com[0], com[2])


def tray_mount_local() -> np.ndarray:
    """Tray frame origin in the left-gripper frame: R_local @ offset (pose independent)."""
    return TRAY_R_LOCAL @ TRAY_OFFSET


def main() -> None:
    """Build krang.xml, check it compiles and the CoM is over the axle, print derived numbers."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT_PATH, help="output MJCF path")
    args = parser.parse_args()

    tray = tray_mount_local()
    pitch = compute_home_pitch(load(build_xml(0.0, tray)))
    xml = build_xml(pitch, tray)
    model = load(xml)
    data = home_data(model, pitch)
    com = body_com_in_axle_frame(model, data)
    if abs(com[0]) > 1e-9:
        raise RuntimeError(f"CoM not over the axle at home: {com}")
    if model.geom("wheel_left").size[0] != WHEEL_RADIUS:  # the radius comes from common.xml
        raise RuntimeError("common.xml wheel_collision radius differs from WHEEL_RADIUS")
    args.out.write_text(xml)

    base = data.xpos[model.body("base").id]
    print(f"wrote {args.out}")
    print(f"total mass {model.body_mass.sum():.6f} kg, nq {model.nq}, nv {model.nv}, nu {model.nu}")
    print(f"home base pitch {pitch:.9f} rad ({math.degrees(pitch):.4f} deg)")
    print(f"body CoM (axle frame) {fmt(com)}, distance {np.linalg.norm(com):.5f} m")
    for site in ("ee", "ee_right", "tray_mount"):
        print(f"{site:10s} (axle frame) {fmt(np.round(data.site(site).xpos - base, 5))}")
    tray_rot = data.body("left_gripper").xmat.reshape(3, 3) @ TRAY_R_LOCAL
    print(f"tray frame rotation at home (world):\n{np.round(tray_rot, 4)}")


if __name__ == "__main__":
    main()
