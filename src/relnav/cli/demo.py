"""``relnav demo``: simulate → estimate → evaluate → plot on a built-in scenario, no data needed."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import typer

from relnav.cli._common import console, progress_bar

DEMO_PRESET = "sim-voyager"
DEMO_FRAMES = 60
DEMO_METHODS = ("relnav", "paper1", "icp-point")
"""relnav's navigator, paper 1's pipeline as published, plain ICP (``--method extended`` adds
paper 1's descriptors with relnav's extensions)."""
DEMO_PEER = "kiss-icp"
"""The best peer of the navigation suite, added to the demo when ``[baselines]`` is installed."""


def default_methods() -> list[str]:
    """:data:`DEMO_METHODS`, plus :data:`DEMO_PEER` when its package is importable."""
    import importlib.util

    peer = [DEMO_PEER] if importlib.util.find_spec("kiss_icp") is not None else []
    return [*DEMO_METHODS, *peer]


TABLE_KEYS = (
    ("e_T_avg", "m"),
    ("e_T_max", "m"),
    ("drift", "m"),
    ("T_error_pct", "%"),
    ("e_R_avg", "deg"),
    ("e_R_max", "deg"),
    ("e_RT", "m²+deg²"),
    ("rpe_trans_rmse", "m"),
    ("rpe_rot_rmse", "deg"),
    ("time_ms", "ms"),
)
"""Rows of the demo table (``relnav evaluate --metrics`` defines each key)."""


def short_labels(methods: list[str], width: int = 10) -> dict[str, str]:
    """Column labels that fit an 80-column table: the name itself when it is at most ``width``
    characters (presets, ``icp-point``), else a letter ``A``, ``B``, … (explained in a legend)."""
    out: dict[str, str] = {}
    letters = iter("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    for m in methods:
        out[m] = m if len(m) <= width else next(letters)
    return out


def run_folder_name(method: str) -> str:
    """A file-system-safe folder name for a method string or preset."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", method).strip("_") or "method"


def default_jobs() -> int:
    """Processes for the demo's methods: the usable cores, at most 2 (the methods are few and
    each one's numba compilation is the cold run's main cost)."""
    from relnav._threads import usable_cores

    return min(2, usable_cores())


class _Trajectory(NamedTuple):
    """What the demo keeps of a method's run for the joint figures (a run's steps stay in its
    worker): times (N,) s, poses (N, 4, 4) target frame, and the steps' 1σ (N, 2)
    [translation m, rotation deg] when the method gives them (the navigator), else None."""

    timestamps: np.ndarray
    poses: np.ndarray
    step_sigma: np.ndarray | None = None


def _run_method(
    seq_dir: Path,
    m: str,
    name: str,
    options: dict[str, Any],
    preset: str | None,
    folder: Path,
    seed: int,
    progress: Callable[[], None] | None = None,
) -> tuple[dict[str, Any], _Trajectory]:
    """Run one method on the simulated sequence and write its run folder
    (:class:`relnav.pipeline.OdometryPipeline`); returns its metrics and trajectory. Called in
    the CLI process or in a worker (:func:`_run_side_by_side`)."""
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import OdometryPipeline

    seq = ScanSequence(seq_dir)
    tick = (lambda i, s: progress()) if progress is not None else None
    pipe = OdometryPipeline(name, options, validate=False)  # resolved and checked already
    pipe.preset = preset  # the name it was expanded from (labels, run.json)
    result = pipe.run(seq, progress=tick, stream=False)
    run = result.run
    metrics = pipe.write(result, seq, folder, command="demo", seed=seed)
    if run.causal_poses is not None and "causal" in metrics:  # like the causal peers
        smoothed = {k: metrics[k] for k in metrics["causal"] if k in metrics}
        metrics = {**metrics, **metrics.pop("causal"), "smoothed": smoothed}
    poses = np.asarray(run.online_poses)
    return metrics, _Trajectory(np.asarray(run.timestamps), poses, run.step_sigma)


_QUEUE: Any = None


def _worker_init(queue: Any) -> None:
    """A worker ignores Ctrl-C (the CLI process ends the pool), reports frames to ``queue`` and
    imports the odometry modules while the CLI process simulates."""
    import signal

    global _QUEUE
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _QUEUE = queue
    import relnav.pipeline.run  # noqa: F401  (the registry: navigator, odometry, methods)


def _worker_run(*job: Any) -> tuple[dict[str, Any], _Trajectory]:
    """:func:`_run_method` in a worker, each frame put on the progress queue."""
    m = job[1]
    return _run_method(*job, progress=lambda: _QUEUE.put(m))


class _Workers:
    """``n`` spawned processes that run methods beside the CLI process (each compiles its own
    kernels, the cold run's main cost; the results are those of a sequential run). Started
    before the simulation so that their imports overlap it; :meth:`close` ends them (also on
    Ctrl-C)."""

    def __init__(self, n: int) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.queue = ctx.Queue()
        self.pool = ctx.Pool(n, initializer=_worker_init, initargs=(self.queue,))
        self._procs = list(getattr(self.pool, "_pool", []))  # the workers, to notice a death

    def run(
        self, jobs: list[tuple], bar: Any, tasks: dict[str, Any]
    ) -> dict[str, tuple[dict[str, Any], _Trajectory]]:
        """The first job in this process, the others in the workers; progress bars fed from the
        workers' queue."""
        pending = {j[1]: self.pool.apply_async(_worker_run, j) for j in jobs[1:]}

        def tick(t: Any = tasks[jobs[0][1]]) -> None:
            bar.advance(t)
            self._drain(bar, tasks)

        results = {jobs[0][1]: _run_method(*jobs[0], progress=tick)}
        while len(results) < len(jobs):
            self._drain(bar, tasks, timeout=0.1)
            for m, r in pending.items():
                if m not in results and r.ready():
                    results[m] = r.get()  # re-raises a worker's error here
            dead = [p.exitcode for p in self._procs if p.exitcode not in (None, 0)]
            if dead and len(results) < len(jobs):  # its job would never finish: no hang
                from relnav.errors import RelnavError

                left = ", ".join(m for m in pending if m not in results)
                raise RelnavError(
                    f"a demo worker process died (exit code {dead[0]}) while running {left}; "
                    "rerun with --jobs 1 to run the methods in this process (a script that "
                    "calls the demo needs the `if __name__ == '__main__':` guard of spawned "
                    "processes)"
                )
        self._drain(bar, tasks)
        return results

    def _drain(self, bar: Any, tasks: dict[str, Any], timeout: float | None = None) -> None:
        import queue as queue_mod

        try:
            if timeout is not None:
                bar.advance(tasks[self.queue.get(timeout=timeout)])
            while True:
                bar.advance(tasks[self.queue.get_nowait()])
        except queue_mod.Empty:
            pass

    def close(self) -> None:
        """End the workers."""
        self.pool.terminate()
        self.pool.join()


def _simulate_and_run(
    scenario: Any,
    preset: str,
    frames: int,
    seq_dir: Path,
    method: list[str],
    resolved: dict[str, tuple],
    out: Path,
    seed: int,
    workers: _Workers | None,
    timings: dict[str, float],
) -> tuple[dict[str, _Trajectory], dict[str, dict[str, Any]]]:
    """Simulate the sequence, then run every method (side by side with ``workers``) and write
    its run folder; returns the trajectories and metrics by method."""
    import time

    from relnav.io.sequences import ScanSequence
    from relnav.sim.scenario import simulate

    with progress_bar() as bar:
        task = bar.add_task(f"simulate {preset}", total=min(frames, scenario.frames))
        t0 = time.perf_counter()
        simulate(scenario, seq_dir, progress=lambda *a: bar.advance(task), overwrite=True)
        timings["simulate_s"] = time.perf_counter() - t0
        n = len(ScanSequence(seq_dir))
        tasks = {m: bar.add_task(m, total=n) for m in method}
        jobs = [(seq_dir, m, *resolved[m], out / "runs" / run_folder_name(m), seed) for m in method]
        if workers is not None:
            results = workers.run(jobs, bar, tasks)
        else:
            results = {
                j[1]: _run_method(*j, progress=lambda t=tasks[j[1]]: bar.advance(t)) for j in jobs
            }
    return {m: results[m][1] for m in method}, {m: results[m][0] for m in method}


def demo(
    out: Path = typer.Option(Path("relnav-demo"), "--out", "-o", help="Output folder."),
    preset: str = typer.Option(DEMO_PRESET, "--preset", help="Scenario preset to simulate."),
    frames: int = typer.Option(
        DEMO_FRAMES, "--frames", help="Frames (the first N of the preset, at its own rate)."
    ),
    seed: int = typer.Option(0, "--seed", help="Simulation seed."),
    method: list[str] = typer.Option(
        None,
        "--method",
        "-m",
        help="Methods or presets to compare (`relnav methods`); default: relnav, paper1, "
        "icp-point, and kiss-icp when [baselines] is installed.",
    ),
    jobs: int = typer.Option(
        default_jobs(),
        "--jobs",
        "-j",
        min=1,
        help="Methods run side by side in this many processes (default: up to 2 cores; "
        "1: one after the other). Results are the same; time_ms is each method's own.",
    ),
) -> None:
    """Run the whole chain on a built-in scenario (procedural target, ~60 frames).

    Writes OUT/sequence/, one folder per method OUT/runs/<method>/ (estimate.tum,
    diagnostics.csv, metrics.json, errors.png, run.json), and OUT/metrics.json,
    OUT/trajectory.png, OUT/errors.png and OUT/run.json for all methods together.
    """
    import json

    from rich.table import Table

    from relnav.eval.metrics import match_trajectories
    from relnav.eval.plots import plot_errors, plot_trajectories
    from relnav.io.runinfo import run_info, write_run_info
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import resolve_method
    from relnav.pipeline.outputs import json_safe
    from relnav.sim.presets import get_preset

    method = list(method) if method else default_methods()
    resolved = {m: resolve_method(m) for m in method}  # unknown names fail before any work
    labels = short_labels(list(method))
    out.mkdir(parents=True, exist_ok=True)
    seq_dir = out / "sequence"
    scenario = get_preset(preset, max_frames=frames, seed=seed)
    timings: dict[str, float] = {}
    n_workers = min(jobs, len(method)) - 1
    workers = _Workers(n_workers) if n_workers > 0 else None
    try:
        runs, metrics = _simulate_and_run(
            scenario, preset, frames, seq_dir, method, resolved, out, seed, workers, timings
        )
    finally:
        if workers is not None:
            workers.close()
    seq = ScanSequence(seq_dir)
    folders = {m: f"runs/{run_folder_name(m)}" for m in method}
    (out / "metrics.json").write_text(
        json.dumps(
            {
                "preset": preset,
                "frames": frames,
                "seed": seed,
                "folders": folders,
                "methods": {m: json_safe(v) for m, v in metrics.items()},
            },
            indent=2,
        )
    )
    title = f"relnav demo — {preset}, {len(seq)} frames, seed {seed}"
    plot_trajectories(
        out / "trajectory.png", seq.gt_poses, {m: r.poses for m, r in runs.items()}, title=title
    )
    matched = {
        m: match_trajectories(r.timestamps, r.poses, seq.timestamps, seq.gt_poses)
        for m, r in runs.items()
    }
    first = next(iter(matched.values()))
    plot_errors(
        out / "errors.png",
        first.gt_poses,
        {m: mt.est_poses for m, mt in matched.items()},
        times=first.times,
        title=f"{title}: error with respect to the ground truth",
        step_sigmas={
            m: runs[m].step_sigma[mt.idx_est]
            for m, mt in matched.items()
            if runs[m].step_sigma is not None
        },
    )
    write_run_info(
        out,
        run_info(
            command="demo",
            method=None,
            options={
                m: {"method": resolved[m][0], "preset": resolved[m][2], "options": resolved[m][1]}
                for m in method
            },
            sequence=seq,
            seed=seed,
            timings=timings,
            outputs=["metrics.json", "trajectory.png", "errors.png", "run.json", *folders.values()],
            extra={"scenario_preset": preset},
        ),
    )

    table = Table(title=f"relnav demo — {preset} ({len(seq)} frames, seed {seed})")
    table.add_column("metric")
    table.add_column("unit")
    for m in runs:
        table.add_column(labels[m], justify="right")
    for key, unit in TABLE_KEYS:
        table.add_row(key, unit, *(f"{metrics[m][key]:.4g}" for m in runs))
    table.add_row("flagged", "frames", *(str(metrics[m]["flagged_frames"]) for m in runs))
    console.print(table)
    for m in runs:
        legend = f"{labels[m]} = {m}" if labels[m] != m else m
        # the path as the user can type it (never broken across lines)
        console.print(f"  {legend}: {out / folders[m]}/", highlight=False, soft_wrap=True)
    console.print(
        "  time_ms = median per frame; `relnav evaluate --metrics` defines every metric",
        highlight=False,
    )
    if any(metrics[m]["flagged_frames"] for m in runs):
        console.print(
            "  flagged = frames whose step the method did not trust (degenerate, failed or "
            "suspect: its diagnostics.csv says why per frame)",
            highlight=False,
        )
    for m in runs:
        if "smoothed" in metrics[m]:
            sm = metrics[m]["smoothed"]
            console.print(
                f"  {labels[m]}: causal poses (each frame's, when it was estimated: "
                f"estimate_causal.tum), like every other column; its smoothed trajectory "
                f"(estimate.tum, which used later frames): T_error {sm['T_error_pct']:.4g} %, "
                f"ape_trans_rmse {sm['ape_trans_rmse']:.4g} m",
                highlight=False,
            )
    for name in ("metrics.json", "trajectory.png", "errors.png", "run.json"):
        console.print(f"wrote {out / name}", highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Register ``relnav demo``."""
    app.command("demo")(demo)
