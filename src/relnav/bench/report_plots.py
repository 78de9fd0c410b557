"""Deprecated alias: the report figures moved to :mod:`relnav.bench.report.plots`."""

from __future__ import annotations

import warnings
from typing import Any

from relnav.bench.report import plots as _plots

__all__ = list(_plots.__all__)

warnings.warn(
    "relnav.bench.report_plots is deprecated: import relnav.bench.report.plots",
    DeprecationWarning,
    stacklevel=2,
)


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(_plots, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
