"""The cluster recipe of docs/sweeps.md §2 on the Ray the project pins: a head and a second
node started with ``ray start`` on loopback, with token authentication (``RAY_AUTH_MODE=token``
and one ``RAY_AUTH_TOKEN`` for both nodes and the driver), and ``wip-bench sweep --address``
on them. Both nodes must run episodes (each row names its Ray node).

The nodes run ``ray start --block`` in their own process groups, in a temporary session
directory, and are stopped by signalling those processes (``ray stop`` would stop every Ray
node of the machine, other users' too). Their addresses are 127.0.0.2 and 127.0.0.3: Ray rewrites
127.0.0.1 and ``localhost`` to the machine's outward address, the rest of 127.0.0.0/8 it
leaves on loopback. The episodes are the plug-in's (tests/plugin_package.py: no JAX to
compile), so the test takes well under a minute.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchmarks.sweep.store import read_rows
from tests.plugin_package import write_plugin

ROOT = Path(__file__).resolve().parents[1]
RAY = Path(sys.executable).with_name("ray")
HEAD_IP, NODE_IP = "127.0.0.2", "127.0.0.3"
START_TIMEOUT_S = 60.0

SPEC = """
env = "PlanarTray-v0"
controllers = ["balance", "balance-imported"]
duration = 0.2
seeds = 1
[grid]
"balance.kd" = [70.0, 90.0]
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _node_ports() -> list[str]:
    """Ports of one node's own servers: free ones, so that two nodes share the machine."""
    names = (
        "--node-manager-port",
        "--object-manager-port",
        "--dashboard-agent-listen-port",
        "--dashboard-agent-grpc-port",
        "--runtime-env-agent-port",
        "--metrics-export-port",
    )
    return [item for name in names for item in (name, str(_free_port()))]


def _wait_started(process: subprocess.Popen[bytes], log: Path) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"ray start exited with {process.returncode}:\n{log.read_text()}")
        if "Ray runtime started" in log.read_text():
            return
        time.sleep(0.5)
    raise RuntimeError(f"ray start did not start in {START_TIMEOUT_S} s:\n{log.read_text()}")


def _stop(process: subprocess.Popen[bytes], grace_s: float = 30.0) -> None:
    """SIGTERM to ``ray start --block``, which stops its node's processes (about 2 s); if it
    has not within ``grace_s``, SIGKILL to its process group."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(grace_s)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, str]]]:
    """``(head address, the environment of every node and of the driver)``."""
    site = write_plugin(tmp_path_factory.mktemp("site"))
    session = Path(tempfile.mkdtemp(prefix="wr", dir="/tmp"))  # Ray's socket paths are short
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(
        RAY_AUTH_MODE="token",
        RAY_AUTH_TOKEN=secrets.token_hex(32),
        RAY_USAGE_STATS_ENABLED="0",
        PYTHONPATH=f"{site}{os.pathsep}{ROOT}",  # each node imports the plug-in and wip-gym
        MUJOCO_GL="egl",
    )
    port = _free_port()
    started: list[subprocess.Popen[bytes]] = []
    try:
        for role, ip in (("head", HEAD_IP), ("node", NODE_IP)):
            log = session / f"{role}.log"
            where = (
                ["--head", "--port", str(port), "--temp-dir", str(session)]
                + ["--include-dashboard", "false"]
                if role == "head"
                else ["--address", f"{HEAD_IP}:{port}"]
            )
            process = subprocess.Popen(
                [str(RAY), "start", "--block", "--node-ip-address", ip, "--num-cpus", "1"]
                + ["--disable-usage-stats", *where, *_node_ports()],
                env=env,
                stdout=log.open("w"),
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            started.append(process)
            _wait_started(process, log)
        yield f"{HEAD_IP}:{port}", env
    finally:
        for process in reversed(started):
            _stop(process)
        shutil.rmtree(session, ignore_errors=True)


def test_a_sweep_runs_on_a_two_node_cluster_with_token_authentication(
    cluster: tuple[str, dict[str, str]], tmp_path: Path
) -> None:
    address, env = cluster
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", "sweep", str(spec), "--out", str(out)]
        + ["--address", address, "--workers", "2", "--import", "my_imported_controllers"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-3000:]
    rows = read_rows(out)
    assert len(rows) == 4 and all(row["status"] == "ok" for row in rows)
    assert all(row["metrics"]["steps"] == 200 for row in rows)
    assert len({row["node_id"] for row in rows}) == 2  # both nodes ran episodes
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes_ok"] == 4 and summary["episodes_failed"] == 0


def test_a_node_without_the_token_is_refused(
    cluster: tuple[str, dict[str, str]], tmp_path: Path
) -> None:
    """What the recipe guards against: ``ray start --address`` without the token settings
    never joins (the head answers ``InvalidAuthToken``)."""
    address, env = cluster
    bare = {k: v for k, v in env.items() if not k.startswith("RAY_AUTH")}
    log = tmp_path / "refused.log"
    process = subprocess.Popen(
        [str(RAY), "start", "--block", "--address", address, "--node-ip-address", "127.0.0.4"]
        + ["--num-cpus", "1", "--disable-usage-stats", *_node_ports()],
        env=bare,
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 30
        while "InvalidAuthToken" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.5)
        text = log.read_text()
        assert "InvalidAuthToken" in text
        assert "Ray runtime started" not in text
    finally:
        _stop(process, grace_s=5.0)  # it never started a node: nothing to stop gracefully
