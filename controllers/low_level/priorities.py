"""Strict task priorities: the task QP as a lexicographic problem, solved by DAQP's levels.

The weighted task QP (``controllers.low_level.task_qp``) trades every task against every other by
its weight. With strict priorities a level is met as well as it can be without worsening any
level above it: balance first, then the carried object's constraints, then the hand, then the
posture (``unified-upright``'s ``priority = "strict"``; docs/upright.md §4). The actuators' torque
limits and the joint limits stay hard constraints, above every level.

Each level holds equality rows ``A x = b`` (weighted tasks: rows and targets already scaled by
their weights, so that a level is the weighted least-squares problem of its own tasks) and
inequality rows ``C x <= d`` (the object's balance). DAQP (Arnström, Bemporad and Axehill; a dual
active-set solver with hierarchical levels) solves the whole hierarchy in one call: the first
block of rows is hard, each later block is a soft level whose violation is minimised without
worsening the blocks before it, and the remaining freedom goes to ``min 0.5 ||x||^2``. Its
``info["lam"]`` gives, for a soft row, the slack by which it is relaxed.

One trap, measured with daqp 0.11.0: DAQP normalises every row of a soft level before it
minimises the level's violation (the level ``{x = 1, 10 x = 0}`` gives ``x = 0.5``, not the
least-squares ``1/101``), so a level of weighted tasks would lose its weights. An orthogonal
change of a level's equality rows ``(A, b) -> (Q A, Q b)`` keeps ``||A x - b||`` and can give
every row the same norm (the Schur-Horn theorem: a symmetric matrix's diagonal can be made
constant by an orthogonal similarity; :func:`equal_norm_rows` does it with at most ``m - 1``
plane rotations). On such rows DAQP's normalised violation is the level's least squares, scaled.
An inequality level's rows are left as they are: its violation is measured row by row as a
distance, each row normalised (the object's rows are all in units of its weight).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import daqp
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: DAQP's stand-in for an infinite bound (its ``DAQP_INF``)
INFINITY = 1e30
#: DAQP's exit flags that give a usable point: 1 every level met, 2 some soft rows relaxed (the
#: normal answer to conflicting levels), 3 stopped early at a point that meets the levels solved
SOLVED_FLAGS = (1, 2, 3)
#: DAQP's regularisation of the soft levels (its default, 1e-6, left x up to 9e-6 off a
#: null-space chain's exact answer on 50 random equality hierarchies; 1e-10, up to 7e-9)
RHO_SOFT = 1e-10


@dataclass(frozen=True)
class Level:
    """One priority level: ``A x = b`` and ``C x <= d`` (either may be empty), and its name."""

    name: str
    A: Array
    b: Array
    C: Array
    d: Array

    @classmethod
    def equalities(cls, name: str, A: Array, b: Array) -> Level:
        return cls(name, A, b, np.zeros((0, A.shape[1])), np.zeros(0))

    @classmethod
    def inequalities(cls, name: str, C: Array, d: Array) -> Level:
        return cls(name, np.zeros((0, C.shape[1])), np.zeros(0), C, d)


@dataclass(frozen=True)
class LexicographicSolution:
    """``x``, DAQP's exit flag, and per level (by name) the largest slack of its inequality
    rows: 0 when they hold, else by how much (normalised) the worst one is relaxed."""

    x: Array
    exitflag: int
    slack: dict[str, float]

    @property
    def solved(self) -> bool:
        return self.exitflag in SOLVED_FLAGS and bool(np.all(np.isfinite(self.x)))


def equal_norm_rows(A: Array, b: Array) -> tuple[Array, Array]:
    """``(Q A, Q b)`` with ``Q`` orthogonal and every row of ``Q A`` of the same norm (module
    docstring). Each plane rotation of two rows, one longer and one shorter than the mean,
    makes the first exactly the mean: the squared row norms are the diagonal of ``A A^T``."""
    A, b = A.copy(), b.copy()
    m = len(A)
    if m < 2:
        return A, b
    target = float(np.sum(A * A)) / m
    scale = max(target, 1e-300)
    for _ in range(m - 1):
        norms = np.sum(A * A, axis=1)
        i, j = int(np.argmax(norms)), int(np.argmin(norms))
        if norms[i] - norms[j] <= 1e-12 * scale:
            break
        gii, gjj, gij = norms[i], norms[j], float(A[i] @ A[j])
        # rows (c A_i + s A_j, -s A_i + c A_j); the first's squared norm is target when
        # t = tan(angle) solves (gjj - target) t^2 + 2 gij t + (gii - target) = 0
        qa, qb, qc = gjj - target, 2.0 * gij, gii - target
        disc = max(qb * qb - 4.0 * qa * qc, 0.0)
        t = (-qb + np.sqrt(disc)) / (2.0 * qa) if qa != 0.0 else -qc / qb
        c = 1.0 / np.sqrt(1.0 + t * t)
        s = t * c
        A[i], A[j] = c * A[i] + s * A[j], -s * A[i] + c * A[j]
        b[i], b[j] = c * b[i] + s * b[j], -s * b[i] + c * b[j]
    return A, b


def solve_lexicographic(
    hard_C: Array, hard_lower: Array, hard_upper: Array, levels: Sequence[Level]
) -> LexicographicSolution:
    """The lexicographic optimum of ``levels`` (first the most important) under the hard rows
    ``hard_lower <= hard_C x <= hard_upper``, ties broken by the smallest ``x``.

    ``ValueError`` for rows of the wrong width, bounds of the wrong length or NaN entries."""
    n = hard_C.shape[1]
    if hard_lower.shape != (len(hard_C),) or hard_upper.shape != (len(hard_C),):
        raise ValueError("the hard bounds must hold one value per hard row")
    blocks_A, blocks_upper, blocks_lower = [hard_C], [hard_upper], [hard_lower]
    ends = [len(hard_C)]
    for level in levels:
        for rows, label in ((level.A, "A"), (level.C, "C")):
            if rows.ndim != 2 or rows.shape[1] != n:
                raise ValueError(f"level {level.name!r}: {label} must have {n} columns")
        if level.b.shape != (len(level.A),) or level.d.shape != (len(level.C),):
            raise ValueError(f"level {level.name!r}: one bound per row")
        values = (level.A, level.b, level.C, level.d)
        if any(np.isnan(v).any() for v in values) or not np.isfinite(level.A).all():
            raise ValueError(f"level {level.name!r}: its rows must be finite (NaN found)")
        A, b = equal_norm_rows(level.A, level.b)
        blocks_A += [A, level.C]
        blocks_upper += [b, level.d]
        blocks_lower += [b, np.full(len(level.C), -INFINITY)]
        ends.append(ends[-1] + len(level.A) + len(level.C))
    A = np.ascontiguousarray(np.vstack(blocks_A))
    upper = np.clip(np.concatenate(blocks_upper), -INFINITY, INFINITY)
    lower = np.clip(np.concatenate(blocks_lower), -INFINITY, INFINITY)
    sense = np.zeros(len(A), dtype=np.intc)
    x, _, flag, info = daqp.solve(
        None, None, A, upper, lower, sense, np.array(ends, dtype=np.intc), rho_soft=RHO_SOFT
    )
    lam = np.asarray(info["lam"])
    slack = {}
    for level, start in zip(levels, ends[:-1], strict=True):
        rows = lam[start + len(level.A) : start + len(level.A) + len(level.C)]
        slack[level.name] = float(np.abs(rows).max()) if len(rows) else 0.0
    return LexicographicSolution(np.asarray(x, dtype=float), int(flag), slack)
