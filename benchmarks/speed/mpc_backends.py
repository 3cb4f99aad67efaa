"""The MPC step's two backends timed on the same windows: the JAX DDP jitted by XLA (the
reference) and the numba DDP generated from the same JAX functions
(``controllers.optimizer.numba_ddp``, ``MPCConfig.backend``).

    python -m benchmarks.speed.mpc_backends [--rounds 5] [--index 100 --index 400]

Per window (``ddp_parts.mpc_window``: Krang's WIPM, the plan's state plus 0.01 at a plan index,
warm-started from the plan's controls), each backend's ``ModelPredictiveController.solve`` on
the same packed inputs, timed call by call in alternation (``yardstick.interleaved_rounds``),
in units, with the largest differences of their predictions (docs/performance.md §17, §18).
"""

from __future__ import annotations

import numpy as np

from benchmarks.speed.ddp_parts import window_arguments


def measure(
    rounds: int = 5,
    indices: tuple[int, ...] = (100, 400),
    problems: tuple[str, ...] = ("planar", "3d"),
) -> dict[str, dict[str, float]]:
    """Per MPC window (problem and plan index, ``ddp_parts.mpc_window``): the JAX and the
    numba backends' ``ModelPredictiveController.solve`` on the same inputs (warm-started from
    the plan's controls), medians in us interleaved call by call; the largest differences of
    their predicted controls and states; ``unit_us``."""
    from benchmarks.speed.ddp_parts import mpc_window  # noqa: PLC0415
    from benchmarks.speed.yardstick import ReferenceStep, interleaved_rounds  # noqa: PLC0415
    from controllers.high_level.mpc import (  # noqa: PLC0415
        ModelPredictiveController,
        MPCConfig,
        pack_inputs,
    )

    reference = ReferenceStep()
    out: dict[str, dict[str, float]] = {}
    for problem in problems:
        for index in indices:
            window = mpc_window(problem, index)
            jax_mpc = ModelPredictiveController(window.plan, MPCConfig(backend="jax"))
            numba_mpc = ModelPredictiveController(window.plan, MPCConfig(backend="numba"))
            x0 = np.asarray(window.X[0])
            host = pack_inputs(index, True, x0, window.params)  # warm start: the plan's
            ours, theirs = jax_mpc.solve(host), numba_mpc.solve(host)
            functions = {
                "jax": lambda m=jax_mpc, h=host: m.solve(h),
                "numba": lambda m=numba_mpc, h=host: m.solve(h),
            }
            med, unit = interleaved_rounds(functions, rounds, reference)
            dU = theirs.predicted_controls - ours.predicted_controls
            dX = theirs.predicted_states - ours.predicted_states
            out[f"{problem} {index}"] = {
                "jax_us": med["jax"],
                "numba_us": med["numba"],
                "max_dU": float(np.max(np.abs(dU))),
                "max_dX": float(np.max(np.abs(dX))),
                "unit_us": unit,
            }
    return out


def main(argv: list[str] | None = None) -> int:
    from controllers.optimizer import jax_setup  # noqa: PLC0415

    jax_setup.configure()
    rounds, indices = window_arguments(__doc__.splitlines()[0], argv)
    print("the MPC step (2 DDP iterations), the JAX and numba backends, median us (units):")
    for name, f in measure(rounds, indices).items():
        unit = f["unit_us"]
        print(
            f"  {name:11s} jax {f['jax_us']:6.1f} ({f['jax_us'] / unit:5.1f})  numba "
            f"{f['numba_us']:6.1f} ({f['numba_us'] / unit:5.1f})  ratio "
            f"{f['jax_us'] / f['numba_us']:4.2f}  max |dU| {f['max_dU']:.1e} "
            f"max |dX| {f['max_dX']:.1e}  (unit {unit:.1f} us)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
