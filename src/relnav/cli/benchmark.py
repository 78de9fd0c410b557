"""``relnav benchmark`` (run a grid, parallel, resumable) and ``relnav report`` (write it up)."""

from __future__ import annotations

from pathlib import Path

import typer

from relnav.cli._common import console, progress_bar


def benchmark(
    grid: Path = typer.Argument(..., help="Grid YAML (e.g. configs/paper1-quick.yaml)."),
    out: Path = typer.Option(..., "--out", "-o", help="Benchmark folder (created; resumable)."),
    workers: int = typer.Option(
        2, "--workers", "-w", min=0, help="Local worker processes (0 = in this process)."
    ),
    scheduler: str = typer.Option(
        None, "--scheduler", help="Existing Dask scheduler, e.g. tcp://host:8786."
    ),
    force: bool = typer.Option(False, "--force", help="Rerun every job, finished or not."),
    retry_failed: bool = typer.Option(
        False, "--retry-failed", help="Rerun jobs recorded as failed."
    ),
    seeds: int = typer.Option(None, "--seeds", min=1, help="Only the first N seeds."),
    max_frames: int = typer.Option(
        None, "--max-frames", min=2, help="Only the first N frames of every scenario."
    ),
    scenario: list[str] = typer.Option(
        None, "--scenario", help="Only these scenarios (glob, repeatable)."
    ),
    method: list[str] = typer.Option(
        None, "--method", "-m", help="Only methods whose label matches (glob, repeatable)."
    ),
    dry_run: bool = typer.Option(
        False, "--dry-run", help="List the jobs (and how many are finished) and stop."
    ),
    report: bool = typer.Option(True, "--report/--no-report", help="Write the report at the end."),
) -> None:
    """Run a benchmark grid: scenarios × methods × seeds (× nuisances), in parallel.

    Results go to OUT/results.sqlite as each job finishes; rerunning the same command skips
    finished jobs (a killed run resumes). At the end OUT/report.md, OUT/tables/*.csv and
    OUT/figures/*.png are written.

    Examples:

    [bold]relnav benchmark configs/paper1-quick.yaml --out bench/quick[/]

    [bold]relnav benchmark configs/paper1-full.yaml --out bench/full --seeds 1 --max-frames 20[/]

    [bold]relnav benchmark grid.yaml --out bench/x --scheduler tcp://10.0.0.5:8786[/]
    """
    import logging

    from rich.table import Table

    from relnav.bench.benchmark import STORE_FILE, expand_jobs, load_grid, run_benchmark

    g = load_grid(
        grid, seeds=seeds, max_frames=max_frames, scenarios=scenario or None, methods=method or None
    )
    jobs = expand_jobs(g)
    if dry_run:
        from relnav.bench.store import ResultsStore

        done: set[str] = set()
        if (out / STORE_FILE).is_file():
            with ResultsStore(out / STORE_FILE, readonly=True) as st:
                done = st.finished_ids()
        t = Table(title=f"{g.name}: {len(jobs)} jobs")
        for col in ("scenario", "nuisance", "seed", "method", "finished"):
            t.add_column(col)
        for j in jobs:
            t.add_row(
                j.scenario,
                j.nuisance_label,
                str(j.seed),
                j.method_label,
                "yes" if j.job_id in done else "",
            )
        console.print(t)
        return
    where = scheduler or ("this process" if workers == 0 else f"{workers} local workers")
    console.print(
        f"[bold]{g.name}[/]: {len(g.scenarios)} scenarios × {len(g.methods)} methods × "
        f"{len(g.seeds)} seeds × {len(g.nuisance_levels())} nuisance levels = {len(jobs)} jobs "
        f"on {where}",
        highlight=False,
    )
    logging.getLogger("relnav").setLevel(max(logging.getLogger().level, logging.WARNING))
    with progress_bar() as bar:
        task = bar.add_task("jobs", total=None)

        def prog(done: int, total: int, row: dict) -> None:  # type: ignore[type-arg]
            bar.update(task, completed=done, total=total)
            if row.get("status") != "ok":
                bar.console.print(
                    f"[yellow]failed[/] {row['method_label']} on {row['scenario']} seed "
                    f"{row['seed']}: {row.get('error', '')[:200]}",
                    highlight=False,
                )

        import signal

        def on_sigint(signum: int, frame: object) -> None:
            _quiet_teardown()  # before the cluster's teardown, which logs about the interrupt
            raise KeyboardInterrupt

        previous = signal.signal(signal.SIGINT, on_sigint)
        try:
            s = run_benchmark(
                g,
                out,
                workers=workers,
                scheduler=scheduler,
                force=force,
                retry_failed=retry_failed,
                progress=prog,
            )
        except KeyboardInterrupt:
            _quiet_teardown()
            bar.stop()
            console.print(
                f"[yellow]interrupted[/]: finished jobs are kept in {out / STORE_FILE}; "
                "rerun the same command to resume",
                highlight=False,
                soft_wrap=True,
            )
            raise typer.Exit(130) from None
        finally:
            signal.signal(signal.SIGINT, previous)
    console.print(
        f"{s.n_jobs} jobs: {s.n_skipped} already finished, {s.n_ok} ok, {s.n_failed} failed "
        f"in {s.wall_s / 60:.1f} min ({s.executor}); store {out / STORE_FILE}",
        highlight=False,
    )
    if report:
        from relnav.bench.report import write_report

        p = write_report(out)
        console.print(f"wrote {p}", highlight=False)


def _quiet_teardown() -> None:
    """After Ctrl-C: nothing more from Dask's, tornado's or asyncio's loggers while the cluster
    is torn down (their tracebacks are about the interruption itself)."""
    import logging

    for name in ("distributed", "tornado", "asyncio", "dask"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def report(
    out: Path = typer.Argument(..., help="Benchmark folder written by `relnav benchmark`."),
    grid: Path = typer.Option(
        None, "--grid", help="Report on this grid's jobs instead of the folder's grid.yaml."
    ),
    export: Path = typer.Option(
        None, "--export", help="Also copy report.md + compressed figures to this folder."
    ),
) -> None:
    """(Re)write OUT/report.md, OUT/tables/*.csv and OUT/figures/*.png from the results store.

    Examples: [bold]relnav report bench/quick[/],
    [bold]relnav report bench/full --export docs/results/paper1-full[/]
    """
    from relnav.bench.benchmark import load_grid
    from relnav.bench.report import export_report, write_report

    p = write_report(out, grid=None if grid is None else load_grid(grid))
    console.print(f"wrote {p}", highlight=False)
    if export is not None:
        q = export_report(out, export)
        console.print(f"exported {q}", highlight=False)


def register(app: typer.Typer) -> None:
    """Register ``relnav benchmark`` and ``relnav report``."""
    app.command("benchmark")(benchmark)
    app.command("report")(report)
