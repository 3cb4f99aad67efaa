"""Record the task QPs of a real closed loop of the ``unified`` controller.

The QP is the one ``controllers.low_level.task_qp.TaskQP.solve`` hands ProxQP,

    min 0.5 qdd' H qdd + g' qdd   s.t.   lower <= C qdd <= upper,

``H = T'T + eps I``, ``g = -T'b`` (the stacked weighted tasks; paper eq. ``iso3`` and the task
rows of ``controllers.low_level.tasks``), ``C`` the actuator-torque rows and the joint-limit rows.
It is captured from the benchmark side by wrapping the controller's ``qp.solve`` on the instance
(the controller's code is not touched): after every control step's solve, the QP kernel's
buffers hold that step's arrays (whichever path the solve took: ProxQP's or the feasible
unconstrained minimiser's), and they are copied.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

import wip_gym  # noqa: F401  (registers the environments)
from controllers.registry import make_policy

FloatArray = NDArray[np.float64]
CONTROLLER = "unified"


@dataclass(frozen=True)
class RecordedQP:
    """One task QP: ``min 0.5 x'Hx + g'x  s.t.  lower <= C x <= upper``."""

    H: FloatArray
    g: FloatArray
    C: FloatArray
    lower: FloatArray
    upper: FloatArray

    @property
    def n(self) -> int:
        return self.g.shape[0]

    @property
    def m(self) -> int:
        return self.C.shape[0]


@dataclass(frozen=True)
class Recording:
    """The QPs of one closed loop, in the order the controller solved them, and how many of
    them ProxQP reported unsolved inside the controller."""

    env_id: str
    seconds: float
    qps: tuple[RecordedQP, ...]
    controller_failures: int


def record_qps(env_id: str, seconds: float, seed: int = 0) -> Recording:
    """Run ``unified`` on ``env_id`` for ``seconds`` (from ``reset(seed)``) and record every
    control step's QP (the QP solved in ``reset`` is left out: it is the cold start)."""
    env = gym.make(env_id)
    try:
        observation, info = env.reset(seed=seed)
        policy = make_policy(CONTROLLER, env)
        policy.reset(observation, info)
        qp = policy.qp
        recorded: list[RecordedQP] = []
        original = qp.solve

        def solve(*args: object) -> object:
            solution = original(*args)
            k = qp.kernel  # this step's QP, as ProxQP is (or would be) handed it
            arrays = (k.H, k.g, k.C, k.lower, k.upper)
            recorded.append(RecordedQP(*(np.array(a, dtype=np.float64) for a in arrays)))
            return solution

        qp.solve = solve  # an instance attribute: shadows the method for this object only
        steps = int(round(seconds / env.unwrapped.dt))
        try:
            for _ in tqdm(range(steps), desc=f"record {env_id}", leave=False, disable=None):
                action = policy(observation)
                observation, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
        finally:
            del qp.solve
        failures = policy.diagnostics.get("qp_failures", np.zeros(1))
        return Recording(env_id, seconds, tuple(recorded), int(np.max(failures, initial=0)))
    finally:
        env.close()
