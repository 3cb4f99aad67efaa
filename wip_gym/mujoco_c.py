"""MuJoCo's C functions, callable from numba-compiled code.

The compiled parts of the per-step computation (``wip_gym.minimal_kernels``,
``controllers.low_level.compiled_tasks``) call MuJoCo's kinematics, Jacobians and dynamics
directly, so that a control step is a few compiled calls instead of dozens of Python-level
ones. The shared library that the ``mujoco`` package ships is loaded once (``llvmlite``), and
each function is declared by its C name and signature (``mujoco/include/mujoco/mujoco.h`` of
the releases in :data:`TESTED_VERSIONS`; another release is refused at import); the call is
resolved by symbol when the compiled code is loaded, so numba's on-disk cache stays valid
across processes.

Arguments are addresses: ``model._address`` and ``data._address`` of the ``mujoco.MjModel`` and
``mujoco.MjData`` (whose Python objects must outlive the call), ``array.ctypes.data`` of
C-contiguous float64 arrays of the sizes MuJoCo expects (``3 x nv`` for ``jacp``), 0 for a
null pointer. ``tests/test_mujoco_c.py`` checks every declaration against the Python bindings.
"""

from __future__ import annotations

import glob
import os
from typing import Any

import llvmlite.binding as llvm
import mujoco
import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic

_PATTERNS = ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll")
TESTED_VERSIONS = ("3.17",)
"""MuJoCo releases whose ``mujoco.h`` these declarations were checked against: a C signature
that changed (``mj_fullM``'s did in 3.x) would corrupt memory instead of raising, so another
release is refused until ``tests/test_mujoco_c.py`` has passed on it and it is added here."""


def _check_version() -> None:
    release = ".".join(mujoco.__version__.split(".")[:2])
    if release not in TESTED_VERSIONS:
        raise ImportError(
            f"wip_gym.mujoco_c: MuJoCo {mujoco.__version__} is not one of the releases its C "
            f"declarations were checked against ({', '.join(TESTED_VERSIONS)}); install "
            "mujoco 3.17 (pyproject.toml pins it)"
        )


def library_path() -> str:
    """The MuJoCo shared library inside the installed ``mujoco`` package."""
    directory = os.path.dirname(mujoco.__file__)
    for pattern in _PATTERNS:
        found = sorted(glob.glob(os.path.join(directory, pattern)))
        if found:
            return found[0]
    raise RuntimeError(f"no MuJoCo shared library ({', '.join(_PATTERNS)}) in {directory}")


_check_version()
llvm.load_library_permanently(library_path())

_ptr = types.uint64  # a pointer, passed as its address
_int = types.intc


def _declare(name: str, *args: types.Type) -> Any:
    """``void name(args)`` as numba's external function (typed ``Any`` for the type checker:
    it is called only from compiled code, with addresses and ints)."""
    return types.ExternalFunction(name, types.void(*args))


mj_kinematics = _declare("mj_kinematics", _ptr, _ptr)
mj_comPos = _declare("mj_comPos", _ptr, _ptr)
mj_comVel = _declare("mj_comVel", _ptr, _ptr)
mj_crb = _declare("mj_crb", _ptr, _ptr)
mj_passive = _declare("mj_passive", _ptr, _ptr)
mj_subtreeVel = _declare("mj_subtreeVel", _ptr, _ptr)
mj_rnePostConstraint = _declare("mj_rnePostConstraint", _ptr, _ptr)
mj_fullM = _declare("mj_fullM", _ptr, _ptr, _ptr)  # (m, d, dst)
mj_rne = _declare("mj_rne", _ptr, _ptr, _int, _ptr)  # (m, d, flg_acc, result)
mj_jac = _declare("mj_jac", _ptr, _ptr, _ptr, _ptr, _ptr, _int)  # (m, d, jacp, jacr, point, body)
mj_jacDot = _declare("mj_jacDot", _ptr, _ptr, _ptr, _ptr, _ptr, _int)  # as mj_jac
mju_quat2Mat = _declare("mju_quat2Mat", _ptr, _ptr)  # (res[9], quat[4])
mj_jacSite = _declare("mj_jacSite", _ptr, _ptr, _ptr, _ptr, _int)  # (m, d, jacp, jacr, site)
mj_jacSubtreeCom = _declare("mj_jacSubtreeCom", _ptr, _ptr, _ptr, _int)  # (m, d, jacp, body)
mj_contactForce = _declare("mj_contactForce", _ptr, _ptr, _int, _ptr)  # (m, d, id, result[6])


def _pointer_intrinsic(element: types.Type) -> Any:
    """An intrinsic ``(element *) address`` for compiled code, for ``numba.carray``: a view of a
    buffer whose address (``array.ctypes.data``) was taken once, so that a compiled call gets
    one table of addresses instead of one argument per array (numba unboxes every array
    argument on each call)."""

    def pointer(typingctx: Any, address: Any) -> Any:
        if not isinstance(address, types.Integer):
            return None
        signature = types.CPointer(element)(address)

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            return builder.inttoptr(args[0], context.get_value_type(sig.return_type))

        return signature, codegen

    pointer.__name__ = f"{element}_pointer"
    return intrinsic(pointer)


float64_pointer: Any = _pointer_intrinsic(types.float64)
"""``(double *) address`` in compiled code (:func:`float64_view`, ``wip_gym.array_table``)."""
int64_pointer: Any = _pointer_intrinsic(types.int64)
"""``(int64_t *) address`` in compiled code (``wip_gym.array_table``)."""
int32_pointer: Any = _pointer_intrinsic(types.int32)
"""``(int *) address`` in compiled code (the contacts' geom ids: ``wip_gym.envs.measures``)."""


@njit(cache=True)
def float64_view(address: int, shape: tuple[int, ...]) -> np.ndarray:
    """In compiled code, the C-contiguous float64 array of ``shape`` at ``address`` (an entry of
    a table of :func:`float64_addresses`): a view, read and written in place."""
    return carray(float64_pointer(np.uint64(address)), shape)


def float64_addresses(arrays: tuple[Any, ...]) -> list[int]:
    """The addresses (``array.ctypes.data``) of C-contiguous float64 arrays, for a table that
    compiled code reads through :data:`float64_pointer` (valid while the arrays' owners, the
    MjModel and MjData, live). Raises ``ValueError`` for any other array: compiled code would
    read it as float64 at the wrong strides."""
    addresses = []
    for i, array in enumerate(arrays):
        if array.dtype != "float64" or not array.flags.c_contiguous:
            raise ValueError(
                f"array {i} of the address table is {array.dtype}, "
                f"{'C-contiguous' if array.flags.c_contiguous else 'strided'}: "
                "a table needs C-contiguous float64 arrays"
            )
        addresses.append(int(array.ctypes.data))
    return addresses
