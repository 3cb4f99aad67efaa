"""The README's Python recipes, verbatim: each ```python block of README.md, read when the test
runs, in a fresh process with no JAX option set (a user's first program), must run and print
no warning: no call to remember (docs/DESIGN.md §4). Python's default warning filters are
the user's, so what counts is what a user would see on stderr."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```", re.DOTALL | re.MULTILINE)
RECIPES = FENCE.findall((ROOT / "README.md").read_text())


def test_the_readme_has_python_recipes() -> None:
    assert len(RECIPES) >= 2


@pytest.mark.parametrize("recipe", RECIPES, ids=[f"recipe{i}" for i in range(len(RECIPES))])
def test_a_readme_recipe_runs_without_a_warning(recipe: str, tmp_path: Path) -> None:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("XLA_FLAGS", "JAX_ENABLE_X64", "PYTHONWARNINGS", "WIP_GYM_JAX_CACHE")
    }
    env.update(PYTHONPATH=str(ROOT), MUJOCO_GL="egl")
    result = subprocess.run(
        [sys.executable, "-c", recipe],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip()  # each recipe prints its result
    assert "Warning" not in result.stderr, result.stderr[-3000:]
