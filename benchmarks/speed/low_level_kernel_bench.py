"""The low level's compiled parts against NumPy and JAX, on the inputs of a real ``unified``
closed loop on KrangTray-v0: the QP kernel (``controllers.low_level.kernel``) and the task rows
(``controllers.low_level.task_stack``).

    python -m benchmarks.speed.low_level_kernel_bench [--steps 300] [--repeats 5]

Timed per call (median over the recorded states, then the median of ``--repeats`` rounds,
interleaved so that the machine's load falls on every variant alike), beside the unit of
``benchmarks.speed.yardstick``:

* ``numba``: ``LowLevelKernel.run`` (steps 1 to 5, eq. iso3 included), ours; since fd4c7b9
  it includes the shape checks ``run`` makes on its inputs, which figures measured before it
  do not;
* ``numpy``: the same five steps as one NumPy function into preallocated buffers (the kernel
  before it was compiled);
* ``before``: the same arithmetic as the task QP did it before the kernel, piece by piece
  (``isolated_dynamics``, products with ``E`` and ``e``, the constraint rows,
  ``feasible_unconstrained_minimiser``);
* ``jax``: the same five steps as one ``jax.jit`` function of the eight input arrays
  (``jax.scipy.linalg.cho_factor``/``cho_solve`` for the minimiser), result fetched to NumPy;
* ``jax_packed``: the same with the inputs packed in one vector (one transfer);
* ``jax_empty``: a jitted function of the packed vector that returns it: the call's floor;

and for the task rows (``J``, ``xdd*``, ``Jdot nu``, weights of the seven tasks, MuJoCo calls
included): ``rows_compiled`` (``CompiledTaskStack.fill``, ours) against ``rows_python`` (the
task objects one by one, ``QPSettings(compiled_tasks=False)``).

Measured before numba (``--steps 300 --repeats 5``, the 2-core machine shared with other
jobs; two runs): ``numpy`` 4.3 / 3.3 units, ``before`` 4.5 units, ``jax`` 7.4 / 5.1,
``jax_packed`` 6.0 / 3.9, ``jax_empty`` 1.35 / 0.95: a jitted JAX call's floor is about one unit
before any arithmetic, XLA:CPU runs this size's arithmetic no faster than NumPy, and NumPy's
cost is its number of calls, not the arithmetic (18 variables, 31 task rows, 34 constraint rows
for Krang). numba compiles the loops once (cached on disk) and calls them for well under a
unit; docs/performance.md §7 has today's figures.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import wip_gym  # noqa: F401
from benchmarks.speed.yardstick import reference_step_us
from controllers.hierarchical import HierarchicalController
from controllers.low_level.kernel import KernelLayout

Inputs = tuple[np.ndarray, ...]


def record_inputs(steps: int) -> tuple[KernelLayout, Any, list[Inputs]]:
    """The kernel's inputs ``(A, h, J, target, jdot_nu, w, q, nu)`` at every step of a
    ``unified`` closed loop on KrangTray-v0 (seed 0)."""
    env = gym.make("wip_gym/KrangTray-v0")
    obs, info = env.reset(seed=0)
    policy = HierarchicalController.for_env(env)
    policy.reset(obs, info)
    qp, robot = policy.qp, policy.robot
    inputs: list[Inputs] = []
    for _ in range(steps):
        action = policy(obs)
        inputs.append(
            tuple(
                np.array(a)
                for a in (robot.A, robot.h, qp._J, qp._target, qp._bias, qp._w, robot.q, robot.nu)
            )
        )
        obs, *_ = env.step(action)
    env.close()
    return qp.kernel.layout, robot.layout, inputs


def jax_kernel(layout: KernelLayout) -> Callable[..., Any]:
    """Steps 1 to 5 of the kernel in JAX (not jitted)."""
    import jax.numpy as jnp  # noqa: PLC0415
    from jax.scipy.linalg import cho_factor, cho_solve  # noqa: PLC0415

    k, r = layout.index_q1, layout.wheel_radius
    M = jnp.asarray(layout.actuator_map)
    n = layout.n_min - 1
    columns = jnp.asarray(layout.limit_columns)
    index = jnp.asarray(layout.limit_indices)
    C_limit = jnp.zeros((len(columns), n)).at[jnp.arange(len(columns)), columns].set(1.0)

    def kernel(A: Any, h: Any, J: Any, target: Any, jdot_nu: Any, w: Any, q: Any, nu: Any) -> Any:
        a_xx, a_xq, h_x, h_q = A[0, 0], A[1:, 0], h[0], h[1:]
        A_star = A[1:, 1:] - jnp.outer(a_xq, a_xq) / a_xx
        beta = 1.0 / (1.0 + a_xq[k] / (r * a_xx))
        scale = beta / (r * a_xx)
        calA = A_star - scale * jnp.outer(a_xq, A_star[k])
        h_star = h_q - a_xq * h_x / a_xx
        Ph = h_star - scale * a_xq * h_star[k]
        E0 = (-calA[k] / r - a_xq) / a_xx
        e0 = (-Ph[k] / r - h_x) / a_xx
        T = w[:, None] * (J[:, 1:] + J[:, :1] * E0)
        b = w * (target - jdot_nu - J[:, 0] * e0)
        H = T.T @ T + layout.regularization * jnp.eye(n)
        g = -T.T @ b
        C = jnp.concatenate([M @ calA, C_limit])
        offset = M @ Ph
        drift = q[index] + nu[index] * layout.limit_horizon
        scale_limit = 2.0 / layout.limit_horizon**2
        lower = jnp.concatenate(
            [layout.torque_low - offset, (layout.limit_min - drift) * scale_limit]
        )
        upper = jnp.concatenate(
            [layout.torque_high - offset, (layout.limit_max - drift) * scale_limit]
        )
        x = cho_solve(cho_factor(H), -g)
        Cx = C @ x
        feasible = jnp.all(Cx >= lower) & jnp.all(Cx <= upper)
        return jnp.concatenate([x, calA.ravel(), Ph, feasible[None].astype(x.dtype)])

    return kernel


def before_kernel(layout: KernelLayout, robot_layout: Any) -> Callable[..., Any]:
    """The pre-kernel sequence of calls for the same five steps."""
    from types import SimpleNamespace  # noqa: PLC0415

    from controllers.low_level.isolated_dynamics import isolated_dynamics  # noqa: PLC0415
    from controllers.low_level.qp_solver import feasible_unconstrained_minimiser  # noqa: PLC0415

    M = layout.actuator_map
    n = layout.n_min - 1
    C_limit = np.zeros((len(layout.limit_columns), n))
    C_limit[np.arange(len(layout.limit_columns)), layout.limit_columns] = 1.0
    reg = layout.regularization * np.eye(n)
    index, horizon = layout.limit_indices, layout.limit_horizon

    def kernel(A: Any, h: Any, J: Any, target: Any, jdot_nu: Any, w: Any, q: Any, nu: Any) -> Any:
        iso = isolated_dynamics(SimpleNamespace(layout=robot_layout, A=A, h=h))  # type: ignore[arg-type]
        T = w[:, None] * (J @ iso.E)
        b = w * (target - jdot_nu - J @ iso.e)
        H = T.T @ T + reg
        g = -(T.T @ b)
        C = np.vstack([M @ iso.calA, C_limit])
        offset = M @ iso.Ph
        drift = q[index] + nu[index] * horizon
        lower = np.concatenate(
            [layout.torque_low - offset, 2.0 * (layout.limit_min - drift) / horizon**2]
        )
        upper = np.concatenate(
            [layout.torque_high - offset, 2.0 * (layout.limit_max - drift) / horizon**2]
        )
        return feasible_unconstrained_minimiser(H, g, C, lower, upper)

    return kernel


def numpy_kernel(layout: KernelLayout) -> Callable[..., Any]:
    """The kernel's five steps as one NumPy function into preallocated buffers (the kernel as
    it was before it was compiled)."""
    from scipy.linalg.lapack import dposv  # noqa: PLC0415

    k, r = layout.index_q1, layout.wheel_radius
    n = layout.n_min - 1
    M = layout.actuator_map
    m = len(M)
    n_limit = len(layout.limit_columns)
    outer, A_star, calA = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    Ph, E0 = np.zeros(n), np.zeros(n)
    T, b = np.zeros((layout.rows, n)), np.zeros(layout.rows)
    H, g, x = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    C = np.zeros((m + n_limit, n))
    C[m + np.arange(n_limit), layout.limit_columns] = 1.0
    lower, upper = np.zeros(m + n_limit), np.zeros(m + n_limit)
    diagonal, square = np.arange(n), layout.limit_horizon**2

    def kernel(A: Any, h: Any, J: Any, target: Any, jdot_nu: Any, w: Any, q: Any, nu: Any) -> Any:
        a_xx, a_xq = float(A[0, 0]), A[1:, 0]
        h_x, h_q = float(h[0]), h[1:]
        np.multiply(a_xq[:, None], a_xq, out=outer)
        np.divide(outer, a_xx, out=outer)
        np.subtract(A[1:, 1:], outer, out=A_star)
        scale = 1.0 / (1.0 + float(a_xq[k]) / (r * a_xx)) / (r * a_xx)
        np.multiply(a_xq[:, None], A_star[k], out=outer)
        np.multiply(outer, scale, out=outer)
        np.subtract(A_star, outer, out=calA)
        h_star = h_q - a_xq * h_x / a_xx
        np.subtract(h_star, scale * a_xq * float(h_star[k]), out=Ph)
        np.divide(-calA[k] / r - a_xq, a_xx, out=E0)
        e0 = (-float(Ph[k]) / r - h_x) / a_xx
        column = J[:, 0]
        np.multiply(column[:, None], E0, out=T)
        np.add(T, J[:, 1:], out=T)
        np.multiply(T, w[:, None], out=T)
        np.subtract(target, jdot_nu, out=b)
        np.subtract(b, column * e0, out=b)
        np.multiply(b, w, out=b)
        np.matmul(T.T, T, out=H)
        H[diagonal, diagonal] += layout.regularization
        np.matmul(T.T, b, out=g)
        np.negative(g, out=g)
        np.matmul(M, calA, out=C[:m])
        offset = M @ Ph
        np.subtract(layout.torque_low, offset, out=lower[:m])
        np.subtract(layout.torque_high, offset, out=upper[:m])
        index = layout.limit_indices
        drift = q[index] + nu[index] * layout.limit_horizon
        np.subtract(layout.limit_min, drift, out=lower[m:])
        np.subtract(layout.limit_max, drift, out=upper[m:])
        for bound in (lower[m:], upper[m:]):
            bound *= 2.0
            bound /= square
        _, solution, info = dposv(H, g, overwrite_b=False)
        if info != 0:
            return False
        np.negative(solution, out=x)
        Cx = C @ x
        return bool(np.isfinite(Cx).all() and (Cx >= lower).all() and (Cx <= upper).all())

    return kernel


def compare_task_rows(steps: int, repeats: int) -> dict[str, float]:
    """Median microseconds per step of the task rows, compiled and by the task objects."""
    import dataclasses  # noqa: PLC0415

    env = gym.make("wip_gym/KrangTray-v0")
    obs, info = env.reset(seed=0)
    policy = HierarchicalController.for_env(env)
    policy.reset(obs, info)
    states = []
    for _ in range(steps):
        action = policy(obs)
        states.append((obs["qpos"].copy(), obs["qvel"].copy()))
        obs, *_ = env.step(action)
    env.close()
    qp, robot, tasks = policy.qp, policy.robot, policy.tasks
    settings = {
        "rows_compiled": dataclasses.replace(qp.settings, compiled_tasks=True),
        "rows_python": dataclasses.replace(qp.settings, compiled_tasks=False),
    }
    rounds: dict[str, list[float]] = {name: [] for name in settings}
    for _ in range(repeats):
        for name, setting in settings.items():
            qp.settings = setting
            times = []
            for qpos, qvel in states:
                robot.update(qpos, qvel)
                start = time.perf_counter()
                qp._snapshot(robot, tasks)
                times.append(time.perf_counter() - start)
            rounds[name].append(float(np.median(times)) * 1e6)
    return {name: float(np.median(values)) for name, values in rounds.items()}


def _median_call(function: Callable[[Inputs], Any], inputs: list[Inputs]) -> float:
    function(inputs[0])
    times = []
    for args in inputs:
        start = time.perf_counter()
        function(args)
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def compare(steps: int, repeats: int) -> dict[str, float]:
    """Median microseconds per call of each variant (module docstring) and the unit."""
    import jax  # noqa: PLC0415

    from controllers.low_level.kernel import LowLevelKernel  # noqa: PLC0415

    layout, robot_layout, inputs = record_inputs(steps)
    before = before_kernel(layout, robot_layout)
    ours = LowLevelKernel(layout)
    kernel = jax_kernel(layout)
    jitted = jax.jit(kernel)
    sizes = [a.size for a in inputs[0]]
    shapes = [a.shape for a in inputs[0]]
    bounds = np.cumsum([0, *sizes])

    def unpack(packed: Any) -> list[Any]:
        return [packed[bounds[i] : bounds[i + 1]].reshape(shapes[i]) for i in range(len(sizes))]

    packed_kernel = jax.jit(lambda packed: kernel(*unpack(packed)))
    empty = jax.jit(lambda packed: packed)

    def pack(args: Inputs) -> np.ndarray:
        return np.concatenate([a.ravel() for a in args])

    fused_numpy = numpy_kernel(layout)
    variants: dict[str, Callable[[Inputs], Any]] = {
        "numba": lambda args: ours.run(*args),
        "numpy": lambda args: fused_numpy(*args),
        "before": lambda args: before(*args),
        "jax": lambda args: np.asarray(jitted(*args)),
        "jax_packed": lambda args: np.asarray(packed_kernel(pack(args))),
        "jax_empty": lambda args: np.asarray(empty(pack(args))),
    }
    # the JAX and NumPy results agree with ours (x, calA; feasibility)
    for args in inputs[:: max(1, len(inputs) // 20)]:
        assert fused_numpy(*args) == ours.run(*args)
        out = np.asarray(jitted(*args))
        n = ours.n
        np.testing.assert_allclose(out[:n], ours.x, rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(out[n : n + n * n], ours.calA.ravel(), rtol=1e-12, atol=1e-9)
    rounds: dict[str, list[float]] = {name: [] for name in (*variants, "unit")}
    for _ in range(repeats):
        rounds["unit"].append(reference_step_us(repeats=200))
        for name, function in variants.items():
            rounds[name].append(_median_call(function, inputs) * 1e6)
    result = {name: float(np.median(values)) for name, values in rounds.items()}
    return result | compare_task_rows(steps, repeats)


def main() -> None:
    from controllers.optimizer import jax_setup

    jax_setup.configure()  # the solvers' JAX settings, before JAX starts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    result = compare(args.steps, args.repeats)
    unit = result["unit"]
    print(f"unit (bare mj_step of Krang-v0): {unit:.1f} us")
    for name, value in result.items():
        if name != "unit":
            print(f"{name:>11}: {value:7.1f} us = {value / unit:5.2f} units")


if __name__ == "__main__":
    main()
