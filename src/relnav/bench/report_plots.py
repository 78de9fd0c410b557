"""Deprecated alias: the report figures moved to :mod:`relnav.bench.report.plots`."""

from __future__ import annotations

import warnings

from relnav.bench.report.plots import (
    plot_axis_errors,
    plot_filter_scores,
    plot_normalised_ert_vs_time,
    plot_nuisance_curves,
    plot_time_vs_points,
    plot_trajectory_panels,
)

__all__ = [
    "plot_axis_errors",
    "plot_filter_scores",
    "plot_normalised_ert_vs_time",
    "plot_nuisance_curves",
    "plot_time_vs_points",
    "plot_trajectory_panels",
]

warnings.warn(
    "relnav.bench.report_plots is deprecated: import relnav.bench.report.plots",
    DeprecationWarning,
    stacklevel=2,
)
