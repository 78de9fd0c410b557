"""Noise settings of Paper 2's pose filters in physical units (1σ per nominal step): process noise,
measurement noise and initial uncertainty, shared by :class:`relnav.filtering.ukf.TwistorUKF` and
:class:`relnav.filtering.ekf.QuaternionEKF` ([interpretation]: Paper 2 gives no values; the defaults
are documented in :mod:`relnav.filtering.ukf`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from relnav.errors import ConfigError

__all__ = ["InitialUncertainty", "MeasurementNoise", "ProcessNoise"]


def _positive_fields(obj: Any) -> None:
    for f in fields(obj):
        v = getattr(obj, f.name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
            raise ConfigError(
                f"{type(obj).__name__}.{f.name} must be a finite number >= 0, got {v!r}"
            )


@dataclass(frozen=True)
class ProcessNoise:
    """Process noise: random walks (1σ per nominal step) and accelerations held over a step.

    The four random walks are Paper 2's (variance scaled by ``Δt/dt`` for a step of ``Δt``).
    The accelerations state the physics instead **[interpretation, not in Paper 2]**: an
    acceleration ``a`` (angular: ``α``) held constant over a step of ``Δt`` s moves the velocity
    by ``a Δt`` and the position by ``a Δt²/2``; each adds that squared to the variances
    (diagonal: their correlation is dropped).

    Attributes
    ----------
    position : float
        m (default 1e-4).
    velocity : float
        m/s (default 1e-4).
    attitude : float
        rad (default 4e-3 = pose-twist 1e-3, since ``B_r ≈ δθ/4``).
    omega : float
        rad/s (default 1e-3).
    acceleration : float
        1σ of the unmodelled relative acceleration of the target's reference point, m/s²
        (default 0): the chaser's thrusts, the orbital terms a free model leaves out.
    angular_acceleration : float
        1σ of the target's angular acceleration, rad/s² (default 0).
    torque_free : bool
        Add the bound of a torque-free rigid body's angular acceleration (default False):
        Euler's equations give ``|ω̇ᵢ| = |Iⱼ − Iₖ| |ωⱼ ωₖ| / Iᵢ ≤ |ωⱼ ωₖ|`` whatever the inertia
        (``|Iⱼ − Iₖ| ≤ Iᵢ`` for principal moments), so ``|ω̇| ≤ |ω|²/√3``; the filter takes
        ``angular_acceleration + |ω̂|²/√3`` (``ω̂`` the estimate at the start of each step) as
        the step's ``α``. Not ``E|ω|² = |ω̂|² + tr P_ω``: the rate's covariance would then grow
        its own process noise (it diverges where the rate is unobserved). It is a bound: a target
        spinning about a principal axis has ``ω̇ = 0`` and gets a conservative rate.
    torque_free_share : float
        Share of that bound taken (default 1): a bank of filters with smaller shares lets the
        data say whether the target spins about a principal axis
        (:func:`relnav.filtering.multiple_model.mix_tracks`).
    """

    position: float = 1e-4
    velocity: float = 1e-4
    attitude: float = 4e-3
    omega: float = 1e-3
    acceleration: float = 0.0
    angular_acceleration: float = 0.0
    torque_free: bool = False
    torque_free_share: float = 1.0

    def __post_init__(self) -> None:
        _positive_fields(self)


@dataclass(frozen=True)
class MeasurementNoise:
    """Measurement noise, 1σ: ``position`` (m, default 0.01), ``attitude`` (rad, default 1°).

    The attitude noise is a small rotation about each body axis (``Q = q ⊗ exp(δθ)``).
    """

    position: float = 0.01
    attitude: float = math.radians(1.0)

    def __post_init__(self) -> None:
        _positive_fields(self)

    def covariance(self) -> np.ndarray:
        """``(6, 6)`` covariance of ``[δp (m), δθ (rad)]``."""
        return np.diag([self.position**2] * 3 + [self.attitude**2] * 3)


@dataclass(frozen=True)
class InitialUncertainty:
    """Initial 1σ: position (m), velocity (m/s), attitude (rad), omega (rad/s).

    Defaults ``0.1, 0.1, 0.4, 0.1`` equal Paper-2-style ``P₀ = 1e-2 I`` in the UKF's error
    coordinates (``δθ ≈ 4 B_r``). ``offset`` (m, default 0.1) is the 1σ of the body-frame
    offset from the rotation centre to the observed reference point (used only by
    ``TwistorUKF(centre_offset=True)``).
    """

    position: float = 0.1
    velocity: float = 0.1
    attitude: float = 0.4
    omega: float = 0.1
    offset: float = 0.1

    def __post_init__(self) -> None:
        _positive_fields(self)


def _coerce(cls: type, value: Any, name: str) -> Any:
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        known = {f.name for f in fields(cls)}
        bad = sorted(set(value) - known)
        if bad:
            raise ConfigError(f"{name}: unknown key(s) {bad}; accepted: {sorted(known)}")
        flags = {f.name for f in fields(cls) if f.type in (bool, "bool")}
        return cls(**{k: (bool(v) if k in flags else float(v)) for k, v in value.items()})
    if isinstance(value, int | float) and cls is MeasurementNoise:
        raise ConfigError(f"{name}: give a MeasurementNoise, a dict or a (6, 6) matrix")
    raise ConfigError(
        f"{name}: expected {cls.__name__}, a dict or None, got {type(value).__name__}"
    )
