"""Structured-light depth camera: :class:`DepthCamera` (Kinect v1)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from relnav.errors import ConfigError
from relnav.sim.noise import (
    kinect_depth,
)
from relnav.sim.sensors.base import (
    _check_fov,
    _check_ranges,
    _int,
    _num,
    _pinhole_dirs,
    _RaySensor,
)
from relnav.sim.targets import Target


class DepthCamera(_RaySensor):
    """Kinect-v1-like structured-light depth camera (pinhole, depth along +x).

    Parameters
    ----------
    name : str
        Sensor name.
    width, height : int
        Native depth image size, pixels.
    fov_h_deg, fov_v_deg : float
        Full fields of view, degrees.
    min_range, max_range : float
        Detected DEPTH interval ``Z`` (along the boresight +x, not slant range), metres.
    decimation : int
        Keep a ``(width // decimation) × (height // decimation)`` pixel grid over the same
        FOV (Paper 2 used the native 320 × 240 depth of 640 × 480: ``decimation=2``).
    sigma_coeff : float
        Axial noise ``σ_Z = sigma_coeff · Z²`` (m⁻¹) **[interpretation: 1.43e-3]**.
    quantize : bool
        Quantise depth through the OpenKinect raw-disparity map (step ≈ 0.00307·Z²).
    dropout : float
        Probability that a valid pixel is lost.
    max_incidence_deg : float
        Grazing-incidence rejection, degrees **[interpretation, 85°]**.
    shadows : bool
        Also drop pixels the IR projector cannot illuminate (second ray test from the
        projector, offset by ``baseline`` along −y; BlenSor-style shadows). Off by default.
    baseline : float
        Projector–camera baseline, metres (≈ 7.5 cm, from memory).

    Notes
    -----
    Each point lies on its pixel ray at measured depth ``Z``: ``p = Z · d / d_x``. Noise is
    added before quantisation (measured disparity is noisy, then rounded).
    """

    kind: ClassVar[str] = "depth_camera"
    _depth_gate: ClassVar[bool] = True

    def __init__(
        self,
        name: str,
        width: int = 640,
        height: int = 480,
        fov_h_deg: float = 57.0,
        fov_v_deg: float = 43.0,
        min_range: float = 0.8,
        max_range: float = 6.0,
        decimation: int = 1,
        sigma_coeff: float = 1.43e-3,
        quantize: bool = True,
        dropout: float = 0.0,
        max_incidence_deg: float = 85.0,
        shadows: bool = False,
        baseline: float = 0.075,
    ) -> None:
        self.name = str(name)
        self.width = _int("width", width)
        self.height = _int("height", height)
        self.fov_h_deg = _check_fov("fov_h_deg", fov_h_deg)
        self.fov_v_deg = _check_fov("fov_v_deg", fov_v_deg)
        self.min_range, self.max_range_m = _check_ranges(min_range, max_range)
        self.decimation = _int("decimation", decimation)
        if self.decimation > min(self.width, self.height):
            raise ConfigError(f"decimation {self.decimation} leaves no pixels")
        self.sigma_coeff = _num("sigma_coeff", sigma_coeff, lo=0.0)
        self.quantize = bool(quantize)
        self._set_gates(dropout, max_incidence_deg)
        self.shadows = bool(shadows)
        self.baseline = _num("baseline", baseline, lo=0.0)
        self._dirs = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "fov_h_deg": self.fov_h_deg,
            "fov_v_deg": self.fov_v_deg,
            "min_range": self.min_range,
            "max_range": self.max_range_m,
            "decimation": self.decimation,
            "sigma_coeff": self.sigma_coeff,
            "quantize": self.quantize,
            "dropout": self.dropout,
            "max_incidence_deg": self.max_incidence_deg,
            "shadows": self.shadows,
            "baseline": self.baseline,
        }

    @property
    def max_range(self) -> float:
        """Largest slant range of a valid return (max depth at the FOV corner), metres."""
        th = math.tan(math.radians(self.fov_h_deg) / 2)
        tv = math.tan(math.radians(self.fov_v_deg) / 2)
        return float(self.max_range_m * math.sqrt(1.0 + th * th + tv * tv))

    @property
    def image_shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the (decimated) depth image."""
        return self.height // self.decimation, self.width // self.decimation

    def ray_directions(self) -> np.ndarray:
        if self._dirs is None:
            rows, cols = self.image_shape
            self._dirs = _pinhole_dirs(cols, rows, self.fov_h_deg, self.fov_v_deg)
        return self._dirs

    def _extra_gate(
        self, target: Target, T: np.ndarray, pts_t: np.ndarray, keep: np.ndarray
    ) -> np.ndarray:
        if not self.shadows or pts_t.shape[0] == 0:
            return keep
        proj_t = T[:3, :3] @ np.array([0.0, -self.baseline, 0.0]) + T[:3, 3]
        v = pts_t - proj_t
        dist = np.linalg.norm(v, axis=1)
        ok = dist > 0
        d = np.divide(v, dist[:, None], out=np.zeros_like(v), where=ok[:, None])
        d[~ok] = [1.0, 0.0, 0.0]
        r, _ = target.raycaster.cast(np.broadcast_to(proj_t, d.shape), d)
        lit = r >= dist * (1.0 - 1e-7) - 1e-9
        return keep & (lit | ~ok)

    def _measure(
        self, ranges: np.ndarray, dirs_s: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        z = ranges * dirs_s[:, 0]
        zm = kinect_depth(z, rng, sigma_coeff=self.sigma_coeff, quantize=self.quantize)
        ok = np.isfinite(zm)
        pts = dirs_s * (np.where(ok, zm, 0.0) / dirs_s[:, 0])[:, None]
        return pts, ok
