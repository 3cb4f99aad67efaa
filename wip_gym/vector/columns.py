"""The native vector env's step results from its sub-envs' measures, a few array operations
per step (docs/vector.md §3).

A wip env's step info, reset info and observation are read from its data (``qpos``,
``qvel``), its goal, its measures (``WIPEnv._block``, ``wip_gym.envs.measures.OUT``) and a
step's reward terms; ``WIPEnv.step_layout`` says where each entry is. On the vector env's fast
path every sub-env keeps its measures in a row of one ``(N, N_OUT)`` array
(``WIPEnv._measure_into``: the compiled measures write them there) and leaves its
``WIPEnv._advance`` result (reward, terms, ends) in a row of one array; after the pass
:meth:`ColumnBatcher.observe` makes the step's observation (the sub-envs' ``qpos`` and
``qvel`` in one copy each) and :meth:`ColumnBatcher.batch` its rewards, ends and info. The
info is what Gymnasium's ``VectorEnv._add_info`` makes of the sub-envs' info dicts (every key
an array over the sub-envs, float64 for the floats, bool for the flags, the arrays stacked,
and a mask ``"_" + key``; a sub-env reset in the step gives its reset info: no reward terms,
masked out, and ``fallen`` False), with no dict made per sub-env.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wip_gym.envs.base import REWARD_TERMS, StepLayout, WIPEnv


class ColumnBatcher:
    """Batches ``num_envs`` sub-envs' steps of the layout ``layout`` from their measures
    (``width`` entries each, in the rows of :attr:`measures`) and their state (the sizes
    ``state_sizes`` of ``WIPEnv._state_views``, in the rows of :attr:`states`)."""

    def __init__(
        self, layout: StepLayout, num_envs: int, width: int, state_sizes: tuple[int, ...]
    ) -> None:
        self.num_envs = num_envs
        #: the sub-envs' measures, a row each (``WIPEnv._measure_into``)
        self.measures = np.zeros((num_envs, width))
        #: the sub-envs' state (``qpos``, ``qvel``), a row each: written by the compiled
        #: steps, or from the sub-env's views by :meth:`observe`
        self.states = tuple(np.zeros((num_envs, size)) for size in state_sizes)
        #: the sub-envs' goals, a row each (written at their resets)
        self.goals = np.zeros((num_envs, 2))
        self.state = layout.state
        self.goal = layout.goal
        self._measured = tuple((key, a, a + n) for key, a, n in layout.measured)
        singles = [where[0] for _, where in layout.flags]
        # the entries taken at each step: the floats', then the flags'
        self._taken = np.array([index for _, index in layout.floats] + singles, dtype=np.intp)
        self._n_floats = len(layout.floats)
        # a flag of several entries (cup_on_tray: on the plate and upright): their rows' AND
        self._conjunctions = [
            (position, [singles.index(w) for w in where[1:]])
            for position, (_, where) in enumerate(layout.flags)
            if len(where) > 1
        ]
        flag_keys = [key for key, _ in layout.flags]
        self._fallen = flag_keys.index("fallen")
        self._arrays = tuple((start, start + length) for _, start, length in layout.arrays)
        # the values batch() makes, in its order: floats, flags, arrays, reward terms
        keys = (
            *(key for key, _ in layout.floats),
            *flag_keys,
            *(key for key, _, _ in layout.arrays),
        )
        self._keys = keys
        self._all_keys = (*keys, *REWARD_TERMS)
        self._masks = tuple("_" + key for key in self._all_keys)
        self._all_true = np.ones((len(self._all_keys), num_envs), dtype=np.bool_)

    def observe(
        self,
        envs: Sequence[WIPEnv],
        into: dict[str, NDArray[np.float64]] | None,
        unwritten: Sequence[int] | None = None,
    ) -> dict[str, NDArray[np.float64]]:
        """The step's observation (a row per sub-env), in fresh arrays or written ``into``
        these: the state of the sub-envs ``envs`` (their ``qpos``, ``qvel``: the rows of
        :attr:`states`, those of ``unwritten`` first copied from the sub-envs' views, every
        one if None), the goals and the measured entries."""
        states = self.states
        if unwritten is None:
            views = zip(*[env._state_views() for env in envs], strict=True)
            for rows, state in zip(states, views, strict=True):
                np.concatenate(state, out=rows.reshape(-1))
        else:
            for i in unwritten:
                for rows, view in zip(states, envs[i]._state_views(), strict=True):
                    rows[i] = view
        measures = self.measures
        if into is None:
            out = {key: rows.copy() for key, rows in zip(self.state, states, strict=True)}
            out[self.goal] = self.goals.copy()
            for key, a, b in self._measured:
                out[key] = measures[:, a:b].copy()
            return out
        for key, rows in zip(self.state, states, strict=True):
            np.copyto(into[key], rows)
        np.copyto(into[self.goal], self.goals)
        for key, a, b in self._measured:
            np.copyto(into[key], measures[:, a:b])
        return into

    def batch(
        self, results: NDArray[np.float64], stepped: list[bool]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """The rewards, terminations, truncations and info of a step from :attr:`measures`,
        ``results`` (each sub-env's ``WIPEnv._advance`` result, a row: reward, the four reward
        terms, terminated, truncated, as float64; zero terms where it was reset) and
        ``stepped`` (False: the sub-env was reset in this step, its info is the reset's). The
        info has Gymnasium's keys and arrays, in another order (the values, then the
        masks)."""
        numbers = results.T.copy()  # a row per entry
        ends = numbers[5:7] != 0.0
        measures = self.measures
        taken = measures.T.take(self._taken, axis=0)  # the floats' and flags' rows
        floats = self._n_floats
        flags = taken[floats:] != 0.0
        for position, others in self._conjunctions:
            row = flags[position]
            for other in others:
                row &= flags[other]
        everyone = all(stepped)
        if not everyone:
            flags[self._fallen] &= np.array(stepped, dtype=np.bool_)  # a reset's: False
        values: list[Any] = [*taken[:floats], *flags]
        for a, b in self._arrays:
            values.append(measures[:, a:b].copy())
        if everyone:
            values.extend(numbers[1:5])
            info = dict(zip(self._all_keys, values, strict=True))
            info.update(zip(self._masks, self._all_true.copy(), strict=True))
        elif any(stepped):
            values.extend(numbers[1:5])
            info = dict(zip(self._all_keys, values, strict=True))
            masks = self._all_true.copy()
            masks[len(self._keys) :] = np.array(stepped, dtype=np.bool_)
            info.update(zip(self._masks, masks, strict=True))
        else:  # every sub-env reset: no reward terms at all
            info = dict(zip(self._keys, values, strict=True))
            masks = self._all_true[: len(self._keys)].copy()
            info.update(zip(self._masks[: len(self._keys)], masks, strict=True))
        return numbers[0], ends[0], ends[1], info
