"""The per-step snapshot and parameters of a task stack, for its compiled rows.

:class:`CompiledTaskStack` turns a list of task objects of ``controllers.low_level.tasks``
(``ThetaTask``, ``SpinTask``, ``FramePositionTask``, ``FrameOrientationTask``, ``PostureTask``,
the two frame tasks optionally wrapped by ``DisturbanceRejectingTask``) into the arrays of
:func:`controllers.low_level.compiled_tasks.task_rows`, once; then, every control step,

1. fills the snapshot with MuJoCo calls into preallocated buffers: each site's ``[jacp; jacr]``
   at the robot's state (``mj_jacSite``), and at the motion probe's idealised state the origin's
   and each site's Jacobian and its time derivative (``mj_jac``, ``mj_jacDot``), and the subtree
   rows of the CoM drift (``mj_subtreeVel``, ``mj_rnePostConstraint``; only with a theta task);
2. reads the tasks' parameters (gains, targets, weights) where they live: in this stack's
   arrays (``params``, ``targets``, ``row_target``, ``weights``), which the tasks were given
   when the stack was built (``controllers.low_level.tasks.StoredParameters``: an assignment
   to a task, or a change in place of its target, writes there, so a target changed between
   steps is seen without copying anything per step);
3. makes one call of the compiled function.

Steps 1 and 3 are one compiled call (:func:`stack_rows`); before it, Python only marks which
observers advance and copies the weights into the QP's row buffer (:meth:`prepare_parameters`).

The disturbance observers keep their state in one array of this stack
(``DisturbanceRejectingTask.adopt_memory``), advanced by the compiled call.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import NDArray

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.disturbance_tasks import ADVANCED_IN_MEMORY, DisturbanceRejectingTask
from controllers.low_level.motion_probe import MotionProbe, idealise
from controllers.low_level.tasks import (
    FrameOrientationTask,
    FramePositionTask,
    PostureTask,
    SpinTask,
    StoredParameters,
    ThetaTask,
)
from wip_gym import mujoco_c as mjc
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]


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
def snapshot(
    model: int,
    data: int,
    probe_data: int,
    probe_qacc: np.ndarray,
    probe_qacc0: np.ndarray,
    probe_xpos: np.ndarray,
    probe_site_xpos: np.ndarray,
    bodies: np.ndarray,
    site_ids: np.ndarray,
    site_bodies: np.ndarray,
    site_jac: np.ndarray,
    probe_jac: np.ndarray,
    probe_jac_dot: np.ndarray,
    theta: bool,
) -> None:
    """Step 1 of the module docstring, compiled (``wip_gym.mujoco_c``), once the motion probe
    is at its idealised state (``MotionProbe.idealise``): each site's ``[jacp; jacr]`` at the
    robot's state (``data``); at the probe's, the origin's and each site's Jacobian and its time
    derivative, and with a theta task ``mj_subtreeVel`` and ``mj_rnePostConstraint`` at
    ``qacc = qacc_0`` (the CoM drift)."""
    for i in range(len(site_ids)):
        mjc.mj_jacSite(
            model, data, site_jac[i, :3].ctypes.data, site_jac[i, 3:].ctypes.data, site_ids[i]
        )
    base = bodies[0]
    _point_jacobians(model, probe_data, probe_jac[0], probe_jac_dot[0], probe_xpos[base], base)
    for i in range(len(site_ids)):
        _point_jacobians(
            model,
            probe_data,
            probe_jac[1 + i],
            probe_jac_dot[1 + i],
            probe_site_xpos[site_ids[i]],
            site_bodies[i],
        )
    if theta:
        mjc.mj_subtreeVel(model, probe_data)
        probe_qacc[:] = probe_qacc0
        mjc.mj_rnePostConstraint(model, probe_data)


@njit(cache=True)
def robot_scalars_into(robot_scalars: np.ndarray, nu: np.ndarray, scalars: np.ndarray) -> None:
    """The robot's ``theta, thetad, cos psi, sin psi, psid`` into ``scalars[:5]`` (as
    :func:`controllers.low_level.compiled_tasks.task_rows` reads them) from the update's
    ``robot_scalars`` (``wip_gym.minimal_kernels.UPDATE_SCALARS``) and ``nu``; ``psid`` 0 when
    ``scalars[5]``, the index of ``psi``, is -1 (planar)."""
    index_psi = int(scalars[5])
    scalars[0], scalars[1] = robot_scalars[5], robot_scalars[6]
    scalars[2], scalars[3] = robot_scalars[2], robot_scalars[3]
    scalars[4] = 0.0 if index_psi < 0 else nu[index_psi]


@njit(cache=True, nogil=True)
def stack_rows(
    model: int,
    data: int,
    probe_data: int,
    layout: np.ndarray,
    body_qpos: np.ndarray,
    body_dof: np.ndarray,
    wheel_radius: float,
    wheel_separation: float,
    Jdot_tf_nu: np.ndarray,
    probe_qpos: np.ndarray,
    probe_qacc: np.ndarray,
    site_bodies: np.ndarray,
    theta: bool,
    kinds: np.ndarray,
    sites: np.ndarray,
    observers: np.ndarray,
    row_start: np.ndarray,
    params: np.ndarray,
    targets: np.ndarray,
    row_column: np.ndarray,
    row_target: np.ndarray,
    q: np.ndarray,
    nu: np.ndarray,
    J_tf: np.ndarray,
    J_pattern: np.ndarray,
    J_theta: np.ndarray,
    scalars: np.ndarray,
    bodies: np.ndarray,
    site_ids: np.ndarray,
    xpos: np.ndarray,
    site_xpos: np.ndarray,
    site_xmat: np.ndarray,
    site_jac: np.ndarray,
    origin_jac: np.ndarray,
    probe_qvel: np.ndarray,
    probe_qacc0: np.ndarray,
    probe_xpos: np.ndarray,
    probe_site_xpos: np.ndarray,
    probe_jac: np.ndarray,
    probe_jac_dot: np.ndarray,
    probe_subtree_com: np.ndarray,
    probe_xipos: np.ndarray,
    probe_subtree_linvel: np.ndarray,
    probe_cfrc_int: np.ndarray,
    subtree_mass: np.ndarray,
    gravity: np.ndarray,
    observer_memory: np.ndarray,
    observer_settings: np.ndarray,
    observer_advance: np.ndarray,
    J: np.ndarray,
    target: np.ndarray,
    jdot_nu: np.ndarray,
) -> None:
    """Steps 1 and 3 of the module docstring in one compiled call: the motion probe at its
    idealised state (:func:`controllers.low_level.motion_probe.idealise`, the axle at the
    robot's base position ``xpos[bodies[0]]``), :func:`snapshot`, then
    :func:`controllers.low_level.compiled_tasks.task_rows` (its arguments from ``kinds`` on;
    ``probe_qpos``, ``probe_qvel`` the probe's whole arrays: only the robot's entries are
    written). One call instead of three: each array argument costs the dispatcher about
    0.1 us, and these share most of theirs."""
    base = bodies[0]
    idealise(
        model,
        probe_data,
        q,
        nu,
        xpos[base, 0],
        xpos[base, 1],
        layout,
        body_qpos,
        body_dof,
        wheel_radius,
        wheel_separation,
        probe_qpos,
        probe_qvel,
        probe_qacc0,
        Jdot_tf_nu,
    )
    snapshot(
        model,
        data,
        probe_data,
        probe_qacc,
        probe_qacc0,
        probe_xpos,
        probe_site_xpos,
        bodies,
        site_ids,
        site_bodies,
        site_jac,
        probe_jac,
        probe_jac_dot,
        theta,
    )
    ct.task_rows(
        kinds,
        sites,
        observers,
        row_start,
        params,
        targets,
        row_column,
        row_target,
        q,
        nu,
        J_tf,
        J_pattern,
        J_theta,
        scalars,
        bodies,
        site_ids,
        xpos,
        site_xpos,
        site_xmat,
        site_jac,
        origin_jac,
        probe_qvel,
        probe_qacc0,
        probe_xpos,
        probe_site_xpos,
        probe_jac,
        probe_jac_dot,
        probe_subtree_com,
        probe_xipos,
        probe_subtree_linvel,
        probe_cfrc_int,
        subtree_mass,
        gravity,
        observer_memory,
        observer_settings,
        observer_advance,
        J,
        target,
        jdot_nu,
    )


_KINDS: dict[type, int] = {
    ThetaTask: ct.THETA,
    SpinTask: ct.SPIN,
    FramePositionTask: ct.POSITION,
    FrameOrientationTask: ct.ORIENTATION,
    PostureTask: ct.POSTURE,
}


_DESIRED: dict[int, tuple[str, str, str]] = {
    ct.THETA: ThetaTask.desired_names,
    ct.SPIN: SpinTask.desired_names,
}
"""A theta or spin task's desired value, rate and acceleration: columns 2 to 4 of its
``params`` row (``compiled_tasks.PARAMETERS``)."""


def _unwrap(task: object) -> tuple[object, DisturbanceRejectingTask | None]:
    if type(task) is DisturbanceRejectingTask:
        return task.task, task
    return task, None


def supports(tasks: Sequence[object], planar: bool) -> bool:
    """Whether every task is of a kind the compiled rows know (exact types: a subclass may
    change the arithmetic, and then runs the Python path) and appears once. An observer may
    wrap a frame task; a planar robot has no heading task."""
    inners = [id(_unwrap(task)[0]) for task in tasks]
    if len(set(inners)) != len(inners):
        return False  # a task twice: its parameters can live in one place of the arrays only
    for task in tasks:
        inner, observer = _unwrap(task)
        kind = _KINDS.get(type(inner))
        if kind is None or (observer is not None and kind not in (ct.POSITION, ct.ORIENTATION)):
            return False
        if planar and kind == ct.SPIN:
            return False
    return bool(tasks)


def structure(tasks: Sequence[object]) -> tuple[object, ...]:
    """What a compiled stack is built from and reads only then: the task objects, the tasks an
    observer wraps, each frame task's site, each posture task's columns. A stack serves a task
    list only while this is unchanged (a target or a gain may change every step)."""
    parts: list[object] = []
    for task in tasks:
        inner, _ = _unwrap(task)
        columns = getattr(inner, "columns", None)
        parts.append(
            (
                id(task),
                id(inner),
                getattr(inner, "site", None),
                None if columns is None else np.asarray(columns).tobytes(),
            )
        )
    return tuple(parts)


def _same_columns(task: object, columns: bytes) -> bool:
    """Whether a posture task's columns are the ``columns`` bytes :func:`structure` took."""
    return np.asarray(task.columns).tobytes() == columns  # type: ignore[attr-defined]


def check_indices(tasks: Sequence[object], n_sites: int, n_min: int) -> None:
    """``ValueError`` naming the task for a frame task's site that is not one of the model's
    ``n_sites`` or a posture task's column that is not an integer index into the ``n_min``
    minimal coordinates (NumPy's rule: ``-n_min`` to ``n_min - 1``). The compiled rows read
    them without bounds checks, where the Python path would raise ``IndexError`` (or MuJoCo
    read past its arrays); checked whenever a stack is built, which a change of either causes,
    and by ``TaskQP``'s Python path at every step. A posture task needs one joint weight per
    column, or one for all (broadcast, as both paths do)."""
    for task in (_unwrap(task)[0] for task in tasks):
        name = getattr(task, "name", type(task).__name__)
        if isinstance(task, FramePositionTask | FrameOrientationTask):
            site = task.site
            if isinstance(site, bool) or not isinstance(site, int | np.integer):
                raise ValueError(f"task {name!r}: site must be an integer id, got {site!r}")
            if not 0 <= site < n_sites:
                raise ValueError(f"task {name!r}: site {site} is not one of the model's {n_sites}")
        elif isinstance(task, PostureTask):
            columns = np.asarray(task.columns)
            if columns.ndim != 1 or (columns.size and not np.issubdtype(columns.dtype, np.integer)):
                raise ValueError(
                    f"task {name!r}: columns must be a 1-D array of integers, got {task.columns!r}"
                )
            outside = (columns < -n_min) | (columns >= n_min)
            if outside.any():
                raise ValueError(
                    f"task {name!r}: columns {columns[outside].tolist()} are not indices into "
                    f"the {n_min} minimal coordinates"
                )
            weights = np.atleast_1d(task.joint_weights)
            if weights.ndim != 1 or weights.size not in (1, columns.size):
                raise ValueError(
                    f"task {name!r}: {columns.size} columns and joint weights of shape "
                    f"{np.shape(task.joint_weights)} (one weight per column, or one for all)"
                )


class CompiledTaskStack:
    """One task list's arrays and snapshot buffers (module docstring)."""

    def __init__(self, robot: RobotModel, probe: MotionProbe, tasks: Sequence[object]) -> None:
        if not supports(tasks, robot.layout.planar):
            raise ValueError("CompiledTaskStack: a task of a kind the compiled rows do not know")
        if probe.model is not robot.model:
            raise ValueError("the motion probe must be on the robot's own model")
        m, lay = robot.model, robot.layout
        self.tasks = list(tasks)
        self._structure = structure(tasks)
        # what matches() compares every step: each task object, the task it wraps (itself
        # unwrapped), a frame task's site, a posture task's columns (as structure() has them)
        self._expected = [
            (task, _unwrap(task)[0], site, columns)
            for task, (_, _, site, columns) in zip(self.tasks, self._structure, strict=True)
        ]
        self._count = len(self.tasks)
        self._column_checks = [
            (task, columns) for _, task, _, columns in self._expected if columns is not None
        ]
        self._robot = robot
        self._probe = probe
        inner = [_unwrap(task) for task in tasks]
        self._inner = [task for task, _ in inner]
        check_indices(self._inner, m.nsite, lay.n_min)
        self.kinds = np.array([_KINDS[type(task)] for task in self._inner], dtype=np.int64)
        sites: list[int] = []
        slots = []
        for task in self._inner:
            if isinstance(task, FramePositionTask | FrameOrientationTask):
                if task.site not in sites:
                    sites.append(task.site)
                slots.append(sites.index(task.site))
            else:
                slots.append(-1)
        self.site_ids = np.array(sites, dtype=np.int64)
        self.sites = np.array(slots, dtype=np.int64)
        # a task's rows: a posture task's columns (its weights may be one for all), else its
        # weights
        counts = [
            len(np.atleast_1d(task.columns))
            if isinstance(task, PostureTask)
            else len(np.atleast_1d(task.weights()))  # type: ignore[attr-defined]
            for task in self.tasks
        ]
        self.row_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.rows = int(self.row_start[-1])
        observers = [observer for _, observer in inner if observer is not None]
        self.observer_memory = np.zeros((max(len(observers), 1), 4, 3))
        self.observer_settings = np.zeros((max(len(observers), 1), 3))
        self.observers = np.full(len(tasks), -1, dtype=np.int64)
        # 1: the observer advances at this state; 0: it already has (its command is memoised)
        self.observer_advance = np.ones(max(len(observers), 1), dtype=np.int64)
        slot = 0
        self._observer_rows: list[tuple[object, int, int]] = []
        # each observer and the view on this stack's memory it was given (its own while
        # observer.memory is that view: another stack may adopt it later)
        self._observer_memory_views: list[tuple[DisturbanceRejectingTask, Array]] = []
        for k, (_, observer) in enumerate(inner):
            if observer is not None:
                self._observer_rows.append(
                    (observer.cache_key, int(self.row_start[k]), int(self.row_start[k + 1]))
                )
                view = self.observer_memory[slot]
                observer.adopt_memory(view)
                self._observer_memory_views.append((observer, view))
                s = observer.settings
                self.observer_settings[slot] = (s.dt, s.alpha, s.bound)
                self.observers[k] = slot
                slot += 1
        self._observer_keys = [key for key, _, _ in self._observer_rows]
        self._observer_key_set = frozenset(self._observer_keys)
        # memoise_observers' entries: every observer marked as advanced at this state
        self._advanced_entries: dict[object, object] = dict.fromkeys(
            self._observer_keys, ADVANCED_IN_MEMORY
        )
        self._all_advance = True  # prepare_parameters: no observer had advanced at the state
        self.params = np.zeros((len(tasks), ct.PARAMETERS))
        self.targets = np.zeros((len(tasks), 9))
        self.row_column = np.zeros(self.rows, dtype=np.int64)
        self.row_target = np.zeros(self.rows)
        for k, task in enumerate(self._inner):
            if isinstance(task, PostureTask):
                start, stop = self.row_start[k], self.row_start[k + 1]
                self.row_column[start:stop] = task.columns
        # every task's gains, targets and weights live in the stack's arrays (the tasks'
        # StoredParameters): the compiled call reads them in place, nothing is copied per step
        self.weights = np.zeros(self.rows)
        self._owner = object()  # what the tasks hold of this stack (not the stack: no cycle)
        self._stored = [(task, self._parameter_slots(k)) for k, task in enumerate(self._inner)]
        for task, slots in self._stored:
            task.store_parameters(self._owner, slots)  # type: ignore[attr-defined]
        # StoredParameters.store_events when every task was last seen stored here, and when
        # matches() last held (unchanged() compares both): built from these tasks, the stack
        # matches them at this count
        self._store_events_seen = self._checked_events = StoredParameters.store_events
        n_sites, nv = len(sites), m.nv
        self.scalars = np.zeros(6)
        self.scalars[5] = -1 if lay.index_psi is None else lay.index_psi
        self.site_jac = np.zeros((n_sites, 6, nv))
        self.probe_jac = np.zeros((n_sites + 1, 6, nv))
        self.probe_jac_dot = np.zeros((n_sites + 1, 6, nv))
        self._theta = bool((self.kinds == ct.THETA).any())
        self.bodies = np.array([lay.base_body, *lay.wheel_bodies], dtype=np.int64)
        # views on MuJoCo's arrays, read by the compiled call as they are (no copies); an
        # attribute read makes a new view, so they are made once
        d, pd = robot.data, probe.data
        self._model_arrays = (m.body_subtreemass, m.opt.gravity)
        self._robot_arrays = (d.xpos, d.site_xpos, d.site_xmat)
        self._probe_arrays = (pd.qvel, probe.qacc0, pd.xpos, pd.site_xpos)
        self._probe_subtree = (pd.subtree_com, pd.xipos, pd.subtree_linvel, pd.cfrc_int)
        self._site_bodies = m.site_bodyid[self.site_ids].astype(np.int64)
        # stack_rows' leading arguments: the models' addresses and the probe's constants, then
        # (after Jdot_tf nu) the probe's qpos and qacc and the sites' bodies
        model_address, data_address = mjc.addresses(m, robot.data)
        self._probe_constants = (
            model_address,
            data_address,
            mjc.addresses(m, pd)[1],
            probe._layout_ints,
            probe._body_qpos,
            probe._body_dof,
            probe._wheel_radius,
            probe._wheel_separation,
        )
        self._probe_state = (pd.qpos, pd.qacc, self._site_bodies)

    def matches(self, tasks: Sequence[object]) -> bool:
        """Whether this stack serves ``tasks``: :func:`structure` unchanged in what the stack
        reads of it (the same task objects, the same tasks wrapped by observers, each frame
        task's site, each posture task's columns), compared against the objects the stack
        holds, without building the tuple (it runs every step)."""
        expected = self._expected
        events = StoredParameters.store_events
        if len(tasks) != len(expected):
            return False
        for task, (task0, inner, site, columns) in zip(tasks, expected, strict=True):
            if task is not task0 or (task is not inner and task.task is not inner):  # type: ignore[attr-defined]
                return False
            if site is not None and inner.site != site:  # type: ignore[attr-defined]
                return False
            if columns is not None and not _same_columns(inner, columns):
                return False
        self._checked_events = events
        return True

    def unchanged(self, tasks: Sequence[object]) -> bool:
        """:meth:`matches` for the cost of its cheapest part, when nothing it compares can
        have changed since it last held, and nothing :meth:`prepare_parameters` looks after
        either: ``tasks`` are this stack's task objects in order, no store event since both
        last looked (``StoredParameters.store_events``: a task stored elsewhere, an assignment
        to a task or an observer, its site or its wrapped task included) and each posture
        task's columns as they were (a change in place is no assignment). False says only
        "not known": :meth:`matches` and :meth:`prepare_parameters` decide then."""
        events = StoredParameters.store_events
        if events != self._checked_events or events != self._store_events_seen:
            return False
        if len(tasks) != self._count:
            return False
        if not all(map(operator.is_, tasks, self.tasks)):
            return False
        return all(_same_columns(task, columns) for task, columns in self._column_checks)

    def __getstate__(self) -> dict[str, object]:
        raise TypeError(
            "a compiled task stack holds views on MuJoCo's arrays: build a new one from the "
            "tasks instead of copying it (TaskQP does so by itself)"
        )

    def _parameter_slots(self, k: int) -> dict[str, tuple[Array, object]]:
        """Where task ``k``'s parameters live in the stack's arrays (``StoredParameters``):
        ``params[k]`` holds ``kp, kv`` and a theta or spin task's desired value, rate and
        acceleration; ``targets[k]`` a frame task's target (3, or 3 x 3 row-major), the
        posture rows of ``row_target`` a posture task's; ``weights`` every row's weight."""
        kind, start, stop = (
            int(self.kinds[k]),
            int(self.row_start[k]),
            int(self.row_start[k + 1]),
        )
        p = self.params[k]
        slots: dict[str, tuple[Array, object]] = {"kp": (p, 0), "kv": (p, 1)}
        if kind in _DESIRED:
            for column, name in enumerate(_DESIRED[kind], start=2):
                slots[name] = (p, column)
            slots["weight"] = (self.weights, start)
        elif kind == ct.POSTURE:
            slots["target"] = (self.row_target[start:stop], None)
            slots["joint_weights"] = (self.weights[start:stop], None)
        else:
            view = self.targets[k, :3] if kind == ct.POSITION else self.targets[k].reshape(3, 3)
            slots["target"] = (view, None)
            slots["weight"] = (self.weights, slice(start, stop))
        return slots

    def prepare_parameters(self, robot: RobotModel, w: Array) -> None:
        """Whether each observer advances at this state, and the weights into ``w``: what the
        one-call step (``controllers.low_level.compiled_step``) needs done in Python before
        its call. A task another stack has stored since (``StoredParameters``) is stored here
        again."""
        if robot is not self._robot:
            raise ValueError("a compiled task stack serves the robot model it was built for")
        cache = robot.cache
        self._all_advance = self._observer_key_set.isdisjoint(cache)
        if self._all_advance:
            self.observer_advance.fill(1)  # the common case: none has advanced at this state
        else:
            advance = self.observer_advance
            for slot, key in enumerate(self._observer_keys):
                advance[slot] = key not in cache
        if StoredParameters.store_events != self._store_events_seen:
            # a task was stored somewhere or left its stack since: look which
            owner = self._owner
            for task, slots in self._stored:
                if task._stored_by is not owner:  # type: ignore[attr-defined]
                    task.store_parameters(owner, slots)  # another stack took it: take it back
            self._store_events_seen = StoredParameters.store_events
        w[:] = self.weights

    def prepare(self, robot: RobotModel, w: Array) -> None:
        """What :meth:`fill` does before its compiled call: :meth:`prepare_parameters`, then
        the robot's scalars (:func:`robot_scalars_into`)."""
        self.prepare_parameters(robot, w)
        robot_scalars_into(robot.update_buffers()["robot_scalars"], robot.nu, self.scalars)

    def owns_its_observers(self) -> bool:
        """Whether every observer's memory is still this stack's (another stack built on the
        same tasks adopts them: their Python path then reads that stack's memory)."""
        return all(observer.memory is view for observer, view in self._observer_memory_views)

    def steady_parts(
        self,
    ) -> tuple[frozenset[object], NDArray[np.int64], Array, dict[object, object]]:
        """What a step that :meth:`unchanged` allows does in place of
        :meth:`prepare_parameters` and :meth:`memoise_observers` when no observer has advanced
        at the state yet: the observers' ``robot.cache`` keys (none of them in the cache),
        the advance flags (all set), the weights (copied into the QP's rows) and the entries
        that mark every observer advanced (``TaskQP``'s one-call step inlines them)."""
        return (
            self._observer_key_set,
            self.observer_advance,
            self.weights,
            self._advanced_entries,
        )

    def memoise_observers(self, robot: RobotModel, target: Array) -> None:
        """What :meth:`fill` does after its compiled call: an observer advances once per state,
        so each is marked as advanced at this state in ``robot.cache``
        (``disturbance_tasks.ADVANCED_IN_MEMORY``: its command is its memory's last command,
        which the compiled call wrote, equal to its rows of ``target``; its Python path copies
        it from there when asked at this state). An observer another stack has adopted since
        (its memory is no longer this stack's) gets a copy of its rows of ``target`` instead,
        and one whose Python path advanced it at this state keeps its own entry."""
        if not self._advanced_entries:
            return
        cache = robot.cache
        if self._all_advance and self.owns_its_observers():
            cache.update(self._advanced_entries)  # the common case: one dict update
            return
        commands = target.copy()
        for (key, start, stop), (observer, view) in zip(
            self._observer_rows, self._observer_memory_views, strict=True
        ):
            if key in cache:
                continue
            cache[key] = ADVANCED_IN_MEMORY if observer.memory is view else commands[start:stop]

    def table_entries(self, robot: RobotModel) -> dict[str, np.ndarray]:
        """The arrays of :func:`stack_rows` by name, for the one-call step of
        ``controllers.low_level.compiled_step`` (all but the robot's ``J_theta`` and origin
        Jacobian, which ``RobotModel.update_buffers`` gives, and the rows ``J``, ``target``,
        ``jdot_nu``); its scalars as
        ``stack_ints`` (the model's, data's and probe's addresses, the theta flag) and
        ``stack_floats`` (the probe's wheel radius and separation)."""
        if robot is not self._robot:
            raise ValueError("a compiled task stack serves the robot model it was built for")
        model, data, probe_data, layout, body_qpos, body_dof, radius, separation = (
            self._probe_constants
        )
        probe_qpos, probe_qacc, site_bodies = self._probe_state
        xpos, site_xpos, site_xmat = self._robot_arrays
        probe_qvel, probe_qacc0, probe_xpos, probe_site_xpos = self._probe_arrays
        subtree_com, xipos, subtree_linvel, cfrc_int = self._probe_subtree
        subtree_mass, gravity = self._model_arrays
        return {
            "stack_ints": np.array([model, data, probe_data, int(self._theta)], dtype=np.int64),
            "stack_floats": np.array([radius, separation], dtype=float),
            "layout": layout,
            "body_qpos": body_qpos,
            "body_dof": body_dof,
            "Jdot_tf_nu": robot.Jdot_tf_nu,
            "probe_qpos": probe_qpos,
            "probe_qacc": probe_qacc,
            "site_bodies": site_bodies,
            "kinds": self.kinds,
            "sites": self.sites,
            "observers": self.observers,
            "row_start": self.row_start,
            "params": self.params,
            "targets": self.targets,
            "row_column": self.row_column,
            "row_target": self.row_target,
            "q": robot.q,
            "nu": robot.nu,
            "J_tf": robot.J_tf,
            "J_pattern": robot.J_tf_pattern,
            "scalars": self.scalars,
            "bodies": self.bodies,
            "site_ids": self.site_ids,
            "xpos": xpos,
            "site_xpos": site_xpos,
            "site_xmat": site_xmat,
            "site_jac": self.site_jac,
            "probe_qvel": probe_qvel,
            "probe_qacc0": probe_qacc0,
            "probe_xpos": probe_xpos,
            "probe_site_xpos": probe_site_xpos,
            "probe_jac": self.probe_jac,
            "probe_jac_dot": self.probe_jac_dot,
            "probe_subtree_com": subtree_com,
            "probe_xipos": xipos,
            "probe_subtree_linvel": subtree_linvel,
            "probe_cfrc_int": cfrc_int,
            "subtree_mass": subtree_mass,
            "gravity": gravity,
            "observer_memory": self.observer_memory,
            "observer_settings": self.observer_settings,
            "observer_advance": self.observer_advance,
        }

    def fill(self, robot: RobotModel, J: Array, target: Array, jdot_nu: Array, w: Array) -> None:
        """The stacked rows ``J``, ``xdd*``, ``Jdot nu`` and weights ``w`` of this state (the
        same as the task objects' ``jacobian``, ``reference_acceleration``, ``jdot_nu`` and
        ``weights``, tested), advancing the observers once per state (a second call at the
        same state takes their memoised commands, as their Python path does)."""
        self.prepare(robot, w)
        stack_rows(
            *self._probe_constants,
            robot.Jdot_tf_nu,
            *self._probe_state,
            self._theta,
            self.kinds,
            self.sites,
            self.observers,
            self.row_start,
            self.params,
            self.targets,
            self.row_column,
            self.row_target,
            robot.q,
            robot.nu,
            robot.J_tf,
            robot.J_tf_pattern,
            robot.J_theta,
            self.scalars,
            self.bodies,
            self.site_ids,
            *self._robot_arrays,
            self.site_jac,
            robot.cache["origin_jacobian"],  # type: ignore[arg-type]
            *self._probe_arrays,
            self.probe_jac,
            self.probe_jac_dot,
            *self._probe_subtree,
            *self._model_arrays,
            self.observer_memory,
            self.observer_settings,
            self.observer_advance,
            J,
            target,
            jdot_nu,
        )
        self.memoise_observers(robot, target)
