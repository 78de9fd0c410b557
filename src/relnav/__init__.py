"""relnav — LIDAR-based relative navigation around uncooperative space targets.

Simulate a sensor flying around a target, estimate the chaser's motion and the target's
tumbling from point clouds, compare the methods of the literature on the same data, and
report the results.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from relnav.errors import ConfigError, EstimationError, InputError, RelnavError
from relnav.scan import Scan

try:
    __version__ = version("relnav")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "ConfigError",
    "EstimationError",
    "InputError",
    "RelnavError",
    "Scan",
    "__version__",
]
