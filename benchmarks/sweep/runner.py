"""Run a sweep's episodes on Ray, one task per episode, one CPU each, and store each row as
its episode ends.

With no address the sweep starts a local cluster of its own (``address="local"``: a
``RAY_ADDRESS`` in the environment is never joined by accident) with ``--workers`` CPUs (the
machine's by default), without dashboard or usage reporting, its temporary files under
:data:`RAY_TEMP_DIR`. With an address it joins that cluster and ``--workers`` caps the episodes
in flight. If this process already has Ray initialised (a test's shared cluster), it is used.

Workers get XLA's loop option for the DDP through the task's runtime environment, set before the
worker process starts JAX (:func:`worker_env_vars`; the solvers scope float64 themselves), and
turn JAX's persistent compilation cache on, which stays per node (its default directory is
under each node's home). A worker that dies is retried (``max_retries``); an
episode that raises or outlives the wall-clock limit becomes an error row and the sweep goes on.
Ctrl-C cancels the episodes in flight (nothing is written for them) and writes the report.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import ray
from tqdm import tqdm

from benchmarks.sweep.report import SPEC_NAME, write_report
from benchmarks.sweep.spec import Episode, SpecError, SweepSpec
from benchmarks.sweep.store import StoreWriter, cut_torn_tail, latest_rows, read_rows
from benchmarks.sweep.worker import finish_row

RAY_TEMP_DIR = "/tmp/ray_wipgym"  # short: Ray's socket paths must fit in 107 bytes
MAX_RETRIES = 3  # re-runs of an episode whose worker process died
# The driver kills an episode's worker when it outlives the limit by this much (the worker's
# own alarm could not interrupt it, e.g. stuck inside a C call).
HARD_LIMIT_FACTOR = 1.5
HARD_LIMIT_MARGIN_S = 60.0
LOCK_NAME = ".sweep.lock"

EpisodeFn = Callable[[Mapping[str, Any]], dict[str, Any]]


def worker_env_vars() -> dict[str, str]:
    """The environment of a sweep worker: XLA's small-while-loop threshold of
    ``controllers.optimizer.jax_setup`` before JAX starts, and one thread each for XLA, BLAS and
    OpenMP (one CPU per episode)."""
    from controllers.optimizer import jax_setup

    flags = os.environ.get("XLA_FLAGS", "")
    option = jax_setup.loop_option()
    if option is not None:
        flags = jax_setup.with_loop_option(flags, option)
    if "xla_cpu_multi_thread_eigen" not in flags:
        flags += " --xla_cpu_multi_thread_eigen=false"
    env = {
        "XLA_FLAGS": flags.strip(),
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "RAY_USAGE_STATS_ENABLED": "0",
    }
    for name in (jax_setup.CACHE_ENV, "MUJOCO_GL"):  # the user's choices, if any
        if name in os.environ:
            env[name] = os.environ[name]
    return env


def make_job(spec: SweepSpec, episode: Episode) -> dict[str, Any]:
    """What a worker needs to run ``episode``; also the identity part of its store row.
    ``run_controllers``: the sweep's controllers, for which the worker resolves the keys."""
    return {
        "id": episode.id,
        "env": spec.env,
        "preset": spec.preset,
        "controller": episode.controller,
        "run_controllers": list(spec.controllers),
        "duration": spec.duration,
        "cell": episode.cell,
        "parameters": episode.parameters,
        "random": episode.random,
        "replicate": episode.replicate,
        "seed": episode.seed,
        "sweep_seed": spec.seed,
    }


def _run_task(
    job: Mapping[str, Any],
    episode_fn: EpisodeFn | None,
    timeout_s: float,
    imports: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One episode in a worker: the ``--import`` modules first (their controllers), then the
    episode; its row says on which Ray node it ran (``node_id``)."""
    from benchmarks.sweep.worker import execute
    from controllers import registry
    from controllers.optimizer import jax_setup

    registry.import_modules(imports)  # idempotent: a worker runs many episodes
    jax_setup.use_compilation_cache()  # before the episode's first JAX compilation
    if episode_fn is None:
        from benchmarks.sweep.episode import run_episode_job

        episode_fn = run_episode_job
    row = execute(job, episode_fn, timeout_s)
    row["node_id"] = ray.get_runtime_context().get_node_id()
    return row


@contextlib.contextmanager
def _cluster(address: str | None, workers: int | None) -> Iterator[None]:
    if ray.is_initialized():
        yield
        return
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    if address is None:
        ray.init(
            address="local",
            num_cpus=workers or os.cpu_count() or 1,
            include_dashboard=False,
            log_to_driver=False,
            _temp_dir=RAY_TEMP_DIR,
        )
    else:
        ray.init(address=address, log_to_driver=False)
    try:
        yield
    finally:
        ray.shutdown()


@contextlib.contextmanager
def _locked(directory: Path) -> Iterator[None]:
    with open(directory / LOCK_NAME, "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SpecError(f"another sweep is writing into {directory}") from None
        yield


def plan_run(spec: SweepSpec, directory: str | Path) -> tuple[list[Episode], int, int]:
    """The episodes still to run (no row, or an error row), the number skipped (an ok row)
    and how many of those to run are error rows."""
    latest = latest_rows(read_rows(directory))
    todo, skipped, errors = [], 0, 0
    for episode in spec.episodes():
        row = latest.get(episode.id)
        if row is not None and row["status"] == "ok":
            skipped += 1
            continue
        errors += row is not None
        todo.append(episode)
    return todo, skipped, errors


def run_sweep(
    spec: SweepSpec,
    directory: str | Path,
    address: str | None = None,
    workers: int | None = None,
    episode_fn: EpisodeFn | None = None,
    progress: bool = True,
    imports: Sequence[str] = (),
) -> dict[str, Any]:
    """Run the spec's missing and failed episodes into ``directory``; write the report and
    return the summary (``interrupted`` after Ctrl-C). ``imports``: modules that register
    controllers (``--import``), imported by every worker before its episodes."""
    if workers is not None and workers < 1:
        raise SpecError(f"--workers must be >= 1, got {workers}")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    with _locked(directory):
        saved = directory / SPEC_NAME
        if saved.exists() and saved.read_text() != spec.text:
            print(
                f"note: the spec differs from the one saved in {saved}; rows of episodes it "
                "no longer plans stay in the store and out of the report"
            )
        saved.write_text(spec.text)
        torn = cut_torn_tail(directory)
        if torn:
            print(f"cut a torn last line ({torn} bytes) from the store")
        todo, skipped, errors = plan_run(spec, directory)
        total = len(spec.episodes())
        print(
            f"{total} episodes: {skipped} already in {directory} skipped, {len(todo)} to run"
            + (f" ({errors} of them failed before)" if errors else "")
        )
        run: dict[str, Any] = {"episodes_run": 0, "episodes_skipped": skipped, "wall_s": 0.0}
        if todo:
            run.update(
                _execute(
                    spec, directory, todo, address, workers, episode_fn, progress, tuple(imports)
                )
            )
        summary = write_report(spec, directory, run)
        print(f"wrote {directory / 'summary.json'} and {directory / 'report.md'}")
        if todo:
            print(
                f"{run['episodes_run']} episodes ({run['episodes_failed_this_run']} failed) in "
                f"{run['wall_s']:.0f} s on {run['workers']} workers: "
                f"{run['episodes_per_hour'] or 0:.0f} episodes per hour"
            )
        return summary


def _execute(
    spec: SweepSpec,
    directory: Path,
    todo: list[Episode],
    address: str | None,
    workers: int | None,
    episode_fn: EpisodeFn | None,
    progress: bool,
    imports: tuple[str, ...],
) -> dict[str, Any]:
    timeout = spec.episode_timeout
    hard_limit = HARD_LIMIT_FACTOR * timeout + HARD_LIMIT_MARGIN_S
    with _cluster(address, workers), StoreWriter(directory) as store:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        cap = min(workers or cpus, len(todo))
        task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_run_task).options(
            runtime_env={"env_vars": worker_env_vars()}
        )
        pending = [make_job(spec, e) for e in reversed(todo)]
        in_flight: dict[Any, tuple[dict[str, Any], float]] = {}
        done = failed = 0
        interrupted = False
        bar = tqdm(
            total=len(todo), unit="ep", desc="episodes", disable=not progress, dynamic_ncols=True
        )
        bar.set_postfix(failed=0)
        start = time.monotonic()

        def record(row: dict[str, Any]) -> None:
            nonlocal done, failed
            store.write(row)
            done += 1
            failed += row["status"] != "ok"
            bar.set_postfix(failed=failed)
            bar.update()

        try:
            while pending or in_flight:
                while pending and len(in_flight) < cap:
                    job = pending.pop()
                    ref = task.remote(job, episode_fn, timeout, imports)
                    in_flight[ref] = (job, time.monotonic())
                ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
                for ref in ready:
                    job, submitted = in_flight.pop(ref)
                    try:
                        row = ray.get(ref)
                    except ray.exceptions.RayError as error:  # its worker died MAX_RETRIES times
                        row = finish_row(
                            job,
                            None,
                            f"{type(error).__name__}: {error}",
                            time.monotonic() - submitted,
                        )
                    record(row)
                now = time.monotonic()
                for ref, (job, submitted) in list(in_flight.items()):
                    if now - submitted > hard_limit:
                        ray.cancel(ref, force=True)
                        del in_flight[ref]
                        record(
                            finish_row(
                                job,
                                None,
                                f"EpisodeTimeout: no result after "
                                f"{now - submitted:.0f} s (limit {timeout:.0f} s); "
                                "its worker was killed",
                                now - submitted,
                            )
                        )
        except KeyboardInterrupt:
            interrupted = True
            for ref in in_flight:
                ray.cancel(ref, force=True)
        bar.close()
        wall = time.monotonic() - start
        per_hour = done / wall * 3600.0 if wall > 0 else None
        if interrupted:
            print(
                f"interrupted: {len(in_flight)} episodes in flight not written; "
                "run the same command again to resume"
            )
    return {
        "episodes_run": done,
        "episodes_failed_this_run": failed,
        "wall_s": wall,
        "episodes_per_hour": per_hour,
        "workers": cap,
        "interrupted": interrupted,
    }
