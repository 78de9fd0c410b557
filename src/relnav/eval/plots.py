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

__all__ = ["new_figure", "plot_errors", "plot_trajectories", "save_png", "step_envelope"]

log = logging.getLogger(__name__)

_GT_STYLE = {"color": "black", "linestyle": "--", "linewidth": 1.5, "label": "ground truth"}


def _check_estimates(estimates: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    if not isinstance(estimates, Mapping):
        raise InputError("estimates must be a mapping {name: (N, 4, 4) poses}")
    return {str(k): _as_poses(f"estimates[{k!r}]", v) for k, v in estimates.items()}


def _shown(name: str) -> str:
    """A method's name as a legend shows it: matplotlib hides labels starting with ``_``, so
    leading underscores are dropped (``"_Mine"`` → ``"Mine"``)."""
    return name.lstrip("_") or name


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


_GT_TOP = {**_GT_STYLE, "color": "black", "linewidth": 1.3, "zorder": 10}
"""Ground truth in the trajectory panels: dashed black, drawn last (on top of every method)."""

INSET_MAX_FRACTION = 0.08
"""A zoom inset is added to a view when the methods' final errors (the median over the
methods) are smaller than this fraction of the path's extent: the lines would overlap."""


def _translation_errors(gt: np.ndarray | None, est: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-frame ‖t_est − t_gt‖ (m) of every estimate as long as the ground truth (others:
    none)."""
    if gt is None:
        return {}
    return {
        n: np.linalg.norm(p[:, :3, 3] - gt[:, :3, 3], axis=1)
        for n, p in est.items()
        if p.shape == gt.shape
    }


def _add_zoom(ax, series, centre: np.ndarray, half: float, dims: tuple[int, int]) -> None:  # type: ignore[no-untyped-def]
    """A zoom inset of ``ax`` around ``centre`` (±``half`` m), in the axes corner (or the
    middle) that covers the fewest points of ``series`` (``(xyz, style)`` pairs; ``dims`` the
    view's axes)."""
    a, b = dims
    pts = np.concatenate([xyz[:, [a, b]] for xyz, _ in series if len(xyz)])
    ax.apply_aspect()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    u = (pts[:, 0] - x0) / max(x1 - x0, 1e-12)
    v = (pts[:, 1] - y0) / max(y1 - y0, 1e-12)
    # margins keep the inset's own tick labels (left, below) off the view's frame and labels;
    # the middle last (an orbit's view is empty inside, its corners are not)
    size = 0.38
    corners = [(0.6, 0.58), (0.13, 0.58), (0.6, 0.08), (0.13, 0.08), (0.35, 0.33)]
    cover = [
        int(np.sum((u >= cx) & (u <= cx + size) & (v >= cy) & (v <= cy + size)))
        for cx, cy in corners
    ]
    cx, cy = corners[int(np.argmin(cover))]
    axins = ax.inset_axes((cx, cy, size, size))
    for xyz, style in series:
        axins.plot(xyz[:, a], xyz[:, b], **{**style, "label": None})
    axins.set_xlim(centre[a] - half, centre[a] + half)
    axins.set_ylim(centre[b] - half, centre[b] + half)
    axins.set_aspect("equal", adjustable="box")
    axins.tick_params(labelsize=6)
    axins.text(
        0.03,
        0.97,
        f"zoom ±{half:.2g} m",
        transform=axins.transAxes,
        fontsize=6,
        va="top",
        bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1},
        zorder=20,
    )
    ax.indicate_inset_zoom(axins, edgecolor="0.4")


def plot_trajectories(
    path: str | Path,
    gt_poses: np.ndarray | None,
    estimates: Mapping[str, np.ndarray],
    *,
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Write a PNG of trajectories in evo's manner: the best estimate coloured by its error,
    then a top view (x–y) and a side view (x–z) of every method, ground truth on top.

    The methods are drawn from the worst (mean translation error) to the best, so the best is
    never hidden under a lost one; the ground truth (dashed black) is drawn last. When the
    errors are small against the path (:data:`INSET_MAX_FRACTION`) each view gets a zoom inset
    around the end of the path. Without ground truth the first panel is a 3-D view.

    Parameters
    ----------
    path : str or Path
        Output ``.png`` file (parent folders are created).
    gt_poses : (N, 4, 4) float64 or None
        Ground-truth absolute poses, or ``None`` to plot estimates only.
    estimates : mapping str → (M, 4, 4) float64
        Estimated absolute poses per method name, in the ground-truth frame (align first);
        an estimate as long as the ground truth is taken as associated frame by frame.
    title : str, optional
        Figure title.
    dpi : int
        Resolution.

    Returns
    -------
    Path
        The written file.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    est = _check_estimates(estimates)
    gt = None if gt_poses is None else _as_poses("gt_poses", gt_poses)
    if gt is None and not est:
        raise InputError("plot_trajectories: nothing to plot (no ground truth, no estimates)")
    errs = _translation_errors(gt, est)
    mean_err = {n: float(np.mean(e)) if len(e) else np.inf for n, e in errs.items()}
    colours = {n: f"C{i % 10}" for i, n in enumerate(est)}  # stable: the order given
    order = sorted(est, key=lambda n: -mean_err.get(n, np.inf))  # worst first, best on top
    series: list[tuple[np.ndarray, dict]] = [
        (est[n][:, :3, 3], {"linewidth": 1.3, "label": n, "color": colours[n]}) for n in order
    ]
    if gt is not None:
        series.append((gt[:, :3, 3], _GT_TOP))
    all_xyz = np.concatenate([s[0] for s in series if len(s[0])] or [np.zeros((1, 3))])
    fig = new_figure(16.5, 5.8)
    gs = fig.add_gridspec(1, 3, width_ratios=(1.12, 1.0, 1.0))
    best = min(mean_err, key=mean_err.__getitem__) if mean_err else None
    if best is not None:
        ax0 = fig.add_subplot(gs[0, 0])
        xy = est[best][:, :3, 3][:, :2]
        segs = np.stack([xy[:-1], xy[1:]], axis=1)
        e = errs[best]
        lc = LineCollection(segs, cmap="jet", linewidth=2.2)
        lc.set_array(0.5 * (e[:-1] + e[1:]))
        lc.set_clim(0.0, max(float(np.max(e, initial=0.0)), 1e-12))  # from zero, as a length
        ax0.add_collection(lc)
        ax0.plot(
            gt[:, 0, 3],
            gt[:, 1, 3],
            **{**_GT_TOP, "label": None, "color": "0.25", "linewidth": 0.9},
        )  # type: ignore[index]
        ax0.autoscale_view()
        ax0.set_aspect("equal", adjustable="datalim")
        ax0.grid(True, alpha=0.3)
        ax0.set_xlabel("x [m]")
        ax0.set_ylabel("y [m]")
        ax0.set_title(f"{best} (best): translation error along the path, top view", fontsize=10)
        cb = fig.colorbar(lc, ax=ax0, shrink=0.85, pad=0.01)
        cb.set_label("APE translation [m]")
        cb.formatter.set_useOffset(False)  # type: ignore[attr-defined]
        cb.update_ticks()
    else:
        ax0 = fig.add_subplot(gs[0, 0], projection="3d")
        for xyz, style in series:
            ax0.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], **style)
        _equal_3d(ax0, all_xyz)
        ax0.set_xlabel("x [m]", labelpad=2)
        ax0.set_ylabel("y [m]", labelpad=2)
        ax0.set_zlabel("z [m]", labelpad=2)
        ax0.set_title("3-D view")
    views = []
    for k, ((a, b), name) in enumerate((((0, 1), "top view (x–y)"), ((0, 2), "side view (x–z)"))):
        ax = fig.add_subplot(gs[0, k + 1])
        for xyz, style in series:
            ax.plot(xyz[:, a], xyz[:, b], **style)
            if len(xyz):
                ax.plot(xyz[0, a], xyz[0, b], "o", color=style["color"], markersize=4, zorder=11)
        ax.set_xlabel(f"{'xyz'[a]} [m]")
        ax.set_ylabel(f"{'xyz'[b]} [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
        ax.set_title(name)
        views.append((ax, (a, b)))
    extent = float(np.ptp(all_xyz, axis=0).max())
    final = [float(e[-1]) for e in errs.values() if len(e)]
    if gt is not None and final and extent > 0:
        half = 4.0 * float(np.median(final)) + 1e-3 * extent
        if half < INSET_MAX_FRACTION * extent:
            fig.canvas.draw()  # the views' limits after the layout, for the inset's corner
            for ax, dims in views:
                _add_zoom(ax, series, gt[-1, :3, 3], half, dims)
    handles = [
        Line2D(
            [],
            [],
            color=style["color"],
            linestyle=style.get("linestyle", "-"),
            label=style["label"],
        )
        for _, style in reversed(series)
    ]
    handles.append(
        Line2D([], [], marker="o", color="grey", linestyle="none", markersize=5, label="start")
    )
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=min(len(handles), 7),
        fontsize="small",
        frameon=False,
    )
    if title:
        fig.suptitle(title)
    return save_png(fig, path, dpi)


OFF_SCALE = 20.0
"""An estimate whose largest error exceeds this many times the smallest method's is drawn
off-scale (clipped, its peak in the legend) so that it does not flatten the others."""


ENVELOPE_CLIP = 4.0
"""The error plots' ‖Δ‖ and rotation axes stop at this many times the largest error when a
step envelope goes higher (its end value is then said in the legend)."""


def step_envelope(step_sigma: np.ndarray) -> np.ndarray:
    """3σ of the accumulated steps: ``3 √(Σ_{j≤k} σ_j²)`` per frame, from per-step 1σ values
    (N, 2) [translation m, rotation deg] (NaN or inf: unknown, the envelope NaN from there)."""
    s = np.asarray(step_sigma, dtype=np.float64)
    s = np.where(np.isfinite(s), s, np.nan)
    s[0] = 0.0  # the first frame is the start: no step
    return 3.0 * np.sqrt(np.cumsum(s * s, axis=0))


def plot_errors(
    path: str | Path,
    gt_poses: np.ndarray,
    estimates: Mapping[str, np.ndarray],
    *,
    times: np.ndarray | None = None,
    title: str | None = None,
    dpi: int = 120,
    log_scale: bool | None = None,
    step_sigmas: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """Write a PNG of per-frame errors: ``‖Δ‖``, signed ``Δx, Δy, Δz`` and the rotation error.

    ``Δ_k = t(T_k^GT) − t(T_k^est)`` (metres) and the geodesic rotation error (degrees), as in
    :func:`relnav.eval.metrics.pose_errors`. Linear axes scaled from the second frame on (the
    first is the start, zero by construction); a method more than :data:`OFF_SCALE` times worse
    than the best is clipped, its peak said in the legend.

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
        Logarithmic ‖Δ‖ and rotation axes (default off: linear, as evo's).
    step_sigmas : mapping str → (N, 2) float64, optional
        Per-frame step 1σ [translation m, rotation deg] of a method (e.g. the navigator's
        ``step_sigma_t_m``, ``step_sigma_r_deg``): its accumulated 3σ envelope
        (:func:`step_envelope`) is shaded under ``‖Δ‖`` and the rotation error; an envelope
        above :data:`ENVELOPE_CLIP` times the largest error is clipped there (its end value
        in the legend) so that the errors stay readable.

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
    k1 = 1 if len(gt) > 1 else 0  # scales from the second frame on
    peaks = {n: float(np.nanmax(e.trans[k1:], initial=0.0)) for n, e in errs.items()}
    rpeaks = {n: float(np.nanmax(e.rot_deg[k1:], initial=0.0)) for n, e in errs.items()}
    pos = [p for p in peaks.values() if p > 0]
    floor = min(pos) if pos else 0.0
    off = {n for n, p in peaks.items() if floor > 0 and p > OFF_SCALE * floor}
    fig = new_figure(9, 10.5)
    axes = fig.subplots(5, 1, sharex=True)
    labels = ["‖Δ‖ [m]", "Δx [m]", "Δy [m]", "Δz [m]", "rotation error [deg]"]
    colours = {n: f"C{i % 10}" for i, n in enumerate(est)}
    for name, pe in errs.items():
        curves = [pe.trans, pe.delta[:, 0], pe.delta[:, 1], pe.delta[:, 2], pe.rot_deg]
        label = _shown(name)
        if name in off:
            label = f"{name} (off scale: peak {peaks[name]:.3g} m, {rpeaks[name]:.3g}°)"
        for ax, y in zip(axes, curves, strict=True):
            ax.plot(x, y, linewidth=1.2, label=label, color=colours[name])
    envelopes = {}
    for name, sig in (step_sigmas or {}).items():
        sig = np.asarray(sig, dtype=np.float64)
        if name in errs and sig.shape == (len(gt), 2):
            envelopes[name] = step_envelope(sig)
    for ax, lab in zip(axes, labels, strict=True):
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    for ax in axes[1:4]:
        ax.axhline(0.0, color="black", linewidth=0.6)
    kept = [n for n in errs if n not in off] or list(errs)

    def span(values: list[np.ndarray]) -> float:
        v = np.concatenate([np.abs(a[k1:]) for a in values]) if values else np.zeros(1)
        v = v[np.isfinite(v)]
        return float(v.max(initial=0.0))

    def limit(err: float, env: float) -> tuple[float, bool]:
        """Axis top: the envelope's when it is comparable to the errors, else ENVELOPE_CLIP
        times the largest error (the errors stay readable; the envelope is said off scale)."""
        if err > 0 and env > ENVELOPE_CLIP * err:
            return ENVELOPE_CLIP * err, True
        return max(err, env), False

    env_kept = [n for n in envelopes if n in kept]
    t_lim, t_clip = limit(
        span([errs[n].trans for n in kept]), span([envelopes[n][:, 0] for n in env_kept])
    )
    r_lim, r_clip = limit(
        span([errs[n].rot_deg for n in kept]), span([envelopes[n][:, 1] for n in env_kept])
    )
    d_lim = span([errs[n].delta[:, i] for n in kept for i in range(3)])
    for name, env in envelopes.items():
        label = f"{_shown(name)}: 3σ of its accumulated steps"
        if (t_clip or r_clip) and not log_scale:
            last = env[np.isfinite(env).all(axis=1)]
            if len(last):
                label += f" (off scale: {last[-1, 0]:.3g} m, {last[-1, 1]:.3g}° at the end)"
        for ax, col in ((axes[0], 0), (axes[4], 1)):
            ax.fill_between(
                x,
                0.0,
                env[:, col],
                color=colours[name],
                alpha=0.15,
                lw=0,
                label=label if col == 0 else None,
            )
    if log_scale:
        for ax in (axes[0], axes[4]):
            ax.set_yscale("log", nonpositive="mask")
    else:
        axes[0].set_ylim(0.0, 1.08 * t_lim or 1.0)
        axes[4].set_ylim(0.0, 1.08 * r_lim or 1.0)
    for ax in axes[1:4]:
        ax.set_ylim(-1.08 * d_lim or -1.0, 1.08 * d_lim or 1.0)
    axes[-1].set_xlabel(xlabel)
    if len(x) > 1:
        axes[-1].set_xlim(x[0], x[-1])
    handles, hl = axes[0].get_legend_handles_labels()
    fig.legend(
        handles,
        hl,
        loc="outside lower center",
        ncol=min(len(handles), 3 if off or envelopes else 4),
        fontsize="small",
        frameon=False,
    )
    fig.suptitle(title or "Error with respect to the ground truth")
    return save_png(fig, path, dpi)
