"""MuJoCo's C functions for compiled code: the fast path's one adapter to MuJoCo's C layout.

The compiled parts of the per-step computation (``wip_gym.minimal_kernels.robot_update_at``,
the task QP's one-call step ``controllers.low_level.compiled_step``, the env's
``wip_gym.envs.measures.env_measures``) call MuJoCo's kinematics, Jacobians and dynamics
directly, so that a control step is a few compiled calls instead of dozens of Python-level
ones. Each function is declared by its C name and signature (:data:`DECLARATIONS`, as
``mujoco/include/mujoco/mujoco.h`` has them) and resolved by symbol in the shared library the
``mujoco`` package ships (loaded with ``llvmlite``), so numba's on-disk cache stays valid
across processes. Their arguments are addresses: the ``MjModel``'s and ``MjData``'s, which
MuJoCo's bindings keep private (``_address``, read here and nowhere else:
:func:`addresses`), and arrays' ``ctypes.data``.

A C declaration that does not match the library corrupts memory instead of raising, so this
*fast path* is used only on the releases in :data:`VERIFIED_RELEASES`, whose ``mujoco.h``
declares every function as :data:`DECLARATIONS` does and on which ``tests/test_mujoco_c.py``
and a smoke of every env and controller passed (``tools/verify_mujoco_releases.py``;
docs/robot_model.md §3). Elsewhere, or when switched off (``WIP_GYM_FAST_PATH=0``, or
:func:`set_fast_path`), the robot model, the controllers' task QP and the env step take their
readable path through MuJoCo's Python bindings (:func:`fast_path` decides, when such an object
is made), and one warning says what that costs.
"""

from __future__ import annotations

import ctypes
import glob
import os
import warnings
from typing import Any

import mujoco
from numba import types

_PATTERNS = ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll")

VERIFIED_RELEASES = ("3.10", "3.11", "3.12", "3.13", "3.14", "3.17")
"""MuJoCo releases on which the fast path was verified (module docstring): each one's
``mujoco.h`` declares every function of :data:`DECLARATIONS` so, and the compiled calls give
what the bindings give."""

FAST_PATH_ENV = "WIP_GYM_FAST_PATH"
"""``WIP_GYM_FAST_PATH=0`` makes every object take the readable path (read when the first one
is made, or at :func:`set_fast_path` ``(None)``)."""

READABLE_COST = (
    "measured about 5 times slower in the unified controller's control step, 3 times in the "
    "env step, 4 times in their closed loop (docs/robot_model.md §3)"
)
"""What the readable path costs, as measured (docs/robot_model.md §3): the warning's words."""

_ptr = types.uint64  # a pointer, passed as its address
_int = types.intc

#: every C function compiled code calls: its declaration in ``mujoco.h`` and its numba argument
#: types (all return void)
DECLARATIONS: dict[str, tuple[str, tuple[types.Type, ...]]] = {
    "mj_kinematics": ("void mj_kinematics(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_comPos": ("void mj_comPos(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_comVel": ("void mj_comVel(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_crb": ("void mj_crb(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_passive": ("void mj_passive(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_subtreeVel": ("void mj_subtreeVel(const mjModel* m, mjData* d)", (_ptr, _ptr)),
    "mj_rnePostConstraint": (
        "void mj_rnePostConstraint(const mjModel* m, mjData* d)",
        (_ptr, _ptr),
    ),
    "mj_fullM": (
        "void mj_fullM(const mjModel* m, const mjData* d, mjtNum* dst)",
        (_ptr, _ptr, _ptr),
    ),
    "mj_rne": (
        "void mj_rne(const mjModel* m, mjData* d, int flg_acc, mjtNum* result)",
        (_ptr, _ptr, _int, _ptr),
    ),
    "mj_jac": (
        "void mj_jac(const mjModel* m, const mjData* d, mjtNum* jacp, mjtNum* jacr, "
        "const mjtNum point[3], int body)",
        (_ptr, _ptr, _ptr, _ptr, _ptr, _int),
    ),
    "mj_jacDot": (
        "void mj_jacDot(const mjModel* m, const mjData* d, mjtNum* jacp, mjtNum* jacr, "
        "const mjtNum point[3], int body)",
        (_ptr, _ptr, _ptr, _ptr, _ptr, _int),
    ),
    "mj_jacSite": (
        "void mj_jacSite(const mjModel* m, const mjData* d, mjtNum* jacp, mjtNum* jacr, int site)",
        (_ptr, _ptr, _ptr, _ptr, _int),
    ),
    "mj_jacSubtreeCom": (
        "void mj_jacSubtreeCom(const mjModel* m, mjData* d, mjtNum* jacp, int body)",
        (_ptr, _ptr, _ptr, _int),
    ),
    "mj_contactForce": (
        "void mj_contactForce(const mjModel* m, const mjData* d, int id, mjtNum result[6])",
        (_ptr, _ptr, _int, _ptr),
    ),
    "mj_step": ("void mj_step(const mjModel* m, mjData* d)", (_ptr, _ptr)),
}


def _declare(name: str) -> Any:
    """``void name(args)`` as numba's external function (typed ``Any`` for the type checker:
    it is called only from compiled code, with addresses and ints). Declaring it resolves
    nothing: the symbol is looked up when compiled code that calls it is loaded."""
    return types.ExternalFunction(name, types.void(*DECLARATIONS[name][1]))


mj_kinematics = _declare("mj_kinematics")
mj_comPos = _declare("mj_comPos")
mj_comVel = _declare("mj_comVel")
mj_crb = _declare("mj_crb")
mj_passive = _declare("mj_passive")
mj_subtreeVel = _declare("mj_subtreeVel")
mj_rnePostConstraint = _declare("mj_rnePostConstraint")
mj_fullM = _declare("mj_fullM")  # (m, d, dst)
mj_rne = _declare("mj_rne")  # (m, d, flg_acc, result)
mj_jac = _declare("mj_jac")  # (m, d, jacp, jacr, point, body)
mj_jacDot = _declare("mj_jacDot")  # as mj_jac
mj_jacSite = _declare("mj_jacSite")  # (m, d, jacp, jacr, site)
mj_jacSubtreeCom = _declare("mj_jacSubtreeCom")  # (m, d, jacp, body)
mj_contactForce = _declare("mj_contactForce")  # (m, d, id, result[6])
mj_step = _declare("mj_step")  # the native vector env's compiled steps (wip_gym.vector.compiled)


def release() -> str:
    """The installed MuJoCo's release, ``major.minor``."""
    return ".".join(mujoco.__version__.split(".")[:2])


def library_path() -> str:
    """The MuJoCo shared library inside the installed ``mujoco`` package."""
    directory = os.path.dirname(mujoco.__file__)
    for pattern in _PATTERNS:
        found = sorted(glob.glob(os.path.join(directory, pattern)))
        if found:
            return found[0]
    raise RuntimeError(f"no MuJoCo shared library ({', '.join(_PATTERNS)}) in {directory}")


def _unavailable() -> str | None:
    """Why the fast path cannot run in this process (None: it can; the library is then
    loaded)."""
    if release() not in VERIFIED_RELEASES:
        return (
            f"MuJoCo {mujoco.__version__} is not one of the releases wip_gym's compiled fast "
            f"path was verified on ({', '.join(VERIFIED_RELEASES)})"
        )
    probe = mujoco.MjModel.from_xml_string("<mujoco/>")
    if not isinstance(getattr(probe, "_address", None), int):
        return f"MuJoCo {mujoco.__version__}'s bindings do not give the model's address"
    try:
        import llvmlite.binding as llvm

        llvm.load_library_permanently(library_path())
    except (OSError, RuntimeError) as error:
        return f"MuJoCo's shared library could not be loaded ({error})"
    return None


_available: bool | None = None  # whether the fast path can run (checked once)
_chosen: bool | None = None  # set_fast_path's choice, or the environment's once read


def available() -> bool:
    """Whether the fast path can run in this process (checked once; the first time it cannot,
    one warning says why and what the readable path costs)."""
    global _available
    if _available is None:
        reason = _unavailable()
        _available = reason is None
        if reason is not None:
            warnings.warn(
                f"{reason}: the envs and controllers run on MuJoCo's Python bindings instead, "
                f"{READABLE_COST}",
                RuntimeWarning,
                stacklevel=3,
            )
    return _available


def fast_path() -> bool:
    """Whether objects made now take the compiled fast path: the user's choice
    (:func:`set_fast_path`, else ``WIP_GYM_FAST_PATH``: ``0`` is off) where it can run
    (:func:`available`)."""
    global _chosen
    if _chosen is None:
        _chosen = os.environ.get(FAST_PATH_ENV, "1").strip() != "0"
    return _chosen and available()


def set_fast_path(enabled: bool | None) -> None:
    """Choose the path of the objects made from now on (robot models, task QPs, envs): False
    the readable path, True the fast path (``ValueError`` where it cannot run), None the
    default again (``WIP_GYM_FAST_PATH``, read now). Objects made before keep theirs."""
    global _chosen
    if enabled is None:
        _chosen = None
        return
    _chosen = bool(enabled)
    if enabled and not fast_path():
        _chosen = None
        raise ValueError(f"the fast path cannot run here: {_unavailable()}")


def addresses(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[int, int]:
    """The addresses of ``model`` and ``data`` for the C functions (MuJoCo's private
    ``_address``; valid while both live). ``RuntimeError`` unless the fast path can run."""
    if not available():
        raise RuntimeError("the compiled fast path is not available (wip_gym.mujoco_c)")
    return int(model._address), int(data._address)


def contact_layout(data: mujoco.MjData) -> tuple[int, int, int, int]:
    """Where ``data``'s contacts are: the addresses of the first contact's ``geom`` and
    ``frame``, the size of MuJoCo's ``mjContact`` (bytes) and a bound on their count (the
    arena's size over that: the arena also holds the constraints and the stack, so fewer fit).
    MuJoCo keeps the contacts at the start of the arena, which is allocated once per MjData
    (``mj_resetData`` and ``mj_step`` do not move it; ``tests/test_step_measures.py`` checks
    this along episodes), so the layout is taken once and compiled code reads the first
    ``data.ncon`` contacts through it instead of the bindings' per-step views."""
    contact = data.contact
    geom, frame = contact.geom, contact.frame
    if geom.strides[0] != frame.strides[0] or geom.dtype.itemsize != 4:
        raise RuntimeError(
            f"unexpected mjContact layout: {geom.dtype}, {geom.strides}, {frame.strides}"
        )
    stride = int(geom.strides[0])
    return int(geom.ctypes.data), int(frame.ctypes.data), stride, int(data.narena) // stride


_SIZES_PROBE = """<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
<body pos="0 0 .1"><freejoint/><geom type="box" size=".1 .1 .1"/></body></worldbody></mujoco>"""
_sizes_offset: int | None = None  # ncon's offset before time in mjData (found once)


def _find_sizes_offset() -> int:
    """How many bytes ``mjData.ncon`` lies before ``mjData.time`` on this release: the
    variable sizes (``ncon, ne, nf, nl, nefc``, ints, then more that vary by release: 64
    bytes on 3.10, 80 on 3.11 and 3.12, 88 on 3.13 to 3.17) come shortly before ``time`` in
    every 3.x ``mjdata.h``; found on a probe box resting on a plane
    (4 contacts, 16 constraint rows) as the place of the bindings' own five values, and
    ``RuntimeError`` if no place or several hold them."""
    model = mujoco.MjModel.from_xml_string(_SIZES_PROBE)
    data = mujoco.MjData(model)
    for _ in range(100):
        mujoco.mj_step(model, data)
    expected = (data.ncon, data.ne, data.nf, data.nl, data.nefc)
    if expected[0] < 1 or expected[4] < 1:
        raise RuntimeError(f"the probe has no contacts to find ncon by: {expected}")
    time = int(data.energy.ctypes.data) - 8  # mjtNum time; mjtNum energy[2]
    if ctypes.c_double.from_address(time).value != data.time:
        raise RuntimeError("mjData.time is not right before mjData.energy on this release")
    found = [
        offset
        for offset in range(8, 260, 4)
        if tuple(ctypes.c_int.from_address(time - offset + 4 * k).value for k in range(5))
        == expected
    ]
    if len(found) != 1:
        raise RuntimeError(f"mjData.ncon not found before mjData.time: candidates {found}")
    return found[0]


def sizes_found() -> bool:
    """Whether :func:`size_addresses` can find ``ncon`` and ``time`` on this release (the
    fast path runs and the probe found ``ncon``'s place; found once)."""
    global _sizes_offset
    if not available():
        return False
    if _sizes_offset is None:
        try:
            _sizes_offset = _find_sizes_offset()
        except RuntimeError:
            _sizes_offset = -1
    return _sizes_offset > 0


def size_addresses(data: mujoco.MjData) -> tuple[int, int]:
    """The addresses of ``data``'s ``ncon`` (int) and ``time`` (mjtNum), which the bindings
    give only as Python numbers, for compiled code that steps ``data`` and then reads them
    (``wip_gym.vector.compiled``): ``time`` right before ``energy`` (whose view the bindings
    give), ``ncon`` where :func:`_find_sizes_offset` found it on this release; each checked
    against the bindings' value. ``RuntimeError`` where the layout differs."""
    if not sizes_found():
        raise RuntimeError(
            "mjData's ncon is not where wip_gym.mujoco_c looks for it on MuJoCo "
            f"{mujoco.__version__} (or the fast path is off)"
        )
    assert _sizes_offset is not None
    time = int(data.energy.ctypes.data) - 8
    ncon = time - _sizes_offset
    if (
        ctypes.c_double.from_address(time).value != data.time
        or ctypes.c_int.from_address(ncon).value != data.ncon
    ):
        raise RuntimeError("mjData's ncon and time are not where this release keeps them")
    return ncon, time
