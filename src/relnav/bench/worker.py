"""Benchmark worker side: simulate a job's sequence once (published atomically with a
``.complete`` marker) and run one odometry job into a store row. Pure functions of their
arguments, importable by Dask workers; driven by :func:`relnav.bench.benchmark.run_benchmark`.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from relnav.errors import InputError
from relnav.sim.nuisance import NuisanceSpec

__all__ = [
    "failed_row",
    "prepare_sequence",
    "run_job",
]

log = logging.getLogger(__name__)


_MARKER = ".complete"


# --------------------------------------------------------------------------------------------
# worker side: sequences and jobs (pure functions of their arguments, importable by workers)
# --------------------------------------------------------------------------------------------


def _abs(root: str | Path, rel: str) -> Path:
    p = Path(rel)
    return p if p.is_absolute() else Path(root) / p


def _scenario_for(spec: dict[str, Any], seed: int) -> Any:
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import load_scenario

    if "preset" in spec:
        return get_preset(
            spec["preset"],
            frames=spec.get("frames"),
            max_frames=spec.get("max_frames"),
            seed=seed,
            **spec.get("options", {}),
        )
    data = dict(spec["scenario"])
    data["seed"] = int(seed)
    if spec.get("frames") is not None:
        data["frames"] = spec["frames"]
    if spec.get("max_frames") is not None:
        data["max_frames"] = spec["max_frames"]
    return load_scenario(data)


def _publish(tmp: Path, final: Path) -> None:
    (tmp / _MARKER).write_text(datetime.now(UTC).isoformat(timespec="seconds") + "\n")
    if final.exists():
        if (final / _MARKER).exists():  # another worker finished first: identical content
            shutil.rmtree(tmp, ignore_errors=True)
            return
        shutil.rmtree(final, ignore_errors=True)  # left over by a killed run
    try:
        os.replace(tmp, final)
    except OSError:
        if not (final / _MARKER).exists():
            raise
        shutil.rmtree(tmp, ignore_errors=True)


def prepare_sequence(job: dict[str, Any], out_root: str, base_dir: str | None = None) -> str:
    """Make sure the sequence of ``job`` exists on disk; returns its folder.

    Clean simulated sequences are simulated from ``job["scenario_spec"]`` with
    ``job["seed"]``; nuisance variants are written from the clean folder (``base_dir`` when
    given, else prepared first). Existing complete folders are reused. Pure: the content
    depends only on (scenario spec, seed, nuisance).
    """
    from relnav.sim.scenario import simulate

    final = _abs(out_root, job["sequence_rel"])
    if job["scenario_kind"] == "sequence" and not job["nuisance"]:
        if not final.is_dir():
            raise InputError(f"{final}: sequence folder not found on this machine")
        return str(final)
    if (final / _MARKER).exists():
        return str(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f"{final.name}.tmp-{uuid.uuid4().hex[:8]}")
    try:
        if not job["nuisance"]:
            simulate(_scenario_for(job["scenario_spec"], job["seed"]), tmp)
        else:
            from relnav.sim.nuisance import write_nuisance_sequence

            if base_dir is None:
                clean = {**job, "nuisance": {}, "sequence_rel": job["base_rel"]}
                base_dir = prepare_sequence(clean, out_root)
            write_nuisance_sequence(
                base_dir,
                tmp,
                NuisanceSpec.parse(job["nuisance"]),
                seed=job["seed"],
                max_frames=job["scenario_spec"].get("max_frames"),
            )
        _publish(tmp, final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return str(final)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"local:{os.getpid()}"


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _base_row(job: dict[str, Any]) -> dict[str, Any]:
    from relnav import __version__

    return {
        "job_id": job["job_id"],
        "scenario": job["scenario"],
        "scenario_kind": job["scenario_kind"],
        "scenario_spec": job["scenario_spec"],
        "nuisance": job["nuisance_label"],
        "nuisance_params": job["nuisance"],
        "method": job["method"],
        "method_label": job["method_label"],
        "method_options": job["options"],
        "seed": job["seed"],
        "relnav_version": __version__,
        "host": socket.gethostname(),
        "worker": _worker_name(),
    }


def failed_row(job: dict[str, Any], error: BaseException | str) -> dict[str, Any]:
    """The store row of a job that could not run (``status = "failed"``)."""
    row = _base_row(job)
    msg = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    row.update(status="failed", error=msg[:2000], finished_at=_now())
    return row


def run_job(job: dict[str, Any], out_root: str, sequence_dir: str | None = None) -> dict[str, Any]:
    """Run one job and return its store row (never raises: failures become ``failed`` rows).

    Parameters
    ----------
    job : dict
        :meth:`Job.as_dict`.
    out_root : str
        Benchmark folder (``runs/<job_id>/`` is written there).
    sequence_dir : str, optional
        The prepared sequence (from :func:`prepare_sequence`); prepared here when ``None``.

    Returns
    -------
    dict
        Store row: identity columns, status, metrics (:data:`relnav.eval.metrics.METRIC_KEYS`,
        from the written files as ``relnav evaluate`` computes them, plus ``time_ms`` = mean
        time per registered frame), per-stage mean times (ms), points per scan, timestamps.
    """
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.io.trajectories import read_tum
    from relnav.pipeline import OdometryPipeline

    started = _now()
    t0 = time.perf_counter()
    row = _base_row(job)
    row["started_at"] = started
    try:
        if sequence_dir is None:
            sequence_dir = prepare_sequence(job, out_root)
        spec = job["scenario_spec"]
        seq = ScanSequence(sequence_dir, sensor=spec.get("sensor"))
        max_frames = spec.get("max_frames") if job["scenario_kind"] == "sequence" else None
        warm = int(job.get("warmup_frames", 0))
        # the grid resolved the method (a preset expanded) and checked its options
        pipe = OdometryPipeline(job["method"], job["options"], validate=False)
        if warm >= 2 and len(seq) >= 2:
            pipe.run(seq, max_frames=warm, stream=False)
        run = pipe.run(seq, max_frames=max_frames, stream=False).run
        out = Path(out_root) / "runs" / job["job_id"]
        paths = run.write(out)
        diag = run.diagnostics()
        reg = diag[1:] or diag
        stages = {
            k: float(np.mean([float(d[k]) for d in reg])) for k in diag[0] if k.startswith("t_")
        }
        row.update(stages)
        row["mean_points"] = float(np.mean([d["n_points"] for d in diag]))
        row["n_flagged"] = run.n_flagged
        row["estimate_path"] = str(paths["estimate"].relative_to(out_root))
        row["sequence_path"] = (
            str(Path(sequence_dir).relative_to(out_root))
            if Path(sequence_dir).is_relative_to(out_root)
            else str(sequence_dir)
        )
        gt_file = seq.layout.gt
        if gt_file.is_file():
            t_est, P_est = read_tum(paths["estimate"])
            t_gt, P_gt = read_tum(gt_file)
            row.update(evaluate_trajectories(t_est, P_est, t_gt, P_gt))
            row["error"] = ""
        else:
            row["error"] = "no ground truth: timing only"
        row["time_ms"] = run.mean_time_ms
        row["status"] = "ok"
    except Exception as e:  # a failing method must not stop the grid
        log.warning(
            "job %s (%s on %s) failed: %s", job["job_id"], job["method"], job["scenario"], e
        )
        row.update(failed_row(job, e))
    row["finished_at"] = _now()
    row["wall_s"] = time.perf_counter() - t0
    row["started_at"] = started
    return row


def _worker_setup() -> dict[str, Any]:
    """Run on every worker once: its pid and numba's cache setting (logged at INFO)."""
    import numba

    cache_dir = numba.config.CACHE_DIR or "(next to the sources / user cache)"
    return {"pid": os.getpid(), "numba_cache_dir": cache_dir, "numba": numba.__version__}
