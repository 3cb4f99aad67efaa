"""The MPC's numba backend under other numba options, timed side by side: which fast-math
flags the generated code should carry.

    python -m benchmarks.speed.numba_options [--rounds 5] [--index 100 --index 400]

Per window (``ddp_parts.mpc_window``), the generated module's ``mpc_step`` under each variant of
:data:`VARIANTS` (``controllers.optimizer.numba_ddp``'s default first), interleaved call by
call (``yardstick.interleaved_rounds``), in units; and each variant's largest difference from
the JAX step's predicted controls. Each variant is its own module (its source differs in its
decorators): the first run compiles each, about half a minute per variant and problem
(docs/performance.md §18).
"""

from __future__ import annotations

import numpy as np

from benchmarks.speed.ddp_parts import window_arguments

#: name -> the ``numba.njit`` options of every generated function
VARIANTS = {
    "default": None,  # numba_ddp.OPTIONS
    "no fast-math": 'cache=True, error_model="numpy", nogil=True',
    "contract, reassoc": 'cache=True, error_model="numpy", nogil=True, '
    'fastmath={"contract", "reassoc"}',
}


def measure(
    rounds: int = 5,
    indices: tuple[int, ...] = (100, 400),
    problems: tuple[str, ...] = ("planar", "3d"),
) -> dict[str, dict[str, float]]:
    """Per window ``"<problem> <index>"``: ``<variant>_us`` medians, ``<variant>_dU`` (the
    largest difference from the JAX step's predicted controls) and ``unit_us``."""
    from benchmarks.speed.ddp_parts import mpc_window  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, interleaved_rounds  # noqa: PLC0415
    from controllers.high_level.mpc import (  # noqa: PLC0415
        _N_PARAMS,
        ModelPredictiveController,
        MPCConfig,
        pack_inputs,
        params_from_vector,
    )
    from controllers.optimizer import numba_ddp  # noqa: PLC0415

    reference = ReferenceStep()
    layout = params_from_vector(np.zeros(_N_PARAMS))
    out: dict[str, dict[str, float]] = {}
    for problem in problems:
        for index in indices:
            window = mpc_window(problem, index)
            mpc = ModelPredictiveController(window.plan)
            jax_mpc = ModelPredictiveController(window.plan, MPCConfig(backend="jax"))
            host = pack_inputs(index, True, np.asarray(window.X[0]), window.params)
            truth = jax_mpc.solve(host).predicted_controls.ravel()
            step = mpc.compiled
            args = (host, np.zeros_like(mpc._warm), mpc._plan_states, mpc._plan_controls)
            args += (step.constants, step.settings, step.alphas)  # type: ignore[union-attr]
            nx, nu = mpc._sizes
            row: dict[str, float] = {}
            functions = {}
            for name, options in VARIANTS.items():
                module = numba_ddp._write_and_load(
                    mpc.problem, layout, options or numba_ddp.OPTIONS
                )
                packed, _ = module.mpc_step(*args)
                row[f"{name}_dU"] = float(np.max(np.abs(packed[nx : nx + nu] - truth)))
                functions[name] = lambda m=module: m.mpc_step(*args)  # noqa: B023
            medians, unit = interleaved_rounds(functions, rounds, reference)
            row |= {f"{name}_us": us for name, us in medians.items()} | {"unit_us": unit}
            out[f"{problem} {index}"] = row
    return out


def main(argv: list[str] | None = None) -> int:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()
    rounds, indices = window_arguments(__doc__.splitlines()[0], argv)
    print("the numba MPC step under each variant's options, median us (units), max |dU| vs JAX:")
    for window, row in measure(rounds, indices).items():
        unit = row["unit_us"]
        cells = "  ".join(
            f"{name} {row[f'{name}_us']:6.1f} ({row[f'{name}_us'] / unit:4.1f}) "
            f"{row[f'{name}_dU']:.0e}"
            for name in VARIANTS
        )
        print(f"  {window:11s} {cells}  (unit {unit:.1f} us)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
