"""Sub-envs' steps in one compiled call, for the native vector env (docs/vector.md §3).

A wip env's step (``WIPEnv._advance``) is Python around MuJoCo's step and the env's compiled
measures: the action's check and its ctrl cost, the torques written, ``frame_skip`` calls of
``mj_step``, the measures, the cup's loss, the reward's four terms (docs/learning.md §3) and the
two ends. :func:`advance` does exactly that, in the same order and arithmetic, for a list of
sub-envs in one compiled call that holds no GIL, so a :class:`Team` of threads steps the batch
beside the caller, and one thread pays the Python once per pass instead of once per sub-env.

What stays in Python, per sub-env and pass (:class:`CompiledSteps`): whether it may take this
way (no push or payload due, no perturbed torques, its data and ``frame_skip`` those bound
here; otherwise the vector env calls its ``_advance``), its episode's two numbers (the last
goal distance, whether the cup was lost) read before and written back after, the islands'
switch at a cup's loss (``WIPEnv._solve_by_islands``, which touches the model only), and a
rejected action, which its own ``_advance`` then raises as the single env does. The steps'
results are the single env's to the bit: ``tests/test_vector_env.py`` holds the vector env to
Gymnasium's ``SyncVectorEnv`` of single envs on every path.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import carray, njit
from numpy.typing import NDArray

from wip_gym import mujoco_c as mjc
from wip_gym.array_table import float64_pointer, float_vector, int32_pointer, int_vector
from wip_gym.envs import measures as ms
from wip_gym.envs.base import WIPEnv
from wip_gym.vector.atomics import atomic_add, atomic_load, atomic_store, atomic_swap

_CTRL, _NCON, _TIME = range(3)  # addresses: the data's ctrl, ncon and time
_FRAMES, _TRAY, _END_ON_LOSS = range(3)  # settings
# parameters: the reward's weights (progress, ctrl, fall, cup loss), the step's duration, the
# time limit (NaN: none) and MuJoCo's timestep
_W_PROGRESS, _W_CTRL, _W_FALL, _W_CUP, _DT, _LIMIT, _TIMESTEP = range(7)
_PREVIOUS, _LOST = range(2)  # an episode's numbers: the last goal distance, the cup lost (1.0)
#: a result's columns, as ``WIPEnv._advance`` returns them (the ends 1.0 or 0.0)
REWARD, PROGRESS, CTRL, FALL, CUP_LOSS, TERMINATED, TRUNCATED = range(7)
STEPPED, NEWLY_LOST, REJECTED = 0, 1, -1  # a note: stepped; the cup lost now; not stepped
TEAM_SPINS = 200_000
"""Turns a team thread spins waiting for the next pass before it sleeps (about a millisecond
on the development machine: a loop of RL steps keeps it awake, an idle env lets it sleep)."""
_OUT, _E, _MODEL, _DATA = ms.OUT, ms._E, ms._MODEL, ms._DATA


@njit(cache=True, nogil=True)
def advance_one(
    i: int,
    tables: NDArray[np.int64],
    addresses: NDArray[np.int64],
    actions: NDArray[np.float64],
    action_tables: NDArray[np.float64],
    settings: NDArray[np.int64],
    parameters: NDArray[np.float64],
    episodes: NDArray[np.float64],
    results: NDArray[np.float64],
    notes: NDArray[np.int64],
    qpos_out: NDArray[np.float64],
    qvel_out: NDArray[np.float64],
) -> int:
    """Step sub-env ``i`` as ``WIPEnv._advance`` does (see :func:`advance`); its note
    (:data:`STEPPED`, :data:`NEWLY_LOST` or :data:`REJECTED`)."""
    action = actions[i]
    row = results[i]
    effort = ms.action_effort(action, action_tables[i])
    if effort != effort:  # a torque beyond its band, or NaN
        notes[i] = REJECTED
        return REJECTED
    table = tables[i]
    layout = int_vector(table[_E.mujoco])
    model, data = np.uint64(layout[_MODEL]), np.uint64(layout[_DATA])
    where = addresses[i]
    nu = action.shape[0]
    ctrl = carray(float64_pointer(np.uint64(where[_CTRL])), (nu,))
    for j in range(nu):
        ctrl[j] = action[j]
    setting = settings[i]
    for _ in range(setting[_FRAMES]):
        mjc.mj_step(model, data)
    ncon = carray(int32_pointer(np.uint64(where[_NCON])), (1,))[0]
    ms.env_measures(table, ncon)
    qpos, qvel = float_vector(table[_E.qpos]), float_vector(table[_E.qvel])
    qpos_row, qvel_row = qpos_out[i], qvel_out[i]
    for j in range(qpos_row.shape[0]):  # the robot's, the observation's first entries
        qpos_row[j] = qpos[j]
    for j in range(qvel_row.shape[0]):
        qvel_row[j] = qvel[j]
    values = float_vector(table[_E.out])
    fallen = values[_OUT.fallen] != 0.0
    episode = episodes[i]
    newly_lost = False
    tray = setting[_TRAY] != 0
    if tray:
        kept = (
            values[_OUT.cup_on_plate] != 0.0
            and values[_OUT.cup_upright] != 0.0
            and values[_OUT.tray_on_hand] != 0.0
        )
        lost = episode[_LOST] != 0.0
        newly_lost = not kept and not lost
        if not kept:
            episode[_LOST] = 1.0
    distance = values[_OUT.goal_distance]
    p = parameters[i]
    progress = p[_W_PROGRESS] * (episode[_PREVIOUS] - distance)
    ctrl_cost = -p[_W_CTRL] * effort * p[_DT]
    fall = -p[_W_FALL] if fallen else 0.0
    cup_loss = -p[_W_CUP] if newly_lost else 0.0
    episode[_PREVIOUS] = distance
    terminated = fallen or (tray and setting[_END_ON_LOSS] != 0 and episode[_LOST] != 0.0)
    limit = p[_LIMIT]
    time = carray(float64_pointer(np.uint64(where[_TIME])), (1,))[0]
    truncated = not math.isnan(limit) and time >= limit - 0.5 * p[_TIMESTEP]
    row[REWARD] = progress + ctrl_cost + fall + cup_loss
    row[PROGRESS] = progress
    row[CTRL] = ctrl_cost
    row[FALL] = fall
    row[CUP_LOSS] = cup_loss
    row[TERMINATED] = 1.0 if terminated else 0.0
    row[TRUNCATED] = 1.0 if truncated else 0.0
    note = NEWLY_LOST if newly_lost else STEPPED
    notes[i] = note
    return note


# A pass's shared counters (``sync``, int64, read and written atomically): the claim word
# (the pass's generation, its number of sub-envs and the next one to claim, in one word so
# that a thread claims with one compare-and-swap and never from another pass), the sub-envs
# done and noted in the pass, and the order to stop.
_CLAIM, _DONE, _NOTED, _STOP = range(4)
_GENERATION_SHIFT, _COUNT_SHIFT, _INDEX_MASK = 32, 16, (1 << 16) - 1
MAX_SUB_ENVS = _INDEX_MASK
"""Sub-envs a pass can step (the claim word's 16 bits)."""


@njit(cache=True, nogil=True)
def _work(sync: NDArray[np.int64], generation: int, todo: NDArray[np.int64], arrays: Any) -> None:
    """Claim and step the pass ``generation``'s sub-envs (``todo[k]``, with ``arrays``: the
    arrays of :func:`advance_one` after ``i``) until none is left."""
    while True:
        word = atomic_load(sync, _CLAIM)
        if word >> _GENERATION_SHIFT != generation:
            return
        k = word & _INDEX_MASK
        if k >= (word >> _COUNT_SHIFT) & _INDEX_MASK:
            return
        if not atomic_swap(sync, _CLAIM, word, word + 1):
            continue  # another thread claimed it
        if advance_one(todo[k], *arrays) != STEPPED:
            atomic_add(sync, _NOTED, 1)
        atomic_add(sync, _DONE, 1)


@njit(cache=True, nogil=True)
def publish(sync: NDArray[np.int64], count: int) -> int:
    """Publish a pass of ``count`` sub-envs in ``sync`` (the team's threads start claiming
    them; :func:`advance` steps them on this thread too); returns its generation."""
    atomic_store(sync, _DONE, 0)
    atomic_store(sync, _NOTED, 0)
    generation = ((atomic_load(sync, _CLAIM) >> _GENERATION_SHIFT) + 1) & 0x7FFFFFFF
    atomic_store(sync, _CLAIM, (generation << _GENERATION_SHIFT) | (count << _COUNT_SHIFT))
    return generation


@njit(cache=True, nogil=True)
def advance(
    sync: NDArray[np.int64], generation: int, count: int, todo: NDArray[np.int64], arrays: Any
) -> int:
    """Step the sub-envs ``todo[:count]`` of the pass ``generation`` (:func:`publish`) as
    ``WIPEnv._advance`` does, on this thread and on the team's (:func:`serve`) that the pass
    finds awake: every thread claims sub-envs one at a time (each is stepped once, by
    whichever thread is free; a thread the system does not run leaves its share to the
    others), and this one returns when all are done.

    ``arrays``, :func:`advance_one`'s after ``i``: each sub-env ``i`` from its row of every
    array, ``tables[i]`` its measures' table
    (``wip_gym.envs.measures.env_table``: its model, data and measures), ``addresses[i]`` its
    data's ``ctrl``, ``ncon`` and ``time``, ``actions[i]`` its torques, ``action_tables[i]``
    their band and scale (``measures.action_effort``), ``settings[i]`` its ``frame_skip``,
    tray and end at the cup's loss, ``parameters[i]`` its reward's weights, step duration,
    time limit and timestep, ``episodes[i]`` its last goal distance and cup loss (updated);
    into ``results[i]`` (:data:`REWARD` ... :data:`TRUNCATED`), ``notes[i]``
    (:data:`STEPPED`, :data:`NEWLY_LOST`, or :data:`REJECTED`: its action rejected, the
    sub-env not stepped), and its robot's ``qpos`` and ``qvel`` after the step (the
    observation's) into ``qpos_out[i]`` and ``qvel_out[i]``. Returns how many were noted
    otherwise than :data:`STEPPED` (Python has work then)."""
    _work(sync, generation, todo, arrays)
    while atomic_load(sync, _DONE) < count:  # the others' last sub-envs
        pass
    return atomic_load(sync, _NOTED)


@njit(cache=True, nogil=True)
def serve(
    sync: NDArray[np.int64],
    asleep: NDArray[np.int64],
    me: int,
    spins: int,
    todo: NDArray[np.int64],
    arrays: Any,
) -> bool:
    """A team thread's loop: wait for each pass of :func:`advance` (spinning, without the
    GIL) and claim sub-envs in it; after ``spins`` turns with no new pass, note itself
    ``asleep[me]`` and return True (its Python sleeps until the next pass wakes it); False
    once ``sync`` says stop."""
    seen = -1
    while True:
        idle = 0
        while True:
            generation = atomic_load(sync, _CLAIM) >> _GENERATION_SHIFT
            if generation != seen:
                break
            if atomic_load(sync, _STOP) != 0:
                return False
            idle += 1
            if idle > spins:
                atomic_store(asleep, me, 1)
                return True
        seen = generation
        _work(sync, generation, todo, arrays)


def _serve_loop(
    sync: NDArray[np.int64],
    asleep: NDArray[np.int64],
    me: int,
    spins: int,
    wake: threading.Semaphore,
    arrays: tuple[NDArray[np.int64], tuple[NDArray[Any], ...]],
) -> None:
    """A team thread: :func:`serve` until told to stop, asleep on ``wake`` between."""
    todo, rest = arrays
    while serve(sync, asleep, me, spins, todo, rest):
        wake.acquire()
        if sync[_STOP]:
            return


class Team:
    """``helpers`` threads that step the passes of :func:`advance` with its caller, each
    running :func:`serve` on ``arrays`` (the pass's ``todo`` and :func:`advance_one`'s arrays,
    the same objects at every pass): they spin for ``spins`` turns after a pass (about a
    millisecond), then sleep until :meth:`wake` (called before each pass) wakes them."""

    def __init__(
        self,
        helpers: int,
        arrays: tuple[NDArray[np.int64], tuple[NDArray[Any], ...]],
        spins: int,
    ) -> None:
        self.sync = np.zeros(4, dtype=np.int64)
        self.asleep = np.zeros(helpers, dtype=np.int64)
        self._wakes = [threading.Semaphore(0) for _ in range(helpers)]
        self._threads = [
            threading.Thread(
                target=_serve_loop,
                args=(self.sync, self.asleep, me, spins, self._wakes[me], arrays),
                name=f"wip-vector-step-{me + 1}",
                daemon=True,
            )
            for me in range(helpers)
        ]
        for thread in self._threads:
            thread.start()

    def wake(self) -> None:
        """Wake the threads that fell asleep since the last pass."""
        asleep = self.asleep
        if asleep.any():
            for me in np.flatnonzero(asleep):
                asleep[me] = 0
                self._wakes[me].release()

    def close(self) -> None:
        """Stop the threads (idempotent)."""
        if self.sync[_STOP]:
            return
        self.sync[_STOP] = 1
        for wake in self._wakes:
            wake.release()
        for thread in self._threads:
            thread.join()


class CompiledSteps:
    """The arrays :func:`advance` reads for the sub-envs ``envs`` (bare wip envs on the fast
    path, each keeping its measures in its row: ``WIPEnv._measure_into``), kept bound to each
    sub-env's data and measures' table: :meth:`eligible` says whether sub-env ``i`` may take
    the compiled step now (binding it again when the env made new ones), :meth:`step` steps
    a list of them into :attr:`results` and :attr:`states` (the robot's ``qpos`` and
    ``qvel``, the observation's), on one thread or several (:meth:`use_threads`: a
    :class:`Team`).

    A sub-env's episode numbers (last goal distance, cup lost) and its ``_values`` and
    ``_block`` are the batch's after a compiled step: :meth:`fresh` gives them back to the
    env before its own code runs (its ``_advance``, or anyone reading it), :meth:`forget`
    takes the env's as they are after its own code changed them (a reset, its ``_advance``).
    """

    def __init__(
        self,
        envs: list[WIPEnv],
        results: NDArray[np.float64],
        states: tuple[NDArray[np.float64], NDArray[np.float64]],
    ) -> None:
        n = len(envs)
        self.envs = envs
        if n > MAX_SUB_ENVS:
            raise ValueError(f"at most {MAX_SUB_ENVS} sub-envs take compiled steps, got {n}")
        self._team: Team | None = None
        self._sync = np.zeros(4, dtype=np.int64)  # a pass's counters on one thread
        first = envs[0]
        rows = first._measure_table.rows.shape if first._measure_table is not None else (0, 0)
        nu = first.model.nu
        self.tables = np.zeros((n, *rows), dtype=np.int64)
        self.addresses = np.zeros((n, 3), dtype=np.int64)
        self.action_tables = np.zeros((n, 3, nu))
        self.settings = np.zeros((n, 3), dtype=np.int64)
        self.parameters = np.zeros((n, 7))
        self.episodes = np.zeros((n, 2))
        if results.shape != (n, 7) or results.dtype != np.float64:
            raise ValueError(f"results must be float64 of shape ({n}, 7), got {results.shape}")
        self.results = results
        self.states = states  # where the robot's qpos and qvel go, a row each
        self.notes = np.zeros(n, dtype=np.int64)
        # a pass's sub-envs and actions (the same arrays at every pass: the team reads them)
        self.todo = np.arange(n, dtype=np.int64)
        self._todo_everyone = True  # todo holds every sub-env in order
        self.actions = np.zeros((n, nu))
        self.stale = np.zeros(n, dtype=np.bool_)  # the batch's numbers newer than the env's
        self.taken = np.zeros(n, dtype=np.bool_)  # the batch holds the env's episode numbers
        self._all_taken = False  # every one is
        self._bound: list[tuple[object, object, int]] = [(None, None, -1)] * n
        self.steps = 0  #: sub-env steps taken here (for the tests and the benchmark)
        #: advance_one's arrays after ``i`` (the same objects at every pass: the team reads them)
        self._arrays = (
            self.tables,
            self.addresses,
            self.actions,
            self.action_tables,
            self.settings,
            self.parameters,
            self.episodes,
            self.results,
            self.notes,
            *self.states,
        )
        #: whether each sub-env can ever take it (:meth:`can_take`, and the first's sizes)
        self.capable = [
            self.can_take(env)
            and env._measure_table is not None  # (can_take says so; for the type checker)
            and env._measure_table.rows.shape == rows
            and env.model.nu == nu
            for env in envs
        ]

    @staticmethod
    def can_take(env: WIPEnv) -> bool:
        """Whether the wip env ``env`` can take the compiled step at all: it measures on the
        fast path (``wip_gym.mujoco_c``, where it finds ``mjData.ncon``) and its torques are
        applied as given (no delay or noise: ``Perturber.actuate`` is Python)."""
        return env._measure_table is not None and not env._perturb_action and mjc.sizes_found()

    def eligible(self, i: int) -> bool:
        """Whether sub-env ``i`` takes the compiled step now: it can, no event is due, its
        views are of its data and model and its ``frame_skip`` has been checked (otherwise
        its ``_advance`` does both); its arrays bound again if its data, table or
        ``frame_skip`` changed."""
        env = self.envs[i]
        if not self.capable[i] or env._events_due or env._frames_bound != env.frame_skip:
            return False
        views = env._views_of
        if views[1] is not env.data or views[0] is not env.model:  # _advance binds them
            return False
        if self._bound[i] != (env.data, env._measure_table, env._frames_bound):
            self._bind(i)
        return True

    def _bind(self, i: int) -> None:
        env = self.envs[i]
        table, data, model = env._measure_table, env.data, env.model
        assert table is not None
        self.tables[i] = table.rows
        ncon, time = mjc.size_addresses(data)
        self.addresses[i] = (data.ctrl.ctypes.data, ncon, time)
        self.action_tables[i] = env._action_table
        self.settings[i] = (env._frames_bound, env._tray, env._terminate_on_cup_loss)
        limit = math.nan if env._time_limit is None else env._time_limit
        self.parameters[i] = (*env._weights, env._step_dt, limit, model.opt.timestep)
        self._bound[i] = (data, table, env._frames_bound)

    def use_threads(self, threads: int, spins: int = TEAM_SPINS) -> None:
        """Step on ``threads`` threads: this one and a :class:`Team` of the others, which spin
        ``spins`` turns after each pass before they sleep."""
        if threads < 2:
            return
        self._team = Team(threads - 1, (self.todo, self._arrays), spins)

    def close(self) -> None:
        """Stop the team's threads (idempotent)."""
        if self._team is not None:
            self._team.close()

    def fresh(self, i: int) -> None:
        """Sub-env ``i``'s ``_values``, ``_block`` and episode numbers given back to it if a
        compiled step left them behind."""
        if self.stale[i]:
            env = self.envs[i]
            env._keep_measures()
            env._prev_distance = self.episodes.item(i, _PREVIOUS)
            env._cup_lost = self.episodes.item(i, _LOST) != 0.0
            self.stale[i] = False

    def forget(self, i: int) -> None:
        """Sub-env ``i``'s own code changed its episode numbers (reset, ``_advance``): taken
        from the env at its next compiled step."""
        self.stale[i] = False
        self.taken[i] = False
        self._all_taken = False

    def step(
        self,
        todo: list[int],
        actions: NDArray[np.float64],
        meanwhile: Callable[[], None] | None = None,
    ) -> list[int]:
        """Step the sub-envs ``todo`` (each :meth:`eligible`) with their rows of ``actions``
        (C-contiguous float64, a row per sub-env) into :attr:`results` and :attr:`notes`, the
        islands switched at a cup's loss; ``meanwhile()`` (Python work on other sub-envs:
        their resets) runs once the pass is published, while the team steps it. Returns those
        whose actions were rejected (not stepped: their own ``_advance`` raises why)."""
        everyone = len(todo) == len(self.envs)
        taken, episodes = self.taken, self.episodes
        if not self._all_taken:
            for i in todo:
                if not taken[i]:  # the env's own numbers, after its reset or _advance
                    env = self.envs[i]
                    episodes[i, _PREVIOUS] = env._prev_distance
                    episodes[i, _LOST] = 1.0 if env._cup_lost else 0.0
                    taken[i] = True
            self._all_taken = everyone or bool(taken.all())
        if not (everyone and self._todo_everyone):
            self.todo[: len(todo)] = todo
            self._todo_everyone = everyone
        np.copyto(self.actions, actions)
        team = self._team
        if team is not None:
            team.wake()
        sync = self._sync if team is None else team.sync
        generation = publish(sync, len(todo))
        if meanwhile is not None:
            meanwhile()
        noted = advance(sync, generation, len(todo), self.todo, self._arrays)
        if everyone:
            self.stale.fill(True)
        else:
            self.stale[todo] = True
        self.steps += len(todo)
        rejected = []
        if noted:
            notes = self.notes
            for i in todo:
                note = notes.item(i)
                if note == NEWLY_LOST:
                    self.envs[i]._solve_by_islands(True)
                elif note == REJECTED:
                    rejected.append(i)
            self.steps -= len(rejected)
        return rejected
