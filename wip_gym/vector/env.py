"""The native vector env: the single env N times, stepped in one call (docs/vector.md).

``gymnasium.make_vec(id, num_envs=N)`` makes a :class:`WIPVectorEnv` (each env's
``vector_entry_point``, ``wip_gym/registration.py``). Sub-env ``i`` is ``gymnasium.make(id,
**kwargs)`` itself (its own MjModel and MjData, since an episode may change its model: mass
randomisation, a payload; its own time limit), reset with seed ``S + i`` by ``reset(seed=S)``,
so that it equals the single env bit for bit, through autoresets. What it saves over
Gymnasium's ``SyncVectorEnv`` is everything around the sub-envs' physics that a batch does not
need (docs/vector.md §3): the sub-envs' steps are one compiled call per pass
(``wip_gym.vector.compiled``: the single env's ``WIPEnv._advance``, the step without its
observation and info dicts, in compiled code holding no GIL), their measures and state written
straight into their rows of the batch's arrays, and the step's observation and info are made
from those after the pass, a few array operations per step (``wip_gym.vector.columns``); a
sub-env with an event due or perturbed torques takes its own ``_advance``, and sub-envs whose
infos may change type their own ``step``, their dicts batched a few conversions per step
(``wip_gym.vector.infos``). With ``num_threads`` > 1, the threads claim sub-envs from a shared
counter inside the compiled call (``wip_gym.vector.threads``).
"""

from __future__ import annotations

import copy
import os
import weakref
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers import TimeLimit
from numpy.typing import NDArray

from wip_gym.envs import measures as ms
from wip_gym.envs.base import WIPEnv
from wip_gym.vector.columns import ColumnBatcher
from wip_gym.vector.compiled import CompiledSteps
from wip_gym.vector.infos import InfoBatcher
from wip_gym.vector.threads import ParallelLoop

_MODES = {mode.value: mode for mode in AutoresetMode}
#: the default number of threads: one, as Gymnasium's own vector envs; ``num_threads=2`` steps
#: the sub-envs' compiled steps on two cores (docs/vector.md §3), at the cost of a second core
#: that a sweep of many processes would rather have
DEFAULT_THREADS = 1


def available_cores() -> int:
    """The cores this process may run on (``taskset`` and cgroups' affinity respected)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _autoreset_mode(mode: AutoresetMode | str) -> AutoresetMode:
    if isinstance(mode, AutoresetMode):
        return mode
    if mode in _MODES:
        return _MODES[mode]
    raise ValueError(
        f"autoreset_mode must be an AutoresetMode or one of {sorted(_MODES)}, got {mode!r}"
    )


def make_sub_env(
    env_id: str, max_episode_steps: int | None = None, **env_kwargs: Any
) -> gym.Env[Any, Any]:
    """One sub-env: ``gymnasium.make(env_id, **env_kwargs)`` (its time limit included), without
    the order-enforcing and checker wrappers (the vector env keeps the order itself).

    ``max_episode_steps`` is passed on only when it differs from the registered one (what
    ``make_vec`` hands every vector entry point): otherwise the sub-env gets the time limit
    ``gymnasium.make`` gives the single env, however that is derived from the arguments."""
    spec = copy.deepcopy(gym.spec(env_id))
    spec.order_enforce = False
    spec.disable_env_checker = True
    if max_episode_steps is not None and max_episode_steps != spec.max_episode_steps:
        return gym.make(spec, max_episode_steps=max_episode_steps, **env_kwargs)
    return gym.make(spec, **env_kwargs)


def step_path(env: gym.Env[Any, Any]) -> tuple[gym.Env[Any, Any], int | None]:
    """What to step for the made env ``env`` and the time limit to count beside it: the base
    env and the ``TimeLimit``'s step count when ``env`` is exactly ``TimeLimit(base)`` (the
    vector env counts the steps as ``TimeLimit`` does: truncated at the step whose count
    reaches it), the base env and None when ``env`` is the base env, else ``env`` itself with
    whatever wrappers ``gymnasium.make`` gave it."""
    base = env.unwrapped
    if env is base:
        return base, None
    if type(env) is TimeLimit and env.env is base and env.spec is not None:
        return base, env.spec.max_episode_steps
    return env, None


_NO_TERMS = (0.0, 0.0, 0.0, 0.0)  # a reset sub-env's reward terms (masked out)
#: a next-step autoreset's result: reward 0, no terms, neither end
_RESET_RESULT = (0.0, *_NO_TERMS, False, False)


class _SubEnvs:
    """The sub-envs and what one pass over them reads and writes (kept apart from the vector
    env so that its threads hold no reference to it: an unclosed vector env is collected).

    Two ways to step: the fast one, when every sub-env is a wip env stepped bare (or under
    the ``TimeLimit`` counted here) with a :meth:`WIPEnv.step_layout` (its infos' types
    fixed): each sub-env's :meth:`WIPEnv._advance` (the step without its observation and
    info dicts; for the sub-envs that can, all of them in one compiled call,
    :class:`CompiledSteps`), its measures kept in its row of
    :attr:`ColumnBatcher.measures`, from which (and the rows of the sub-envs' ``qpos`` and
    ``qvel``) the step's info and observation are made after the pass
    (``wip_gym.vector.columns``); otherwise each sub-env's ``step`` and its dicts batched
    (:class:`InfoBatcher`). Resets take the second way (their infos through Gymnasium's
    rule). The fast way's pass is :meth:`pass_fast` (the compiled call spreads over its own
    threads); without compiled steps and with several threads, the loop's threads take the
    sub-envs one at a time (:meth:`step_one`)."""

    def __init__(
        self,
        envs: list[gym.Env[Any, Any]],
        observation_keys: tuple[str, ...],
        batcher: InfoBatcher,
    ) -> None:
        self.envs = envs
        paths = [step_path(env) for env in envs]
        self.stepped = [path for path, _ in paths]
        self.limits = [limit for _, limit in paths]
        self.keys = observation_keys
        self.batcher = batcher
        n = len(envs)
        self.elapsed = [0] * n  # steps since the reset, against the limits
        self.started = [False] * n  # reset at least once
        bases = [env.unwrapped for env in envs]
        layouts = [
            base.step_layout() if isinstance(base, WIPEnv) and self.stepped[i] is base else None
            for i, base in enumerate(bases)
        ]
        first = layouts[0]
        self.columns: ColumnBatcher | None = None
        self.bases: list[WIPEnv] = []
        if first is not None and all(layout == first for layout in layouts):
            self.bases = bases  # type: ignore[assignment]
            sizes = tuple(len(view) for view in self.bases[0]._state_views())
            self.columns = ColumnBatcher(first, n, ms.N_OUT, sizes)
            for i, base in enumerate(self.bases):
                base._measure_into(self.columns.measures[i])
        self.fast = self.columns is not None
        self.advances = [base._advance for base in self.bases]
        # each sub-env's _advance result: reward, the four reward terms, terminated,
        # truncated (a row each; zero terms where it was reset in the step)
        self.results = np.zeros((n, 7))
        # the compiled steps (wip_gym.vector.compiled), where a sub-env can take them; the
        # sub-envs they stepped have their _values and _block made only when read (fresh)
        self.compiled: CompiledSteps | None = None
        if self.columns is not None and any(CompiledSteps.can_take(b) for b in self.bases):
            qpos, qvel = self.columns.states
            self.compiled = CompiledSteps(self.bases, self.results, (qpos, qvel))
        self.everyone = list(range(n))
        self.has_limits = any(limit is not None for limit in self.limits)
        self.counted = False  # a pass with a time limit counted here or same-step autoresets
        # one pass's inputs
        self.stepping = True
        self.actions: Any = ()  # a row per sub-env
        self.action_array = np.zeros((0, 0))  # the same, one C-contiguous float64 array
        self.reset_first = [False] * n  # next-step autoreset
        self.same_step = False
        self.seeds: Sequence[int | None] = [None] * n
        self.options: dict[str, Any] | None = None
        self.reset_mask = np.ones(n, dtype=np.bool_)
        # its outputs
        self.observations: dict[str, NDArray[np.float64]] = {}
        self.rewards: list[Any] = [0.0] * n
        self.terminations: list[Any] = [False] * n
        self.truncations: list[Any] = [False] * n
        self.infos: list[dict[str, Any] | None] = [None] * n
        self.last: list[dict[str, Any] | None] = [None] * n  # each sub-env's last observation
        self.finals: list[tuple[int, Any, dict[str, Any]]] = []
        # the fast way's: whether each sub-env stepped (False: reset in the step)
        self.stepped_now = [True] * n
        # the sub-envs whose state rows the compiled steps did not write since their state
        # changed (resets, steps in Python); without compiled steps, every one at every step
        self.unwritten: list[int] = list(range(n))
        self.errors: list[tuple[int, ValueError, ValueError]] = []  # a pass's rejected actions

    def fresh(self, i: int) -> None:
        """Sub-env ``i`` given back what a compiled step left in the batch (its measures'
        values, its episode's numbers: ``CompiledSteps.fresh``), before its own code runs."""
        if self.compiled is not None:
            self.compiled.fresh(i)

    def fresh_all(self) -> None:
        """:meth:`fresh` for every sub-env (before the sub-envs are handed out)."""
        if self.compiled is not None and self.compiled.stale.any():
            for i in self.everyone:
                self.compiled.fresh(i)

    def write(self, i: int, observation: dict[str, Any], info: dict[str, Any] | None) -> None:
        self.last[i] = observation
        observations = self.observations
        for key in self.keys:
            observations[key][i] = observation[key]
        self.infos[i] = info
        self.batcher.write(i, info)

    def reset_one(self, i: int, seed: int | None, options: dict[str, Any] | None) -> Any:
        self.elapsed[i] = 0
        self.started[i] = True
        if self.compiled is not None:  # the reset makes the env's numbers anew
            self.compiled.forget(i)
            self.unwritten.append(i)
        observation, info = self.stepped[i].reset(seed=seed, options=options)
        if self.columns is not None:
            self.columns.goals[i] = self.bases[i].goal
        return observation, info

    def last_observation(self, i: int) -> dict[str, Any]:
        """Sub-env ``i``'s last observation (it was not reset now)."""
        if not self.started[i]:
            raise RuntimeError(f"sub-env {i} was never reset: reset it first")
        if self.fast:  # its steps kept no dict: the observation is read again, as it was made
            self.fresh(i)
            return self.bases[i]._get_obs()
        last = self.last[i]
        assert last is not None
        return last

    def __call__(self, i: int) -> None:
        """Sub-env ``i``'s part of the pass (a step or a reset)."""
        if not self.stepping:
            if self.reset_mask[i]:
                observation, info = self.reset_one(i, self.seeds[i], self.options)
                self.write(i, observation, info)
            else:  # not reset: its observation stands
                self.write(i, self.last_observation(i), None)
            return
        if self.reset_first[i]:
            observation, info = self.reset_one(i, None, None)
            self.rewards[i], self.terminations[i], self.truncations[i] = 0.0, False, False
            self.write(i, observation, info)
            return
        try:
            observation, reward, terminated, truncated, info = self.stepped[i].step(self.actions[i])
        except ValueError as error:
            raise ValueError(f"sub-env {i}: {error}") from error
        limit = self.limits[i]
        if limit is not None:
            self.elapsed[i] = elapsed = self.elapsed[i] + 1
            if elapsed >= limit:
                truncated = True
        if self.same_step and (terminated or truncated):
            self.finals.append((i, observation, info))
            observation, info = self.reset_one(i, None, None)
        self.rewards[i] = reward
        self.terminations[i] = terminated
        self.truncations[i] = truncated
        # write(), inline: the common case of every step
        self.last[i] = observation
        observations = self.observations
        for key in self.keys:
            observations[key][i] = observation[key]
        self.infos[i] = info
        self.batcher.write(i, info)

    def reset_all(self, resets: list[int]) -> None:
        """The sub-envs ``resets`` (ended at the last step, ``NextStep``) reset in the pass
        (while the compiled steps' team steps the others)."""
        for i in resets:
            self.results[i] = _RESET_RESULT
            self.reset_fast(i)

    def pass_fast(self) -> None:
        """Every sub-env's step the fast way in this thread (:meth:`step_part` of all)."""
        self.step_part(self.everyone)
        self.raise_errors()

    def step_one(self, i: int) -> None:
        """Sub-env ``i``'s step the fast way (:meth:`step_part`): a thread's part of a pass
        of the loop's threads, which hand the sub-envs out one at a time."""
        self.step_part([i])

    def raise_errors(self) -> None:
        """After a pass: the lowest sub-env's rejected action raised, if any (every sub-env
        was stepped all the same)."""
        if self.errors:
            errors, self.errors = sorted(self.errors, key=lambda e: e[0]), []
            _, error, cause = errors[0]
            raise error from cause

    def step_part(self, part: list[int]) -> None:
        """Step the sub-envs ``part`` the fast way: a sub-env that ended is reset
        (``NextStep``), the others advance: in one compiled call those that can
        (``wip_gym.vector.compiled``), the rest by their ``_advance``; each one's result
        (reward, reward terms, terminated, truncated) kept as it is (its measures are in its
        row; its state is read after the pass). A rejected action is kept in
        :attr:`errors`, its sub-env not stepped, the others stepped."""
        reset_first, results, stepped_now = self.reset_first, self.results, self.stepped_now
        todo = part
        resets: list[int] = []
        if any(reset_first):
            todo = []
            for i in part:
                if reset_first[i]:
                    resets.append(i)
                else:
                    stepped_now[i] = True
                    todo.append(i)
        else:
            for i in part:
                stepped_now[i] = True
        by_python = todo
        compiled = self.compiled
        ready: list[int] = []
        if compiled is not None:
            ready = [i for i in todo if compiled.eligible(i)]
        if compiled is not None and ready:
            # the resets in Python while the compiled pass runs on the team
            rejected = compiled.step(
                ready, self.action_array, (lambda: self.reset_all(resets)) if resets else None
            )
            if len(ready) < len(todo) or rejected:
                taken = set(ready).difference(rejected)
                by_python = [i for i in todo if i not in taken]
            else:
                by_python = []
        elif resets:
            self.reset_all(resets)
        for i in by_python:
            self.fresh(i)
            try:
                results[i] = self.advances[i](self.action_array[i])
            except ValueError as error:
                self.errors.append((i, ValueError(f"sub-env {i}: {error}"), error))
            if compiled is not None:
                compiled.forget(i)
                self.unwritten.append(i)
        if self.counted:
            for i in todo:
                self.finish(i)

    def finish(self, i: int) -> None:
        """After sub-env ``i``'s ``_advance``: the time limit counted here, the same-step
        autoreset."""
        result = self.results[i]  # a view: written in place
        limit = self.limits[i]
        if limit is not None:
            self.elapsed[i] = elapsed = self.elapsed[i] + 1
            if elapsed >= limit:
                result[6] = 1.0
        if self.same_step and (result[5] or result[6]):
            self.fresh(i)
            base = self.bases[i]
            self.finals.append((i, base._get_obs(), base._step_info(*result[1:5].tolist())))
            result[1:5] = 0.0  # the terms masked
            self.reset_fast(i)

    def reset_fast(self, i: int) -> None:
        """Sub-env ``i`` reset within a step (an autoreset), the fast way."""
        self.reset_one(i, None, None)
        self.stepped_now[i] = False


def _close_threads(loop: ParallelLoop, compiled: CompiledSteps | None) -> None:
    """Stop a vector env's threads (its finalizer: holds no reference to the env)."""
    loop.close()
    if compiled is not None:
        compiled.close()


class WIPVectorEnv(VectorEnv[dict[str, NDArray[np.float64]], NDArray[Any], NDArray[Any]]):
    """``num_envs`` copies of the env ``env_id`` stepped in one call (docs/vector.md).

    Args:
        env_id: a registered wip-gym env.
        num_envs: sub-envs.
        max_episode_steps: as ``gymnasium.make``'s (``make_vec`` passes the registered value;
            see :func:`make_sub_env`).
        autoreset_mode: ``NextStep`` (the default, as Gymnasium's), ``SameStep`` or
            ``Disabled`` (an ``AutoresetMode`` or its value), with Gymnasium's semantics.
        num_threads: threads that step the sub-envs (the caller's included; at most
            ``num_envs``); default :data:`DEFAULT_THREADS`.
        copy: return fresh observation arrays at every call (True, as Gymnasium's vector
            envs) or the same buffers, overwritten by the next call.
        **env_kwargs: the single env's arguments (``gymnasium.make(env_id, **env_kwargs)``);
            ``render_mode`` ``rgb_array`` or ``depth_array`` (``render()`` gives one frame per
            sub-env), not ``human``.
    """

    def __init__(
        self,
        env_id: str,
        num_envs: int = 1,
        *,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int | None = None,
        copy: bool = True,
        **env_kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if env_kwargs.get("render_mode") == "human":
            raise ValueError(
                "a vector env draws no window: make it with render_mode='rgb_array' and call "
                "render() (a frame per sub-env), or watch one env with `wip-bench view` "
                "(docs/videos.md §6)"
            )
        threads = DEFAULT_THREADS if num_threads is None else num_threads
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"num_threads must be a positive integer, got {num_threads!r}")
        mode = _autoreset_mode(autoreset_mode)
        self.env_id = env_id
        self.num_envs = num_envs
        self.copy = copy
        envs = [make_sub_env(env_id, max_episode_steps, **env_kwargs) for _ in range(num_envs)]
        first = envs[0]
        observation_space = first.observation_space
        if not isinstance(observation_space, spaces.Dict) or not all(
            isinstance(s, spaces.Box) for s in observation_space.spaces.values()
        ):
            raise TypeError(f"{env_id}: expected a Dict of Box observations")
        self.single_observation_space = observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(observation_space, num_envs)
        self.action_space = batch_space(first.action_space, num_envs)
        self.render_mode = first.render_mode
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": [m for m in first.metadata.get("render_modes", []) if m != "human"],
            "render_fps": first.metadata.get("render_fps"),
        }
        self.spec = None  # make_vec sets it
        self._autoreset_mode = mode
        self._batcher = InfoBatcher(num_envs, self._add_info)
        self._sub = _SubEnvs(envs, tuple(observation_space.spaces), self._batcher)
        self._shapes: dict[str, tuple[int, ...]] = {
            key: tuple(space.shape or ()) for key, space in observation_space.spaces.items()
        }
        self._buffers = self._new_observations()
        self._ended = np.zeros(num_envs, dtype=np.bool_)  # ended at the last step
        self._no_resets = [False] * num_envs  # reset_first of the modes other than NextStep
        self._has_reset = False
        self._threads = min(threads, num_envs)
        compiled = self._sub.compiled
        # with compiled steps, a team of threads steps with the caller (CompiledSteps) while
        # the caller resets the sub-envs that ended; the other passes (resets) run here
        self._loop = ParallelLoop(self._sub, num_envs, 1 if compiled else self._threads)
        if compiled is not None:
            compiled.use_threads(self._threads)
        self._finalizer = weakref.finalize(self, _close_threads, self._loop, compiled)

    # ------------------------------------------------------------------ properties
    @property
    def envs(self) -> tuple[gym.Env[Any, Any], ...]:
        """The sub-envs (for reading; stepping one by hand breaks the batch's bookkeeping)."""
        self._sub.fresh_all()
        return tuple(self._sub.envs)

    @property
    def num_threads(self) -> int:
        """Threads that step the sub-envs (the caller's included)."""
        return self._threads

    def _new_observations(self) -> dict[str, NDArray[np.float64]]:
        n = self.num_envs
        return {key: np.empty((n, *shape)) for key, shape in self._shapes.items()}

    def _observations_out(self) -> dict[str, NDArray[np.float64]]:
        """Where this call's observations go: fresh arrays (``copy``), or the buffers."""
        return self._new_observations() if self.copy else self._buffers

    # ------------------------------------------------------------------ reset, step
    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[dict[str, NDArray[np.float64]], dict[str, Any]]:
        """Reset the sub-envs: ``seed`` an int (sub-env ``i`` gets ``seed + i``), a list (one
        per sub-env) or None; ``options`` passed to each, with ``reset_mask`` (a bool array
        over the sub-envs) resetting only those (as Gymnasium's vector envs)."""
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, int | np.integer):
            if isinstance(seed, bool):
                raise ValueError(f"seed must be an int, a list of them or None, got {seed!r}")
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed: {len(seeds)} seeds for {n} sub-envs")
        options = dict(options) if options is not None else None
        mask = np.ones(n, dtype=np.bool_)
        if options is not None and "reset_mask" in options:
            mask = options.pop("reset_mask")
            if not isinstance(mask, np.ndarray) or mask.shape != (n,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({n},)")
            if not mask.any():
                raise ValueError("options['reset_mask'] resets no sub-env")
        sub = self._sub
        sub.stepping = False
        sub.seeds, sub.options, sub.reset_mask = seeds, options, mask
        sub.observations = observations = self._observations_out()
        self._loop.run()
        self._ended[mask] = False
        self._has_reset = True
        return observations, self._batcher.batch(sub.infos)

    def step(
        self, actions: NDArray[Any]
    ) -> tuple[
        dict[str, NDArray[np.float64]],
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every sub-env with its row of ``actions`` (``(num_envs, nu)`` torques); a
        sub-env that ended at the last step is reset instead (``NextStep``: reward 0, its
        action ignored), or at the step it ends (``SameStep``: ``final_obs``, ``final_info``).
        """
        if not self._has_reset:
            raise ResetNeeded("call reset() before step()")
        actions = np.asarray(actions)
        if actions.shape != self.action_space.shape:
            raise ValueError(
                f"actions must have shape {self.action_space.shape} (num_envs x actuators), "
                f"got {actions.shape}"
            )
        mode = self._autoreset_mode
        if mode is AutoresetMode.DISABLED and self._ended.any():
            raise RuntimeError(
                f"sub-envs {np.flatnonzero(self._ended).tolist()} ended and autoreset is "
                "disabled: reset them with reset(options={'reset_mask': ...})"
            )
        sub = self._sub
        sub.stepping = True
        sub.reset_first = (
            self._ended.tolist() if mode is AutoresetMode.NEXT_STEP else self._no_resets
        )
        sub.same_step = mode is AutoresetMode.SAME_STEP
        sub.finals = []
        columns = sub.columns
        if columns is None:
            sub.observations = observations = self._observations_out()
            sub.actions = actions
            self._loop.run()
            rewards = np.array(sub.rewards, dtype=np.float64)
            terminations = np.array(sub.terminations, dtype=np.bool_)
            truncations = np.array(sub.truncations, dtype=np.bool_)
            finals = sorted(sub.finals, key=lambda f: f[0]) if sub.finals else ()
            infos = self._batcher.batch(sub.infos, finals)
        else:  # the fast way: rows of float64, as each sub-env's step converts its own
            sub.action_array = np.ascontiguousarray(actions, dtype=np.float64)
            sub.counted = sub.has_limits or sub.same_step
            if self._loop.threads == 1:  # so with compiled steps, which have their team
                sub.pass_fast()
            else:
                self._loop.run(sub.step_one)
                sub.raise_errors()
            observations = columns.observe(
                sub.bases,
                None if self.copy else self._buffers,
                None if sub.compiled is None else sub.unwritten,
            )
            if sub.unwritten:
                sub.unwritten = []
            rewards, terminations, truncations, infos = columns.batch(sub.results, sub.stepped_now)
            if sub.finals:  # Gymnasium's final_obs and final_info, in the sub-envs' order
                for i, observation, info in sorted(sub.finals, key=lambda f: f[0]):
                    final = {"final_obs": observation, "final_info": info}
                    infos = self._add_info(infos, final, i)
        self._ended = terminations | truncations
        return observations, rewards, terminations, truncations, infos

    # ------------------------------------------------------------------ the rest
    def render(self) -> tuple[Any, ...] | None:
        """A frame per sub-env (``rgb_array``/``depth_array``), None without a render mode."""
        if self.render_mode is None:
            return None
        return tuple(env.render() for env in self.envs)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call ``name`` on every sub-env (an attribute: its value), as Gymnasium's."""
        results = []
        for env in self.envs:
            attribute = env.get_wrapper_attr(name)
            results.append(attribute(*args, **kwargs) if callable(attribute) else attribute)
        return tuple(results)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Every sub-env's attribute ``name``."""
        return self.call(name)

    def set_attr(self, name: str, values: Any) -> None:
        """Set ``name`` on every sub-env: one value each (a list or tuple) or one for all."""
        if not isinstance(values, list | tuple):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(f"set_attr: {len(values)} values for {self.num_envs} sub-envs")
        for env, value in zip(self.envs, values, strict=True):
            env.set_wrapper_attr(name, value)

    def close_extras(self, **kwargs: Any) -> None:
        self._finalizer()  # stops the threads
        for env in self._sub.envs:
            env.close()


def _vector_env_class(env_id: str, name: str) -> type[WIPVectorEnv]:
    """The class ``name``: :class:`WIPVectorEnv` of ``env_id``, the env's
    ``vector_entry_point`` (``wip_gym/registration.py``), taking ``num_envs`` and the rest."""

    def __init__(self: WIPVectorEnv, num_envs: int = 1, **kwargs: Any) -> None:
        WIPVectorEnv.__init__(self, env_id, num_envs, **kwargs)

    namespace = {
        "__init__": __init__,
        "__doc__": f"``{env_id}`` x ``num_envs`` (its ``vector_entry_point``).",
        "__module__": __name__,
        "__qualname__": name,
    }
    return type(name, (WIPVectorEnv,), namespace)


WIPDriveVectorEnv = _vector_env_class("wip_gym/WIP-v0", "WIPDriveVectorEnv")
PlanarVectorEnv = _vector_env_class("wip_gym/Planar-v0", "PlanarVectorEnv")
PlanarTrayVectorEnv = _vector_env_class("wip_gym/PlanarTray-v0", "PlanarTrayVectorEnv")
KrangVectorEnv = _vector_env_class("wip_gym/Krang-v0", "KrangVectorEnv")
KrangTrayVectorEnv = _vector_env_class("wip_gym/KrangTray-v0", "KrangTrayVectorEnv")
