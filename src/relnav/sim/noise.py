"""Seeded measurement-noise helpers shared by the simulated sensors.

All functions take an explicit :class:`numpy.random.Generator` and draw a fixed number of
variates per call (one per element, only when the noise is enabled), so the same generator
state always gives byte-identical outputs.
"""

from __future__ import annotations

import numpy as np

from relnav.errors import InputError

__all__ = [
    "KINECT_RAW_A",
    "KINECT_RAW_B",
    "add_range_noise",
    "as_generator",
    "dropout_mask",
    "kinect_depth",
    "kinect_depth_to_raw",
    "kinect_raw_to_depth",
    "range_noise_points",
]

KINECT_RAW_A = -0.00307
"""OpenKinect raw-disparity map slope: ``1/Z = A·raw + B`` (1/m per raw unit)."""
KINECT_RAW_B = 3.3309
"""OpenKinect raw-disparity map offset (1/m)."""
_KINECT_RAW_MAX = 2047


def as_generator(rng: np.random.Generator | int | None) -> np.random.Generator:
    """A :class:`numpy.random.Generator` from a generator or an int seed.

    ``None`` is refused: every simulated measurement must be reproducible.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise InputError(
        f"rng must be a numpy.random.Generator or an int seed, got {type(rng).__name__} "
        "(use np.random.default_rng(seed))"
    )


def add_range_noise(ranges: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """``ranges + N(0, sigma²)``, clipped at 0 (metres). Draws ``len(ranges)`` normals if σ > 0."""
    r = np.asarray(ranges, dtype=np.float64)
    if sigma <= 0 or r.size == 0:
        return r.copy()
    return np.maximum(r + sigma * rng.standard_normal(r.shape), 0.0)


def range_noise_points(
    points: np.ndarray, sigma: float, rng: np.random.Generator, origin: np.ndarray | None = None
) -> np.ndarray:
    """Move each point along its line of sight from ``origin`` by ``N(0, sigma²)`` (metres)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if sigma <= 0 or P.shape[0] == 0:
        return P.copy()
    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64).reshape(3)
    v = P - o
    r = np.linalg.norm(v, axis=1)
    u = np.divide(v, r[:, None], out=np.zeros_like(v), where=r[:, None] > 0)
    r_new = add_range_noise(r, sigma, rng)
    return o + u * r_new[:, None]


def dropout_mask(n: int, p: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean keep-mask of length ``n``: each element dropped with probability ``p``.

    Draws ``n`` uniforms when ``p > 0``; none otherwise.
    """
    if p <= 0 or n == 0:
        return np.ones(n, dtype=bool)
    return rng.random(n) >= p


def kinect_depth_to_raw(z: np.ndarray) -> np.ndarray:
    """Continuous Kinect v1 raw disparity of depth ``z`` (m): ``raw = (1/z − B) / A``."""
    z = np.asarray(z, dtype=np.float64)
    return (1.0 / z - KINECT_RAW_B) / KINECT_RAW_A


def kinect_raw_to_depth(raw: np.ndarray) -> np.ndarray:
    """Depth (m) of a Kinect v1 raw disparity: ``Z = 1 / (A·raw + B)`` (OpenKinect map)."""
    raw = np.asarray(raw, dtype=np.float64)
    return 1.0 / (KINECT_RAW_A * raw + KINECT_RAW_B)


def kinect_depth(
    z: np.ndarray,
    rng: np.random.Generator,
    *,
    sigma_coeff: float = 1.43e-3,
    quantize: bool = True,
) -> np.ndarray:
    """Kinect v1 measured depth of true depths ``z`` (m).

    1. Axial Gaussian noise ``σ_Z = sigma_coeff · Z²`` (Khoshelham & Oude Elberink 2012;
       coefficient **[interpretation]**, ≈ 4 cm at 5 m). Draws ``len(z)`` normals if
       ``sigma_coeff > 0``.
    2. Disparity quantisation: depth → raw (OpenKinect map ``Z = 1/(−0.00307·raw + 3.3309)``),
       round to an integer, → depth. The step is ``ΔZ ≈ 0.00307·Z²``.

    Returns
    -------
    (N,) float64
        Measured depths; ``nan`` where the noisy depth left the sensor's raw range
        (``raw`` outside ``[0, 2047]`` or non-positive depth) — callers drop those.
    """
    z = np.asarray(z, dtype=np.float64)
    out = z.copy()
    if sigma_coeff > 0 and z.size:
        out = z + sigma_coeff * z**2 * rng.standard_normal(z.shape)
    if quantize and out.size:
        with np.errstate(divide="ignore", invalid="ignore"):
            raw = np.rint(kinect_depth_to_raw(out))
            bad = ~np.isfinite(raw) | (raw < 0) | (raw > _KINECT_RAW_MAX) | (out <= 0)
            depth = kinect_raw_to_depth(raw)
        bad |= ~(depth > 0)
        out = np.where(bad, np.nan, depth)
    else:
        out = np.where(out > 0, out, np.nan)
    return out
