"""``python -m benchmarks.warm_caches`` (run by ``make install``) leaves caches that a second
process loads without compiling.

Two processes run it in turn on the same env, each recording what it compiles: numba's
compilations (numba's ``numba:compile`` events: a function loaded from numba's on-disk cache
raises none) and JAX's requests to its persistent compilation cache (``jax.monitoring``
events: each request, and each request the cache answered). JAX's cache is a fresh directory
(``WIP_GYM_JAX_CACHE``): the first process must compile into it, the second must find every
program there. numba's caches are the machine's own (compiling them from empty takes minutes):
whatever state they were in, after the first process the second compiles nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
ENV_ID = "wip_gym/Planar-v0"

SCRIPT = f"""
import json
import jax.monitoring
import numba.core.event

jax_events = []
jax.monitoring.register_event_listener(lambda event, **kwargs: jax_events.append(event))
from benchmarks.warm_caches import main

with numba.core.event.install_recorder("numba:compile") as recorder:
    main(["--env", "{ENV_ID}", "--steps", "3"])
compiled = sorted(
    {{
        event.data["dispatcher"].py_func.__module__ + "." + event.data["dispatcher"].__name__
        for _, event in recorder.buffer
        if event.is_start
    }}
)
requests = jax_events.count("/jax/compilation_cache/compile_requests_use_cache")
hits = jax_events.count("/jax/compilation_cache/cache_hits")
print(json.dumps({{"numba_compiled": compiled, "jax_requests": requests, "jax_hits": hits}}))
"""


def _warm_in_a_new_process(jax_cache: Path) -> dict[str, Any]:
    environment = dict(os.environ, WIP_GYM_JAX_CACHE=str(jax_cache))
    result = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        cwd=ROOT,
        env=environment,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    lines = result.stdout.strip().splitlines()
    assert lines[0].startswith(f"{ENV_ID}: ") and lines[0].endswith(" s"), lines
    return json.loads(lines[-1])


def test_a_second_process_after_warm_caches_compiles_nothing(tmp_path: Path) -> None:
    jax_cache = tmp_path / "jax"
    first = _warm_in_a_new_process(jax_cache)
    # the fresh directory: the first process compiled what it asked the cache for
    assert first["jax_requests"] > 0 and first["jax_hits"] < first["jax_requests"], first
    assert any(jax_cache.iterdir())
    second = _warm_in_a_new_process(jax_cache)
    assert second["jax_requests"] == first["jax_requests"], (first, second)
    assert second["jax_hits"] == second["jax_requests"], second
    assert second["numba_compiled"] == [], second["numba_compiled"]
