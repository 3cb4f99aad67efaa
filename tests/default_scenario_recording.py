"""Record the default scenario's episodes, the reference of its seed-spread guard.

The default scenario is what ``make demo`` runs: ``wip-bench compare --env
wip_gym/PlanarTray-v0`` with every controller. :data:`COMMAND` runs it over :data:`EPISODES`
seeds, and ``tests/data/default_scenario.json`` keeps every episode's record except its timing
fields (``benchmarks.rollout.TIMING_FIELDS``), with the revision it was recorded at.
``tests/test_default_scenario_guard.py`` runs the same command and holds each controller's
metrics within their spread over those seeds.

Record again only when a change is meant to change the controllers' behaviour, and say why in
the commit: ``python -m tests.default_scenario_recording``.
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from pathlib import Path
from typing import Any

EPISODES = 5
SEED = 0
ENV_ID = "wip_gym/PlanarTray-v0"
#: the ``wip-bench`` arguments (``--out`` is added)
COMMAND = ("compare", "--env", ENV_ID, "--episodes", str(EPISODES), "--seed", str(SEED))
PATH = Path(__file__).resolve().parents[1] / "tests" / "data" / "default_scenario.json"


def run_default_scenario(jobs: int = 2) -> list[dict[str, Any]]:
    """The episodes of :data:`COMMAND` (``--jobs jobs``), their timing fields left out, in the
    order ``compare`` writes them."""
    from benchmarks.cli import main
    from benchmarks.rollout import without_timing

    with tempfile.TemporaryDirectory(prefix="wip-gym-default-") as out:
        code = main([*COMMAND, "--jobs", str(jobs), "--out", out])
        if code != 0:
            raise RuntimeError(f"wip-bench {' '.join(COMMAND)} exited with {code}")
        lines = (Path(out) / "episodes.jsonl").read_text().splitlines()
    episodes = [json.loads(line) for line in lines]
    return [without_timing(row) for row in episodes]


def main() -> None:
    revision = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    record = {
        "command": "wip-bench " + " ".join(COMMAND),
        "revision": revision or "unknown",
        "episodes": run_default_scenario(),
    }
    PATH.parent.mkdir(parents=True, exist_ok=True)
    PATH.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {PATH} ({len(record['episodes'])} episodes at {record['revision']})")


if __name__ == "__main__":
    main()
