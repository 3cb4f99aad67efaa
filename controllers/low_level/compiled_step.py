"""The low level's task rows and QP kernel as one compiled call per control step: the fast path.

With every task and constraint of a kind the compiled rows know (``controllers.low_level.
compiled_tasks``), eq. ``iso3`` computed from the robot and the fast path on
(``wip_gym.mujoco_c``), a control step's QP is one call of :func:`rows_and_kernel` on the
arrays of one table (``compiled_tasks.STEP``: MuJoCo's, the robot model's, the motion probe's,
the task stack's and the kernel's buffers, made once and written in place, their addresses taken
once; ``controllers.low_level.task_stack.CompiledTaskStack`` builds it). The call

1. idealises the motion probe at the robot's state (``motion_probe.idealise``) and takes the
   snapshot (:func:`snapshot`: each site's Jacobian at the robot's state, the origin's and each
   site's Jacobian and its time derivative at the probe's, the CoM drift's subtree rows);
2. computes each site's frame in the axle frame (``compiled_tasks.site_in_axle_frame_into``) and
   the origin's drift, then each item's rows by its kind's function (``compiled_tasks.
   kind_rows``), a disturbance observer's correction on the rows of a task it wraps;
3. runs the kernel (``controllers.low_level.kernel.kernel_step``) and, when the unconstrained
   minimiser is feasible, what it implies (the torques, ``kernel.solution_terms_into``).

The arithmetic is that of the task objects and the kernel, operation for operation:
``tests/test_compiled_tasks.py`` and ``tests/test_compiled_step.py`` hold it to the readable
path (the task objects' rows, then the kernel).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from controllers.low_level.compiled_tasks import (
    ITEM,
    S,
    _observe,
    _point_motion,
    kind_rows,
    site_in_axle_frame_into,
)
from controllers.low_level.kernel import kernel_step, solution_terms_into
from controllers.low_level.motion_probe import idealise
from wip_gym import mujoco_c as mjc
from wip_gym.array_table import float_cube, float_matrix, float_vector, int_matrix, int_vector


@njit(cache=True)
def _point_jacobians(
    model: int, data: int, jac: np.ndarray, jac_dot: np.ndarray, point: np.ndarray, body: int
) -> None:
    """``[jacp; jacr]`` of a point attached to ``body`` and its time derivative
    (``mj_jac``, ``mj_jacDot``) into the 6-row ``jac`` and ``jac_dot``."""
    mjc.mj_jac(model, data, jac[:3].ctypes.data, jac[3:].ctypes.data, point.ctypes.data, body)
    mjc.mj_jacDot(
        model, data, jac_dot[:3].ctypes.data, jac_dot[3:].ctypes.data, point.ctypes.data, body
    )


@njit(cache=True)
def snapshot(table: np.ndarray) -> None:
    """Step 1 of the module docstring once the motion probe is at its idealised state: each
    site's ``[jacp; jacr]`` at the robot's state; at the probe's, the origin's and each site's
    Jacobian and its time derivative, and with a theta task ``mj_subtreeVel`` and
    ``mj_rnePostConstraint`` at ``qacc = qacc_0`` (the CoM drift)."""
    addresses = int_vector(table[S.mujoco])
    model, data, probe_data = addresses[0], addresses[1], addresses[2]
    site_ids, site_bodies = int_vector(table[S.site_ids]), int_vector(table[S.site_bodies])
    site_jac = float_cube(table[S.site_jac])
    probe_jac, probe_jac_dot = float_cube(table[S.probe_jac]), float_cube(table[S.probe_jac_dot])
    for i in range(len(site_ids)):
        mjc.mj_jacSite(
            model, data, site_jac[i, :3].ctypes.data, site_jac[i, 3:].ctypes.data, site_ids[i]
        )
    base = int_vector(table[S.bodies])[0]
    probe_xpos = float_matrix(table[S.probe_xpos])
    _point_jacobians(model, probe_data, probe_jac[0], probe_jac_dot[0], probe_xpos[base], base)
    probe_site_xpos = float_matrix(table[S.probe_site_xpos])
    for i in range(len(site_ids)):
        _point_jacobians(
            model,
            probe_data,
            probe_jac[1 + i],
            probe_jac_dot[1 + i],
            probe_site_xpos[site_ids[i]],
            site_bodies[i],
        )
    if int_vector(table[S.stack_ints])[1]:
        mjc.mj_subtreeVel(model, probe_data)
        float_vector(table[S.probe_qacc])[:] = float_vector(table[S.probe_qacc0])
        mjc.mj_rnePostConstraint(model, probe_data)


@njit(cache=True)
def _robot_scalars(table: np.ndarray) -> None:
    """The robot's ``theta, thetad, cos psi, sin psi, psid`` into ``scalars[:5]`` from the
    update's scalars (``wip_gym.minimal_kernels.UPDATE_SCALARS``) and ``nu``; ``psid`` 0 when
    ``scalars[5]``, the index of ``psi``, is -1 (planar)."""
    scalars, robot = float_vector(table[S.scalars]), float_vector(table[S.robot_scalars])
    index_psi = int(scalars[5])
    scalars[0], scalars[1] = robot[5], robot[6]
    scalars[2], scalars[3] = robot[2], robot[3]
    scalars[4] = 0.0 if index_psi < 0 else float_vector(table[S.nu])[index_psi]


@njit(cache=True)
def _frames(table: np.ndarray) -> None:
    """Step 2's shared part: each site slot's position, rotation and Jacobians in the axle
    frame, and the origin's velocity and drift at the probe's state."""
    scalars = float_vector(table[S.scalars])
    c, s, index_psi = scalars[2], scalars[3], int(scalars[5])
    site_ids = int_vector(table[S.site_ids])
    xpos, site_xpos = float_matrix(table[S.xpos]), float_matrix(table[S.site_xpos])
    site_xmat, site_jac = float_matrix(table[S.site_xmat]), float_cube(table[S.site_jac])
    origin = xpos[int_vector(table[S.bodies])[0]]
    origin_jac, J_tf = float_matrix(table[S.origin_jac]), float_matrix(table[S.J_tf])
    J_pattern = int_matrix(table[S.J_pattern])
    jac, JJ = float_matrix(table[S.frame_jac]), float_matrix(table[S.frame_JJ])
    rel, R = float_matrix(table[S.site_rel]), float_cube(table[S.site_R])
    Jp, Jr = float_cube(table[S.site_Jp]), float_cube(table[S.site_Jr])
    for i in range(len(site_ids)):
        site = site_ids[i]
        site_in_axle_frame_into(
            site_xpos[site],
            site_xmat[site],
            site_jac[i],
            origin,
            origin_jac,
            J_tf,
            J_pattern,
            c,
            s,
            index_psi,
            jac,
            JJ,
            rel[i],
            R[i],
            Jp[i],
            Jr[i],
        )
    motion = float_matrix(table[S.origin_motion])
    _point_motion(
        float_cube(table[S.probe_jac])[0],
        float_cube(table[S.probe_jac_dot])[0],
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        motion[0],
        motion[1],
    )


@njit(cache=True)
def _observed(table: np.ndarray, slot: int, J: np.ndarray, target: np.ndarray) -> None:
    """A disturbance observer's command in place of the reference rows ``target`` of the task
    it wraps (``DisturbanceRejectingTask``): it advances when its flag is set (the first step
    at this state), else gives its last command (the one of this state)."""
    count = len(target)
    memory = float_cube(table[S.observer_memory])[slot][:, :count]
    work = float_matrix(table[S.observer_work])
    velocity, command = work[0, :count], work[1, :count]
    if int_vector(table[S.observer_advance])[slot]:
        nu = float_vector(table[S.nu])
        for row in range(count):
            total = 0.0
            for j in range(len(nu)):
                total += J[row, j] * nu[j]
            velocity[row] = total
        _observe(memory, float_matrix(table[S.observer_settings])[slot], velocity, target, command)
    else:
        command[:] = memory[2]
    target[:] = command


@njit(cache=True)
def stack_rows(table: np.ndarray) -> None:
    """Steps 1 and 2 of the module docstring: every item's rows of the QP into the kernel's
    ``J``, ``target``, ``jdot_nu``, ``w`` (tasks) and ``G``, ``constraint_lower``,
    ``constraint_bias``, ``constraint_upper`` (constraints)."""
    addresses = int_vector(table[S.mujoco])
    q, nu = float_vector(table[S.q]), float_vector(table[S.nu])
    xpos, bodies = float_matrix(table[S.xpos]), int_vector(table[S.bodies])
    constants = float_vector(table[S.probe_constants])
    base = bodies[0]
    idealise(
        addresses[0],
        addresses[2],
        q,
        nu,
        xpos[base, 0],
        xpos[base, 1],
        int_vector(table[S.probe_layout]),
        int_vector(table[S.body_qpos]),
        int_vector(table[S.body_dof]),
        constants[0],
        constants[1],
        float_vector(table[S.probe_qpos]),
        float_vector(table[S.probe_qvel]),
        float_vector(table[S.probe_qacc0]),
        float_vector(table[S.Jdot_tf_nu]),
    )
    snapshot(table)
    _robot_scalars(table)
    _frames(table)
    items, parameters = int_matrix(table[S.items]), float_vector(table[S.parameters])
    tasks = int_vector(table[S.stack_ints])[0]
    J, target = float_matrix(table[S.J]), float_vector(table[S.target])
    jdot_nu, w = float_vector(table[S.jdot_nu]), float_vector(table[S.w])
    G, lower = float_matrix(table[S.G]), float_vector(table[S.constraint_lower])
    bias, upper = float_vector(table[S.constraint_bias]), float_vector(table[S.constraint_upper])
    for k in range(len(items)):
        item = items[k]
        start, stop = item[ITEM.row], item[ITEM.row] + item[ITEM.rows]
        first = item[ITEM.parameter]
        p = parameters[first : first + item[ITEM.parameters]]
        if k < tasks:
            J[start:stop] = 0.0
            kind_rows(
                item[ITEM.kind], table, item, p, J[start:stop], target[start:stop],
                jdot_nu[start:stop], w[start:stop],
            )  # fmt: skip
            if item[ITEM.observer] >= 0:
                _observed(table, item[ITEM.observer], J[start:stop], target[start:stop])
        else:
            G[start:stop] = 0.0
            kind_rows(
                item[ITEM.kind], table, item, p, G[start:stop], lower[start:stop],
                bias[start:stop], upper[start:stop],
            )  # fmt: skip


@njit(cache=True, nogil=True)
def rows_and_kernel(table: np.ndarray) -> bool:
    """:func:`stack_rows`, then the kernel (with eq. ``iso3`` from the robot's ``A``, ``h``)
    and, when the unconstrained minimiser ``x`` meets every constraint, what it implies
    (``solution_terms_into``), on the arrays of ``table`` (``compiled_tasks.STEP``). Returns
    the kernel's answer: whether ``x`` meets every constraint."""
    stack_rows(table)
    feasible: bool = kernel_step(table, True)
    if feasible:
        solution_terms_into(
            float_matrix(table[S.calA]),
            float_vector(table[S.Ph]),
            float_matrix(table[S.actuator_map]),
            float_matrix(table[S.E]),
            float_vector(table[S.e]),
            float_vector(table[S.x]),
            float_vector(table[S.generalized]),
            float_vector(table[S.actuators]),
            float_vector(table[S.nu_dot]),
        )
    return feasible
