"""The benchmarks' unit of time: one bare, warm ``mj_step`` of Krang-v0's model at its reset state.

Timings on a shared 2-core machine move with its load and differ between machines; their
ratios to a fixed reference workload timed in the same process move much less. The reference is
deliberately the physics of the plain robot (no cup, no controller), so that making an env's own
physics cheaper does not count against it (docs/DESIGN.md §8).

    reference = median over ``repeats`` of the wall time of ``mujoco.mj_step(model, data)``, each
                from a copy of the state ``env.reset(seed=0)`` leaves (``warmup`` untimed first)

``wip-bench profile`` and ``wip-bench solvers`` report it as ``reference_step_us`` and their
figures also in its units.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import gymnasium as gym
import mujoco
import numpy as np

import wip_gym  # noqa: F401  (registers the envs)

REFERENCE_ENV = "wip_gym/Krang-v0"
REFERENCE_SEED = 0


class ReferenceStep:
    """The reference workload, ready to be timed between a benchmark's own steps, so that its
    samples see the same machine load as they do (in warm bursts: :meth:`burst`)."""

    def __init__(self) -> None:
        env = gym.make(REFERENCE_ENV)
        try:
            env.reset(seed=REFERENCE_SEED)
            self.model = env.unwrapped.model
            self.reset_data = mujoco.MjData(self.model)
            mujoco.mj_copyData(self.reset_data, self.model, env.unwrapped.data)
        finally:
            env.close()
        self.data = mujoco.MjData(self.model)

    def sample(self) -> float:
        """Wall time (s) of one bare ``mj_step`` from the reset state."""
        mujoco.mj_copyData(self.data, self.model, self.reset_data)
        start = time.perf_counter()
        mujoco.mj_step(self.model, self.data)
        return time.perf_counter() - start

    def burst(self, count: int = 20, warmup: int = 1) -> list[float]:
        """``count`` timed samples after ``warmup`` untimed ones: the step warm, as the unit
        defines it.

        One sample taken right after a benchmark's own step is not: the benchmark's work has
        evicted the caches the reference step works in, and such samples measured 1.25 to 1.33
        times a warm step between KrangTray-v0's closed-loop steps and 1.5 to 2.2 times between
        MPC steps. A benchmark that follows the machine's load takes
        a burst every so many of its steps instead (:func:`burst_due`,
        :func:`times_between_bursts`)."""
        if count < 1 or warmup < 0:
            raise ValueError(f"count must be >= 1 and warmup >= 0, got {count}, {warmup}")
        for _ in range(warmup):
            self.sample()
        return [self.sample() for _ in range(count)]


def burst_due(step: int, every: int, steps: int) -> bool:
    """Whether a burst of the unit follows a benchmark's ``step`` (0-based) of ``steps``: after
    every ``every``-th step, and after the last (so that a short run has samples too)."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    return (step + 1) % every == 0 or step + 1 == steps


def times_between_bursts(
    timed: Callable[[int], float],
    indices: Iterable[int],
    steps: int,
    every: int,
    reference: ReferenceStep,
    samples: list[float],
) -> list[float]:
    """The wall times (s) that ``timed(i)`` returns for each of ``indices`` (``steps`` of them),
    with a burst of ``reference`` (into ``samples``) after every ``every``-th (:func:`burst_due`);
    the step after a burst, which the burst slowed, is run but not counted."""
    times: list[float] = []
    after_burst = False
    for step, i in enumerate(indices):
        seconds = timed(i)
        if not after_burst:
            times.append(seconds)
        after_burst = burst_due(step, every, steps)
        if after_burst:
            samples.extend(reference.burst())
    return times


def reference_step_samples(repeats: int = 400, warmup: int = 50) -> np.ndarray:
    """Wall times (s) of ``repeats`` bare ``mj_step`` calls of :data:`REFERENCE_ENV`'s model,
    each from its reset state (seed :data:`REFERENCE_SEED`), after ``warmup`` untimed ones."""
    if repeats < 1 or warmup < 0:
        raise ValueError(f"repeats must be >= 1 and warmup >= 0, got {repeats}, {warmup}")
    return np.array(ReferenceStep().burst(repeats, warmup))


def reference_step_us(repeats: int = 400, warmup: int = 50) -> float:
    """The unit (module docstring) in microseconds."""
    return float(np.median(reference_step_samples(repeats, warmup)) * 1e6)
