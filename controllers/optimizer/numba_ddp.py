"""The MPC's DDP compiled by numba: the algorithm of ``controllers.optimizer.ddp`` with the
MPC's settings (iLQR, no gradient norm), every derivative still written by JAX's autodiff.

Why: an MPC step is two DDP iterations over 100 steps of an 8-state model. In XLA:CPU the
small scans' per-step overheads, not the arithmetic, set its time; the same solve as
straight-line scalar code runs 1.3 to 2.5 times as fast (both backends on the same inputs,
interleaved call by call).

How: :func:`generated_module` traces three per-step functions of a :class:`WIPMProblem` to
jaxprs and writes them out as scalar code (``controllers.optimizer.scalar_codegen``, folding the
exact zeros of the Jacobians):

- ``rollout_stage``: the discrete dynamics and the running cost (1);
- ``terminal_stage``: the terminal cost with its gradient and Hessian (``jax.grad``,
  ``jax.hessian`` made exactly symmetric, as the JAX solver takes them);
- ``backward_stage``: the problem's own stage derivatives, then
  ``controllers.optimizer.ddp.riccati_step``, the step (2)-(5) that the JAX solver's backward
  scan runs.

The problem's numbers (``dt``, weights, bounds: :meth:`WIPMProblem.constants`) and
``lambda(q)`` are inputs of that code, not literals: one compilation serves every MPC of the
same structure (planar or 3-D), whatever its weights or its cup's friction. The module is
written to a file under :func:`cache_dir`, named by the hash of its source, beside the driver
loops below (their source copied in), and numba caches its machine code there: the first
process on a machine compiles it (about half a minute for the 3-D model on 2 cores), the next
ones load it. The driver runs ``DDPSolver._solve``'s loop: the warm start's rollout and cost,
backward passes under the regularisation schedule (8), the line search (6)-(7) over the same
step sizes (the largest acceptable one), the stopping test (9), the iteration budget; and
around it the MPC step of ``controllers.high_level.mpc`` (the plan's window, the warm start,
the acceptance test with its fallback, the shifted warm start of the next step).

The solves release the GIL (``nogil``), so an MPC beside the control loop runs in parallel
with it. Tested equal to the JAX solver to round-off on the MPC's windows, with the penalty
active and not, through failed line searches and raised mu, and through a rejected solution
(tests/test_numba_ddp.py).
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import importlib.util
import inspect
import os
import shutil
import sys
import tempfile
import threading
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from controllers.optimizer import jax_setup
from controllers.optimizer.ddp import DDPConfig
from controllers.optimizer.scalar_codegen import nan_max, nan_min

__all__ = [
    "CACHE_ENV",
    "cache_dir",
    "check_config",
    "generated_module",
    "settings_vector",
]

CACHE_ENV = "WIP_GYM_NUMBA_CACHE"

#: the driver's settings vector: DDPConfig's numbers in this order, then its step sizes
SETTINGS = (
    "max_iterations",
    "tolerance",
    "abs_tolerance",
    "mu_init",
    "mu_factor",
    "mu_min",
    "mu_max",
    "line_search_c",
    "final_backward",
)


def cache_dir() -> Path:
    """Where the generated modules (and numba's cache of them) live: ``~/.cache/wip-gym/numba``
    unless ``WIP_GYM_NUMBA_CACHE`` names another directory."""
    value = os.environ.get(CACHE_ENV)
    return Path(value) if value else Path.home() / ".cache" / "wip-gym" / "numba"


def check_config(config: DDPConfig) -> None:
    """``ValueError`` for the settings the compiled driver does not run: the second-order DDP
    (the dynamics' Hessians) and the gradient norm (its adjoint pass; a gradient tolerance
    needs it)."""
    refused = [
        name
        for name, on in (
            ("second_order", config.second_order),
            ("gradient_norm", config.gradient_norm),
        )
        if on
    ]
    if refused:
        raise ValueError(
            f"the numba DDP runs the MPC's settings (iLQR without the gradient norm); "
            f"refused: {', '.join(refused)}. Use the JAX backend for these."
        )


def settings_vector(config: DDPConfig) -> tuple[np.ndarray, np.ndarray]:
    """``(settings, alphas)``: the driver's inputs of ``config`` (checked: :func:`check_config`)."""
    check_config(config)
    settings = np.array([float(getattr(config, name)) for name in SETTINGS])
    alphas = np.asarray(config.alphas, dtype=float)
    if alphas.ndim != 1 or alphas.size == 0:
        raise ValueError(f"DDPConfig.alphas must be a non-empty sequence, got {config.alphas}")
    return settings, alphas


# ---------------------------------------------------------------------------------------------
# Stand-ins for what each generated module defines itself: the lengths of lambda(q) and of the
# problem's constants its stage functions read, and the per-step functions.

N_STATE = 0  # the DDP's state
N_CONTROL = 0
N_REFERENCE = 0  # a reference state's
PARAMETERS = 0
CONSTANTS = 0


def rollout_stage(z: np.ndarray, out: np.ndarray) -> None:
    """``z = [x, u, s_ref, lambda(q), constants]`` -> ``out = [f(x, u), l(x, u)]``."""
    raise NotImplementedError("generated per problem: generated_module()")


def terminal_stage(z: np.ndarray, out: np.ndarray) -> None:
    """``z = [x, s_ref, lambda(q), constants]`` -> ``out = [l_f, l_f,x, l_f,xx]``."""
    raise NotImplementedError("generated per problem: generated_module()")


def backward_stage(z: np.ndarray, out: np.ndarray) -> None:
    """``z = [x, u, s_ref, lambda(q), constants, V_x, V_xx, mu]`` -> ``out = [V_x, V_xx, K, k,
    dV_1, dV_2, ok]`` (``riccati_step`` after the stage's derivatives, iLQR)."""
    raise NotImplementedError("generated per problem: generated_module()")


# ---------------------------------------------------------------------------------------------
# The driver. These functions' source is copied into every generated module (under numba's
# njit), where the three stage functions above are the problem's. Sizes come from the arrays.


def terminal_at(x_end: np.ndarray, s_end: np.ndarray, P: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The terminal cost, its gradient and Hessian at ``x_end``, in one vector."""
    n, ns = x_end.shape[0], s_end.shape[0]
    z = np.empty(n + ns + P.shape[0] + C.shape[0])
    z[:n] = x_end
    z[n : n + ns] = s_end
    z[n + ns : n + ns + P.shape[0]] = P
    z[n + ns + P.shape[0] :] = C
    out = np.empty(1 + n + n * n)
    terminal_stage(z, out)
    return out


def trajectory(  # noqa: PLR0913
    x0: np.ndarray,
    U: np.ndarray,
    X_ref: np.ndarray,
    K: np.ndarray,
    k: np.ndarray,
    alpha: float,
    S: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    X_out: np.ndarray,
    U_out: np.ndarray,
) -> float:
    """The rollout (6) from ``x0`` (``alpha`` < 0: the controls ``U`` open loop, ``K``, ``k``
    unread) into ``X_out``, ``U_out``; returns its cost (1)."""
    steps, m = U.shape
    n = x0.shape[0]
    ns = S.shape[1]
    z = np.empty(n + m + ns + P.shape[0] + C.shape[0])
    out = np.empty(n + 1)
    z[n + m + ns : n + m + ns + P.shape[0]] = P
    z[n + m + ns + P.shape[0] :] = C
    X_out[0] = x0
    total = 0.0
    for t in range(steps):
        x = X_out[t]
        for a in range(m):
            v = U[t, a]
            if alpha >= 0.0:
                v += alpha * k[t, a]
                for j in range(n):
                    v += K[t, a, j] * (x[j] - X_ref[t, j])
            U_out[t, a] = v
        z[:n] = x
        z[n : n + m] = U_out[t]
        z[n + m : n + m + ns] = S[t]
        rollout_stage(z, out)
        X_out[t + 1] = out[:n]
        total += out[n]
    return total + terminal_at(X_out[steps], S[steps], P, C)[0]


def backward(  # noqa: PLR0913
    X: np.ndarray,
    U: np.ndarray,
    S: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    mu: float,
    K: np.ndarray,
    k: np.ndarray,
) -> tuple[float, float, bool]:
    """The backward pass (2)-(5): ``(dV_1, dV_2, ok)``, the gains into ``K``, ``k``."""
    steps, m = U.shape
    n = X.shape[1]
    ns = S.shape[1]
    base = n + m + ns + P.shape[0] + C.shape[0]
    z = np.empty(base + n + n * n + 1)
    out = np.empty(n + n * n + m * n + m + 3)
    o_K = n + n * n
    o_k = o_K + m * n
    o_dv = o_k + m
    z[n + m + ns : n + m + ns + P.shape[0]] = P
    z[n + m + ns + P.shape[0] : base] = C
    z[base : base + n + n * n] = terminal_at(X[steps], S[steps], P, C)[1:]  # V_x, V_xx at N
    z[base + n + n * n] = mu
    dv1, dv2, ok = 0.0, 0.0, True
    for t in range(steps - 1, -1, -1):
        z[:n] = X[t]
        z[n : n + m] = U[t]
        z[n + m : n + m + ns] = S[t]
        backward_stage(z, out)
        z[base : base + n + n * n] = out[: n + n * n]
        for a in range(m):
            k[t, a] = out[o_k + a]
            for j in range(n):
                K[t, a, j] = out[o_K + a * n + j]
        dv1 += out[o_dv]
        dv2 += out[o_dv + 1]
        ok = ok and out[o_dv + 2] != 0.0
    ok = ok and np.isfinite(dv1) and np.isfinite(dv2)
    return dv1, dv2, ok


def increase(mu: float, dmu: float, settings: np.ndarray) -> tuple[float, float]:
    """The schedule (8) upward."""
    factor, mu_min = settings[4], settings[5]
    dmu = max(dmu * factor, factor)
    return max(mu * dmu, mu_min), dmu


def decrease(mu: float, dmu: float, settings: np.ndarray) -> tuple[float, float]:
    """The schedule (8) downward (to 0 below ``mu_min``)."""
    factor, mu_min = settings[4], settings[5]
    dmu = min(dmu / factor, 1.0 / factor)
    mu = mu * dmu
    return (0.0 if mu < mu_min else mu), dmu


def regularised(  # noqa: PLR0913
    X: np.ndarray,
    U: np.ndarray,
    S: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    mu: float,
    dmu: float,
    K: np.ndarray,
    k: np.ndarray,
    settings: np.ndarray,
) -> tuple[float, float, bool, float, float]:
    """Backward passes with mu increased until one succeeds (8): ``(dV_1, dV_2, ok, mu, dmu)``."""
    while True:
        dv1, dv2, ok = backward(X, U, S, P, C, mu, K, k)
        if ok:
            return dv1, dv2, ok, mu, dmu
        mu2, dmu2 = increase(mu, dmu, settings)
        if mu2 > settings[6] or mu2 <= mu:
            return dv1, dv2, False, mu, dmu
        mu, dmu = mu2, dmu2


def stops(ok: bool, dv1: float, dv2: float, cost: float, settings: np.ndarray) -> bool:
    """The stopping test (9) after a backward pass, or its failure."""
    return not ok or -(dv1 + dv2) <= settings[1] * abs(cost) + settings[2]


def solve(  # noqa: PLR0913
    x0: np.ndarray,
    U_init: np.ndarray,
    S: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    settings: np.ndarray,
    alphas: np.ndarray,
    X_init: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float, float, int, float, np.ndarray, np.ndarray]:
    """``DDPSolver._solve`` with iLQR: ``(X, U, cost, the warm start's cost, iterations, mu,
    K, k)`` (``mu``, ``K``, ``k``: the last backward pass's); the warm start's open-loop rollout
    into ``X_init``. ``ValueError`` for inputs of other sizes than the module's (its stage
    functions read and write fixed offsets)."""
    steps, m = U_init.shape
    n = x0.shape[0]
    if n != N_STATE or m != N_CONTROL or S.shape[1] != N_REFERENCE:
        raise ValueError("solve inputs of another width than generated for")
    if P.shape[0] != PARAMETERS or C.shape[0] != CONSTANTS or S.shape[0] != steps + 1:
        raise ValueError("solve inputs of another length than generated for")
    if X_init.shape != (steps + 1, n) or settings.shape[0] != len(SETTINGS):
        raise ValueError("solve inputs of another length than generated for")
    max_iterations = int(settings[0])
    c = settings[7]
    final_backward = settings[8] != 0.0
    mu_max = settings[6]
    X = np.empty((steps + 1, n))
    U = U_init.copy()
    K = np.zeros((steps, m, n))
    k = np.zeros((steps, m))
    X_new = np.empty((steps + 1, n))
    U_new = np.empty((steps, m))
    # the warm start's rollout, then its backward pass (the first pass of the loop)
    cost = trajectory(x0, U_init, X, K, k, -1.0, S, P, C, X, U)
    X_init[:] = X
    initial = cost
    mu, dmu = settings[3], 1.0
    dv1, dv2, ok, mu, dmu = regularised(X, U, S, P, C, mu, dmu, K, k, settings)
    iterations = 0
    done = stops(ok, dv1, dv2, cost, settings)
    while not done and iterations < max_iterations:
        accepted = False
        new_cost = cost
        for alpha in alphas:
            new_cost = trajectory(x0, U, X, K, k, alpha, S, P, C, X_new, U_new)
            actual = cost - new_cost
            expected = -(alpha * dv1 + alpha * alpha * dv2)
            if np.isfinite(new_cost) and actual > 0 and actual >= c * expected:
                accepted = True
                break
        mu_up, dmu_up = increase(mu, dmu, settings)
        stuck = (not accepted) and (mu_up > mu_max or mu_up <= mu)
        if accepted:
            X[:] = X_new
            U[:] = U_new
            cost = new_cost
            mu, dmu = decrease(mu, dmu, settings)
        elif not stuck:
            mu, dmu = mu_up, dmu_up
        iterations += 1
        if stuck or (iterations >= max_iterations and not final_backward):
            break
        dv1, dv2, ok, mu, dmu = regularised(X, U, S, P, C, mu, dmu, K, k, settings)
        done = stops(ok, dv1, dv2, cost, settings)
    return X, U, cost, initial, iterations, mu, K, k


def mpc_step(  # noqa: PLR0913
    host: np.ndarray,
    warm: np.ndarray,
    plan_states: np.ndarray,
    plan_controls: np.ndarray,
    C: np.ndarray,
    settings: np.ndarray,
    alphas: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``controllers.high_level.mpc``'s step: ``(packed, next_warm)`` from the packed host
    inputs ``[index, first, state, lambda(q)]`` (``pack_inputs``), the warm start and the padded
    plan. ``packed``: ``X``, ``U``, the cost, the warm start's cost and the acceptance flag."""
    H, m = warm.shape
    n = plan_states.shape[1]
    if n != N_STATE or n != N_REFERENCE or m != N_CONTROL or plan_controls.shape[1] != m:
        raise ValueError("MPC inputs of another width than generated for")
    if host.shape[0] != 2 + n + PARAMETERS or C.shape[0] != CONSTANTS:
        raise ValueError("MPC inputs or problem constants of another length than generated for")
    if plan_states.shape[0] < H + 1 or plan_controls.shape[0] < H + 1 or H < 1:
        raise ValueError("the padded plan is shorter than the horizon")
    index = max(int(host[0]), 0)  # the JAX step clamps a negative index to 0 too
    # the window's start clamped so that the window fits (as JAX's dynamic_slice does)
    start = min(index, plan_states.shape[0] - (H + 1))
    S = np.ascontiguousarray(plan_states[start : start + H + 1])
    if host[1] != 0.0:  # the first step: the plan's controls
        control_start = min(index, plan_controls.shape[0] - H)
        U0 = np.ascontiguousarray(plan_controls[control_start : control_start + H])
    else:
        U0 = warm.copy()
    x0 = host[2 : 2 + n].copy()
    P = host[2 + n :].copy()
    X_init = np.empty((H + 1, n))
    X, U, cost, initial, _, _, _, _ = solve(x0, U0, S, P, C, settings, alphas, X_init)
    accepted = (
        np.isfinite(cost)
        and np.isfinite(X).all()
        and np.isfinite(U).all()
        and cost <= initial * (1 + 1e-12) + 1e-12
    )
    if not accepted:  # the warm start, rolled out open loop, is kept
        X, U, cost = X_init, U0, initial
    next_warm = np.empty((H, m))
    next_warm[: H - 1] = U[1:]
    next_warm[H - 1] = plan_controls[min(index + H, plan_controls.shape[0] - 1)]
    size_x, size_u = (H + 1) * n, H * m
    packed = np.empty(size_x + size_u + 3)
    packed[:size_x] = X.ravel()
    packed[size_x : size_x + size_u] = U.ravel()
    packed[-3] = cost
    packed[-2] = initial
    packed[-1] = 1.0 if accepted else 0.0
    return packed, next_warm


_DRIVER = (terminal_at, trajectory, backward, increase, decrease, regularised, stops, solve)
#: numba's options for every generated function: NumPy's error model (a division by zero gives
#: inf or NaN, as in JAX); the GIL released; fused multiply-adds allowed (``contract``: 7 to 9 %
#: off the 3-D step, interleaved; no other fast-math flag, so NaN and inf keep their meaning)
OPTIONS = 'cache=True, error_model="numpy", nogil=True, fastmath={"contract"}'


# ---------------------------------------------------------------------------------------------
# Generation


@jax_setup.in_float64  # traced in float64 whatever the process's JAX settings
def _stage_sources(problem: Any, params: Any) -> list[str]:
    """The three stage functions of ``problem`` (a :class:`WIPMProblem` of the MPC: state
    ``s``, input ``u``) as scalar source, its constants and ``params``' leaves inputs."""
    import jax  # noqa: PLC0415
    import jax.numpy as jnp  # noqa: PLC0415

    from controllers.optimizer.ddp import _symmetrised, riccati_step  # noqa: PLC0415
    from controllers.optimizer.scalar_codegen import scalar_source  # noqa: PLC0415

    n, m = problem.n_state, problem.n_control
    constants = jnp.asarray(problem.constants())

    def traced(c: Any) -> Any:
        return problem.with_constants(c)

    def rollout(x: Any, u: Any, s: Any, p: Any, c: Any) -> Any:
        wipm = traced(c)
        running, _ = wipm.costs()
        return wipm.dynamics()(x, u, p), running(x, u, (s, p))

    def terminal(x: Any, s: Any, p: Any, c: Any) -> Any:
        _, cost = traced(c).costs()
        ref = (s, p)
        # made exactly symmetric, as the JAX solver does
        return cost(x, ref), jax.grad(cost)(x, ref), _symmetrised(jax.hessian(cost)(x, ref))

    def backward(x: Any, u: Any, s: Any, p: Any, c: Any, vx: Any, vxx: Any, mu: Any) -> Any:
        wipm = traced(c)
        cost_derivatives = wipm.running_derivatives()
        jacobians = wipm.dynamics_derivatives()
        derivatives = (*cost_derivatives(x, u, (s, p)), *jacobians(x, u, p))
        vx_new, vxx_new, K, k, dv1, dv2, ok = riccati_step(derivatives, vx, vxx, mu, False)
        return vx_new, vxx_new, K, k, dv1, dv2, ok.astype(vx.dtype)

    # the DDP's state: the WIPM state, with the control appended under the rate input
    nx = n + m if problem.rate_input else n
    zx, zs, zm, zero = jnp.zeros(nx), jnp.zeros(n), jnp.zeros(m), jnp.zeros(())
    sources = []
    for name, fun, args in (
        ("rollout_stage", rollout, (zx, zm, zs, params, constants)),
        ("terminal_stage", terminal, (zx, zs, params, constants)),
        ("backward_stage", backward, (zx, zm, zs, params, constants, zx, jnp.eye(nx), zero)),
    ):
        source, _, _ = scalar_source(fun, *args, name=name, fold=True)
        sources.append(source)
    return sources


def module_source(problem: Any, params: Any, options: str = OPTIONS) -> str:
    """The generated module's source: the problem's stage functions and the driver, each under
    ``@numba.njit(options)``."""
    decorator = f"@numba.njit({options})"
    import jax  # noqa: PLC0415

    parameters = sum(int(np.size(leaf)) for leaf in jax.tree.leaves(params))
    header = [
        f'"""Generated by controllers.optimizer.numba_ddp for the {problem.n_state}-state WIPM',
        'MPC problem (do not edit: made again, under another name, when its source changes)."""',
        "",
        "import math",
        "",
        "import numba",
        "import numpy as np",
        "",
        f"N_STATE = {problem.n_state + (problem.n_control if problem.rate_input else 0)}",
        f"N_CONTROL = {problem.n_control}",
        f"N_REFERENCE = {problem.n_state}",
        f"PARAMETERS = {parameters}",
        f"CONSTANTS = {problem.constants().size}",
        f"SETTINGS = {SETTINGS!r}",
        "",
    ]
    parts = ["\n".join(header)]
    # self-contained: numba's cache would not see an edit of a function imported from elsewhere
    for function in (nan_max, nan_min):
        source = inspect.getsource(function.py_func)
        parts.append(f"{decorator}\n{source[source.index('def ') :]}")  # its own decorator off
    for source in _stage_sources(problem, params):
        parts.append(f"{decorator}\n{source}")
    for function in (*_DRIVER, mpc_step):
        parts.append(f"{decorator}\n{inspect.getsource(function)}")
    return "\n\n".join(parts)


def generated_module(problem: Any, params: Any) -> ModuleType:
    """The compiled module of ``problem``'s structure (planar or 3-D, the lengths of its weight
    vectors and of ``params``' leaves: its numbers are inputs), with ``params`` (a
    ``WIPMParams``) fixing the layout of ``lambda(q)``. Generated and written once per source
    (:func:`cache_dir`), loaded once per process. Its ``mpc_step`` and ``solve`` compile on
    their first call (or load from numba's cache); they refuse inputs of other lengths."""
    if problem.rate_input:
        # the plan's problem: written out and solved as well (the driver reads the DDP state's
        # and the reference's sizes apart), but untested here, and only 6 to 8 % faster over
        # the plan's 2000 steps when tried
        raise ValueError("the numba DDP runs the MPC's problem (state s, input u), not rate input")
    import jax  # noqa: PLC0415

    w = problem.weights
    key = (
        problem.planar,
        (len(w.q), len(w.r), len(w.r_rate), len(w.q_terminal)),
        tuple(np.shape(leaf) for leaf in jax.tree.leaves(params)),
    )
    with _LOCK:
        module = _MODULES.get(key)
        if module is None:
            module = _MODULES[key] = _write_and_load(problem, params)
    return module


def _write_and_load(problem: Any, params: Any, options: str = OPTIONS) -> ModuleType:
    """The module of ``module_source(problem, params, options)``, written (:func:`_written`)
    and loaded, apart from the table of :func:`generated_module`, so that variants of
    ``options`` load side by side."""
    source = module_source(problem, params, options)
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    name = f"wipm_mpc_{'planar' if problem.planar else 'spatial'}_{digest}"
    directory = cache_dir()
    try:
        path = _written(directory, name, source)
    except OSError as error:
        fallback = _private_temporary_directory()
        warnings.warn(
            f"cannot write the MPC's generated module under {directory} ({error}); using "
            f"{fallback} (set {CACHE_ENV} to a writable directory to keep it)",
            RuntimeWarning,
            stacklevel=3,
        )
        path = _written(fallback, name, source)
    return _load(path, f"wip_gym_generated_{name}")


def _private_temporary_directory() -> Path:
    """``<tmp>/wip-gym-numba-<uid>``, made by this user with mode ``0o700``; if it exists as
    another user's, a link, or writable by others than its owner (a file planted there would
    be executed), a fresh directory of ``tempfile.mkdtemp`` instead, removed when the process
    exits (not reused: each such process compiles its module again)."""
    uid = os.getuid() if hasattr(os, "getuid") else None
    directory = Path(tempfile.gettempdir()) / f"wip-gym-numba-{uid if uid is not None else 'user'}"
    try:
        directory.mkdir(mode=0o700, exist_ok=True)
        status = directory.lstat()
        private = (uid is None or status.st_uid == uid) and not status.st_mode & 0o022
        if private and not directory.is_symlink():
            return directory
    except OSError:
        pass
    fresh = Path(tempfile.mkdtemp(prefix="wip-gym-numba-"))
    atexit.register(shutil.rmtree, fresh, ignore_errors=True)
    return fresh


def _written(directory: Path, name: str, source: str) -> Path:
    """``directory/name.py`` holding ``source``: written whole to a temporary file, then put
    in place only if no file is there (a process never reads half a file, and a file in place
    is never rewritten: numba's cache is keyed on its time stamp), even when processes race;
    readable by all (mode ``0o644``). On a file system
    without hard links, a rename put in place only if no file is there yet: two processes
    racing there may both rename, which changes nothing but the time stamp (one more
    compilation)."""
    path = directory / f"{name}.py"
    if path.exists():
        return path
    directory.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=directory, prefix=f".{name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as file:
            with contextlib.suppress(OSError, AttributeError):  # a convenience only
                os.fchmod(file.fileno(), 0o644)  # mkstemp makes it 0o600: others may share it
            file.write(source)
        try:
            os.link(temporary, path)
        except FileExistsError:
            pass  # another process wrote it first (the same source: its name is its hash)
        except OSError:  # a file system without hard links
            if not path.exists():
                os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
    return path


def _load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load the generated module {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


_LOCK = threading.Lock()
_MODULES: dict[tuple[Any, ...], ModuleType] = {}
