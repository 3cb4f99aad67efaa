"""Correctness guards of the DDP's speed work: the offline plan and the MPC give the
results recorded before it (tests/data/ddp_recorded.npz, see tests/ddp_recorded.py), the
closed-form running-cost derivatives and the dynamics' derivatives along fewer directions equal
autodiff's, the MPC step is compiled once, and the
persistent compilation cache works from an empty directory."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from controllers.high_level import mpc as mpc_module
from controllers.high_level.mpc import ModelPredictiveController, MPCConfig, mpc_problem
from controllers.high_level.planning import PlanConfig, plan_to_goal, planning_problem
from controllers.optimizer import ddp
from tests import ddp_recorded

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    return dict(np.load(ddp_recorded.PATH))


@pytest.fixture(scope="module")
def computed(reference: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    params = ddp_recorded.params_from_arrays(reference)
    return ddp_recorded.compute(params, float(reference["theta0"]))


@pytest.mark.parametrize("problem", ["planar", "3d"])
def test_plan_and_mpc_equal_the_recorded_reference(
    problem: str, reference: dict[str, np.ndarray], computed: dict[str, np.ndarray]
) -> None:
    """The plan and the MPC's steps (both backends: the default, numba, and the JAX reference
    the recording was made with) against the recording. The summation order of the small
    matrix products changed since it was made (dot -> element-wise sums), so results agree to
    round-off, not bit for bit: 1e-9 relative to each array's scale."""
    keys = [k for k in computed if k.startswith((f"{problem}_", f"jax_{problem}_"))]
    assert len(keys) == 12
    for key in keys:
        expected = reference[key.removeprefix("jax_")].astype(float)
        scale = max(float(np.max(np.abs(expected))), 1.0)
        np.testing.assert_allclose(
            np.asarray(computed[key], dtype=float),
            expected,
            rtol=0.0,
            atol=1e-9 * scale,
            err_msg=key,
        )


def _random_points(problem, rng: np.random.Generator, count: int) -> list[tuple]:
    """Points (z, w) around the penalties' thresholds: some inside, some outside."""
    n, m = problem.n_state, problem.n_control
    nz = n + m if problem.rate_input else n
    nw = m
    points = []
    for i in range(count):
        z = rng.normal(scale=0.3, size=nz)
        w = rng.normal(scale=3.0 if i % 2 else 0.3, size=nw)
        if problem.rate_input:
            z[n:] *= 10.0 if i % 3 == 0 else 1.0  # large thdd: acceleration penalty active
        else:
            w *= 10.0 if i % 3 == 0 else 1.0
        points.append((z, w))
    return points


@pytest.mark.parametrize("planar", [True, False])
@pytest.mark.parametrize("kind", ["plan", "mpc"])
def test_running_derivatives_equal_autodiff(
    planar: bool, kind: str, reference: dict[str, np.ndarray]
) -> None:
    params = ddp_recorded.params_from_arrays(reference)
    if kind == "plan":
        problem = planning_problem(planar, PlanConfig(), a_max=1.0, heading_given=False)
    else:
        problem = mpc_problem(planar, MPCConfig(), a_max=1.0, theta_max=0.25)
    running, _ = problem.costs()
    derivatives = jax.jit(problem.running_derivatives())
    grad = jax.jit(jax.grad(running, argnums=(0, 1)))
    hessian = jax.jit(jax.hessian(running, argnums=(0, 1)))
    rng = np.random.default_rng(3)
    active = 0
    for z, w in _random_points(problem, rng, 24):
        s_ref = rng.normal(scale=0.5, size=problem.n_state)
        ref = (s_ref, params)
        s, u = (z[: problem.n_state], z[problem.n_state :]) if problem.rate_input else (z, w)
        active += bool(problem.penalty(s, u, params)[1])
        lx, lu, lxx, lux, luu = derivatives(z, w, ref)
        gx, gu = grad(z, w, ref)
        (hxx, _), (hux, huu) = hessian(z, w, ref)
        for got, want in ((lx, gx), (lu, gu), (lxx, hxx), (lux, hux), (luu, huu)):
            scale = max(float(np.max(np.abs(want))), 1.0)
            np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-12 * scale)
    assert 4 <= active <= 20  # both branches were exercised


@pytest.mark.parametrize("planar", [True, False])
def test_penalty_depends_only_on_its_inputs(planar: bool, reference: dict[str, np.ndarray]) -> None:
    # running_derivatives differentiates the penalty along penalty_inputs only
    params = ddp_recorded.params_from_arrays(reference)
    problem = mpc_problem(planar, MPCConfig(), a_max=1.0, theta_max=0.25)
    n = problem.n_state

    def value(v: np.ndarray) -> jax.Array:
        return problem.penalty(v[:n], v[n:], params)[0]

    gradient = jax.jit(jax.grad(value))
    others = [i for i in range(n + problem.n_control) if i not in problem.penalty_inputs]
    rng = np.random.default_rng(5)
    active = 0
    for z, w in _random_points(problem, rng, 24):
        v = np.concatenate([z, w])
        active += bool(problem.penalty(v[:n], v[n:], params)[1])
        g = np.asarray(gradient(v))
        assert np.all(g[others] == 0.0)
    assert active >= 4


@pytest.mark.parametrize("planar", [True, False])
@pytest.mark.parametrize("kind", ["plan", "mpc"])
def test_dynamics_derivatives_equal_autodiff(
    planar: bool, kind: str, reference: dict[str, np.ndarray]
) -> None:
    """The DDP's ``f_x``, ``f_u`` (autodiff along ``dynamics_inputs`` only) equal
    ``jax.jacfwd`` of the discrete step, with and without the rate input."""
    params = ddp_recorded.params_from_arrays(reference)
    if kind == "plan":
        problem = planning_problem(planar, PlanConfig(), a_max=1.0, heading_given=False)
    else:
        problem = mpc_problem(planar, MPCConfig(), a_max=1.0, theta_max=0.25)
    derivatives = jax.jit(problem.dynamics_derivatives())
    jacobian = jax.jit(jax.jacfwd(problem.dynamics(), argnums=(0, 1)))
    for z, w in _random_points(problem, np.random.default_rng(8), 24):
        for got, want in zip(derivatives(z, w, params), jacobian(z, w, params), strict=True):
            assert got.shape == want.shape
            scale = max(float(np.max(np.abs(want))), 1.0)
            np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-15 * scale)


@pytest.mark.parametrize("planar", [True, False])
def test_dynamics_depend_only_on_their_inputs(
    planar: bool, reference: dict[str, np.ndarray]
) -> None:
    """``dynamics_inputs`` names every entry of ``[s, u]`` the continuous model reads: its
    Jacobian is exactly zero in the others (and not in these)."""
    params = ddp_recorded.params_from_arrays(reference)
    problem = mpc_problem(planar, MPCConfig(), a_max=1.0, theta_max=0.25)
    n = problem.n_state

    def value(v: np.ndarray) -> jax.Array:
        return problem.continuous(v[:n], v[n:], params)

    jacobian = jax.jit(jax.jacfwd(value))
    read = np.zeros(n + problem.n_control, dtype=bool)
    for z, w in _random_points(problem, np.random.default_rng(9), 24):
        columns = np.any(np.asarray(jacobian(np.concatenate([z, w]))) != 0.0, axis=0)
        read |= columns
    assert tuple(np.flatnonzero(read)) == problem.dynamics_inputs


def test_mpc_step_is_traced_once(reference: dict[str, np.ndarray]) -> None:
    params = ddp_recorded.params_from_arrays(reference)
    state = ddp_recorded.initial_state("planar", float(reference["theta0"]))
    plan = plan_to_goal(state, params, np.array([2.0, 0.0]), planar=True)
    mpc = ModelPredictiveController(plan, MPCConfig(backend="jax"))
    # the compiled step is shared by every MPC of this problem and horizon: count the traces
    # made here (another test may have traced it for a plan of another length already)
    before = mpc.compiled.trace_count
    rng = np.random.default_rng(0)
    for index in range(0, 2400, 60):  # past the plan's end too
        mpc.step(index, plan.states[min(index, 2000)] + 0.01 * rng.normal(size=4), params)
    # a new controller on the same problem and horizon
    again = ModelPredictiveController(plan, MPCConfig(backend="jax"))
    again.step(5, plan.states[5], params)
    assert mpc.compiled is again.compiled
    assert mpc.compiled.trace_count - before <= 1
    assert mpc.solves == 40 and mpc.rejected == 0


_CACHE_SCRIPT = """
from controllers.optimizer import jax_setup
jax_setup.configure()  # a new process is an entry point: the settings, the cache among them
import numpy as np, jax.numpy as jnp
from controllers.optimizer.ddp import make_ddp_solver, DDPConfig
def dynamics(x, u, p):
    return x + 0.1 * jnp.array([x[1], u[0] - p * jnp.sin(x[0])])
def running(x, u, r):
    return jnp.sum((x - r) ** 2) + 0.1 * jnp.sum(u * u)
def terminal(x, r):
    return 10.0 * jnp.sum((x - r) ** 2)
solver = make_ddp_solver(dynamics, running, terminal, DDPConfig(max_iterations=20))
out = solver(np.array([0.5, 0.0]), np.zeros((30, 1)), 9.81, np.zeros((31, 2)))
print(repr(float(out.cost)))
"""


def test_compilation_cache_starts_from_an_empty_directory(tmp_path: Path) -> None:
    cache = tmp_path / "jax-cache"
    env = os.environ | {"WIP_GYM_JAX_CACHE": str(cache)}
    costs = []
    for _ in range(2):  # the first process fills the cache, the second reads it
        done = subprocess.run(
            [sys.executable, "-c", _CACHE_SCRIPT],
            cwd=REPO,
            env=env,
            capture_output=True,
            text=True,
            check=True,
            timeout=300,
        )
        costs.append(float(done.stdout.strip().splitlines()[-1]))
        assert cache.is_dir() and any(cache.iterdir())
    assert np.isfinite(costs[0]) and costs[0] == costs[1]


def test_line_search_takes_the_same_step_however_many_alphas_it_tries_alone(
    reference: dict[str, np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The line search tries the largest alphas one at a time (``ddp._ALPHAS_ALONE``) before
    the rest in parallel: the accepted step is the largest acceptable alpha whatever that
    count, so 60 warm-started planar MPC steps along a plan are the same with 1, 2 (the
    default) and all 11 tried alone. The steps do reach the searches: with ``alpha = 1`` alone,
    or 1 and 1/2, the results differ."""
    params = ddp_recorded.params_from_arrays(reference)
    plan = plan_to_goal(
        ddp_recorded.initial_state("planar", float(reference["theta0"])),
        params,
        np.array(ddp_recorded.GOALS["planar"]),
        planar=True,
        config=PlanConfig(),
    )

    def predictions(alone: int, alphas: tuple[float, ...] | None = None) -> np.ndarray:
        monkeypatch.setattr(ddp, "_ALPHAS_ALONE", alone)
        mpc_module.compiled_step.cache_clear()  # trace again with this count
        config = MPCConfig(backend="jax")  # the JAX solver's line search
        if alphas is not None:
            config = dataclasses.replace(config, ddp=dataclasses.replace(config.ddp, alphas=alphas))
        controller = ModelPredictiveController(plan, config)
        steps = [controller.step(i, state, params) for i, state in enumerate(plan.states[:60])]
        return np.array([step.predicted_states for step in steps])

    try:
        default = predictions(2)
        for alone in (1, len(MPCConfig().ddp.alphas)):
            np.testing.assert_allclose(predictions(alone), default, rtol=0, atol=1e-12)
        for alphas in ((1.0,), (1.0, 0.5)):
            assert np.abs(predictions(2, alphas) - default).max() > 1e-6
    finally:
        mpc_module.compiled_step.cache_clear()  # no step traced under a patched count is kept
