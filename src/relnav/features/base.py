"""Descriptor protocol and registry.

Every descriptor family registers itself by name with :func:`register_descriptor`; users call
:func:`relnav.features.compute`. A descriptor function has the signature::

    fn(points, keypoint_idx, *, radius, normals, **options) -> (K, D) float32

where ``points`` is ``(N, 3)`` float64 (metres, sensor frame), ``keypoint_idx`` ``(K,)`` int64
indices into ``points``, ``radius`` the support radius in metres and ``normals`` ``(N, 3)`` unit
normals (or ``None`` when the descriptor does not need them). Invalid descriptors (fewer than
``MIN_SUPPORT`` support points, undefined local frame) are rows of NaN; matching skips them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from relnav.errors import ConfigError, InputError

__all__ = [
    "MIN_SUPPORT",
    "DescriptorSpec",
    "available_descriptors",
    "compute",
    "get_descriptor",
    "register_descriptor",
]

MIN_SUPPORT = 5
"""Minimum support points (keypoint included) for a valid descriptor (PCL SHOT rule)."""


@dataclass(frozen=True)
class DescriptorSpec:
    """A registered descriptor family.

    Attributes
    ----------
    name : str
        Registry name (``"hod"``, ``"shot"``...).
    dim : int
        Descriptor length ``D``.
    radius_factor : float
        Default support radius in multiples of the mean resolution ``Tr``.
    needs_normals : bool
        Whether the function needs per-point normals.
    description : str
        One line for ``relnav methods``.
    fn : callable
        The implementation (see module docstring).
    """

    name: str
    dim: int
    radius_factor: float
    needs_normals: bool
    description: str
    fn: Callable[..., np.ndarray]


_REGISTRY: dict[str, DescriptorSpec] = {}


def register_descriptor(
    name: str, *, dim: int, radius_factor: float, needs_normals: bool, description: str
) -> Callable[[Callable[..., np.ndarray]], Callable[..., np.ndarray]]:
    """Decorator registering a descriptor function under ``name``."""

    def deco(fn: Callable[..., np.ndarray]) -> Callable[..., np.ndarray]:
        _REGISTRY[name] = DescriptorSpec(name, dim, radius_factor, needs_normals, description, fn)
        return fn

    return deco


def _load_all() -> None:
    # Importing the family modules registers them.
    from relnav.features import fpfh, hod, rops, shot, trisi  # noqa: F401


def available_descriptors() -> dict[str, DescriptorSpec]:
    """All registered descriptors by name."""
    _load_all()
    return dict(_REGISTRY)


def get_descriptor(name: str) -> DescriptorSpec:
    """The :class:`DescriptorSpec` registered as ``name``; :class:`ConfigError` if unknown."""
    _load_all()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ConfigError(
            f"unknown descriptor {name!r}; available: {', '.join(sorted(_REGISTRY))}"
        ) from None


def compute(
    name: str,
    points: np.ndarray,
    *,
    radius: float,
    keypoints: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    **options: object,
) -> np.ndarray:
    """Compute descriptor ``name`` at ``keypoints``.

    Parameters
    ----------
    name : str
        Registered descriptor name.
    points : (N, 3) float64
        Cloud, metres.
    radius : float
        Support radius, metres (typically ``radius_factor · Tr``).
    keypoints : (K,) int, optional
        Indices of the keypoints in ``points``; all points when omitted (paper 1 default).
    normals : (N, 3) float64, optional
        Unit normals; estimated (PCA, radius ``radius/4``, oriented to the origin) when the
        descriptor needs them and none are given.
    **options
        Family-specific options (e.g. ``mode="fast"`` for HoD).

    Returns
    -------
    (K, D) float32
        One row per keypoint; NaN rows are invalid descriptors.
    """
    spec = get_descriptor(name)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(P).all():
        raise InputError("descriptor input contains NaN/inf points")
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"descriptor radius must be positive and finite, got {radius}")
    idx = (
        np.arange(P.shape[0], dtype=np.int64)
        if keypoints is None
        else np.asarray(keypoints, dtype=np.int64).reshape(-1)
    )
    if idx.size and (idx.min() < 0 or idx.max() >= P.shape[0]):
        raise InputError("keypoint index out of range")
    if idx.size == 0 or P.shape[0] == 0:
        return np.full((idx.size, spec.dim), np.nan, dtype=np.float32)
    if spec.needs_normals and normals is None:
        from relnav.geometry.normals import estimate_normals

        normals = estimate_normals(P, radius=radius / 4.0)
    out = spec.fn(P, idx, radius=float(radius), normals=normals, **options)
    out = np.asarray(out, dtype=np.float32)
    if out.shape != (idx.size, spec.dim):
        raise RuntimeError(f"descriptor {name} returned shape {out.shape}")
    return out
