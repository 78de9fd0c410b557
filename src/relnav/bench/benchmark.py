"""Benchmark grid runner: scenarios × nuisances × methods × seeds, in parallel with Dask.

A **grid** (YAML, :class:`GridSpec`) lists scenarios (paper presets, scenario YAML files or
existing sequence folders), methods (method strings, with ``{a,b}`` brace expansion, or
``{method, label, options}`` entries), Monte Carlo seeds and optional nuisance levels
(:mod:`relnav.sim.nuisance`). One **job** = one (scenario, nuisance, method, seed) odometry run.

How a grid runs (:func:`run_benchmark`):

1. Jobs are expanded and identified by :func:`job_id`, a hash of everything that determines
   their result (scenario spec, seed, nuisance, method, options). Jobs already in the results
   store (:mod:`relnav.bench.store`) with status ``ok`` or ``failed`` are skipped, so a killed
   run resumes where it stopped; ``force=True`` reruns everything, ``retry_failed=True`` reruns
   failed jobs.
2. Each (scenario, seed) sequence is simulated **once** into ``OUT/sequences/`` and reused by
   every method (nuisance variants are derived from it, also once). A folder is only used
   once its ``.complete`` marker exists (it is written to a temporary name and renamed).
3. Jobs run on a Dask cluster: ``LocalCluster(n_workers=N, threads_per_worker=1,
   processes=True)`` by default, or an existing scheduler (``scheduler="tcp://host:8786"``).
   ``workers=0`` runs everything in this process (debugging, tests). Each result row is
   written to ``OUT/results.sqlite`` and committed as soon as its job finishes; a job that
   raises is recorded as ``failed`` with its error and the grid goes on.
4. Every job writes ``OUT/runs/<job_id>/estimate.tum`` and ``diagnostics.csv``; its metrics
   are computed **from those files** with the defaults of ``relnav evaluate`` (timestamp
   association, no alignment), so ``relnav evaluate`` on them gives the stored numbers.

Determinism: a job is a pure function of (scenario spec, seed, nuisance, method, options):
the scenario seed drives the sensor noise and pointing jitter, the nuisance draws use
:func:`relnav.sim.nuisance.nuisance_rng`, and the methods' own random parts (RANSAC, CLGV,
Super4PCS, Open3D) keep their fixed default seeds **[interpretation: the Monte Carlo seed varies
the data, not the estimator]**. Only the timing columns differ between runs, except for
the Open3D-based baselines (``o3d-*``): Open3D's parallel reductions and RANSAC are not
bit-reproducible from one process to another (differences from 1e-12 relative up to ~1 %
after a few frames of ``o3d-fpfh-ransac``). Every relnav-native method, KISS-ICP and
small_gicp give bit-identical metrics in-process, on a ``LocalCluster`` or on hand-started
``dask worker`` processes.

On a cluster, ``OUT`` should be on a shared file system; otherwise every worker simulates the
sequences it needs itself (same seeds → same data) and the estimate files stay on the workers.
Numba's on-disk cache (``cache=True``) is shared by the worker processes of one machine: set
``NUMBA_CACHE_DIR`` to a writable folder when the package is installed read-only.

Modules: the grid specification and job expansion live in :mod:`relnav.bench.grid`, the
worker-side functions in :mod:`relnav.bench.worker` (both re-exported here); this module is the
driver.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from relnav.bench.grid import (
    GridSpec,
    Job,
    MethodEntry,
    ReportOptions,
    ScenarioEntry,
    SweepSpec,
    expand_jobs,
    expand_methods,
    job_id,
    load_grid,
)
from relnav.bench.worker import _now, _worker_setup, failed_row, prepare_sequence, run_job
from relnav.config import dump_yaml, load_yaml, validate
from relnav.errors import ConfigError, InputError

__all__ = [
    "BenchmarkSummary",
    "GridSpec",
    "Job",
    "MethodEntry",
    "ReportOptions",
    "ScenarioEntry",
    "SweepSpec",
    "expand_jobs",
    "expand_methods",
    "job_id",
    "load_grid",
    "failed_row",
    "prepare_sequence",
    "read_grid",
    "run_benchmark",
    "run_job",
]

log = logging.getLogger(__name__)

GRID_FILE = "grid.yaml"
STORE_FILE = "results.sqlite"
RUNS_LOG = "runs.jsonl"


# --------------------------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------------------------


@dataclass
class BenchmarkSummary:
    """What :func:`run_benchmark` did.

    Attributes
    ----------
    out_dir : Path
        Benchmark folder.
    grid_hash : str
        :meth:`GridSpec.grid_hash`.
    n_jobs, n_skipped, n_ok, n_failed : int
        Jobs in the grid, skipped as already finished, run now with status ok / failed.
    wall_s : float
        Wall-clock time of this invocation, s.
    executor : str
        ``"in-process"``, ``"LocalCluster(n_workers=N)"`` or the scheduler address.
    n_workers : int
        Workers (processes) used.
    failures : list of (job label, error)
        Jobs that failed in this invocation.
    """

    out_dir: Path
    grid_hash: str
    n_jobs: int
    n_skipped: int
    n_ok: int = 0
    n_failed: int = 0
    wall_s: float = 0.0
    executor: str = ""
    n_workers: int = 0
    failures: list[tuple[str, str]] = field(default_factory=list)


ProgressFn = Callable[[int, int, dict[str, Any]], None]


def _write_grid(grid: GridSpec, out: Path) -> None:
    from relnav.atomic import atomic_write_text

    data = grid.model_dump(mode="json")
    data["grid_hash"] = grid.grid_hash()
    atomic_write_text(out / GRID_FILE, dump_yaml(data))


def read_grid(out_dir: str | Path) -> GridSpec:
    """The resolved grid saved by :func:`run_benchmark` in ``out_dir``."""
    p = Path(out_dir) / GRID_FILE
    if not p.is_file():
        raise InputError(f"{out_dir}: no {GRID_FILE} (not a benchmark folder?)")
    data = load_yaml(p)
    data.pop("grid_hash", None)
    return validate(GridSpec, data, str(p))


def run_benchmark(
    grid: GridSpec | str | Path,
    out_dir: str | Path,
    *,
    workers: int = 2,
    scheduler: str | None = None,
    force: bool = False,
    retry_failed: bool = False,
    progress: ProgressFn | None = None,
    lock_timeout: float | None = None,
) -> BenchmarkSummary:
    """Run every unfinished job of ``grid`` into ``out_dir`` (see the module docstring).

    Parameters
    ----------
    grid : GridSpec or path
        The grid (:func:`load_grid`).
    out_dir : str or Path
        Benchmark folder: ``grid.yaml``, ``results.sqlite``, ``sequences/``, ``runs/``,
        ``runs.jsonl`` (one line per invocation: wall time, workers, host, jobs).
    workers : int
        Local worker processes (``LocalCluster``); 0 = run in this process, serially.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); ``workers`` is ignored.
    force : bool
        Rerun every job, finished or not.
    retry_failed : bool
        Rerun jobs recorded as failed.
    progress : callable, optional
        ``progress(done, total, row)`` after each job is stored.
    lock_timeout : float, optional
        Seconds to wait for another benchmark holding ``out_dir`` (default: as long as it
        takes; it then skips the jobs the other one finished).

    Returns
    -------
    BenchmarkSummary

    Notes
    -----
    Local workers are separate processes started with ``spawn``: a script calling this
    function must guard its entry point with ``if __name__ == "__main__":``.
    """
    from relnav.io.locks import FolderLock

    if not isinstance(grid, GridSpec):
        grid = load_grid(grid)
    if workers < 0:
        raise ConfigError(f"workers must be >= 0, got {workers}")
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    # One benchmark at a time per folder: a second process waits, then skips what the first
    # finished (the lock dies with its holder, even on SIGKILL).
    with FolderLock(out, timeout=lock_timeout, what="relnav benchmark"):
        return _run_locked(grid, out, workers, scheduler, force, retry_failed, progress)


def _run_locked(
    grid: GridSpec,
    out: Path,
    workers: int,
    scheduler: str | None,
    force: bool,
    retry_failed: bool,
    progress: ProgressFn | None,
) -> BenchmarkSummary:
    from relnav.bench.store import ResultsStore

    _write_grid(grid, out)
    jobs = expand_jobs(grid)
    gh = grid.grid_hash()
    t0 = time.perf_counter()
    started = _now()
    load0 = _loadavg()
    with ResultsStore(out / STORE_FILE) as store:
        store.set_meta("last_grid_hash", gh)
        if force:
            done: set[str] = set()
        else:
            done = store.finished_ids(("ok",) if retry_failed else ("ok", "failed"))
        pending = [j for j in jobs if j.job_id not in done]
        summary = BenchmarkSummary(out, gh, len(jobs), len(jobs) - len(pending))
        log.info(
            "grid %s: %d jobs, %d already finished, %d to run",
            grid.name,
            len(jobs),
            summary.n_skipped,
            len(pending),
        )

        def record(row: dict[str, Any]) -> None:
            row["grid_hash"] = gh
            row["grid_name"] = grid.name
            store.put(row)
            if row.get("status") == "ok":
                summary.n_ok += 1
            else:
                summary.n_failed += 1
                summary.failures.append(
                    (f"{row['method_label']} on {row['scenario']} seed {row['seed']}", row["error"])
                )
            if progress is not None:
                progress(summary.n_ok + summary.n_failed, len(pending), row)

        try:
            if pending:
                if scheduler is None and workers == 0:
                    summary.executor, summary.n_workers = "in-process", 1
                    _run_serial(pending, out, record)
                else:
                    _run_dask(pending, out, record, workers, scheduler, summary)
        finally:
            summary.wall_s = time.perf_counter() - t0
            info = {
                "started_at": started,
                "finished_at": _now(),
                "wall_s": round(summary.wall_s, 2),
                "grid": grid.name,
                "grid_hash": gh,
                "executor": summary.executor or "none",
                "n_workers": summary.n_workers,
                "host": socket.gethostname(),
                "cpu_count": os.cpu_count(),
                "cpu": platform.processor() or platform.machine(),
                "python": platform.python_version(),
                "n_jobs": len(jobs),
                "n_skipped": summary.n_skipped,
                "n_ok": summary.n_ok,
                "n_failed": summary.n_failed,
                "completed": summary.n_ok + summary.n_failed == len(pending),
                "load_avg_start": load0,
                "load_avg_end": _loadavg(),
            }
            with (out / RUNS_LOG).open("a") as f:
                f.write(json.dumps(info) + "\n")
    return summary


def _loadavg() -> float | None:
    """1-minute load average (None where unavailable): how shared the machine was."""
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def _run_serial(pending: list[Job], out: Path, record: Callable[[dict[str, Any]], None]) -> None:
    prepared: dict[str, str | BaseException] = {}
    for job in pending:
        d = job.as_dict()
        key = job.sequence_rel
        if key not in prepared:
            try:
                prepared[key] = prepare_sequence(d, str(out))
            except Exception as e:
                log.warning("preparing %s failed: %s", key, e)
                prepared[key] = e
        seq = prepared[key]
        if isinstance(seq, BaseException):
            record(failed_row(d, f"sequence preparation failed: {type(seq).__name__}: {seq}"))
            continue
        record(run_job(d, str(out), seq))


def _run_dask(
    pending: list[Job],
    out: Path,
    record: Callable[[dict[str, Any]], None],
    workers: int,
    scheduler: str | None,
    summary: BenchmarkSummary,
) -> None:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as e:  # pragma: no cover - dask is a core dependency
        raise ConfigError(
            "the benchmark needs dask.distributed: pip install 'dask[distributed]'"
        ) from e

    dlog = logging.getLogger("distributed")
    if not log.isEnabledFor(logging.DEBUG):
        dlog.setLevel(logging.WARNING)
    cluster = None
    if scheduler is not None:
        client = Client(scheduler, timeout="30s")
        summary.executor = str(scheduler)
    else:
        import signal

        # workers started with Ctrl-C ignored (inherited): the CLI process alone handles it;
        # their logs silenced (a job's error comes back as its failed row, and a stopped run's
        # workers would log tracebacks about the closed scheduler)
        sigint = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            cluster = LocalCluster(
                n_workers=max(1, workers),
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",
                silence_logs=logging.CRITICAL,
            )
        finally:
            signal.signal(signal.SIGINT, sigint)
        client = Client(cluster)
        summary.executor = f"LocalCluster(n_workers={max(1, workers)})"
    try:
        info = client.run(_worker_setup)
        summary.n_workers = len(info)
        log.info("workers: %s", info)
        root = str(out)
        prep: dict[str, Any] = {}
        by_key = {}
        for job in pending:
            by_key.setdefault(job.sequence_rel, job)
        # clean sequences first, then the nuisance variants derived from them
        for key, job in by_key.items():
            if job.nuisance:
                continue
            prep[key] = client.submit(
                prepare_sequence, job.as_dict(), root, key=f"prep-{_hash(key)}", pure=False
            )
        for key, job in by_key.items():
            if not job.nuisance:
                continue
            d = job.as_dict()
            base = prep.get(job.base_rel)
            if base is None:
                clean = {**d, "nuisance": {}, "sequence_rel": job.base_rel}
                base = client.submit(
                    prepare_sequence, clean, root, key=f"prep-{_hash(job.base_rel)}", pure=False
                )
                prep[job.base_rel] = base
            prep[key] = client.submit(
                prepare_sequence, d, root, base, key=f"prep-{_hash(key)}", pure=False
            )
        futs = []
        job_of: dict[str, Job] = {}
        for job in pending:
            fut = client.submit(
                run_job,
                job.as_dict(),
                root,
                prep[job.sequence_rel],
                key=f"job-{job.job_id}",
                pure=False,
            )
            futs.append(fut)
            job_of[fut.key] = job
        for fut in as_completed(futs):
            job = job_of[fut.key]
            try:
                row = fut.result()
            except Exception as e:  # preparation failed, worker died, …
                row = failed_row(job.as_dict(), e)
            record(row)
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _hash(s: str) -> str:
    return hashlib.sha1(s.encode()).hexdigest()[:12]
