"""``controllers.optimizer.scalar_codegen``: the scalar code written from a jaxpr gives JAX's
values, corner cases included (the MPC's stage functions are tested in
tests/test_numba_ddp.py and tests/test_solvers_bench.py)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("fold", [False, True])
def test_stage_codegen_small_functions_equal_jax(fold: bool) -> None:
    """The generated code on small functions that reach its corners: a negative folded
    literal to a power, NaN through maximum, where, cond both ways, a batched product, a
    division by zero (inf, not an exception), with and without folding."""
    import jax
    import jax.numpy as jnp

    from controllers.optimizer.scalar_codegen import scalar_function

    def corners(x: jax.Array, b: jax.Array) -> tuple[jax.Array, ...]:
        return (
            (x * 0.0 - 1.0) ** 2 + x,
            jnp.maximum(x, jnp.nan),
            jnp.minimum(x, 0.5),
            jnp.where(x > 0, x, -2.0 * x),
            jax.lax.cond(x[0] > 0, lambda: x * 2.0, lambda: x - 1.0),
            jnp.einsum("bij,bjk->bik", b, b),
            1.0 / (x - x[0]),
            x**-2,
        )

    function, inputs, outputs = scalar_function(
        corners, jnp.ones(3), jnp.ones((2, 2, 2)), fold=fold
    )
    rng = np.random.default_rng(2)
    for sign in (1.0, -1.0):  # the cond's two branches
        x = sign * np.abs(rng.normal(size=3)) + 0.1 * sign
        b = rng.normal(size=(2, 2, 2))
        out = np.empty(outputs)
        function(np.concatenate([x, b.ravel()]), out)
        truth = np.concatenate(
            [np.ravel(np.asarray(a)) for a in corners(jnp.asarray(x), jnp.asarray(b))]
        )
        assert inputs == 11
        np.testing.assert_allclose(out, truth, rtol=1e-14, atol=1e-14, equal_nan=True)
        assert np.isinf(out[-6]) and np.isnan(out[3])  # 1 / 0 and maximum(x, nan)
