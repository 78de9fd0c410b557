"""Simulated range sensors: scanning and flash LIDAR, Kinect-v1 depth camera, HPR sampler.

Every sensor maps ``(target, T_target_sensor, rng)`` to an ``(N, 3)`` float64 cloud in the
**sensor frame** (x forward = boresight, y left, z up; REP-103, also for the depth camera).
``T_target_sensor`` maps sensor coordinates to target coordinates (the sensor's pose in the
target frame).

Ray sensors (:class:`ScanningLidar`, :class:`FlashLidar`, :class:`DepthCamera`) cast one ray
per beam/pixel against the target mesh (first hit, float64-exact range; see
:mod:`relnav.sim.raycast`), gate the true range, reject grazing incidence, drop returns at
random and add noise. Rays that cannot reach the target's bounding sphere are never cast,
which only saves time: the output is identical to casting them.

:class:`SurfaceSampler` reproduces paper 1's simulated clouds: one complete model point cloud
rendered once per target from a tessellated sphere of views (``model_cloud="fixed"``, paper 1's
data generation) or fresh uniform surface samples every frame (``"resample"``), then
hidden-point removal (Katz et al. 2007) from the sensor position, then optional noise.

Random numbers are drawn in a fixed order from the ``rng`` passed to :meth:`Sensor.scan`
(and only for returns that survive the deterministic gates), so a given generator state
gives byte-identical clouds.
"""

from __future__ import annotations

import abc
import logging
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.sim.hpr import hidden_point_removal
from relnav.sim.model_cloud import ModelCloud, mesh_fingerprint, model_cloud_for
from relnav.sim.noise import (
    add_range_noise,
    as_generator,
    dropout_mask,
    kinect_depth,
    range_noise_points,
)
from relnav.sim.targets import Target

__all__ = [
    "DepthCamera",
    "FlashLidar",
    "ScanningLidar",
    "Sensor",
    "SensorReturn",
    "SurfaceSampler",
    "available_sensors",
    "make_sensor",
    "sensor_from_dict",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- helpers


def _check_pose(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise InputError(f"T_target_sensor must be 4x4, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise InputError("T_target_sensor has non-finite entries")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise InputError("T_target_sensor: rotation block is not a proper rotation matrix")
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-12:
        raise InputError("T_target_sensor: last row must be [0, 0, 0, 1]")
    return T


def _num(name: str, v: Any, *, lo: float | None = None, lo_open: bool = False) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {v!r}") from None
    if math.isnan(x):
        raise ConfigError(f"{name} must not be NaN")
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise ConfigError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {x}")
    return x


def _int(name: str, v: Any, *, lo: int = 1) -> int:
    if isinstance(v, bool) or not float(v).is_integer():
        raise ConfigError(f"{name} must be an integer, got {v!r}")
    x = int(v)
    if x < lo:
        raise ConfigError(f"{name} must be >= {lo}, got {x}")
    return x


def _check_ranges(min_range: float, max_range: float) -> tuple[float, float]:
    lo = _num("min_range", min_range, lo=0.0)
    hi = _num("max_range", max_range, lo=0.0, lo_open=True)
    if lo >= hi:
        raise ConfigError(f"min_range ({lo}) must be smaller than max_range ({hi})")
    return lo, hi


def _check_prob(name: str, p: Any) -> float:
    x = _num(name, p, lo=0.0)
    if x >= 1.0:
        raise ConfigError(f"{name} must be in [0, 1), got {x}")
    return x


def _check_fov(name: str, v: Any) -> float:
    x = _num(name, v, lo=0.0, lo_open=True)
    if x >= 180.0:
        raise ConfigError(f"{name} must be in (0, 180) degrees, got {x}")
    return x


def _pinhole_dirs(cols: int, rows: int, fov_h_deg: float, fov_v_deg: float) -> np.ndarray:
    """Unit directions (rows·cols, 3) of a pinhole pixel grid centred on +x, row-major.

    Row 0 is the top (+z), column 0 the left (+y); pixel centres at half-integer offsets.
    """
    th = math.tan(math.radians(fov_h_deg) / 2)
    tv = math.tan(math.radians(fov_v_deg) / 2)
    y = th * (1.0 - 2.0 * (np.arange(cols) + 0.5) / cols)
    z = tv * (1.0 - 2.0 * (np.arange(rows) + 0.5) / rows)
    Z, Y = np.meshgrid(z, y, indexing="ij")
    d = np.stack([np.ones(rows * cols), Y.ravel(), Z.ravel()], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _equiangular_dirs(cols: int, rows: int, fov_h_deg: float, fov_v_deg: float) -> np.ndarray:
    """Unit directions of a grid with equal angular pixel pitch (azimuth/elevation)."""
    h = math.radians(fov_h_deg)
    v = math.radians(fov_v_deg)
    az = h / 2 * (1.0 - 2.0 * (np.arange(cols) + 0.5) / cols)
    el = v / 2 * (1.0 - 2.0 * (np.arange(rows) + 0.5) / rows)
    E, A = np.meshgrid(el, az, indexing="ij")
    E, A = E.ravel(), A.ravel()
    return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=1)


def _jsonable(v: Any) -> Any:
    if isinstance(v, (tuple, list, np.ndarray)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer, int)) and not isinstance(v, bool):
        return int(v)
    return v


@njit(cache=True)
def _rotate(P: np.ndarray, R: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """``P @ R.T`` for (N, 3) rows (avoids BLAS thread overhead on tiny inner dimensions)."""
    n = P.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        for a in range(3):
            out[i, a] = R[a, 0] * x + R[a, 1] * y + R[a, 2] * z
    return out


@njit(cache=True)
def _gate_returns(
    ranges, faces, dirs_t, dirs_s, normals, lo, hi, depth_gate, cos_min
):  # pragma: no cover - compiled
    """Valid-return mask (hit, range/depth in [lo, hi], incidence ok) and |cos incidence|."""
    n = ranges.shape[0]
    ok = np.zeros(n, dtype=np.bool_)
    cos_inc = np.zeros(n)
    for i in range(n):
        f = faces[i]
        if f < 0:
            continue
        r = ranges[i] * dirs_s[i, 0] if depth_gate else ranges[i]
        if r < lo or r > hi:
            continue
        c = abs(
            normals[f, 0] * dirs_t[i, 0]
            + normals[f, 1] * dirs_t[i, 1]
            + normals[f, 2] * dirs_t[i, 2]
        )
        cos_inc[i] = c
        ok[i] = c >= cos_min
    return ok, cos_inc


@dataclass
class SensorReturn:
    """Detailed output of one scan (``Sensor.scan_detailed``).

    Attributes
    ----------
    points : (N, 3) float64
        Measured points, sensor frame, metres.
    ray_index : (N,) int64
        Index of the beam/pixel in the sensor's full pattern (``-1`` for the HPR sampler).
    face_index : (N,) int64
        Mesh face of each return.
    true_range : (N,) float64
        Noiseless distance from the sensor origin, metres.
    incidence : (N,) float64
        Angle between the line of sight and the face normal, radians (in [0, π/2]).
    """

    points: np.ndarray
    ray_index: np.ndarray
    face_index: np.ndarray
    true_range: np.ndarray
    incidence: np.ndarray

    @classmethod
    def empty(cls) -> SensorReturn:
        z = np.zeros(0)
        i = np.zeros(0, dtype=np.int64)
        return cls(np.zeros((0, 3)), i, i.copy(), z, z.copy())


# --------------------------------------------------------------------------- base class


class Sensor(abc.ABC):
    """A simulated range sensor.

    Subclasses define ``kind`` (the ``to_dict``/``sensor_from_dict`` tag) and
    :meth:`scan_detailed`.
    """

    name: str
    kind: ClassVar[str] = "sensor"

    def scan(
        self, target: Target, T_target_sensor: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        """Simulate one frame.

        Parameters
        ----------
        target : Target
            Target whose mesh is in the target frame.
        T_target_sensor : (4, 4) float64
            Sensor pose in the target frame (maps sensor → target coordinates).
        rng : numpy.random.Generator or int
            Source of all randomness of this frame.

        Returns
        -------
        (N, 3) float64
            Points in the SENSOR frame (x forward, y left, z up), metres; ``(0, 3)`` when the
            target is not seen.
        """
        return self.scan_detailed(target, T_target_sensor, rng).points

    @abc.abstractmethod
    def scan_detailed(
        self, target: Target, T_target_sensor: np.ndarray, rng: np.random.Generator
    ) -> SensorReturn:
        """Like :meth:`scan` with per-point ray/face indices, true range and incidence."""

    @property
    @abc.abstractmethod
    def max_range(self) -> float:
        """Largest range returned, metres."""

    @abc.abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """All constructor parameters plus ``kind`` (plain YAML-safe types).

        ``sensor_from_dict(sensor.to_dict())`` rebuilds an identical sensor.
        """

    def __repr__(self) -> str:
        d = self.to_dict()
        kind = d.pop("kind")
        args = ", ".join(f"{k}={v!r}" for k, v in d.items() if k != "elevations_deg")
        return f"{type(self).__name__}<{kind}>({args})"

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.to_dict() == other.to_dict()  # type: ignore[attr-defined]

    __hash__ = None  # type: ignore[assignment]


class _RaySensor(Sensor):
    """Shared ray-casting pipeline; subclasses provide the sensor-frame ray pattern."""

    min_range: float
    max_range_m: float
    max_incidence_deg: float
    dropout: float
    _dirs: np.ndarray | None

    @property
    def max_range(self) -> float:
        """Largest detected slant range, metres."""
        return float(self.max_range_m)

    @abc.abstractmethod
    def ray_directions(self) -> np.ndarray:
        """(R, 3) float64 unit ray directions in the sensor frame (the full pattern)."""

    _depth_gate: ClassVar[bool] = False
    """Gate ``[min_range, max_range_m]`` on the depth along +x instead of the slant range."""

    def _measure(
        self, ranges: np.ndarray, dirs_s: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Noisy points (M, 3) in the sensor frame and a keep mask (M,) for valid returns.

        Default (LIDARs): Gaussian range noise ``range_sigma`` along each ray, every return kept.
        """
        r = add_range_noise(ranges, self.range_sigma, rng)
        return dirs_s * r[:, None], np.ones(r.size, dtype=bool)

    def _candidate_rays(self, target: Target, T: np.ndarray) -> np.ndarray | None:
        """Indices of the rays that may hit the target's bounding sphere (None: none)."""
        dirs = self.ray_directions()
        c_t, rho = target.bounding_sphere
        c_s = T[:3, :3].T @ (c_t - T[:3, 3])  # sphere centre in the sensor frame
        dist = float(np.linalg.norm(c_s))
        if dist - rho > self.max_range or dist + rho < self.min_range:
            return None
        if dist <= rho * (1.0 + 1e-9):
            return np.arange(len(dirs))
        half = math.asin(min(1.0, rho / dist)) + 1e-6
        cosang = dirs @ (c_s / dist)
        return np.flatnonzero(cosang >= math.cos(min(half, math.pi)))

    def _extra_gate(
        self, target: Target, T: np.ndarray, pts_t: np.ndarray, keep: np.ndarray
    ) -> np.ndarray:
        return keep

    def scan_detailed(
        self, target: Target, T_target_sensor: np.ndarray, rng: np.random.Generator
    ) -> SensorReturn:
        T = _check_pose(T_target_sensor)
        gen = as_generator(rng)
        idx = self._candidate_rays(target, T)
        if idx is None or idx.size == 0:
            return SensorReturn.empty()
        dirs_s = self.ray_directions()[idx]
        R, t = T[:3, :3], T[:3, 3]
        dirs_t = _rotate(dirs_s, R)
        rc = target.raycaster
        ranges, faces = rc.cast(np.broadcast_to(t, dirs_t.shape), dirs_t)
        hit, cos_inc = _gate_returns(
            ranges,
            faces,
            dirs_t,
            dirs_s,
            rc.face_normals,
            float(self.min_range),
            float(self.max_range_m),
            bool(self._depth_gate),
            math.cos(math.radians(self.max_incidence_deg)),
        )
        sel = np.flatnonzero(hit)
        if sel.size:
            pts_t = t + dirs_t[sel] * ranges[sel, None]
            ok = self._extra_gate(target, T, pts_t, np.ones(sel.size, dtype=bool))
            sel = sel[ok]
        sel = sel[dropout_mask(sel.size, self.dropout, gen)]
        if sel.size == 0:
            return SensorReturn.empty()
        pts, ok = self._measure(ranges[sel], dirs_s[sel], gen)
        sel = sel[ok]
        return SensorReturn(
            points=np.ascontiguousarray(pts[ok], dtype=np.float64),
            ray_index=idx[sel].astype(np.int64),
            face_index=faces[sel].astype(np.int64),
            true_range=ranges[sel].astype(np.float64),
            incidence=np.arccos(np.clip(cos_inc[sel], 0.0, 1.0)),
        )


# --------------------------------------------------------------------------- sensors


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
        self.dropout = _check_prob("dropout", dropout)
        self.max_incidence_deg = _num("max_incidence_deg", max_incidence_deg, lo=0.0)
        if self.max_incidence_deg > 90.0:
            raise ConfigError(f"max_incidence_deg must be <= 90, got {self.max_incidence_deg}")
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
        self.dropout = _check_prob("dropout", dropout)
        self.max_incidence_deg = _num("max_incidence_deg", max_incidence_deg, lo=0.0)
        if self.max_incidence_deg > 90.0:
            raise ConfigError(f"max_incidence_deg must be <= 90, got {self.max_incidence_deg}")
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
        self.dropout = _check_prob("dropout", dropout)
        self.max_incidence_deg = _num("max_incidence_deg", max_incidence_deg, lo=0.0)
        if self.max_incidence_deg > 90.0:
            raise ConfigError(f"max_incidence_deg must be <= 90, got {self.max_incidence_deg}")
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


class SurfaceSampler(Sensor):
    """Paper 1's simulated clouds: points of the target's surface + hidden point removal.

    Per frame: take the surface points (see ``model_cloud``), transform them to the sensor
    frame, keep the points visible from the sensor origin by HPR
    (:func:`relnav.sim.hpr.hidden_point_removal`), then crop to ``[min_range, max_range]`` and
    the optional field of view, apply dropout and noise (drawn from the scan's ``rng``).

    Parameters
    ----------
    name : str
        Sensor name.
    n_points : int
        Wanted number of VISIBLE points per frame, on average (calibrates ``n_surface`` or
        ``model_voxel`` when they are None).
    n_surface : int, optional
        ``resample`` only: surface samples per frame. ``None`` = calibrate once per target: the
        mean HPR visible fraction ``f`` over 8 fixed viewpoints (cube-corner directions at 3×
        the bounding radius, fixed seed) gives ``n_surface = n_points / f`` (two fixed-point
        passes, since HPR's kept fraction depends on density). Independent of the scan order,
        hence deterministic.
    hpr_radius_factor : float
        HPR flipping radius over the farthest point distance, ``10**γ`` (default 100,
        ``γ = 2`` **[interpretation]**). Smaller → sparser, more aggressive removal.
    min_range, max_range : float
        Range crop, metres (``max_range`` may be ``inf``).
    fov_h_deg, fov_v_deg : float, optional
        Rectangular pinhole field of view centred on +x, degrees (None: no crop).
    noise_sigma : float
        1σ Gaussian noise, metres: along the line of sight (``noise_mode="range"``, default)
        or on each coordinate (``"isotropic"``).
    dropout : float
        Probability that a visible point is lost.
    model_cloud : {"resample", "fixed"}
        ``"fixed"`` = paper 1's data generation: ONE complete model cloud per target, rendered
        from ``model_views`` views of a tessellated sphere and merged
        (:mod:`relnav.sim.model_cloud`), shared by every frame, so consecutive noiseless scans
        share points. ``"resample"`` = fresh area-weighted uniform surface samples every frame
        (harsher: no point repeats between scans).
    model_views : int
        ``fixed``: views of the tessellated sphere (paper 1: 800).
    model_resolution : int
        ``fixed``: pixels per side of each rendered view **[interpretation]**.
    model_thinning : {"random", "voxel", "none"}
        ``fixed``: how the merged views are thinned to the wanted density (see
        :mod:`relnav.sim.model_cloud`; ``random`` by default **[interpretation]**).
    model_size : int, optional
        ``fixed``/``random``: points of the model cloud. ``None`` = calibrate once per target
        so that about ``n_points`` points are visible from the same 8 viewpoints as
        ``n_surface`` (fixed-point iteration ``size ← size · n_points / count``).
    model_voxel : float, optional
        ``fixed``/``voxel``: voxel edge, m. ``None`` = calibrate likewise
        (``v ← v · sqrt(count / n_points)``).
    model_seed : int
        ``fixed``: seed of the rendering (view-sphere rotation, pixel-grid rolls). Like the
        target's own seed it is fixed by default, so scenario seeds vary only the noise.
    """

    kind: ClassVar[str] = "surface_sampler"

    def __init__(
        self,
        name: str,
        n_points: int = 500,
        n_surface: int | None = None,
        hpr_radius_factor: float = 100.0,
        min_range: float = 0.0,
        max_range: float = math.inf,
        fov_h_deg: float | None = None,
        fov_v_deg: float | None = None,
        noise_sigma: float = 0.0,
        noise_mode: str = "range",
        dropout: float = 0.0,
        model_cloud: str = "resample",
        model_views: int = 800,
        model_resolution: int = 64,
        model_thinning: str = "random",
        model_size: int | None = None,
        model_voxel: float | None = None,
        model_seed: int = 0,
    ) -> None:
        self.name = str(name)
        self.n_points = _int("n_points", n_points)
        if model_cloud not in ("resample", "fixed"):
            raise ConfigError(f"model_cloud must be 'fixed' or 'resample', got {model_cloud!r}")
        self.model_cloud = model_cloud
        self.model_views = _int("model_views", model_views)
        self.model_resolution = _int("model_resolution", model_resolution, lo=2)
        if self.model_resolution > 4096:
            raise ConfigError(f"model_resolution must be <= 4096, got {self.model_resolution}")
        if model_thinning not in ("random", "voxel", "none"):
            raise ConfigError(
                f"model_thinning must be 'random', 'voxel' or 'none', got {model_thinning!r}"
            )
        self.model_thinning = model_thinning
        self.model_size = None if model_size is None else _int("model_size", model_size)
        self.model_voxel = (
            None if model_voxel is None else _num("model_voxel", model_voxel, lo=0.0, lo_open=True)
        )
        if self.model_voxel is not None and not math.isfinite(self.model_voxel):
            raise ConfigError(f"model_voxel must be finite, got {self.model_voxel}")
        self.model_seed = _int("model_seed", model_seed, lo=0)
        self.n_surface = None if n_surface is None else _int("n_surface", n_surface)
        self.hpr_radius_factor = _num("hpr_radius_factor", hpr_radius_factor, lo=1.0, lo_open=True)
        self.min_range, self.max_range_m = _check_ranges(min_range, max_range)
        self.fov_h_deg = None if fov_h_deg is None else _check_fov("fov_h_deg", fov_h_deg)
        self.fov_v_deg = None if fov_v_deg is None else _check_fov("fov_v_deg", fov_v_deg)
        self.noise_sigma = _num("noise_sigma", noise_sigma, lo=0.0)
        if noise_mode not in ("range", "isotropic"):
            raise ConfigError(f"noise_mode must be 'range' or 'isotropic', got {noise_mode!r}")
        self.noise_mode = noise_mode
        self.dropout = _check_prob("dropout", dropout)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "name": self.name,
            "n_points": self.n_points,
            "n_surface": self.n_surface,
            "hpr_radius_factor": self.hpr_radius_factor,
            "min_range": self.min_range,
            "max_range": self.max_range_m,
            "fov_h_deg": self.fov_h_deg,
            "fov_v_deg": self.fov_v_deg,
            "noise_sigma": self.noise_sigma,
            "noise_mode": self.noise_mode,
            "dropout": self.dropout,
            "model_cloud": self.model_cloud,
            "model_views": self.model_views,
            "model_resolution": self.model_resolution,
            "model_thinning": self.model_thinning,
            "model_size": self.model_size,
            "model_voxel": self.model_voxel,
            "model_seed": self.model_seed,
        }

    @property
    def max_range(self) -> float:
        return float(self.max_range_m)

    # -- fixed model cloud ------------------------------------------------------------------

    def _model(self, target: Target, param: float) -> ModelCloud:
        return model_cloud_for(
            target,
            n_views=self.model_views,
            resolution=self.model_resolution,
            thinning=self.model_thinning,
            size=int(param) if self.model_thinning == "random" else 0,
            voxel=float(param) if self.model_thinning == "voxel" else 0.0,
            seed=self.model_seed,
        )

    def model_cloud_of(self, target: Target) -> ModelCloud:
        """The fixed model cloud of ``target`` (rendered and cached on first use)."""
        param = {"random": self.model_size, "voxel": self.model_voxel, "none": 0.0}[
            self.model_thinning
        ]
        if param is None:
            key = ("surface_sampler.model", mesh_fingerprint(target), self.n_points,
                   self.hpr_radius_factor, self.model_views, self.model_resolution,
                   self.model_thinning, self.model_seed)  # fmt: skip
            param = _MODEL_PARAM_CACHE.get(key)
            if param is None:
                param = self._calibrate_model(target)
                _MODEL_PARAM_CACHE[key] = param
                log.info(
                    "SurfaceSampler %s: model cloud of %s, %d views, %s thinning (%.4g), "
                    "%d points for ~%d visible",
                    self.name,
                    target.name,
                    self.model_views,
                    self.model_thinning,
                    param,
                    self._model(target, param).points.shape[0],
                    self.n_points,
                )
        return self._model(target, param)

    def _calibrate_model(self, target: Target) -> float:
        """Model-cloud size (random) or voxel edge (voxel) giving ~``n_points`` visible."""
        c, rho = target.bounding_sphere
        views = c + 3.0 * rho * _CUBE_CORNERS
        voxel = self.model_thinning == "voxel"
        x = (
            math.sqrt(float(target.mesh.area) / (4.0 * self.n_points))
            if voxel
            else 3.0 * self.n_points
        )
        for _ in range(10):
            P = self._model(target, x).points
            count = np.mean(
                [hidden_point_removal(P, w, self.hpr_radius_factor).size for w in views]
            )
            ratio = max(float(count), 1.0) / self.n_points
            if abs(ratio - 1.0) < 0.02:
                break
            if voxel:
                x = x * math.sqrt(ratio)
            else:
                x_new = max(1, round(x / ratio))
                if x_new >= P.shape[0] and x >= P.shape[0]:
                    log.warning(
                        "SurfaceSampler %s: the merged views of %s (%d points) give only ~%d "
                        "visible points; raise model_resolution",
                        self.name,
                        target.name,
                        P.shape[0],
                        count,
                    )
                    break
                x = float(x_new)
        return float(x)

    # -- sampling -------------------------------------------------------------------------

    @staticmethod
    def _sampling_tables(
        target: Target,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        key = ("surface_sampler.tables", id(target.mesh))
        tab = target.cache.get(key)
        if tab is None:
            V = np.asarray(target.mesh.vertices, dtype=np.float64)
            F = np.asarray(target.mesh.faces, dtype=np.int64)
            v0 = V[F[:, 0]]
            e1 = V[F[:, 1]] - v0
            e2 = V[F[:, 2]] - v0
            n = np.cross(e1, e2)
            dbl = np.linalg.norm(n, axis=1)
            cdf = np.cumsum(0.5 * dbl)
            if not cdf[-1] > 0:
                raise InputError(f"target {target.name!r}: mesh has zero surface area")
            normals = np.divide(n, dbl[:, None], out=np.zeros_like(n), where=dbl[:, None] > 0)
            tab = (v0, e1, e2, cdf / cdf[-1], normals)
            target.cache[key] = tab
        return tab

    def sample_surface(
        self, target: Target, n: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """``n`` uniform surface samples (target frame, m) and their face indices.

        Draws ``n`` uniforms (face, area-weighted) then ``2n`` (barycentric) from ``rng``.
        """
        v0, e1, e2, cdf, _ = self._sampling_tables(target)
        f = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(cdf) - 1)
        ab = rng.random((n, 2))
        flip = ab.sum(axis=1) > 1.0
        ab[flip] = 1.0 - ab[flip]
        pts = v0[f] + ab[:, :1] * e1[f] + ab[:, 1:] * e2[f]
        return pts, f.astype(np.int64)

    def surface_samples_for(self, target: Target) -> int:
        """Surface samples per frame for ``target`` (``n_surface`` or the calibration)."""
        if self.n_surface is not None:
            return self.n_surface
        key = ("surface_sampler.n_surface", id(target.mesh), self.n_points, self.hpr_radius_factor)
        n = target.cache.get(key)
        if n is None:
            n = self._calibrate(target)
            target.cache[key] = n
            log.info(
                "SurfaceSampler %s: %d surface samples per frame on %s for ~%d visible points",
                self.name,
                n,
                target.name,
                self.n_points,
            )
        return int(n)

    def _calibrate(self, target: Target) -> int:
        c, rho = target.bounding_sphere
        views = c + 3.0 * rho * _CUBE_CORNERS
        n = 4 * self.n_points
        for _ in range(2):
            rng = np.random.default_rng(0)
            frac = []
            for v in views:
                pts, _ = self.sample_surface(target, n, rng)
                vis = hidden_point_removal(pts, v, self.hpr_radius_factor)
                frac.append(vis.size / n)
            f = max(float(np.mean(frac)), 1e-3)
            n = max(round(self.n_points / f), self.n_points)
        return n

    def scan_detailed(
        self, target: Target, T_target_sensor: np.ndarray, rng: np.random.Generator
    ) -> SensorReturn:
        T = _check_pose(T_target_sensor)
        gen = as_generator(rng)
        if self.model_cloud == "fixed":
            mc = self.model_cloud_of(target)
            pts_t, faces = mc.points, mc.faces
        else:
            pts_t, faces = self.sample_surface(target, self.surface_samples_for(target), gen)
        R, t = T[:3, :3], T[:3, 3]
        pts_s = (pts_t - t) @ R
        vis = hidden_point_removal(pts_s, np.zeros(3), self.hpr_radius_factor)
        p = pts_s[vis]
        r = np.linalg.norm(p, axis=1)
        keep = (r >= self.min_range) & (r <= self.max_range_m)
        if self.fov_h_deg is not None or self.fov_v_deg is not None:
            keep &= p[:, 0] > 0
            with np.errstate(divide="ignore", invalid="ignore"):
                if self.fov_h_deg is not None:
                    keep &= np.abs(p[:, 1] / p[:, 0]) <= math.tan(math.radians(self.fov_h_deg) / 2)
                if self.fov_v_deg is not None:
                    keep &= np.abs(p[:, 2] / p[:, 0]) <= math.tan(math.radians(self.fov_v_deg) / 2)
        vis = vis[keep]
        vis = vis[dropout_mask(vis.size, self.dropout, gen)]
        if vis.size == 0:
            return SensorReturn.empty()
        p = pts_s[vis]
        r = np.linalg.norm(p, axis=1)
        if self.noise_sigma > 0:
            if self.noise_mode == "range":
                p = range_noise_points(p, self.noise_sigma, gen)
            else:
                p = p + self.noise_sigma * gen.standard_normal(p.shape)
        normals = self._sampling_tables(target)[4][faces[vis]] @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_inc = np.abs(np.einsum("ij,ij->i", normals, pts_s[vis])) / r
        return SensorReturn(
            points=np.ascontiguousarray(p, dtype=np.float64),
            ray_index=np.full(vis.size, -1, dtype=np.int64),
            face_index=faces[vis],
            true_range=r,
            incidence=np.arccos(np.clip(np.nan_to_num(cos_inc), 0.0, 1.0)),
        )


_CUBE_CORNERS = np.array(
    [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64
) / math.sqrt(3.0)
_MODEL_PARAM_CACHE: dict[tuple, float] = {}


# --------------------------------------------------------------------------- presets

_RS32_ELEVATIONS = (
    # [interpretation] non-linear 32-beam table, -25..+15°, 1/3° pitch near the horizon
    # (the manufacturer's exact factory table was not checked).
    -25.0,
    -15.6,
    -11.3,
    -8.8,
    -7.3,
    -6.1,
    -5.3,
    *[round(-14.0 / 3.0 + k / 3.0, 4) for k in range(19)],  # -4.667 .. +1.333
    2.333,
    3.333,
    4.667,
    7.0,
    10.333,
    15.0,
)

_PRESETS: dict[str, tuple[type[Sensor], dict[str, Any]]] = {
    "vlp16": (
        ScanningLidar,
        dict(
            elevations_deg=tuple(float(e) for e in range(-15, 16, 2)),
            azimuth_step_deg=0.2,
            azimuth_fov_deg=(-180.0, 180.0),
            min_range=0.5,
            max_range=100.0,
            range_sigma=0.03,
        ),
    ),
    "hdl64": (
        ScanningLidar,
        dict(
            # [interpretation] 64 beams evenly spaced +2..-24.9° (≈0.427°)
            elevations_deg=tuple(float(e) for e in np.round(np.linspace(2.0, -24.9, 64), 6)),
            azimuth_step_deg=0.1728,
            azimuth_fov_deg=(-180.0, 180.0),
            min_range=0.9,
            max_range=120.0,
            range_sigma=0.01,
        ),
    ),
    "rs32": (
        ScanningLidar,
        dict(
            elevations_deg=_RS32_ELEVATIONS,
            azimuth_step_deg=0.2,
            azimuth_fov_deg=(-180.0, 180.0),
            min_range=0.4,
            max_range=200.0,
            range_sigma=0.03,
        ),
    ),
    "goldeneye": (
        FlashLidar,
        dict(
            rows=128,
            cols=128,
            fov_h_deg=45.0,
            fov_v_deg=45.0,
            min_range=1.0,
            max_range=3000.0,
            range_sigma=0.10,
        ),
    ),
    "dragoneye": (
        FlashLidar,
        dict(
            rows=128,
            cols=128,
            fov_h_deg=45.0,
            fov_v_deg=45.0,
            min_range=1.0,
            max_range=1500.0,
            range_sigma=0.15,
        ),
    ),
    "flash256": (
        FlashLidar,
        dict(
            # [interpretation] a dense 256×256 flash LIDAR (65 536 pixels), 30°×30°, 2 cm
            rows=256,
            cols=256,
            fov_h_deg=30.0,
            fov_v_deg=30.0,
            min_range=0.5,
            max_range=1000.0,
            range_sigma=0.02,
        ),
    ),
    "kinect1": (DepthCamera, {}),
    "surface-hpr": (SurfaceSampler, dict(n_points=500, hpr_radius_factor=100.0)),
}

_KINDS: dict[str, type[Sensor]] = {
    c.kind: c for c in (ScanningLidar, FlashLidar, DepthCamera, SurfaceSampler)
}


def available_sensors() -> list[str]:
    """Names of the sensor presets accepted by :func:`make_sensor`."""
    return list(_PRESETS)


def _construct(cls: type[Sensor], kwargs: dict[str, Any], what: str) -> Sensor:
    import inspect

    allowed = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise ConfigError(f"{what}: unknown parameter(s) {unknown}; allowed: {allowed}")
    missing = [
        p
        for p, prm in inspect.signature(cls.__init__).parameters.items()
        if p != "self" and prm.default is inspect.Parameter.empty and p not in kwargs
    ]
    if missing:
        raise ConfigError(f"{what}: missing parameter(s) {missing}")
    return cls(**kwargs)  # type: ignore[call-arg]


def make_sensor(name: str, **overrides: Any) -> Sensor:
    """A sensor preset by name, with optional parameter overrides.

    Presets: ``vlp16``, ``hdl64``, ``rs32`` (scanning), ``goldeneye``, ``dragoneye`` (flash,
    128×128, 45°×45°), ``flash256`` (dense flash, 256×256, 30°×30°), ``kinect1`` (depth
    camera), ``surface-hpr`` (paper 1's HPR sampler).
    See ALGORITHMS.md §H for the numbers.

    Raises
    ------
    ConfigError
        Unknown preset or parameter, or an invalid value (negative range, min > max, ...).
    """
    key = str(name).lower().replace("_", "-")
    if key not in _PRESETS:
        raise ConfigError(f"unknown sensor {name!r}; available: {', '.join(available_sensors())}")
    cls, params = _PRESETS[key]
    kwargs: dict[str, Any] = {"name": key, **params, **overrides}
    return _construct(cls, kwargs, f"sensor {key!r}")


def sensor_from_dict(d: dict[str, Any]) -> Sensor:
    """Rebuild a sensor from :meth:`Sensor.to_dict` output (e.g. a ``sensor.yaml``).

    A dict with ``preset`` (and optional overrides) instead of ``kind`` is passed to
    :func:`make_sensor`.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"sensor description must be a mapping, got {type(d).__name__}")
    d = dict(d)
    if "preset" in d and "kind" not in d:
        return make_sensor(d.pop("preset"), **d)
    kind = d.pop("kind", None)
    if kind not in _KINDS:
        raise ConfigError(f"sensor kind {kind!r} unknown; expected one of {sorted(_KINDS)}")
    return _construct(_KINDS[kind], d, f"sensor kind {kind!r}")
