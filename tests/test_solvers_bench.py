"""``wip-bench solvers`` (issue 4): runs, writes the JSON schema, and the NumPy iLQR peer
reaches the JAX DDP's optimum. No timing assertions (the figures depend on the machine)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks.cli import main

SOLVER_KEYS = {
    "compile_s",
    "plan_ms",
    "plan_iterations",
    "iter_ms",
    "plan_cost",
    "plan_converged",
    "mpc_compile_s",
    "mpc_step_ms",
}
RATIO_KEYS = {"compile", "plan", "iter", "mpc_step_median", "mpc_step_p99"}


def positive_finite(value: float) -> bool:
    return isinstance(value, int | float) and math.isfinite(value) and value > 0


def test_quick_run_schema_and_agreement(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "solvers.json"
    assert main(["solvers", "--quick", "--mpc-steps", "10", "--json", str(path)]) == 0
    printed = capsys.readouterr().out
    assert "| planar | ours |" in printed and "Targets:" in printed
    results = json.loads(path.read_text())
    assert {"planar", "3d", "ratios", "targets", "machine", "command"} <= results.keys()
    for problem in ("planar", "3d"):
        entry = results[problem]
        for solver in ("ours", "numpy_ilqr"):
            r = entry[solver]
            assert r.keys() >= SOLVER_KEYS, (problem, solver)
            for key in ("compile_s", "plan_ms", "iter_ms", "plan_cost", "mpc_compile_s"):
                # a compile time is a difference of two timings: >= 0 is all one can ask
                if key.endswith("compile_s"):
                    assert math.isfinite(r[key]) and r[key] >= 0, (problem, solver, key)
                else:
                    assert positive_finite(r[key]), (problem, solver, key, r[key])
            assert positive_finite(r["mpc_step_ms"]["median"])
            assert positive_finite(r["mpc_step_ms"]["p99"])
            assert r["mpc_step_ms"]["p99"] >= r["mpc_step_ms"]["median"]
            assert r["plan_converged"] is True
            assert r["plan_iterations"] >= 1
        # the two solvers, same algorithm: same optimum, same iterations
        ours, peer = entry["ours"], entry["numpy_ilqr"]
        assert entry["costs_agree"] is True
        assert abs(ours["plan_cost"] - peer["plan_cost"]) <= 1e-6 * abs(ours["plan_cost"])
        assert ours["plan_iterations"] == peer["plan_iterations"]
        ratios = results["ratios"][problem]
        assert ratios.keys() >= RATIO_KEYS
        for key in RATIO_KEYS - {"compile"}:
            assert positive_finite(ratios[key]), (problem, key)
    for target in ("plan_under_50ms", "mpc_median_under_1ms"):
        assert set(results["targets"][target]) == {"planar", "3d"}
