"""The solvers' JAX settings are applied by one explicit call, never by an import; a program
whose JAX runs without them is warned, with what it costs (docs/DESIGN.md §7)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

BUILD_A_SOLVER = """
import jax.numpy as jnp
from controllers.optimizer.ddp import make_ddp_solver
make_ddp_solver(lambda x, u, p: x, lambda x, u, r: jnp.sum(x**2), lambda x, r: jnp.sum(x**2))
"""


def _run(code: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_ENABLE_X64")}
    env["PYTHONPATH"] = str(ROOT)
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=True,
    )


def test_importing_the_controllers_changes_no_jax_setting() -> None:
    out = _run(
        """
        import os
        import jax
        import controllers, controllers.optimizer.ddp, controllers.simplified.wipm
        import controllers.high_level.planning
        import controllers.hierarchical, controllers.registry
        flags = os.environ.get("XLA_FLAGS", "")
        print(jax.config.jax_enable_x64, "xla_backend_extra_options" in flags)
        """
    )
    assert out.stdout.split() == ["False", "False"]


def test_a_program_with_other_jax_settings_is_warned_with_the_cost() -> None:
    out = _run("import jax.numpy as jnp\njnp.zeros(3).sum()  # JAX already runs\n" + BUILD_A_SOLVER)
    assert "wip-gym's JAX settings are not applied" in out.stderr
    assert "float32" in out.stderr and "10x slower" in out.stderr
    assert "controllers.optimizer.jax_setup.configure()" in out.stderr


def test_the_explicit_call_applies_the_settings_and_silences_the_warning() -> None:
    out = _run(
        "import os, jax\nfrom controllers.optimizer import jax_setup\njax_setup.configure()\n"
        + BUILD_A_SOLVER
        + "print(jax.config.jax_enable_x64, jax_setup.SMALL_LOOP_OPTION in os.environ['XLA_FLAGS'])"
    )
    assert out.stdout.split() == ["True", "True"]
    assert "not applied" not in out.stderr
