"""What every simulated sensor shares: the :class:`Sensor` interface, its per-point
:class:`SensorReturn`, the ray-casting pipeline of the ray sensors, parameter checks."""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.sim.noise import (
    add_range_noise,
    as_generator,
    dropout_mask,
)
from relnav.sim.targets import Target

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

    def _set_gates(self, dropout: Any, max_incidence_deg: Any) -> None:
        """Check and set the return dropout probability and the incidence limit (≤ 90°)."""
        self.dropout = _check_prob("dropout", dropout)
        self.max_incidence_deg = _num("max_incidence_deg", max_incidence_deg, lo=0.0)
        if self.max_incidence_deg > 90.0:
            raise ConfigError(f"max_incidence_deg must be <= 90, got {self.max_incidence_deg}")

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
