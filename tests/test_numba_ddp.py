"""The MPC's numba backend (``controllers.optimizer.numba_ddp``) against the JAX reference:
the same steps to round-off along a plan and past its end, with the penalty active and not,
with other weights and bounds through the same machine code, through failed line searches
and raised mu, and through a rejected solution; its refusals; its module on disk."""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
import pickle
import re
from pathlib import Path

import numpy as np
import pytest

from controllers.high_level.mpc import (
    _N_PARAMS,
    ModelPredictiveController,
    MPCConfig,
    MPCStep,
    numba_step,
    pack_inputs,
    params_from_vector,
)
from controllers.high_level.planning import Plan, PlanConfig, plan_to_goal
from controllers.optimizer import numba_ddp
from controllers.simplified.wipm import WIPMParams
from controllers.simplified.wipm_problem import ddp_solver_for, refs_for
from tests import ddp_recorded


@pytest.fixture(scope="module")
def params() -> WIPMParams:
    return ddp_recorded.params_from_arrays(dict(np.load(ddp_recorded.PATH)))


@pytest.fixture(scope="module")
def plans(params: WIPMParams) -> dict[str, Plan]:
    theta0 = float(np.load(ddp_recorded.PATH)["theta0"])
    return {
        problem: plan_to_goal(
            ddp_recorded.initial_state(problem, theta0),
            params,
            np.array(goal),
            planar=problem == "planar",
            config=PlanConfig(),
        )
        for problem, goal in ddp_recorded.GOALS.items()
    }


def _assert_same_step(ours: MPCStep, reference: MPCStep, what: str) -> None:
    """Equal to round-off: 1e-10 of each array's scale, the cost to 1e-12 relative."""
    assert ours.accepted == reference.accepted, what
    for a, b in (
        (ours.predicted_controls, reference.predicted_controls),
        (ours.predicted_states, reference.predicted_states),
    ):
        scale = max(float(np.abs(b).max()), 1.0)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * scale, err_msg=what)
    assert ours.cost == pytest.approx(reference.cost, rel=1e-12), what


@pytest.mark.parametrize("problem", ["planar", "3d"])
def test_numba_steps_equal_the_jax_steps_along_a_plan_and_past_its_end(
    problem: str, plans: dict[str, Plan], params: WIPMParams
) -> None:
    """Warm-started MPC steps from disturbed plan states, each backend carrying its own warm
    start, from the plan's start to past its end (the window padded with the goal), and from
    a negative index (taken as 0 by both): the same predictions, costs and acceptances. The
    penalty is active at some of the predicted steps and not at others (checked), and the
    solves did work (their controls left the warm start)."""
    plan = plans[problem]
    numba_mpc = ModelPredictiveController(plan, MPCConfig())
    jax_mpc = ModelPredictiveController(plan, MPCConfig(backend="jax"))
    assert numba_mpc.config.backend == "numba"
    rng = np.random.default_rng(3)
    penalty, moved = [], []
    last = len(plan.states) - 1
    for index in [*range(0, 400, 40), last - 20, last, last + 50]:
        state = plan.states[min(index, last)] + 0.02 * rng.normal(size=plan.states.shape[1])
        ours = numba_mpc.step(index, state, params)
        reference = jax_mpc.step(index, state, params)
        _assert_same_step(ours, reference, f"index {index}")
        u = reference.predicted_controls
        active = [
            bool(numba_mpc.problem.penalty(x, u_k, params)[1])
            for x, u_k in zip(reference.predicted_states, u, strict=False)
        ]
        penalty.append(sum(active) / len(active))
        window = plan.control_window(min(index, last), numba_mpc.horizon)
        moved.append(float(np.abs(u - window).max()))
    assert 0 < np.mean(penalty) < 1  # the penalty's cond both ways
    assert max(moved) > 1e-3
    assert numba_mpc.solves == jax_mpc.solves and numba_mpc.rejected == jax_mpc.rejected == 0
    # a negative index, packed by hand (inputs() clamps it): both take the window at 0
    state = plan.states[0] + 0.01
    steps = {}
    for name, mpc in (("numba", numba_mpc), ("jax", jax_mpc)):
        fresh = ModelPredictiveController(plan, mpc.config)
        steps[name, -5] = fresh.solve(pack_inputs(-5, True, state, params))
        steps[name, 0] = ModelPredictiveController(plan, mpc.config).solve(
            pack_inputs(0, True, state, params)
        )
    for name in ("numba", "jax"):
        np.testing.assert_array_equal(
            steps[name, -5].predicted_controls, steps[name, 0].predicted_controls
        )
    _assert_same_step(steps["numba", -5], steps["jax", -5], "index -5")


def test_other_weights_and_bounds_run_through_the_same_machine_code(
    plans: dict[str, Plan], params: WIPMParams
) -> None:
    """The problem's numbers are inputs of the generated code: an MPC with other weights and
    bounds shares the module (no new compilation) and still solves as the JAX backend. A
    problem whose weight vectors have other lengths gets its own module, and inputs of other
    lengths than the module's are refused."""
    plan = plans["planar"]
    default = ModelPredictiveController(plan)
    other = dataclasses.replace(MPCConfig(), q_theta=50.0, r_control=0.5, q_terminal=3e4)
    tight = dataclasses.replace(plan, a_max=0.3, theta_max=0.05)
    mpc = ModelPredictiveController(tight, other)
    reference = ModelPredictiveController(tight, dataclasses.replace(other, backend="jax"))
    assert mpc.compiled.module is default.compiled.module  # type: ignore[union-attr]
    assert mpc.problem.weights != default.problem.weights
    state = plan.states[60] + 0.01
    _assert_same_step(mpc.step(60, state, params), reference.step(60, state, params), "other")
    np.testing.assert_array_equal(mpc.compiled.constants, mpc.problem.constants())  # type: ignore[union-attr]
    assert mpc.problem.with_constants(mpc.problem.constants()) == mpc.problem
    layout = params_from_vector(np.zeros(_N_PARAMS))
    weights = dataclasses.replace(mpc.problem.weights, r_rate=(0.1,))
    longer = dataclasses.replace(mpc.problem, weights=weights)
    assert numba_ddp.generated_module(longer, layout) is not mpc.compiled.module  # type: ignore[union-attr]
    host = pack_inputs(60, True, state, params)
    for short in (host[:-1], np.append(host, 0.0)):
        with pytest.raises(ValueError, match="another length"):
            mpc.solve(short)
    # the planar module given the 3-D problem's widths, or other lengths, refuses them
    module, step = mpc.compiled.module, mpc.compiled  # type: ignore[union-attr]
    warm = np.zeros((mpc.horizon, 1))
    plan_states, plan_controls = mpc._plan_states, mpc._plan_controls
    wide_host = pack_inputs(60, True, np.zeros(8), params)  # a host as long as 8 states need
    for what, h, states, controls, constants, settings in (
        ("width", wide_host, np.zeros((plan_states.shape[0], 8)), plan_controls, None, None),
        ("width", host, plan_states, np.zeros((plan_controls.shape[0], 2)), None, None),
        ("length", host, plan_states, plan_controls, step.constants[:-1], None),
        ("length", host, plan_states, plan_controls, None, step.settings[:-1]),
    ):
        constants = step.constants if constants is None else constants
        settings = step.settings if settings is None else settings
        with pytest.raises(ValueError, match=f"another {what}"):
            module.mpc_step(h, warm, states, controls, constants, settings, step.alphas)
    # solve, called directly, checks the widths too (its stage code reads fixed offsets)
    H = mpc.horizon
    P, C = host[6:], step.constants
    U, S = np.zeros((H, 1)), np.zeros((H + 1, 4))
    for x0, S_ in ((np.zeros(3), S), (np.zeros(4), np.zeros((H + 1, 3)))):
        X_init = np.empty((H + 1, x0.size))
        with pytest.raises(ValueError, match="another width"):
            module.solve(x0, U, S_, P, C, step.settings, step.alphas, X_init)


#: (name, problem, MPCConfig changes, DDPConfig changes) of the schedule test
_SCHEDULE_CASES = (
    # one step size and a strict acceptance ratio: line searches fail and mu rises
    (
        "failed searches",
        "planar",
        {},
        {"max_iterations": 6, "alphas": (1.0,), "line_search_c": 0.9},
    ),
    ("failed searches", "3d", {}, {"max_iterations": 6, "alphas": (1.0,), "line_search_c": 0.9}),
    # ... and with a low ceiling on mu the solve is stuck and stops before its budget
    (
        "stuck",
        "planar",
        {},
        {"max_iterations": 30, "alphas": (1.0,), "line_search_c": 0.9, "mu_max": 50.0},
    ),
    # a negative control weight: backward passes fail (Q_uu not positive) and are retried
    ("failed backward", "planar", {"r_control": -50.0}, {"max_iterations": 4}),
    # the stopping test (9) ends the solve before its budget
    (
        "tolerance",
        "planar",
        {},
        {"max_iterations": 50, "abs_tolerance": 100.0, "final_backward": True},
    ),
    ("final backward", "3d", {}, {"final_backward": True}),
    ("no iteration", "3d", {}, {"max_iterations": 0}),
)


def test_the_regularisation_schedule_and_the_stopping_test_follow_the_jax_solver(
    plans: dict[str, Plan], params: WIPMParams
) -> None:
    """The numba solve against the JAX solver in the corners of the loop (_SCHEDULE_CASES):
    failed line searches (mu rises: the JAX solver's mu history shows it), a solve stuck at
    ``mu_max``, failed backward passes retried, the stopping test, the final backward pass and
    a budget of 0. The iterations, states, controls and costs are the JAX solver's, and each
    case reaches the corner it is named for."""
    from controllers.high_level.mpc import mpc_problem

    for name, problem_name, mpc_change, ddp_change in _SCHEDULE_CASES:
        plan = plans[problem_name]
        mpc_config = dataclasses.replace(MPCConfig(), **mpc_change)  # type: ignore[arg-type]
        problem = mpc_problem(plan.planar, mpc_config, plan.a_max, plan.theta_max)
        base = ModelPredictiveController(plan).solver.config
        config = dataclasses.replace(base, **ddp_change)  # type: ignore[arg-type]
        horizon = MPCConfig().steps
        x0 = plan.states[100] + 0.01
        U = plan.control_window(100, horizon)
        S = np.ascontiguousarray(plan.window(100, horizon + 1))
        P = np.array(pack_inputs(0, False, x0, params)[2 + x0.size :])
        ours = ddp_solver_for(problem, config).jitted(x0, U, params, refs_for(S, params))
        settings, alphas = numba_ddp.settings_vector(config)
        module = numba_ddp.generated_module(problem, params_from_vector(np.zeros(_N_PARAMS)))
        X, Un, cost, initial, iterations, mu_last, K, k = module.solve(
            x0, U, S, P, problem.constants(), settings, alphas, np.empty_like(S)
        )
        what = f"{name} ({problem_name})"
        assert iterations == int(ours.iterations), what
        np.testing.assert_allclose(Un, np.asarray(ours.U), rtol=0, atol=1e-9, err_msg=what)
        np.testing.assert_allclose(X, np.asarray(ours.X), rtol=0, atol=1e-9, err_msg=what)
        assert initial == pytest.approx(float(ours.cost_history[0]), rel=1e-12), what
        assert cost == pytest.approx(float(ours.cost), rel=1e-12), what
        mu = np.asarray(ours.mu_history)
        # the schedule itself, and the last backward pass's gains (the final one's, if asked)
        assert mu_last == pytest.approx(float(mu[-1]), rel=1e-12), what
        for ours_gain, jax_gain in ((K, ours.K), (k, ours.k)):
            reference = np.asarray(jax_gain)
            assert np.isfinite(reference).all(), what
            scale = max(float(np.abs(reference).max()), 1.0)
            np.testing.assert_allclose(
                ours_gain, reference, rtol=0, atol=1e-8 * scale, err_msg=what
            )
        budget = config.max_iterations
        if name == "failed searches":
            assert (np.diff(mu) > 0).any(), what
        elif name == "stuck":
            assert iterations < budget and not bool(ours.converged), what
        elif name == "failed backward":
            assert mu[0] > config.mu_init, what  # the first pass was retried with mu raised
        elif name == "tolerance":
            assert iterations < budget and bool(ours.converged), what
        elif name == "no iteration":
            assert iterations == 0 and np.array_equal(Un, U), what
        else:
            assert iterations == budget, what


def test_a_rejected_solution_keeps_the_warm_start_as_the_jax_backend_does(
    plans: dict[str, Plan], params: WIPMParams
) -> None:
    """``lambda(q)`` with an infinite mass makes every rollout NaN: both backends reject the
    solution, keep the warm start rolled out open loop, and count the rejection."""
    plan = plans["3d"]
    broken = params._replace(body_mass=np.float64(math.inf))
    outs = []
    for backend in ("numba", "jax"):
        mpc = ModelPredictiveController(plan, MPCConfig(backend=backend))
        mpc.step(10, plan.states[10], params)  # a good step first: the warm start is its own
        outs.append((mpc.step(11, plan.states[11], broken), mpc))
    (ours, numba_mpc), (reference, jax_mpc) = outs
    assert not ours.accepted and not reference.accepted
    assert numba_mpc.rejected == jax_mpc.rejected == 1
    np.testing.assert_allclose(
        ours.predicted_controls, reference.predicted_controls, rtol=0, atol=1e-10
    )
    np.testing.assert_array_equal(
        np.isnan(ours.predicted_states), np.isnan(reference.predicted_states)
    )
    assert np.isnan(ours.cost) and np.isnan(reference.cost)


def test_refusals_copies_and_the_module_on_disk(plans: dict[str, Plan], params: WIPMParams) -> None:
    """The settings the numba DDP does not run are refused by name, as is an unknown backend;
    a copied or pickled MPC (either backend) shares the step and solves as the original, and
    the step pickles as itself;
    the module on disk is the generated source, named by its hash, and its solves release the
    GIL."""
    plan = plans["planar"]
    for change in ({"second_order": True}, {"gradient_norm": True}):
        ddp = dataclasses.replace(MPCConfig().ddp, **change)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="refused: " + next(iter(change))):
            ModelPredictiveController(plan, MPCConfig(ddp=ddp))
        ModelPredictiveController(plan, MPCConfig(ddp=ddp, backend="jax"))  # the reference runs it
    with pytest.raises(ValueError, match="backend must be"):
        MPCConfig(backend="xla")  # type: ignore[arg-type]
    rate_input = dataclasses.replace(ModelPredictiveController(plan).problem, rate_input=True)
    with pytest.raises(ValueError, match="rate input"):
        numba_ddp.generated_module(rate_input, params)
    mpc = ModelPredictiveController(plan)
    mpc.step(0, plan.states[0], params)
    twin = copy.deepcopy(mpc)
    assert twin.compiled is mpc.compiled is numba_step(mpc.problem, mpc.compiled.ddp)  # type: ignore[union-attr]
    assert pickle.loads(pickle.dumps(mpc.compiled)) is mpc.compiled
    state = plan.states[10] + 0.01
    a, b = mpc.step(10, state, params), twin.step(10, state, params)
    np.testing.assert_array_equal(a.predicted_controls, b.predicted_controls)
    for backend in ("numba", "jax"):  # a pickled MPC: the shared step and solver, found again
        original = ModelPredictiveController(plan, MPCConfig(backend=backend))
        original.step(0, plan.states[0], params)
        unpickled = pickle.loads(pickle.dumps(original))
        assert unpickled.compiled is original.compiled and unpickled.solver is original.solver
        a, b = original.step(10, state, params), unpickled.step(10, state, params)
        np.testing.assert_array_equal(a.predicted_controls, b.predicted_controls)
    module = mpc.compiled.module  # type: ignore[union-attr]
    path = Path(module.__file__)
    layout = params_from_vector(np.zeros(_N_PARAMS))
    source = numba_ddp.module_source(mpc.problem, layout)
    assert path.parent == numba_ddp.cache_dir() and path.read_text() == source
    assert path.stem.endswith(hashlib.sha256(source.encode()).hexdigest()[:16])
    for name in ("mpc_step", "solve", "backward_stage"):
        options = getattr(module, name).targetoptions
        assert options.get("nogil") is True, name
        # fused multiply-adds only: no fast-math flag that lets NaN or inf lose their meaning
        assert set(options.get("fastmath")) == {"contract"}, name
    # every generated function carries the options asked for
    other = numba_ddp.module_source(mpc.problem, layout, "cache=True")
    functions = source.count("\ndef ")
    assert other.count("@numba.njit(cache=True)\ndef ") == functions > 10


def test_the_generated_backward_stage_writes_v_xx_from_one_triangle(
    plans: dict[str, Plan],
) -> None:
    """``riccati_step`` mirrors the upper triangle of the new ``V_xx`` (``_mirrored_upper``): in
    the generated 3-D backward stage, ``V_xx[i, j]`` and ``V_xx[j, i]`` are written from the same
    variable, so the other triangle's products are dead code for the compiler."""
    mpc = ModelPredictiveController(plans["3d"])
    layout = params_from_vector(np.zeros(_N_PARAMS))
    source = numba_ddp.module_source(mpc.problem, layout)
    stage = source[source.index("def backward_stage(") :]
    stage = stage[: stage.index("\n@numba.njit")]
    written = dict(re.findall(r"^    out\[(\d+)\] = (\S+)$", stage, flags=re.MULTILINE))
    n = mpc.problem.n_state
    for i in range(n):
        for j in range(i + 1, n):
            upper, lower = written[str(n + i * n + j)], written[str(n + j * n + i)]
            assert upper == lower, (i, j)


def test_an_unwritable_cache_directory_falls_back_to_a_temporary_one(
    plans: dict[str, Plan], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``WIP_GYM_NUMBA_CACHE`` under a file (not a directory): the module is written under the
    temporary directory instead, with a warning that names the setting; a file in place is
    never rewritten (numba's cache is keyed on its time stamp)."""
    import tempfile

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv(numba_ddp.CACHE_ENV, str(blocker / "cache"))
    temporary = tmp_path / "tmp"  # the fallback's temporary directory, this test's own
    temporary.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temporary))
    problem = ModelPredictiveController(plans["planar"]).problem
    layout = params_from_vector(np.zeros(_N_PARAMS))
    with pytest.warns(RuntimeWarning, match=numba_ddp.CACHE_ENV):
        module = numba_ddp._write_and_load(problem, layout)
    path = Path(module.__file__)
    assert path.parent.parent == temporary and path.parent.stat().st_mode & 0o077 == 0
    assert path.read_text() == numba_ddp.module_source(problem, layout)
    assert path.stat().st_mode & 0o777 == 0o644  # others sharing a cache can read it
    stamp = path.stat().st_mtime_ns
    again = numba_ddp._written(path.parent, path.stem, "another source")
    assert again == path and path.stat().st_mtime_ns == stamp
    assert not list(path.parent.glob(".*.tmp"))  # no temporary file left behind


def test_the_fallback_directory_is_refused_when_others_can_write_to_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fallback directory ``<tmp>/wip-gym-numba-<uid>`` is used when it is this user's and
    private; writable by others, or a link, it is not (a planted module would be executed), and
    a fresh directory is made instead."""
    import os
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    removed_at_exit: list[Path] = []
    monkeypatch.setattr(
        numba_ddp.atexit, "register", lambda function, path, **_: removed_at_exit.append(path)
    )
    first = numba_ddp._private_temporary_directory()
    assert first.parent == tmp_path and first.stat().st_mode & 0o077 == 0
    assert numba_ddp._private_temporary_directory() == first  # reused
    os.chmod(first, 0o777)
    shared = numba_ddp._private_temporary_directory()
    assert shared != first and shared.parent == tmp_path and shared.stat().st_mode & 0o077 == 0
    first.rmdir()
    (tmp_path / "elsewhere").mkdir(mode=0o700)
    first.symlink_to(tmp_path / "elsewhere")
    fresh = numba_ddp._private_temporary_directory()
    assert fresh not in (first, tmp_path / "elsewhere")
    # the fresh directories, and only they, are removed when the process exits
    assert removed_at_exit == [shared, fresh]


def test_a_module_file_is_put_in_place_once_whatever_the_file_system(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``_written``: a file another process put in place first is kept (its link fails with
    ``FileExistsError``); on a file system without hard links the file is renamed into place;
    either way no temporary file is left and the file is readable by all."""
    import os

    source = "x = 1\n"
    real_link = os.link

    def racing_link(src: str, dst: str) -> None:  # another process wins the race
        Path(dst).write_text("first\n")
        real_link(src, dst)  # raises FileExistsError

    monkeypatch.setattr(os, "link", racing_link)
    raced = numba_ddp._written(tmp_path / "race", "module", source)
    assert raced.read_text() == "first\n"

    def no_links(src: str, dst: str) -> None:
        raise OSError("hard links not supported")

    monkeypatch.setattr(os, "link", no_links)
    renamed = numba_ddp._written(tmp_path / "nolink", "module", source)
    assert renamed.read_text() == source and renamed.stat().st_mode & 0o777 == 0o644
    for directory in (tmp_path / "race", tmp_path / "nolink"):
        assert not list(directory.glob(".*.tmp"))
