"""Strict priorities (controllers/low_level/priorities.py): DAQP's levels, checked against
independent solutions: a null-space chain for equality hierarchies, least squares for one level,
ProxQP for each of the first two levels of hierarchies with inequalities."""

from __future__ import annotations

import numpy as np
import proxsuite
import pytest

from controllers.low_level.priorities import Level, equal_norm_rows, solve_lexicographic

NO_HARD = (np.zeros((0, 2)), np.zeros(0), np.zeros(0))


def _null_space_chain(n: int, levels) -> np.ndarray:
    """Equality levels only: each level's least squares in the null space of those above, the
    smallest ``x`` at the end."""
    x, N = np.zeros(n), np.eye(n)
    for level in levels:
        if N.shape[1] == 0:
            break
        z, *_ = np.linalg.lstsq(level.A @ N, level.b - level.A @ x, rcond=1e-10)
        x = x + N @ z
        _, s, Vt = np.linalg.svd(level.A @ N)
        rank = int((s > 1e-10 * max(s.max(initial=0.0), 1.0)).sum())
        N = N @ Vt[rank:].T
    return x


def _proxqp(H, g, A, b, C, lower, upper):
    qp = proxsuite.proxqp.dense.QP(len(g), len(A), len(C))
    qp.settings.eps_abs = 1e-10
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 20000
    qp.init(H, g, A if len(A) else None, b if len(A) else None, C, lower, upper, False)
    qp.solve()
    assert qp.results.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
    return np.array(qp.results.x)


def test_the_textbook_example():
    """{x1 + x2 = 2} over {x1 = 3, x2 = 3}: (1, 1)."""
    levels = [
        Level.equalities("first", np.array([[1.0, 1.0]]), np.array([2.0])),
        Level.equalities("second", np.eye(2), np.array([3.0, 3.0])),
    ]
    solution = solve_lexicographic(*NO_HARD, levels)
    assert solution.solved and solution.exitflag == 2  # the second level is relaxed
    np.testing.assert_allclose(solution.x, [1.0, 1.0], atol=1e-9)


def test_equal_norm_rows_keep_the_residual_and_equalise_the_rows():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(5, 7)) * np.array([[100.0], [1.0], [0.1], [10.0], [3.0]])
    b = rng.normal(size=5)
    Ae, be = equal_norm_rows(A, b)
    norms = np.linalg.norm(Ae, axis=1)
    np.testing.assert_allclose(norms, norms.mean(), rtol=1e-10)
    for x in rng.normal(size=(10, 7)):
        assert np.linalg.norm(Ae @ x - be) == pytest.approx(np.linalg.norm(A @ x - b), rel=1e-10)


def test_one_level_of_weighted_rows_is_their_least_squares():
    """DAQP alone would normalise the rows ({x = 1, 10 x = 0} gives 0.5): with equal-norm rows
    the level is the least squares, x = 1 / 101."""
    level = Level.equalities("tasks", np.array([[1.0], [10.0]]), np.array([1.0, 0.0]))
    solution = solve_lexicographic(np.zeros((0, 1)), np.zeros(0), np.zeros(0), [level])
    assert solution.x[0] == pytest.approx(1.0 / 101.0, abs=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_equality_hierarchies_equal_the_null_space_chain(seed):
    rng = np.random.default_rng(seed)
    n = 9
    levels = [
        Level.equalities("balance", rng.normal(size=(2, n)), rng.normal(size=2)),
        Level.equalities("hand", rng.normal(size=(4, n)) * 10.0, rng.normal(size=4)),
        Level.equalities("posture", rng.normal(size=(n, n)), rng.normal(size=n)),
    ]
    solution = solve_lexicographic(np.zeros((0, n)), np.zeros(0), np.zeros(0), levels)
    assert solution.solved
    np.testing.assert_allclose(solution.x, _null_space_chain(n, levels), atol=1e-7)


def test_an_object_level_relaxed_under_the_balance_and_met_when_it_can_be():
    """One variable: balance asks x = 2, the object x <= 1: relaxed by 1, the balance met; with
    the balance at 0.5 the object's row holds."""
    hard = np.zeros((0, 1)), np.zeros(0), np.zeros(0)
    for target, relaxed in ((2.0, 1.0), (0.5, 0.0)):
        levels = [
            Level.equalities("balance", np.array([[1.0]]), np.array([target])),
            Level.inequalities("object", np.array([[1.0]]), np.array([1.0])),
        ]
        solution = solve_lexicographic(*hard, levels)
        assert solution.x[0] == pytest.approx(target, abs=1e-9)
        assert solution.slack["object"] == pytest.approx(relaxed, abs=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_random_hierarchies_keep_their_first_two_levels_optimal(seed):
    """Hard box bounds, a balance level, an object level of inequalities that conflicts with the
    levels below, a hand and a posture level: the hard rows hold, the balance residual is the
    best the hard rows allow, and the object's (normalised) violation is the least the balance
    allows; each checked by ProxQP alone."""
    rng = np.random.default_rng(seed)
    n = 8
    bound = rng.uniform(1.0, 3.0, n)
    balance = Level.equalities("balance", rng.normal(size=(2, n)), 5.0 * rng.normal(size=2))
    C = rng.normal(size=(4, n))
    obj = Level.inequalities("object", C, rng.normal(size=4) - 1.0)
    levels = [
        balance,
        obj,
        Level.equalities("hand", rng.normal(size=(3, n)), 3.0 * rng.normal(size=3)),
        Level.equalities("posture", rng.normal(size=(n, n)), rng.normal(size=n)),
    ]
    solution = solve_lexicographic(np.eye(n), -bound, bound, levels)
    assert solution.solved
    x = solution.x
    assert (np.abs(x) <= bound + 1e-9).all()
    # level 1: its least squares under the hard box
    first = _proxqp(
        balance.A.T @ balance.A + 1e-12 * np.eye(n), -balance.A.T @ balance.b,
        np.zeros((0, n)), np.zeros(0), np.eye(n), -bound, bound,
    )  # fmt: skip
    best = np.linalg.norm(balance.A @ first - balance.b)
    assert np.linalg.norm(balance.A @ x - balance.b) == pytest.approx(best, abs=1e-6)
    # level 2: the least normalised violation with the balance held (slack variables v)
    scale = np.linalg.norm(C, axis=1)
    k = len(C)
    H = np.zeros((n + k, n + k))
    H[n:, n:] = np.eye(k)
    H[:n, :n] = 1e-12 * np.eye(n)
    rows = np.vstack(
        [np.hstack([np.eye(n), np.zeros((n, k))]), np.hstack([C / scale[:, None], -np.eye(k)])]
    )
    lower = np.concatenate([-bound, np.full(k, -1e20)])
    upper = np.concatenate([bound, obj.d / scale])
    held = np.hstack([balance.A, np.zeros((2, k))])
    second = _proxqp(H, np.zeros(n + k), held, balance.A @ x, rows, lower, upper)
    least = np.linalg.norm(np.maximum(second[n:], 0.0))
    violation = np.linalg.norm(np.maximum(C @ x - obj.d, 0.0) / scale)
    assert violation == pytest.approx(least, abs=1e-6)
    assert solution.slack["object"] == pytest.approx(
        float(np.max(np.maximum(C @ x - obj.d, 0.0) / scale)), abs=1e-6
    )


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="columns"):
        solve_lexicographic(*NO_HARD, [Level.equalities("a", np.ones((1, 3)), np.ones(1))])
    with pytest.raises(ValueError, match="one bound per row"):
        solve_lexicographic(*NO_HARD, [Level.equalities("a", np.ones((1, 2)), np.ones(2))])
    with pytest.raises(ValueError, match="NaN"):
        solve_lexicographic(*NO_HARD, [Level.equalities("a", np.ones((1, 2)), np.array([np.nan]))])
