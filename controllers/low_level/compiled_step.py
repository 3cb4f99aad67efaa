"""The low level's rows and QP kernel as one compiled call per control step, its arrays in one
table.

With every task of a kind the compiled rows know (``controllers.low_level.task_stack``) and eq.
``iso3`` computed from the robot (the controller's default), a control step's task rows
(:func:`controllers.low_level.task_stack.stack_rows`) and QP kernel
(:func:`controllers.low_level.kernel.kernel_step`) are one call of :func:`rows_and_kernel`. Its
arrays (MuJoCo's, the robot model's, the motion probe's, the task stack's, the kernel's: buffers
made once and written in place) reach it as one :class:`wip_gym.array_table.ArrayTable`
(:data:`ENTRIES`, in this order): one array to unbox instead of the 72 array arguments of the
two calls it replaces (46 of ``stack_rows``, 26 of ``kernel_step``). When the
unconstrained minimiser is feasible, the same call computes what it implies (the torques,
``kernel.solution_terms_into``). The arithmetic is those functions' own, so the result is the
same to the bit as :meth:`CompiledTaskStack.fill`, :meth:`LowLevelKernel.run` and
``solution_terms`` (``tests/test_compiled_step.py``).

The table is built by :func:`step_table` for one task stack and one kernel: ``TaskQP`` builds it
again whenever either is made anew (a new task list, new row buffers, new torque-limit arrays),
and never pickles it. The robot model's arrays in it (``q``, ``nu``, ``J_tf``, ``Jdot_tf nu``,
the origin's Jacobian and :meth:`RobotModel.update_buffers`) are written in place by every
update of the same ``RobotModel`` (tested).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from controllers.low_level.kernel import LowLevelKernel, kernel_step, solution_terms_into
from controllers.low_level.task_stack import CompiledTaskStack, robot_scalars_into, stack_rows
from wip_gym.array_table import (
    ArrayTable,
    float_cube,
    float_matrix,
    float_vector,
    int_matrix,
    int_vector,
)
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]

ENTRIES = (
    # scalars: [model, data, probe data addresses, theta task, index_q1]; [probe's wheel
    # radius, wheel separation, kernel's wheel radius]
    "ints",
    "floats",
    # the motion probe's constants and state
    "layout",
    "body_qpos",
    "body_dof",
    "Jdot_tf_nu",
    "probe_qpos",
    "probe_qacc",
    "site_bodies",
    # the task stack's arrays, in the order of stack_rows' arguments
    "kinds",
    "sites",
    "observers",
    "row_start",
    "params",
    "targets",
    "row_column",
    "row_target",
    "q",
    "nu",
    "J_tf",
    "J_pattern",
    "scalars",
    "bodies",
    "site_ids",
    "xpos",
    "site_xpos",
    "site_xmat",
    "site_jac",
    "origin_jac",
    "probe_qvel",
    "probe_qacc0",
    "probe_xpos",
    "probe_site_xpos",
    "probe_jac",
    "probe_jac_dot",
    "probe_subtree_com",
    "probe_xipos",
    "probe_subtree_linvel",
    "probe_cfrc_int",
    "subtree_mass",
    "gravity",
    "observer_memory",
    "observer_settings",
    "observer_advance",
    # the stacked rows, then the kernel's arrays, in the order of kernel_step's arguments
    "J",
    "target",
    "jdot_nu",
    "w",
    "calA",
    "Ph",
    "E",
    "e",
    "actuator_map",
    "torque_low",
    "torque_high",
    "limits",
    "limit_indices",
    "constants",
    "T",
    "b",
    "H",
    "g",
    "C",
    "lower",
    "upper",
    "x",
    # what a feasible x implies (kernel.solution_terms_into), then the robot model's buffers
    "generalized",
    "actuators",
    "nu_dot",
    "J_theta",
    "A",
    "h",
    "robot_scalars",
)
"""The table's rows, by name (:func:`rows_and_kernel` reads them by these indices)."""

(
    _INTS,
    _FLOATS,
    _LAYOUT,
    _BODY_QPOS,
    _BODY_DOF,
    _JDOT_TF_NU,
    _PROBE_QPOS,
    _PROBE_QACC,
    _SITE_BODIES,
    _KINDS,
    _SITES,
    _OBSERVERS,
    _ROW_START,
    _PARAMS,
    _TARGETS,
    _ROW_COLUMN,
    _ROW_TARGET,
    _Q,
    _NU,
    _J_TF,
    _J_PATTERN,
    _SCALARS,
    _BODIES,
    _SITE_IDS,
    _XPOS,
    _SITE_XPOS,
    _SITE_XMAT,
    _SITE_JAC,
    _ORIGIN_JAC,
    _PROBE_QVEL,
    _PROBE_QACC0,
    _PROBE_XPOS,
    _PROBE_SITE_XPOS,
    _PROBE_JAC,
    _PROBE_JAC_DOT,
    _PROBE_SUBTREE_COM,
    _PROBE_XIPOS,
    _PROBE_SUBTREE_LINVEL,
    _PROBE_CFRC_INT,
    _SUBTREE_MASS,
    _GRAVITY,
    _OBSERVER_MEMORY,
    _OBSERVER_SETTINGS,
    _OBSERVER_ADVANCE,
    _J,
    _TARGET,
    _JDOT_NU,
    _W,
    _CAL_A,
    _PH,
    _E,
    _SMALL_E,
    _ACTUATOR_MAP,
    _TORQUE_LOW,
    _TORQUE_HIGH,
    _LIMITS,
    _LIMIT_INDICES,
    _CONSTANTS,
    _T,
    _B,
    _H,
    _G,
    _C,
    _LOWER,
    _UPPER,
    _X,
    _GENERALIZED,
    _ACTUATORS,
    _NU_DOT,
    _J_THETA,
    _A,
    _H_ROBOT,
    _ROBOT_SCALARS,
) = range(len(ENTRIES))


def step_table(
    stack: CompiledTaskStack,
    kernel: LowLevelKernel,
    robot: RobotModel,
    J: Array,
    target: Array,
    jdot_nu: Array,
    w: Array,
) -> ArrayTable:
    """The table of :func:`rows_and_kernel` for this stack, kernel, robot and row buffers
    (``J``, ``target``, ``jdot_nu``, ``w``: the ones the kernel was made for)."""
    if kernel.layout.rows != stack.rows or J.shape != (stack.rows, robot.layout.n_min):
        raise ValueError(
            f"the kernel and row buffers are for {kernel.layout.rows} rows of "
            f"{J.shape[1]} columns; the stack has {stack.rows} of {robot.layout.n_min}"
        )
    parts = (
        stack.table_entries(robot),
        kernel.table_entries(),
        robot.update_buffers(),
        {"J": J, "target": target, "jdot_nu": jdot_nu, "w": w},
    )
    entries: dict[str, np.ndarray] = {}
    for part in parts:
        twice = entries.keys() & part.keys()
        if twice:
            raise ValueError(f"step table: entries {sorted(twice)} given twice")
        entries.update(part)
    ints = np.array([*entries.pop("stack_ints"), kernel.layout.index_q1], dtype=np.int64)
    floats = np.array([*entries.pop("stack_floats"), kernel.layout.wheel_radius])
    entries["ints"], entries["floats"] = ints, floats
    missing = set(ENTRIES) ^ set(entries)
    if missing:
        raise ValueError(f"step table: entries {sorted(missing)} missing or unknown")
    return ArrayTable([entries[name] for name in ENTRIES], ENTRIES)


@njit(cache=True, nogil=True)
def rows_and_kernel(table: NDArray[np.int64]) -> bool:
    """The robot's scalars into the stack's (:func:`robot_scalars_into`), :func:`stack_rows`,
    :func:`kernel_step` (with eq. ``iso3`` from the robot's ``A``, ``h``) and, when the
    unconstrained minimiser ``x`` meets every constraint, :func:`solution_terms_into`, on the
    arrays of ``table`` (:func:`step_table`). Returns the kernel's answer: whether ``x`` meets
    every constraint."""
    ints, floats = int_vector(table[_INTS]), float_vector(table[_FLOATS])
    J = float_matrix(table[_J])
    target = float_vector(table[_TARGET])
    jdot_nu = float_vector(table[_JDOT_NU])
    q, nu = float_vector(table[_Q]), float_vector(table[_NU])
    scalars = float_vector(table[_SCALARS])
    robot_scalars_into(float_vector(table[_ROBOT_SCALARS]), nu, scalars)
    stack_rows(
        ints[0],
        ints[1],
        ints[2],
        int_vector(table[_LAYOUT]),
        int_vector(table[_BODY_QPOS]),
        int_vector(table[_BODY_DOF]),
        floats[0],
        floats[1],
        float_vector(table[_JDOT_TF_NU]),
        float_vector(table[_PROBE_QPOS]),
        float_vector(table[_PROBE_QACC]),
        int_vector(table[_SITE_BODIES]),
        ints[3] != 0,
        int_vector(table[_KINDS]),
        int_vector(table[_SITES]),
        int_vector(table[_OBSERVERS]),
        int_vector(table[_ROW_START]),
        float_matrix(table[_PARAMS]),
        float_matrix(table[_TARGETS]),
        int_vector(table[_ROW_COLUMN]),
        float_vector(table[_ROW_TARGET]),
        q,
        nu,
        float_matrix(table[_J_TF]),
        int_matrix(table[_J_PATTERN]),
        float_vector(table[_J_THETA]),
        scalars,
        int_vector(table[_BODIES]),
        int_vector(table[_SITE_IDS]),
        float_matrix(table[_XPOS]),
        float_matrix(table[_SITE_XPOS]),
        float_matrix(table[_SITE_XMAT]),
        float_cube(table[_SITE_JAC]),
        float_matrix(table[_ORIGIN_JAC]),
        float_vector(table[_PROBE_QVEL]),
        float_vector(table[_PROBE_QACC0]),
        float_matrix(table[_PROBE_XPOS]),
        float_matrix(table[_PROBE_SITE_XPOS]),
        float_cube(table[_PROBE_JAC]),
        float_cube(table[_PROBE_JAC_DOT]),
        float_matrix(table[_PROBE_SUBTREE_COM]),
        float_matrix(table[_PROBE_XIPOS]),
        float_matrix(table[_PROBE_SUBTREE_LINVEL]),
        float_matrix(table[_PROBE_CFRC_INT]),
        float_vector(table[_SUBTREE_MASS]),
        float_vector(table[_GRAVITY]),
        float_cube(table[_OBSERVER_MEMORY]),
        float_matrix(table[_OBSERVER_SETTINGS]),
        int_vector(table[_OBSERVER_ADVANCE]),
        J,
        target,
        jdot_nu,
    )
    calA, Ph = float_matrix(table[_CAL_A]), float_vector(table[_PH])
    E, e = float_matrix(table[_E]), float_vector(table[_SMALL_E])
    actuator_map, x = float_matrix(table[_ACTUATOR_MAP]), float_vector(table[_X])
    feasible = kernel_step(
        True,
        float_matrix(table[_A]),
        float_vector(table[_H_ROBOT]),
        ints[4],
        floats[2],
        J,
        target,
        jdot_nu,
        float_vector(table[_W]),
        q,
        nu,
        calA,
        Ph,
        E,
        e,
        actuator_map,
        float_vector(table[_TORQUE_LOW]),
        float_vector(table[_TORQUE_HIGH]),
        float_matrix(table[_LIMITS]),
        int_vector(table[_LIMIT_INDICES]),
        float_vector(table[_CONSTANTS]),
        float_matrix(table[_T]),
        float_vector(table[_B]),
        float_matrix(table[_H]),
        float_vector(table[_G]),
        float_matrix(table[_C]),
        float_vector(table[_LOWER]),
        float_vector(table[_UPPER]),
        x,
    )
    if feasible:
        solution_terms_into(
            calA,
            Ph,
            actuator_map,
            E,
            e,
            x,
            float_vector(table[_GENERALIZED]),
            float_vector(table[_ACTUATORS]),
            float_vector(table[_NU_DOT]),
        )
    return feasible
