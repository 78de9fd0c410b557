"""Rotating (scanning) multi-beam LIDAR: :class:`ScanningLidar` (VLP-16, HDL-64, RS-32 presets)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from relnav.errors import ConfigError
from relnav.sim.sensors.base import (
    _check_ranges,
    _jsonable,
    _num,
    _RaySensor,
)


class ScanningLidar(_RaySensor):
    """Spinning multi-beam LIDAR (Velodyne/RoboSense-like).

    Parameters
    ----------
    name : str
        Sensor name.
    elevations_deg : sequence of float
        Beam elevations from the sensor x–y plane, degrees (positive up).
    azimuth_step_deg : float
        Horizontal resolution, degrees. Azimuth is about +z from +x (positive towards +y).
    azimuth_fov_deg : (float, float) or "auto"
        Azimuth interval (degrees, min < max, width ≤ 360). The grid is ``min + k·step``.
        ``"auto"`` = crop the 360° scan to the target's angular extent as paper 1 did in
        post-processing; because rays that cannot reach the target's bounding sphere are
        never cast, this gives exactly the points of the full ``(-180, 180)`` scan.
    min_range, max_range : float
        Detected slant ranges, metres.
    range_sigma : float
        1σ Gaussian range noise along the ray, metres.
    dropout : float
        Probability that a valid return is lost (Bernoulli, independent).
    max_incidence_deg : float
        Returns whose incidence angle (line of sight vs. face normal) exceeds this are
        rejected (grazing) **[interpretation, 85°]**.

    Notes
    -----
    The scan is instantaneous (no motion distortion within a revolution). Points are ordered
    azimuth-major (all beams of one firing, then the next azimuth), as a spinning sensor
    produces them.
    """

    kind: ClassVar[str] = "scanning_lidar"

    def __init__(
        self,
        name: str,
        elevations_deg: Any,
        azimuth_step_deg: float,
        azimuth_fov_deg: Any = (-180.0, 180.0),
        min_range: float = 0.0,
        max_range: float = 100.0,
        range_sigma: float = 0.0,
        dropout: float = 0.0,
        max_incidence_deg: float = 85.0,
    ) -> None:
        self.name = str(name)
        try:
            el = [float(e) for e in np.asarray(elevations_deg, dtype=float).reshape(-1)]
        except (TypeError, ValueError):
            raise ConfigError(f"elevations_deg must be numbers, got {elevations_deg!r}") from None
        if not el:
            raise ConfigError("elevations_deg must contain at least one beam")
        if any(not (-90.0 <= e <= 90.0) for e in el):
            raise ConfigError(f"elevations_deg must be in [-90, 90], got {el}")
        self.elevations_deg = tuple(el)
        self.azimuth_step_deg = _num("azimuth_step_deg", azimuth_step_deg, lo=0.0, lo_open=True)
        if self.azimuth_step_deg > 360.0:
            raise ConfigError(f"azimuth_step_deg must be <= 360, got {self.azimuth_step_deg}")
        if isinstance(azimuth_fov_deg, str):
            if azimuth_fov_deg != "auto":
                raise ConfigError(
                    f"azimuth_fov_deg must be (min, max) degrees or 'auto', got {azimuth_fov_deg!r}"
                )
            self.azimuth_fov_deg = "auto"
        else:
            try:
                lo, hi = (float(a) for a in azimuth_fov_deg)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"azimuth_fov_deg must be (min, max) degrees or 'auto', got {azimuth_fov_deg!r}"
                ) from None
            if not (lo < hi and hi - lo <= 360.0 + 1e-9):
                raise ConfigError(f"azimuth_fov_deg needs min < max, max - min <= 360: {lo, hi}")
            self.azimuth_fov_deg = (lo, hi)
        self.min_range, self.max_range_m = _check_ranges(min_range, max_range)
        self.range_sigma = _num("range_sigma", range_sigma, lo=0.0)
        self._set_gates(dropout, max_incidence_deg)
        self._dirs = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "name": self.name,
            "elevations_deg": _jsonable(self.elevations_deg),
            "azimuth_step_deg": self.azimuth_step_deg,
            "azimuth_fov_deg": _jsonable(self.azimuth_fov_deg),
            "min_range": self.min_range,
            "max_range": self.max_range_m,
            "range_sigma": self.range_sigma,
            "dropout": self.dropout,
            "max_incidence_deg": self.max_incidence_deg,
        }

    def azimuths_deg(self) -> np.ndarray:
        """Azimuth grid, degrees."""
        lo, hi = (-180.0, 180.0) if self.azimuth_fov_deg == "auto" else self.azimuth_fov_deg
        width = hi - lo
        n = width / self.azimuth_step_deg
        if width >= 360.0 - 1e-9:  # full circle: do not repeat the first azimuth
            n_az = math.ceil(n - 1e-9)
        else:
            n_az = math.floor(n + 1e-9) + 1
        return lo + self.azimuth_step_deg * np.arange(max(n_az, 1))

    def ray_directions(self) -> np.ndarray:
        if self._dirs is None:
            az = np.radians(self.azimuths_deg())
            el = np.radians(np.asarray(self.elevations_deg))
            A, E = np.meshgrid(az, el, indexing="ij")  # azimuth-major
            A, E = A.ravel(), E.ravel()
            self._dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], 1)
        return self._dirs
