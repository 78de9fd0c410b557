"""Flash LIDAR: :class:`FlashLidar` (GoldenEye, DragonEye presets)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from relnav.errors import ConfigError
from relnav.sim.sensors.base import (
    _check_fov,
    _check_ranges,
    _equiangular_dirs,
    _int,
    _num,
    _pinhole_dirs,
    _RaySensor,
)


class FlashLidar(_RaySensor):
    """Flash (focal-plane-array) LIDAR: one range per pixel, pixel grid centred on +x.

    Parameters
    ----------
    name : str
        Sensor name.
    rows, cols : int
        Pixel array (rows along z, columns along y).
    fov_h_deg, fov_v_deg : float
        Full horizontal / vertical field of view, degrees.
    min_range, max_range : float
        Detected slant ranges, metres.
    range_sigma : float
        1σ Gaussian range noise along the pixel ray, metres.
    dropout : float
        Probability that a valid return is lost.
    max_incidence_deg : float
        Grazing-incidence rejection threshold, degrees **[interpretation, 85°]**.
    projection : {"pinhole", "equiangular"}
        Pixel rays of a pinhole camera (equal pitch on the focal plane, default
        **[interpretation]**) or of equal angular pitch.

    Notes
    -----
    Points are ordered row-major from the top-left pixel (``ray_index = row·cols + col``).
    """

    kind: ClassVar[str] = "flash_lidar"

    def __init__(
        self,
        name: str,
        rows: int = 128,
        cols: int = 128,
        fov_h_deg: float = 45.0,
        fov_v_deg: float = 45.0,
        min_range: float = 0.0,
        max_range: float = 1500.0,
        range_sigma: float = 0.0,
        dropout: float = 0.0,
        max_incidence_deg: float = 85.0,
        projection: str = "pinhole",
    ) -> None:
        self.name = str(name)
        self.rows = _int("rows", rows)
        self.cols = _int("cols", cols)
        self.fov_h_deg = _check_fov("fov_h_deg", fov_h_deg)
        self.fov_v_deg = _check_fov("fov_v_deg", fov_v_deg)
        self.min_range, self.max_range_m = _check_ranges(min_range, max_range)
        self.range_sigma = _num("range_sigma", range_sigma, lo=0.0)
        self._set_gates(dropout, max_incidence_deg)
        if projection not in ("pinhole", "equiangular"):
            raise ConfigError(f"projection must be 'pinhole' or 'equiangular', got {projection!r}")
        self.projection = projection
        self._dirs = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "name": self.name,
            "rows": self.rows,
            "cols": self.cols,
            "fov_h_deg": self.fov_h_deg,
            "fov_v_deg": self.fov_v_deg,
            "min_range": self.min_range,
            "max_range": self.max_range_m,
            "range_sigma": self.range_sigma,
            "dropout": self.dropout,
            "max_incidence_deg": self.max_incidence_deg,
            "projection": self.projection,
        }

    def ray_directions(self) -> np.ndarray:
        if self._dirs is None:
            f = _pinhole_dirs if self.projection == "pinhole" else _equiangular_dirs
            self._dirs = f(self.cols, self.rows, self.fov_h_deg, self.fov_v_deg)
        return self._dirs
