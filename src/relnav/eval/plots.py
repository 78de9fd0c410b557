"""Trajectory and error plots (matplotlib, headless).

Figures are built on a :class:`matplotlib.figure.Figure` with the Agg canvas, never through
``pyplot``: no global state, no GUI backend, safe in worker processes.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from relnav.errors import InputError
from relnav.eval.metrics import _as_poses, pose_errors

__all__ = ["new_figure", "plot_errors", "plot_trajectories", "save_png"]

log = logging.getLogger(__name__)

_GT_STYLE = {"color": "black", "linestyle": "--", "linewidth": 1.5, "label": "ground truth"}


def _check_estimates(estimates: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    if not isinstance(estimates, Mapping):
        raise InputError("estimates must be a mapping {name: (N, 4, 4) poses}")
    return {str(k): _as_poses(f"estimates[{k!r}]", v) for k, v in estimates.items()}


def new_figure(width: float, height: float) -> Figure:
    """A matplotlib figure (inches, constrained layout) on the Agg canvas: no ``pyplot``."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_png(fig: Figure, path: str | Path, dpi: int, *, what: str = "plots") -> Path:
    """Write ``fig`` to the PNG ``path`` (folders created); ``what`` names the figures in the
    error raised for another suffix."""
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise InputError(f"{out}: {what} are written as PNG; use a .png file name")
    from relnav.atomic import atomic_open

    try:  # atomically: a full disk leaves no truncated PNG, and one line, not a traceback
        with atomic_open(out, "wb") as f:
            fig.savefig(f, dpi=dpi, format="png")
    except OSError as e:
        from relnav.io.outputs import output_error

        raise output_error(e, out) from None
    log.debug("wrote %s", out)
    return out


def _equal_3d(ax, xyz: np.ndarray) -> None:  # type: ignore[no-untyped-def]
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    c = 0.5 * (lo + hi)
    r = 0.5 * max(float((hi - lo).max()), 1e-9)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)


def plot_trajectories(
    path: str | Path,
    gt_poses: np.ndarray | None,
    estimates: Mapping[str, np.ndarray],
    *,
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Write a PNG with a 3-D view, a top view (x–y) and a side view (x–z) of trajectories.

    Parameters
    ----------
    path : str or Path
        Output ``.png`` file (parent folders are created).
    gt_poses : (N, 4, 4) float64 or None
        Ground-truth absolute poses (dashed black), or ``None`` to plot estimates only.
    estimates : mapping str → (M, 4, 4) float64
        Estimated absolute poses per method name, in the ground-truth frame (align first).
    title : str, optional
        Figure title.
    dpi : int
        Resolution.

    Returns
    -------
    Path
        The written file.
    """
    est = _check_estimates(estimates)
    gt = None if gt_poses is None else _as_poses("gt_poses", gt_poses)
    if gt is None and not est:
        raise InputError("plot_trajectories: nothing to plot (no ground truth, no estimates)")
    fig = new_figure(15.5, 5.6)
    # the 3-D panel gets its own wider column so its z label cannot reach the top view's y label
    gs = fig.add_gridspec(1, 3, width_ratios=(1.15, 1.0, 1.0), wspace=0.08)
    ax3 = fig.add_subplot(gs[0, 0], projection="3d")
    ax_top = fig.add_subplot(gs[0, 1])
    ax_side = fig.add_subplot(gs[0, 2])
    series: list[tuple[np.ndarray, dict]] = []
    if gt is not None:
        series.append((gt[:, :3, 3], _GT_STYLE))
    for name, poses in est.items():
        series.append((poses[:, :3, 3], {"linewidth": 1.2, "label": name}))
    all_xyz = np.concatenate([s[0] for s in series if len(s[0])] or [np.zeros((1, 3))])
    for xyz, style in series:
        ax3.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], **style)
        ax_top.plot(xyz[:, 0], xyz[:, 1], **style)
        ax_side.plot(xyz[:, 0], xyz[:, 2], **style)
        if len(xyz):
            color = ax_top.lines[-1].get_color()
            ax3.plot([xyz[0, 0]], [xyz[0, 1]], [xyz[0, 2]], "o", color=color, markersize=4)
            ax_top.plot(xyz[0, 0], xyz[0, 1], "o", color=color, markersize=4)
            ax_side.plot(xyz[0, 0], xyz[0, 2], "o", color=color, markersize=4)
    _equal_3d(ax3, all_xyz)
    ax3.set_xlabel("x [m]", labelpad=2)
    ax3.set_ylabel("y [m]", labelpad=2)
    ax3.set_zlabel("z [m]", labelpad=2)
    ax3.set_title("3-D view")
    for ax, (a, b), name in ((ax_top, "xy", "top view (x–y)"), (ax_side, "xz", "side view (x–z)")):
        ax.set_xlabel(f"{a} [m]")
        ax.set_ylabel(f"{b} [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
        ax.set_title(name)
    from matplotlib.lines import Line2D

    handles = [ax_top.lines[i] for i in range(0, 2 * len(series), 2)]
    handles.append(
        Line2D([], [], marker="o", color="grey", linestyle="none", markersize=5, label="start")
    )
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=min(len(handles), 6),
        fontsize="small",
        frameon=False,
    )
    if title:
        fig.suptitle(title)
    return save_png(fig, path, dpi)


def plot_errors(
    path: str | Path,
    gt_poses: np.ndarray,
    estimates: Mapping[str, np.ndarray],
    *,
    times: np.ndarray | None = None,
    title: str | None = None,
    dpi: int = 120,
    log_scale: bool | None = None,
) -> Path:
    """Write a PNG of per-frame errors: ``‖Δ‖``, signed ``Δx, Δy, Δz`` and the rotation error.

    ``Δ_k = t(T_k^GT) − t(T_k^est)`` (metres) and the geodesic rotation error (degrees), as in
    :func:`relnav.eval.metrics.pose_errors`.

    Parameters
    ----------
    path : str or Path
        Output ``.png`` file.
    gt_poses : (N, 4, 4) float64
        Ground-truth absolute poses.
    estimates : mapping str → (N, 4, 4) float64
        Estimates associated frame by frame with ``gt_poses`` (same length), aligned.
    times : (N,) float64, optional
        Time axis in seconds (frame index otherwise).
    title : str, optional
        Figure title.
    dpi : int
        Resolution.
    log_scale : bool, optional
        Logarithmic ‖Δ‖ and rotation axes, and symmetric-log axis errors (linear within the
        smallest method's range). Default: on when the methods' largest errors differ by more
        than 20×, so that a method that loses the track does not flatten the others to a line.

    Returns
    -------
    Path
        The written file.
    """
    gt = _as_poses("gt_poses", gt_poses)
    est = _check_estimates(estimates)
    if not est:
        raise InputError("plot_errors: no estimates given")
    for name, poses in est.items():
        if poses.shape != gt.shape:
            raise InputError(
                f"plot_errors: estimate {name!r} has {len(poses)} poses but the ground truth "
                f"has {len(gt)}; associate them first"
            )
    if times is None:
        x = np.arange(len(gt), dtype=np.float64)
        xlabel = "frame"
    else:
        x = np.asarray(times, dtype=np.float64)
        if x.shape != (len(gt),):
            raise InputError(f"plot_errors: times must have shape ({len(gt)},), got {x.shape}")
        x = x - x[0] if len(x) else x
        xlabel = "time [s]"
    errs = {name: pose_errors(poses, gt) for name, poses in est.items()}
    peaks = [float(e.trans.max(initial=0.0)) for e in errs.values()]
    if log_scale is None:
        pos = [p for p in peaks if p > 0]
        log_scale = len(pos) > 1 and max(pos) > 20 * min(pos)
    fig = new_figure(9, 10.5)
    axes = fig.subplots(5, 1, sharex=True)
    labels = ["‖Δ‖ [m]", "Δx [m]", "Δy [m]", "Δz [m]", "rotation error [deg]"]
    for name, pe in errs.items():
        curves = [pe.trans, pe.delta[:, 0], pe.delta[:, 1], pe.delta[:, 2], pe.rot_deg]
        for ax, y in zip(axes, curves, strict=True):
            ax.plot(x, y, linewidth=1.2, label=name)
    for ax, lab in zip(axes, labels, strict=True):
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    for ax in axes[1:4]:
        ax.axhline(0.0, color="black", linewidth=0.6)
    if log_scale:
        for ax in (axes[0], axes[4]):
            ax.set_yscale("log", nonpositive="mask")
        lin = max(min(p for p in peaks if p > 0), 1e-6)
        for ax in axes[1:4]:
            ax.set_yscale("symlog", linthresh=lin)
    axes[-1].set_xlabel(xlabel)
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=min(len(est), 4),
        fontsize="small",
        frameon=False,
    )
    scale_note = " (log scales)" if log_scale else ""
    fig.suptitle((title or "Error with respect to the ground truth") + scale_note)
    return save_png(fig, path, dpi)
