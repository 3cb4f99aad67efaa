"""A task list's arrays for the one-call step, and the per-step copy of its parameters.

:class:`CompiledTaskStack` turns a list of task objects (``controllers.low_level.tasks``; a
disturbance observer, ``DisturbanceRejectingTask``, may wrap one) and of constraints
(``controllers.low_level.constraints``), every one of a class with compiled rows
(``compiled_kind``), into the table of ``controllers.low_level.compiled_step.rows_and_kernel``
(``compiled_tasks.STEP``), once: one row of ``items`` per task and per constraint (its kind,
rows, parameters, columns, site slot, a second site's slot (``paired_site``), observer slot),
the sites' slots and their buffers, the observers' memory, the robot model's, the motion probe's
and the kernel's buffers. Then, every control step, :meth:`CompiledTaskStack.prepare` copies
each object's current parameters (``parameters()``: gains, targets, weights, bounds) into the
table's ``parameters`` and marks which observers advance; the compiled call reads nothing else
of the objects. What the stack reads once (the objects, the task an observer wraps, each task's
site and columns, its number of rows and parameters) is its structure:
:meth:`CompiledTaskStack.serves` compares it at every step, and a change makes the task QP build
a new stack.

The disturbance observers keep their state in one array of this stack
(``DisturbanceRejectingTask.adopt_memory``), advanced by the compiled call.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Sequence
from itertools import chain
from typing import Any

import numpy as np
from numpy.typing import NDArray

from controllers.low_level import compiled_tasks as ct
from controllers.low_level.compiled_step import rows_and_kernel
from controllers.low_level.compiled_tasks import ITEM, ITEM_FIELDS, STEP
from controllers.low_level.disturbance_tasks import ADVANCED_IN_MEMORY, DisturbanceRejectingTask
from controllers.low_level.kernel import LowLevelKernel
from controllers.low_level.motion_probe import MotionProbe
from wip_gym import mujoco_c as mjc
from wip_gym.array_table import ArrayTable
from wip_gym.robot_model import RobotModel

Array = NDArray[np.float64]
_task, _site = operator.attrgetter("task"), operator.attrgetter("site")
_paired_site = operator.attrgetter("paired_site")
_columns, _memory = operator.attrgetter("columns"), operator.attrgetter("memory")


def unwrap(task: object) -> tuple[Any, DisturbanceRejectingTask | None]:
    """``(the task, the observer wrapping it or None)``."""
    if type(task) is DisturbanceRejectingTask:
        return task.task, task
    return task, None


def compiled_kind(item: object) -> int | None:
    """The compiled kind of a task or constraint: the one its own class sets (a subclass may
    change the arithmetic: it runs the readable path), None without."""
    kind = type(item).__dict__.get("compiled_kind")
    return kind if isinstance(kind, int) else None


def supports(tasks: Sequence[object], constraints: Sequence[object], planar: bool) -> bool:
    """Whether every task (unwrapped) and constraint is of a compiled kind and appears once (its
    parameters have one place); a planar robot has no heading task."""
    inners = [unwrap(task)[0] for task in tasks]
    items = [*inners, *constraints]
    if not tasks or len({id(item) for item in items}) != len(items):
        return False
    kinds = [compiled_kind(item) for item in items]
    return None not in kinds and not (planar and ct.SPIN in kinds)


def structure(item: object) -> tuple[object, ...]:
    """What a stack reads of a task or constraint once: its sites, and its columns' bytes."""
    columns = getattr(item, "columns", None)
    return (
        getattr(item, "site", None),
        getattr(item, "paired_site", None),
        None if columns is None else np.asarray(columns).tobytes(),
    )


def check_indices(items: Sequence[object], n_sites: int, n_min: int) -> None:
    """``ValueError`` naming the task or constraint for a site that is not one of the model's
    ``n_sites`` or a column that is not an integer index into the ``n_min`` minimal coordinates
    (NumPy's rule: ``-n_min`` to ``n_min - 1``). The compiled rows read them without bounds
    checks, where the readable path would raise ``IndexError`` (or MuJoCo read past its
    arrays): checked whenever a stack is built (which a change of either causes) and by the
    readable path at every step."""
    for item in (unwrap(item)[0] for item in items):
        name = getattr(item, "name", type(item).__name__)
        for site in (getattr(item, "site", None), getattr(item, "paired_site", None)):
            if site is None:
                continue
            if isinstance(site, bool) or not isinstance(site, int | np.integer):
                raise ValueError(f"task {name!r}: site must be an integer id, got {site!r}")
            if not 0 <= site < n_sites:
                raise ValueError(f"task {name!r}: site {site} is not one of the model's {n_sites}")
        if getattr(item, "columns", None) is not None:
            columns = np.asarray(item.columns)
            if columns.ndim != 1 or (columns.size and not np.issubdtype(columns.dtype, np.integer)):
                raise ValueError(
                    f"task {name!r}: columns must be a 1-D array of integers, got {item.columns!r}"
                )
            outside = (columns < -n_min) | (columns >= n_min)
            if outside.any():
                raise ValueError(
                    f"task {name!r}: columns {columns[outside].tolist()} are not indices into "
                    f"the {n_min} minimal coordinates"
                )


def rows_of(item: Any) -> int:
    """How many rows a task or constraint has: one per column, else its ``rows_count``, else
    one per weight."""
    columns = getattr(item, "columns", None)
    if columns is not None:
        return len(columns)
    count = getattr(item, "rows_count", None)
    if count is not None:
        return int(count)
    return len(np.atleast_1d(item.weights()))


class CompiledTaskStack:
    """One task and constraint list's table and per-step copy (module docstring), for one robot,
    motion probe and kernel (whose row buffers receive the rows)."""

    def __init__(
        self,
        robot: RobotModel,
        probe: MotionProbe,
        kernel: LowLevelKernel,
        tasks: Sequence[object],
        constraints: Sequence[object] = (),
    ) -> None:
        m, lay = robot.model, robot.layout
        if not supports(tasks, constraints, lay.planar):
            raise ValueError("CompiledTaskStack: a task or constraint without compiled rows")
        if probe.model is not m:
            raise ValueError("the motion probe must be on the robot's own model")
        self.tasks, self.constraints = list(tasks), list(constraints)
        inner = [unwrap(task) for task in self.tasks]
        items: list[Any] = [task for task, _ in inner] + self.constraints
        check_indices(items, m.nsite, lay.n_min)
        rows = [rows_of(item) for item in items]
        n_tasks = len(self.tasks)
        if kernel.layout.rows != sum(rows[:n_tasks]) or kernel.layout.constraint_rows != sum(
            rows[n_tasks:]
        ):
            raise ValueError(
                f"the kernel is for {kernel.layout.rows} task and {kernel.layout.constraint_rows}"
                f" constraint rows; the stack has {sum(rows[:n_tasks])} and {sum(rows[n_tasks:])}"
            )
        self.robot, self.kernel = robot, kernel
        # the structure serves() compares: the objects in order, each wrapper's task, each
        # site and each column list as built
        self._objects = [*self.tasks, *self.constraints]
        self._wrappers = [task for task, (_, o) in zip(self.tasks, inner, strict=True) if o]
        self._wrapped = [inner_task for inner_task, o in inner if o]
        self._site_items = [item for item in items if getattr(item, "site", None) is not None]
        self._site_ids = list(map(_site, self._site_items))
        self._paired_items = [i for i in items if getattr(i, "paired_site", None) is not None]
        self._paired_ids = list(map(_paired_site, self._paired_items))
        self._column_items = [i for i in items if getattr(i, "columns", None) is not None]
        self._columns = self._column_bytes(self._column_items)
        # the per-step copy: each item's parameters() and how many it gives
        self._items: list[Any] = items
        self._getters = [item.parameters for item in items]
        self._counts = [len(get()) for get in self._getters]
        sites: list[int] = []
        table_items = np.full((len(items), ITEM_FIELDS), -1, dtype=np.int64)
        columns: list[int] = []
        task_row = constraint_row = parameter = 0
        for k, (item, count) in enumerate(zip(items, self._counts, strict=True)):
            row = table_items[k]
            row[ITEM.kind] = compiled_kind(item)
            row[ITEM.row] = task_row if k < n_tasks else constraint_row
            row[ITEM.rows] = rows[k]
            row[ITEM.parameter], row[ITEM.parameters] = parameter, count
            parameter += count
            if k < n_tasks:
                task_row += rows[k]
            else:
                constraint_row += rows[k]
            if getattr(item, "columns", None) is not None:
                row[ITEM.column] = len(columns)
                columns += np.asarray(item.columns).tolist()
            for field, site in (
                (ITEM.site, getattr(item, "site", None)),
                (ITEM.paired_site, getattr(item, "paired_site", None)),
            ):
                if site is not None:
                    if site not in sites:
                        sites.append(int(site))
                    row[field] = sites.index(site)
        self.items = table_items
        self.parameters = np.zeros(parameter)
        self._pack = struct.Struct(f"={parameter}d").pack_into
        self._parameter_bytes = memoryview(self.parameters).cast("B")
        self._bind_observers(inner, rows)
        n_sites, nv, n_min = len(sites), m.nv, lay.n_min
        site_ids = np.array(sites, dtype=np.int64)
        kinds = table_items[:, ITEM.kind]
        scalars = np.zeros(6)
        scalars[5] = -1 if lay.index_psi is None else lay.index_psi
        pd = probe.data
        d = robot.data
        layout_ints, body_qpos, body_dof = lay.kernel_arrays()
        buffers = kernel.buffers()
        update = robot.update_buffers()
        buffers.update(
            A=update["A"],
            h=update["h"],
            q=robot.q,
            nu=robot.nu,
            mujoco=np.array([*mjc.addresses(m, d), mjc.addresses(m, pd)[1]], dtype=np.int64),
            robot_scalars=update["robot_scalars"],
            J_theta=update["J_theta"],
            J_tf=robot.J_tf,
            J_pattern=robot.J_tf_pattern,
            Jdot_tf_nu=robot.Jdot_tf_nu,
            origin_jac=update["origin_jac"],
            xpos=d.xpos,
            site_xpos=d.site_xpos,
            site_xmat=d.site_xmat,
            subtree_mass=m.body_subtreemass,
            gravity=m.opt.gravity,
            probe_layout=layout_ints,
            body_qpos=body_qpos,
            body_dof=body_dof,
            probe_constants=np.array([lay.wheel_radius, lay.wheel_separation]),
            probe_qpos=pd.qpos,
            probe_qvel=pd.qvel,
            probe_qacc=pd.qacc,
            probe_qacc0=probe.qacc0,
            probe_xpos=pd.xpos,
            probe_site_xpos=pd.site_xpos,
            probe_subtree_com=pd.subtree_com,
            probe_xipos=pd.xipos,
            probe_subtree_linvel=pd.subtree_linvel,
            probe_cfrc_int=pd.cfrc_int,
            stack_ints=np.array([n_tasks, int((kinds == ct.THETA).any())], dtype=np.int64),
            items=table_items,
            parameters=self.parameters,
            columns=np.array(columns, dtype=np.int64),
            bodies=np.array([lay.base_body, *lay.wheel_bodies], dtype=np.int64),
            site_ids=site_ids,
            site_bodies=m.site_bodyid[site_ids].astype(np.int64),
            site_jac=np.zeros((n_sites, 6, nv)),
            probe_jac=np.zeros((n_sites + 1, 6, nv)),
            probe_jac_dot=np.zeros((n_sites + 1, 6, nv)),
            site_rel=np.zeros((n_sites, 3)),
            site_R=np.zeros((n_sites, 3, 3)),
            site_Jp=np.zeros((n_sites, 3, n_min)),
            site_Jr=np.zeros((n_sites, 3, n_min)),
            scalars=scalars,
            frame_jac=np.zeros((6, nv)),
            frame_JJ=np.zeros((6, n_min)),
            origin_motion=np.zeros((2, 6)),
            point_motion=np.zeros((2, 6)),
            work=np.zeros((3, 3)),
            drift=np.zeros((3, 3)),
            observer_memory=self.observer_memory,
            observer_settings=self.observer_settings,
            observer_advance=self.observer_advance,
            observer_work=np.zeros((2, self.observer_memory.shape[2])),
        )
        self.table: ArrayTable = STEP.table(buffers)

    def _bind_observers(
        self, inner: list[tuple[Any, DisturbanceRejectingTask | None]], rows: list[int]
    ) -> None:
        """One slot of the stack's memory per observer, which it adopts (its state is then
        advanced by the compiled call)."""
        observed = [(k, observer) for k, (_, observer) in enumerate(inner) if observer]
        width = max((rows[k] for k, _ in observed), default=1)
        slots = max(len(observed), 1)
        self.observer_memory = np.zeros((slots, 4, width))
        self.observer_settings = np.zeros((slots, 3))
        # 1: the observer advances at this state; 0: it already has (its command is memoised)
        self.observer_advance = np.ones(slots, dtype=np.int64)
        # each observer's robot.cache key and rows, and the view of this stack's memory it was
        # given (its own while observer.memory is that view: another stack may adopt it later)
        self._observers: list[tuple[object, int, int, DisturbanceRejectingTask, Array]] = []
        for slot, (k, observer) in enumerate(observed):
            view = self.observer_memory[slot, :, : rows[k]]
            observer.adopt_memory(view)
            s = observer.settings
            self.observer_settings[slot] = (s.dt, s.alpha, s.bound)
            self.items[k, ITEM.observer] = slot
            start = int(self.items[k, ITEM.row])
            self._observers.append((observer.cache_key, start, start + rows[k], observer, view))
        self._observer_keys = frozenset(key for key, *_ in self._observers)
        self._observed = [observer for *_, observer, _ in self._observers]
        self._views = [view for *_, view in self._observers]
        self._advanced = dict.fromkeys(self._observer_keys, ADVANCED_IN_MEMORY)
        self._all_advance = True
        self._flags_set = True  # observer_advance is all ones

    def serves(
        self,
        robot: RobotModel,
        kernel: LowLevelKernel,
        tasks: Sequence[object],
        constraints: Sequence[object],
    ) -> bool:
        """Whether this stack serves these lists on this robot and kernel: the same objects in
        order, each observer's task, each site and each column list as when it was built."""
        return (
            robot is self.robot
            and kernel is self.kernel
            and len(tasks) + len(constraints) == len(self._objects)
            and all(
                map(operator.is_, (*tasks, *constraints) if constraints else tasks, self._objects)
            )
            and all(map(operator.is_, map(_task, self._wrappers), self._wrapped))
            and list(map(_site, self._site_items)) == self._site_ids
            and list(map(_paired_site, self._paired_items)) == self._paired_ids
            and self._column_bytes(self._column_items) == self._columns
        )

    @staticmethod
    def _column_bytes(items: list[Any]) -> list[bytes]:
        """Each item's columns' bytes (as built: the stack reads them once)."""
        try:
            return list(map(np.ndarray.tobytes, map(_columns, items)))
        except TypeError:  # columns given as a list, not an array
            return [np.asarray(item.columns).tobytes() for item in items]

    def step(self, robot: RobotModel) -> bool:
        """One control step on this stack's table: :meth:`prepare`, the compiled call
        (``compiled_step.rows_and_kernel``), :meth:`memoise_observers`; whether the kernel's
        unconstrained minimiser is feasible."""
        self.prepare(robot)
        feasible: bool = rows_and_kernel(self.table.rows)
        if self._observers:
            self.memoise_observers(robot)
        return feasible

    def prepare(self, robot: RobotModel) -> None:
        """Before the compiled call: each object's current parameters into the table (the
        per-step copy: one ``parameters()`` call per object, one pack of all the numbers), and
        whether each observer advances at this state (not if it did already, on this stack's
        path or the readable one)."""
        given = [parameters() for parameters in self._getters]
        if list(map(len, given)) != self._counts:
            for values, count, item in zip(given, self._counts, self._items, strict=True):
                if len(values) != count:
                    raise ValueError(
                        f"task {getattr(item, 'name', type(item).__name__)!r}: {len(values)} "
                        f"parameters where its compiled rows were built for {count} (a target "
                        "or weights of another size: build the task anew)"
                    )
        try:
            self._pack(self._parameter_bytes, 0, *chain.from_iterable(given))
        except struct.error as error:
            raise ValueError(f"a task's parameters are not all numbers: {error}") from error
        if not self._observers:
            return
        cache = robot.cache
        self._all_advance = self._observer_keys.isdisjoint(cache)
        if self._all_advance:  # the common case: none has advanced at this state
            if not self._flags_set:
                self.observer_advance.fill(1)
                self._flags_set = True
        else:
            for slot, (key, *_) in enumerate(self._observers):
                self.observer_advance[slot] = key not in cache
            self._flags_set = False

    def owns_its_observers(self) -> bool:
        """Whether every observer's memory is still this stack's (another stack built on the
        same tasks adopts them: their readable path then reads that stack's memory)."""
        return all(map(operator.is_, map(_memory, self._observed), self._views))

    def memoise_observers(self, robot: RobotModel) -> None:
        """After the compiled call: an observer advances once per state, so each is marked as
        advanced at this state in ``robot.cache`` (``disturbance_tasks.ADVANCED_IN_MEMORY``:
        its command is its memory's last command, which the compiled call wrote, equal to its
        rows of the kernel's ``target``; its readable path copies it from there when asked at
        this state). An observer another stack has adopted since gets a copy of its rows of
        ``target`` instead, and one whose readable path advanced it at this state keeps its own
        entry."""
        cache = robot.cache
        if self._all_advance and self.owns_its_observers():
            cache.update(self._advanced)  # the common case: one dict update
            return
        commands = self.kernel.target.copy()
        for key, start, stop, observer, view in self._observers:
            if key in cache:
                continue
            cache[key] = ADVANCED_IN_MEMORY if observer.memory is view else commands[start:stop]

    def __getstate__(self) -> dict[str, object]:
        raise TypeError(
            "a compiled task stack holds views on MuJoCo's arrays: build a new one from the "
            "tasks instead of copying it (TaskQP does so by itself)"
        )
