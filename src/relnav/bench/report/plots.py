"""Benchmark report figures (matplotlib Agg, no ``pyplot``): Paper 1 Figs. 7–18 style.

Every function writes one PNG sized for a page width (≈ 1000–1300 px at the default dpi),
with axis labels and units, a legend, and returns the path. They take plain arrays and
dictionaries (the report prepares them), so they can be reused on any result set.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.eval.plots import new_figure, save_png

__all__ = [
    "plot_axis_errors",
    "plot_filter_scores",
    "plot_normalised_ert_vs_time",
    "plot_nuisance_curves",
    "plot_time_vs_points",
    "plot_trajectory_panels",
]

_MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h"]
# 20 distinguishable colours: the dark then the light half of matplotlib's tab20
_TAB20 = [
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
    "#aec7e8",
    "#ffbb78",
    "#98df8a",
    "#ff9896",
    "#c5b0d5",
    "#c49c94",
    "#f7b6d2",
    "#c7c7c7",
    "#dbdb8d",
    "#9edae5",
]


_DASHES = ["-", "--", "-.", ":"]


def _style(i: int, *, vary: bool = True) -> dict[str, object]:
    """Colour, line style and width of series ``i``.

    Styles cycle through solid, dashed, dash-dot and dotted, and widths shrink with ``i``, so
    a series drawn over an identical earlier one (e.g. H∞ and Kalman giving the same track)
    leaves the earlier one visible around it. With ``vary=False``: only the colour and a
    solid/dashed style (distinct for the first 40), for plots with markers and own widths.
    """
    if not vary:
        return {
            "color": _TAB20[i % len(_TAB20)],
            "linestyle": "-" if (i // len(_TAB20)) % 2 == 0 else "--",
        }
    return {
        "color": _TAB20[i % len(_TAB20)],
        "linestyle": _DASHES[i % len(_DASHES)],
        "linewidth": max(2.8 - 0.45 * (i % 5), 1.0),
    }


def _same_as(series: Mapping[str, np.ndarray]) -> dict[str, str]:
    """``{label: earlier label}`` for series numerically identical to an earlier one."""
    out: dict[str, str] = {}
    items = [(k, np.asarray(v, dtype=np.float64)) for k, v in series.items()]
    for j, (name, a) in enumerate(items):
        for prev, b in items[:j]:
            if prev not in out and a.shape == b.shape and np.allclose(a, b, atol=1e-9, rtol=0):
                out[name] = prev
                break
    return out


_GT = {"color": "black", "linestyle": "--", "linewidth": 1.6, "label": "ground truth"}


def _limits(xy: np.ndarray, margin: float = 0.35) -> tuple[tuple[float, float], ...]:
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    span = max(float((hi - lo).max()), 1e-6)
    c = 0.5 * (lo + hi)
    r = 0.5 * span * (1 + 2 * margin)
    return tuple((float(c[i] - r), float(c[i] + r)) for i in range(xy.shape[1]))


def plot_trajectory_panels(
    path: str | Path,
    gt_xyz: np.ndarray,
    groups: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    *,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Top (x–y) and side (x–z) views of estimates against the ground truth, one row per group.

    Axis limits follow the ground truth (+35 % margin on each side) so that one diverged
    estimate cannot squash the others; estimates leaving the frame are clipped (noted in the
    panel title when it happens).

    Parameters
    ----------
    path : str or Path
        Output ``.png``.
    gt_xyz : (N, 3) float64
        Ground-truth sensor positions, m (target frame).
    groups : sequence of (title, {label: (M, 3) positions})
        One row of two panels per group (e.g. "best per filter", "competitors").
    title : str, optional
        Figure title.
    dpi : int
        Resolution.
    """
    gt = np.asarray(gt_xyz, dtype=np.float64)
    if gt.ndim != 2 or gt.shape[1] != 3 or len(gt) == 0:
        raise InputError(f"plot_trajectory_panels: gt_xyz must be (N, 3), got {gt.shape}")
    if not groups:
        raise InputError("plot_trajectory_panels: no groups to plot")
    n = len(groups)
    fig = new_figure(12.0, 4.6 * n)
    axes = np.atleast_2d(fig.subplots(n, 2))
    views = []
    for a, b in ((0, 1), (0, 2)):  # each view fitted to the ground truth in its own two axes
        la, lb = _limits(gt[:, [a, b]])
        views.append((a, b, la, lb))
    for row, (gtitle, est) in enumerate(groups):
        clipped = []
        for col, (a, b, la, lb) in enumerate(views):
            ax = axes[row, col]
            ax.plot(gt[:, a], gt[:, b], **_GT, zorder=10)  # on top of every estimate
            ax.plot(gt[0, a], gt[0, b], "ko", markersize=5, zorder=11)
            same = _same_as(est)
            for i, (name, xyz) in enumerate(est.items()):
                p = np.asarray(xyz, dtype=np.float64)
                st = _style(i)
                label = f"{name} (= {same[name]})" if name in same else name
                ax.plot(p[:, a], p[:, b], label=label, **st)
                ax.plot(
                    p[-1, a],
                    p[-1, b],
                    _MARKERS[i % len(_MARKERS)],
                    markersize=5,
                    color=ax.lines[-1].get_color(),
                )
                if col == 0 and (
                    (p[:, a] < la[0]).any()
                    | (p[:, a] > la[1]).any()
                    | (p[:, b] < lb[0]).any()
                    | (p[:, b] > lb[1]).any()
                ):
                    clipped.append(name)
            ax.set_xlim(*la)
            ax.set_ylim(*lb)
            ax.set_aspect("equal", adjustable="box")
            ax.set_xlabel(f"{'xyz'[a]} [m]")
            ax.set_ylabel(f"{'xyz'[b]} [m]")
            ax.grid(True, alpha=0.3)
            view = "top view (x–y)" if col == 0 else "side view (x–z)"
            ax.set_title(f"{gtitle}: {view}", fontsize="medium")
        axes[row, 1].legend(fontsize="small", loc="center left", bbox_to_anchor=(1.02, 0.5))
        if clipped:
            axes[row, 0].text(
                0.01,
                0.01,
                "leave the frame: " + ", ".join(clipped),
                transform=axes[row, 0].transAxes,
                fontsize="x-small",
                va="bottom",
            )
    if title:
        fig.suptitle(title)
    return save_png(fig, path, dpi, what="figures")


def plot_axis_errors(
    path: str | Path,
    frames: np.ndarray,
    errors: Mapping[str, tuple[np.ndarray, np.ndarray]],
    *,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Per-axis position error and rotation error versus frame (Paper 1 Figs. A4–A5 style).

    Parameters
    ----------
    path : str or Path
        Output ``.png``.
    frames : (N,) array
        Frame indices (x axis).
    errors : mapping label → (delta (N, 3) m, rot (N,) deg)
        ``delta = t(T_GT) − t(T_est)`` per frame and the geodesic rotation error.
    title : str, optional
        Figure title.
    dpi : int
        Resolution.
    """
    if not errors:
        raise InputError("plot_axis_errors: nothing to plot")
    x = np.asarray(frames)
    fig = new_figure(10.0, 8.5)
    axes = fig.subplots(4, 1, sharex=True)
    labels = ["Δx [m]", "Δy [m]", "Δz [m]", "rotation error [deg]"]
    same = _same_as({k: np.column_stack([v[0], v[1]]) for k, v in errors.items()})
    for j, (name, (delta, rot)) in enumerate(errors.items()):
        d = np.asarray(delta)
        if d.shape != (len(x), 3) or np.shape(rot) != (len(x),):
            raise InputError(f"plot_axis_errors: {name!r} does not match {len(x)} frames")
        st = _style(j)
        label = f"{name} (= {same[name]})" if name in same else name
        for i in range(3):
            axes[i].plot(x, d[:, i], label=label, **st)
        axes[3].plot(x, rot, label=label, **st)
    for ax, lab in zip(axes, labels, strict=True):
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    for ax in axes[:3]:
        ax.axhline(0.0, color="black", linewidth=0.6)
    axes[-1].set_xlabel("frame")
    axes[-1].xaxis.get_major_locator().set_params(integer=True)
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=min(3, len(errors)),
        fontsize="small",
    )
    fig.suptitle(title or "Error with respect to the ground truth (GT − estimate)")
    return save_png(fig, path, dpi, what="figures")


def plot_normalised_ert_vs_time(
    path: str | Path,
    points: Sequence[tuple[str, str, float, float]],
    *,
    constant: float = 1000.0,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Normalised ``e^RT`` versus time per frame per descriptor and scenario (Paper 1 Fig. 14).

    Parameters
    ----------
    path : str or Path
        Output ``.png``.
    points : sequence of (scenario, descriptor, time_ms, normalised e^RT)
        Marker shape = descriptor, colour = scenario. Non-finite or non-positive values are
        skipped (log axes).
    constant : float
        The constant the normalised values were multiplied by (shown in the axis label).
    """
    pts = [p for p in points if all(math.isfinite(v) and v > 0 for v in p[2:])]
    if not pts:
        raise InputError("plot_normalised_ert_vs_time: no finite positive points")
    scen = list(dict.fromkeys(p[0] for p in pts))
    desc = list(dict.fromkeys(p[1] for p in pts))
    fig = new_figure(9.5, 6.0)
    ax = fig.subplots()
    colors = [_TAB20[i % len(_TAB20)] for i in range(len(scen))]
    for s, d, t, v in pts:
        ax.scatter(
            t,
            v,
            marker=_MARKERS[desc.index(d) % len(_MARKERS)],
            color=colors[scen.index(s)],
            s=46,
            edgecolors="black",
            linewidths=0.4,
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("mean time per frame [ms]")
    ax.set_ylabel(f"normalised e^RT × {constant:g} [1/m]")
    ax.grid(True, which="both", alpha=0.25)
    from matplotlib.lines import Line2D

    h1 = [
        Line2D([], [], color=colors[i], marker="o", linestyle="", label=s)
        for i, s in enumerate(scen)
    ]
    h2 = [
        Line2D([], [], color="gray", marker=_MARKERS[i % len(_MARKERS)], linestyle="", label=d)
        for i, d in enumerate(desc)
    ]
    fig.legend(handles=h1, title="scenario", fontsize="small", loc="outside right upper")
    fig.legend(handles=h2, title="descriptor", fontsize="small", loc="outside right lower")
    ax.set_title(title or "Normalised e^RT (mean over filters) vs processing time")
    return save_png(fig, path, dpi, what="figures")


def plot_time_vs_points(
    path: str | Path,
    series: Mapping[str, Sequence[tuple[float, float, str]]],
    *,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Mean time per frame versus mean points per scan, one line per method group (Fig. 15).

    Parameters
    ----------
    series : mapping label → [(points per scan, time ms, scenario), …]
        Points are sorted by cardinality; the scenario names annotate the first series.
    """
    if not series:
        raise InputError("plot_time_vs_points: nothing to plot")
    fig = new_figure(9.5, 6.0)
    ax = fig.subplots()
    scen_x: dict[str, float] = {}
    for i, (name, pts) in enumerate(series.items()):
        good = sorted(p for p in pts if math.isfinite(p[0]) and math.isfinite(p[1]) and p[1] > 0)
        if not good:
            continue
        xs, ys = [p[0] for p in good], [p[1] for p in good]
        st = _style(i, vary=False)
        if name == name.lower():  # method strings (competitors) dashed, descriptors solid
            st["linestyle"] = "--"
        ax.plot(xs, ys, marker=_MARKERS[i % len(_MARKERS)], linewidth=1.2, label=name, **st)
        for x, _, sc in good:
            scen_x.setdefault(sc, x)
    ax.set_xscale("log")
    ax.set_yscale("log")
    scen = sorted(scen_x.items(), key=lambda kv: kv[1])
    for _, x in scen:
        ax.axvline(x, color="gray", linestyle=":", linewidth=0.8, zorder=0)
    # the scenarios named on a top axis, clear of the lines (not written over them)
    top = ax.secondary_xaxis("top")
    top.set_xticks([x for _, x in scen], labels=[sc for sc, _ in scen], minor=False)
    top.set_xticks([], minor=True)
    top.tick_params(labelsize="x-small", labelrotation=30, colors="dimgray")
    for lab in top.get_xticklabels():
        lab.set_ha("left")
    ax.set_xlabel("mean points per scan")
    ax.set_ylabel("mean time per frame [ms]")
    ax.grid(True, which="both", alpha=0.25)
    fig.legend(*ax.get_legend_handles_labels(), fontsize="small", loc="outside right center")
    ax.set_title(title or "Processing time vs scan cardinality")
    return save_png(fig, path, dpi, what="figures")


def plot_filter_scores(
    path: str | Path,
    scores: Mapping[str, Mapping[str, float]],
    *,
    ylabel: str = "normalised e^RT × 1000 [1/m]",
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Grouped bars: one group per scenario, one bar per filter (Paper 1 Fig. 16), log y axis.

    Parameters
    ----------
    scores : mapping scenario → {filter label: value}
        Non-finite or non-positive values are left out.
    """
    scen = list(scores)
    names = list(dict.fromkeys(k for v in scores.values() for k in v))
    if not scen or not names:
        raise InputError("plot_filter_scores: nothing to plot")
    fig = new_figure(max(7.0, 1.3 * len(scen) + 3.0), 5.2)
    ax = fig.subplots()
    w = 0.8 / len(names)
    x = np.arange(len(scen))
    for i, n in enumerate(names):
        vals = np.array([scores[s].get(n, np.nan) for s in scen], dtype=float)
        vals[~(np.isfinite(vals) & (vals > 0))] = np.nan
        ax.bar(
            x - 0.4 + (i + 0.5) * w,
            vals,
            width=w,
            label=n,
            edgecolor="black",
            linewidth=0.4,
            color=_TAB20[i % len(_TAB20)],
        )
    ax.set_xticks(x, scen, rotation=20, ha="right")
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_xlabel("scenario")
    ax.grid(True, axis="y", which="both", alpha=0.25)
    fig.legend(
        *ax.get_legend_handles_labels(),
        fontsize="small",
        title="filter",
        loc="outside right center",
    )
    ax.set_title(title or "Normalised e^RT per filter (mean over descriptors)")
    return save_png(fig, path, dpi, what="figures")


def plot_nuisance_curves(
    path: str | Path,
    curves: Mapping[str, Mapping[str, Sequence[tuple[float, float, float]]]],
    *,
    xlabel: str,
    ylabel: str = "e^RT [m² + deg²]",
    logy: bool = True,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Error versus nuisance level: one panel per scenario, one line per method (mean ± std).

    Parameters
    ----------
    curves : mapping scenario → {method: [(level, mean, std), …]}
    xlabel : str
        Nuisance parameter with its unit.
    """
    scen = [s for s in curves if curves[s]]
    if not scen:
        raise InputError("plot_nuisance_curves: nothing to plot")
    n = len(scen)
    fig = new_figure(5.6 * n + 2.2, 4.6)
    axes = np.atleast_1d(fig.subplots(1, n, squeeze=False)[0])
    for ax, s in zip(axes, scen, strict=True):
        for i, (m, pts) in enumerate(curves[s].items()):
            good = sorted(p for p in pts if math.isfinite(p[1]))
            if not good:
                continue
            xs = np.array([p[0] for p in good])
            ys = np.array([p[1] for p in good])
            es = np.array([p[2] if math.isfinite(p[2]) else 0.0 for p in good])
            ax.errorbar(
                xs,
                ys,
                yerr=es,
                marker=_MARKERS[i % len(_MARKERS)],
                linewidth=1.2,
                capsize=3,
                label=m,
                **_style(i, vary=False),
            )
        if logy:
            ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(s)
        ax.grid(True, which="both", alpha=0.25)
    fig.legend(*axes[-1].get_legend_handles_labels(), fontsize="small", loc="outside right center")
    if title:
        fig.suptitle(title)
    return save_png(fig, path, dpi, what="figures")
