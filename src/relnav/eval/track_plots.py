"""Figures of a tracked relative state (a :class:`relnav.filtering.track_result.TrackResult`).

:func:`plot_track`: estimate vs truth (position, Euler angles, velocity, angular velocity; paper 2
Figs. 8/13); :func:`plot_track_errors`: estimate − truth with ±3σ bounds (Fig. 14). Used by
``relnav track`` (paper 2's filter on an observer) and by the run folder of the navigator
(:mod:`relnav.pipeline.outputs`: ``state.png``, ``state_errors.png``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_track", "plot_track_errors", "state_title"]

_PANELS = (
    ("position", "translational position (m)", 1.0, ("x", "y", "z")),
    ("euler", "Euler angles (deg)", 180.0 / np.pi, ("roll", "pitch", "yaw")),
    ("velocity", "velocity (m/s)", 1.0, ("x", "y", "z")),
    ("omega", "angular velocity (deg/s)", 180.0 / np.pi, ("x", "y", "z")),
)


def _series(result: Any, key: str, truth: bool = False) -> np.ndarray:
    src = result.truth if truth else result
    return np.asarray(getattr(src, key))


def state_title(result: Any) -> str:
    """The state figures' title: the navigator's relative state from ``relnav odometry``
    (``meta["method"]``) or ``relnav track``'s filter on an observer."""
    method = (getattr(result, "meta", None) or {}).get("method")
    if method:
        return f"relnav odometry — {method}: relative state ({result.filter.upper()} on its poses)"
    return f"relnav track — {result.filter.upper()}"


def _figure_legend(fig: Any, entries: list[tuple[str, str, str]]) -> None:
    """One legend under the panels (``(label, colour, linestyle)``): per-panel legends sat on
    the curves (the state's panels are full of data in every corner)."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=c, ls=ls, label=lab) for lab, c, ls in entries]
    fig.legend(
        handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False
    )


def plot_track(result: Any, path: Path, *, dpi: int = 120) -> Path:
    """Estimate vs truth, 2×2 panels (a) position (b) Euler angles (c) velocity (d) ω."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True)
    colors = ("tab:blue", "tab:orange", "tab:green")
    for ax, (key, label, scale, names), tag in zip(axes.flat, _PANELS, "abcd", strict=True):
        est = _series(result, key) * scale
        for i in range(3):
            ax.plot(result.time, est[:, i], color=colors[i], label=f"{names[i]} estimate")
            if result.truth is not None:
                tr = _series(result, key, truth=True) * scale
                ax.plot(
                    result.time, tr[:, i], color=colors[i], ls="--", lw=1, label=f"{names[i]} truth"
                )
        ax.set_title(f"({tag}) {label}")
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    entries = [
        ("x / roll", colors[0], "-"),
        ("y / pitch", colors[1], "-"),
        ("z / yaw", colors[2], "-"),
        ("estimate", "0.2", "-"),
    ]
    if result.truth is not None:
        entries.append(("truth", "0.2", "--"))
    _figure_legend(fig, entries)
    fig.suptitle(state_title(result))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def plot_track_errors(result: Any, path: Path, *, dpi: int = 120) -> Path:
    """Estimate − truth with ±3σ bounds, 2×2 panels (position, attitude, velocity, ω)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    err = result.errors()
    sig = result.sigma()
    panels = (
        ("position", "position error (m)", 1.0, "position"),
        ("attitude", "attitude error about body axes (deg)", 180.0 / np.pi, "attitude"),
        ("velocity", "velocity error (m/s)", 1.0, "velocity"),
        ("omega", "angular velocity error (deg/s)", 180.0 / np.pi, "omega"),
    )
    fig = Figure(figsize=(11, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True)
    colors = ("tab:blue", "tab:orange", "tab:green")
    for ax, (key, label, scale, skey), tag in zip(axes.flat, panels, "abcd", strict=True):
        e = err[key] * scale
        s = sig[skey] * scale
        for i, ax_name in enumerate("xyz"):
            ax.plot(result.time, e[:, i], color=colors[i], label=ax_name)
            ax.plot(result.time, 3 * s[:, i], color=colors[i], ls=":", lw=0.8)
            ax.plot(result.time, -3 * s[:, i], color=colors[i], ls=":", lw=0.8)
        ax.set_title(f"({tag}) {label}, dotted ±3σ")
        ax.grid(alpha=0.3)
        # scaled to show the errors and the ±3σ bounds after the start-up (the first tenth
        # of the run, at least the first sample: the initial state and its huge σ may leave
        # the axes; the 95th percentile keeps the bounds' level visible)
        k0 = max(1, round(0.1 * len(e))) if len(e) > 2 else 0
        finite = np.abs(e[k0:][np.isfinite(e[k0:])])
        bounds = 3.0 * np.abs(s[k0:][np.isfinite(s[k0:])])
        lim = max(
            1.5 * float(np.percentile(finite, 99)) if finite.size else 0.0,
            1.15 * float(np.percentile(bounds, 95)) if bounds.size else 0.0,
        )
        if lim > 0:
            ax.set_ylim(-lim, lim)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    _figure_legend(
        fig,
        [
            ("x", colors[0], "-"),
            ("y", colors[1], "-"),
            ("z", colors[2], "-"),
            ("±3σ (each axis's colour)", "0.2", ":"),
        ],
    )
    fig.suptitle(f"{state_title(result)}: errors")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path
