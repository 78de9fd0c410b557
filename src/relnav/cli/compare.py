"""``relnav compare``: several runs against the same ground truth (``evo_res``-style)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import typer

from relnav.cli._common import console
from relnav.cli.evaluate import Align, DeltaUnit, read_poses
from relnav.errors import InputError
from relnav.pipeline.outputs import json_safe

ERRORS = ("ape_trans", "ape_rot", "rpe_trans", "rpe_rot")
_UNITS = {"ape_trans": "m", "ape_rot": "deg", "rpe_trans": "m", "rpe_rot": "deg"}


def _estimate_file(run: Path, smoothed: bool = False) -> Path:
    """The run's trajectory: its causal one (``estimate_causal.tum``, the poses a real-time loop
    had, written by methods with a smoother) unless ``smoothed``, else ``estimate.tum``."""
    if run.is_file():
        return run
    names = ("estimate.tum", "estimate_kitti.txt")
    for name in names if smoothed else ("estimate_causal.tum", *names):
        if (run / name).is_file():
            return run / name
    raise InputError(f"{run}: no estimate.tum (give a run folder or a TUM/KITTI file)")


def _label(run: Path) -> str:
    from relnav.io.runinfo import read_run_info

    info = read_run_info(run) if run.is_dir() else None
    if info:
        return str(info.get("preset") or info.get("method") or run.name)
    return run.stem if run.is_file() else run.name


def _ground_truth(runs: list[Path], gt: Path | None) -> tuple[np.ndarray, np.ndarray, str]:
    """``(times, poses, description)`` of the common ground truth."""
    if gt is not None:
        t, P, _ = read_poses(gt, "ground-truth")
        if t is None:
            t = np.arange(len(P), dtype=float)
        return t, P, str(gt)
    from relnav.io.runinfo import read_run_info
    from relnav.io.sources import open_sequence

    seqs = set()
    for r in runs:
        info = read_run_info(r) if r.is_dir() else None
        s = (info or {}).get("sequence") or {}
        if not s.get("path"):
            raise InputError(f"{r}: no run.json naming its sequence; give --gt")
        seqs.add((s["path"], s.get("sensor"), s.get("topic")))
    if len(seqs) != 1:
        raise InputError(
            f"the runs come from different sequences ({', '.join(sorted(p for p, *_ in seqs))}); "
            "give --gt"
        )
    path, sensor, topic = seqs.pop()
    seq = open_sequence(path, sensor=sensor, topic=topic)
    if seq.gt_poses is None:
        raise InputError(f"{path}: the runs' sequence has no ground truth; give --gt")
    return seq.timestamps, seq.gt_poses, str(path)


def sequence_name(gt_desc: str) -> str:
    """A sequence's name for figure titles: its scenario's ``name`` (``scenario.yaml`` of a
    simulated folder) with the folder's name, else the folder or file name."""
    p = Path(gt_desc)
    name = p.name or str(p)
    sc = p / "scenario.yaml"
    if sc.is_file():
        import yaml

        try:
            scenario = (yaml.safe_load(sc.read_text()) or {}).get("name")
        except (OSError, yaml.YAMLError, AttributeError):
            scenario = None
        if scenario and scenario != name:
            return f"{scenario} ({name})"
    return name


def _clipped_limit(values: list[np.ndarray]) -> tuple[float, set[int]]:
    """Upper axis limit for error curves (from their second sample: the first is the start)
    and the indices of curves more than 20x worse than the best, left off-scale."""
    peaks = [float(np.nanmax(v[1:], initial=0.0)) if len(v) > 1 else 0.0 for v in values]
    pos = [p for p in peaks if p > 0]
    floor = min(pos) if pos else 0.0
    off = {i for i, p in enumerate(peaks) if floor > 0 and p > 20 * floor}
    kept = [p for i, p in enumerate(peaks) if i not in off] or peaks
    return 1.08 * max(kept, default=0.0) or 1.0, off


def plot_compare_overview(
    path: Path, all_series: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]], title: str
) -> Path:
    """APE and RPE, translation and rotation, of every run over time (2×2, linear axes from the
    second sample; a run >20x worse than the best is clipped, its peak in the legend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 8.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True)
    names = list(next(iter(all_series.values())))
    colours = {n: f"C{i % 10}" for i, n in enumerate(names)}
    for ax, err in zip(axes.flat, ERRORS, strict=True):
        series = all_series[err]
        lim, off = _clipped_limit([series[n][1] for n in names])
        for k, n in enumerate(names):
            t, e = series[n]
            label = n if k not in off else f"{n} (off scale, peak {np.nanmax(e):.3g})"
            ax.plot(t - t[0] if len(t) else t, e, lw=1.2, color=colours[n], label=label)
        ax.set_ylim(0.0, lim)
        kind = "APE" if err.startswith("ape") else "RPE"
        what = "translation" if err.endswith("trans") else "rotation"
        ax.set_title(f"{kind} {what} ({err})")
        ax.set_ylabel(f"{err} [{_UNITS[err]}]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="x-small", loc="upper left")
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    return path


def plot_compare(
    path: Path, series: dict[str, tuple[np.ndarray, np.ndarray]], error: str, title: str
) -> Path:
    """evo_res-style figure: the error over time, its distribution and its statistics per run.

    ``series`` maps a run label to ``(times, errors)`` of ``error`` (e.g. ``ape_trans``).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from relnav.eval.metrics import error_statistics

    unit = _UNITS[error]
    fig = Figure(figsize=(13, 8.5), layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, 2, height_ratios=(1.1, 1.0))
    ax_t = fig.add_subplot(gs[0, :])
    ax_box = fig.add_subplot(gs[1, 0])
    ax_bar = fig.add_subplot(gs[1, 1])
    labels = list(series)
    lim, off = _clipped_limit([series[k][1] for k in labels])
    log = False  # linear, as evo_res; a run >20x worse than the best is clipped (see legend)
    for k, (name, (t, e)) in enumerate(series.items()):
        label = name if k not in off else f"{name} (off scale, peak {np.nanmax(e):.3g})"
        ax_t.plot(t - t[0] if len(t) else t, e, lw=1.2, label=label)
    ax_t.set_ylim(0.0, lim)
    ax_t.set_xlabel("time [s]")
    ax_t.set_ylabel(f"{error} [{unit}]")
    ax_t.set_title(f"(a) {error} over time")
    ax_t.grid(True, alpha=0.3)
    ax_t.legend(fontsize="small", loc="upper left", ncol=min(len(labels), 4))
    ax_box.boxplot([series[k][1] for k in labels], tick_labels=labels, showfliers=True)
    ax_box.set_ylabel(f"{error} [{unit}]")
    ax_box.set_title("(b) distribution per run")
    ax_box.grid(True, axis="y", alpha=0.3)
    stats = ("rmse", "mean", "median", "std", "max")
    width = 0.8 / max(len(labels), 1)
    x = np.arange(len(stats))
    bars = []
    for k, name in enumerate(labels):
        st = error_statistics(series[name][1])
        bars.append(
            ax_bar.bar(
                x + (k - (len(labels) - 1) / 2) * width, [st[s] for s in stats], width, label=name
            )
        )
    ax_bar.set_xticks(x, stats)
    ax_bar.set_ylabel(f"{error} [{unit}]")
    ax_bar.set_title("(c) statistics (evo names), colours as in (a)")
    ax_bar.grid(True, axis="y", alpha=0.3)
    if off:  # clipped like (a): the clipped runs' values are written, not hidden
        ax_box.set_ylim(0.0, lim)
        ax_bar.set_ylim(0.0, lim)
        ticks = [
            f"{n}\n(off scale, median {np.nanmedian(series[n][1]):.3g})" if k in off else n
            for k, n in enumerate(labels)
        ]
        ax_box.set_xticks(np.arange(1, len(labels) + 1), ticks)
        for cont in bars:
            for rect in cont:
                if rect.get_height() > lim:
                    ax_bar.text(
                        rect.get_x() + rect.get_width() / 2,
                        0.97 * lim,
                        f"{rect.get_height():.3g}",
                        rotation=90,
                        ha="center",
                        va="top",
                        fontsize=7,
                        color="white",
                    )
    if log:
        for ax in (ax_t, ax_box):
            ax.set_yscale("log", nonpositive="mask")
        ax_bar.set_yscale("log", nonpositive="clip")  # bars start at 0
    if len(labels) > 3:
        for lab in ax_box.get_xticklabels():
            lab.set_rotation(20)
            lab.set_ha("right")
    fig.suptitle(title + (" (log scales)" if log else ""))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    return path


def compare(
    runs: list[Path] = typer.Argument(
        ..., help="Run folders (relnav odometry/demo outputs) or TUM/KITTI trajectory files."
    ),
    gt: Path | None = typer.Option(
        None, "--gt", help="Ground truth (TUM/KITTI); default: the runs' sequence (run.json)."
    ),
    align: Align = typer.Option(Align.none, "--align", help="none | first | se3 | sim3"),
    delta: float = typer.Option(1.0, "--delta", min=0.0, help="RPE pair distance (--delta-unit)."),
    delta_unit: DeltaUnit = typer.Option(DeltaUnit.frames, "--delta-unit", help="frames|m|deg|rad"),
    max_diff: float = typer.Option(0.01, "--max-diff", min=0.0, help="Association tolerance, s."),
    error: str = typer.Option(
        "ape_trans", "--error", help="Error of the statistics table and plot: " + ", ".join(ERRORS)
    ),
    json_path: Path | None = typer.Option(None, "--json", help="Write every run's metrics here."),
    plot_dir: Path | None = typer.Option(
        None, "--plot-dir", help="Write compare.png and trajectories.png into this folder."
    ),
    smoothed: bool = typer.Option(
        False,
        "--smoothed/--causal",
        help="Runs with a smoother (relnav): compare its smoothed trajectory (estimate.tum, "
        "which used later frames) instead of its causal one (estimate_causal.tum, the default: "
        "like every causal peer).",
    ),
) -> None:
    """Compare several runs on the same ground truth: an evo_res-style table and plot.

    Every run is evaluated exactly as [bold]relnav evaluate[/] does (same options for all).

    Example: [bold]relnav compare runs/icp runs/ext --plot-dir cmp --json cmp/compare.json[/]
    """
    from rich.table import Table

    from relnav.cli.demo import short_labels
    from relnav.eval.metrics import (
        STAT_NAMES,
        evaluate_trajectories,
        match_trajectories,
        pose_errors,
        relative_pose_errors,
    )

    if error not in ERRORS:
        raise InputError(f"--error {error!r}: choose one of {', '.join(ERRORS)}")
    if delta_unit == DeltaUnit.frames and delta != int(delta):
        raise InputError(f"--delta {delta:g}: an RPE delta in frames must be an integer")
    if delta <= 0:
        raise InputError("--delta must be > 0")
    d = int(delta) if delta_unit == DeltaUnit.frames else float(delta)
    for r in runs:
        if not r.exists():
            raise InputError(f"{r}: no such run folder or trajectory file")
    t_gt, P_gt, gt_desc = _ground_truth(runs, gt)
    names: dict[str, Path] = {}
    for r in runs:
        base = _label(r)
        name, k = base, 2
        while name in names:
            name, k = f"{base} ({k})", k + 1
        names[name] = r
    results: dict[str, dict[str, Any]] = {}
    all_series: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {e: {} for e in ERRORS}
    estimates: dict[str, np.ndarray] = {}
    for name, r in names.items():
        f = _estimate_file(r, smoothed)
        if smoothed and r.is_dir() and (r / "estimate_causal.tum").is_file():
            console.print(f"{name}: smoothed trajectory (it used later frames; --causal: not)")
        t_e, P_e, _ = read_poses(f, "estimated")
        if t_e is None:
            if len(P_e) != len(P_gt):
                raise InputError(
                    f"{f}: KITTI poses without times.txt and {len(P_e)} != "
                    f"{len(P_gt)} ground-truth poses"
                )
            t_e = t_gt.copy()
        kw = dict(max_diff=max_diff, align=align.value)
        res = evaluate_trajectories(
            t_e,
            P_e,
            t_gt,
            P_gt,
            delta=d,
            delta_unit=delta_unit.value,
            **kw,  # type: ignore[arg-type]
        )
        res["file"] = str(f)
        results[name] = res
        m = match_trajectories(t_e, P_e, t_gt, P_gt, **kw)  # type: ignore[arg-type]
        estimates[name] = m.est_poses
        from relnav.eval.metrics import rpe_pairs

        pe = pose_errors(m.est_poses, m.gt_poses)
        tr, rot = relative_pose_errors(
            m.est_poses,
            m.gt_poses,
            delta=d,
            delta_unit=delta_unit.value,  # type: ignore[arg-type]
        )
        i, _ = rpe_pairs(m.est_poses, d, delta_unit.value)  # type: ignore[arg-type]
        all_series["ape_trans"][name] = (m.times, pe.trans)
        all_series["ape_rot"][name] = (m.times, pe.rot_deg)
        all_series["rpe_trans"][name] = (m.times[i], tr)
        all_series["rpe_rot"][name] = (m.times[i], rot)
    series = all_series[error]

    labels = short_labels(list(names), width=12)
    summary = Table(
        title=f"{len(names)} runs vs {gt_desc} (align={align.value}, RPE delta "
        f"{d:g} {delta_unit.value})"
    )
    summary.add_column("run")
    cols = (
        ("ape_trans_rmse", "APE m"),
        ("ape_rot_rmse", "APE deg"),
        ("rpe_trans_rmse", "RPE m"),
        ("rpe_rot_rmse", "RPE deg"),
        ("T_error_pct", "T_err %"),
    )
    for _, head in cols:
        summary.add_column(head, justify="right")
    for name, res in results.items():
        summary.add_row(labels[name], *(_fmt(res[k]) for k, _ in cols))
    console.print(summary)
    stats = Table(title=f"{error} ({_UNITS[error]}) — evo_res statistics")
    stats.add_column("run")
    for s in STAT_NAMES:
        stats.add_column(s, justify="right")
    for name, res in results.items():
        stats.add_row(labels[name], *(_fmt(res[f"{error}_{s}"]) for s in STAT_NAMES))
    console.print(stats)
    for name, r in names.items():
        legend = f"{labels[name]} = {name}" if labels[name] != name else name
        console.print(f"  {legend}: {r}", highlight=False)
    console.print(
        "  APE/RPE m, deg = ape/rpe_{trans,rot}_rmse; T_err % = T_error_pct", highlight=False
    )

    if json_path is not None:
        doc = {
            "gt": gt_desc,
            "align": align.value,
            "delta": d,
            "delta_unit": delta_unit.value,
            "runs": {name: json_safe(res) for name, res in results.items()},
        }
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
        console.print(f"wrote {json_path}", highlight=False)
    if plot_dir is not None:
        from relnav.eval.plots import plot_trajectories

        seq_name = sequence_name(gt_desc)
        rpe = f"RPE (Δ {d:g} {delta_unit.value})"
        p0 = plot_compare_overview(
            plot_dir / "compare.png",
            all_series,
            f"{seq_name}: APE and {rpe}, {len(names)} runs (align={align.value})",
        )
        p1 = plot_compare(
            plot_dir / f"compare_{error}.png",
            series,
            error,
            f"{seq_name}: {error} of {len(names)} runs (align={align.value}"
            + (f", {rpe})" if error.startswith("rpe") else ")"),
        )
        p2 = plot_trajectories(
            plot_dir / "trajectories.png",
            P_gt,
            estimates,
            title=f"{seq_name}: {len(names)} runs (align={align.value})",
        )
        for p in (p0, p1, p2):
            console.print(f"wrote {p}", highlight=False, soft_wrap=True)


def _fmt(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.4g}"


def register(app: typer.Typer) -> None:
    """Register ``relnav compare``."""
    app.command("compare")(compare)
