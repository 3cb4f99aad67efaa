"""``python -m benchmarks.warm_caches`` (run by ``make install``): it runs and reports."""

from __future__ import annotations

import pytest

from benchmarks.warm_caches import main


def test_warm_caches_runs_a_few_steps(capsys: pytest.CaptureFixture[str]) -> None:
    main(["--env", "wip_gym/Planar-v0", "--steps", "3"])
    printed = capsys.readouterr().out
    assert printed.startswith("wip_gym/Planar-v0: ") and printed.rstrip().endswith(" s")
