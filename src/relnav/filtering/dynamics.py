"""Clohessy–Wiltshire (Hill) relative translational dynamics (ALGORITHMS.md §G.5).

LVLH/Hill frame of a circular reference orbit of radius ``a``: ``x`` radial (outward), ``y``
along-track, ``z`` orbit normal; mean motion ``n = sqrt(μ / a³)``::

    ẍ − 2n ẏ − 3n² x = 0
    ÿ + 2n ẋ          = 0
    z̈ + n² z          = 0

State ``s = [x, y, z, ẋ, ẏ, ż]`` (m, m/s), ``ṡ = A s``. Paper 2 eq. 39 swaps the position and
velocity matrices and uses ``G`` instead of ``μ``; the standard form above is used.

The filters keep the relative position in the *sensor* frame (x forward, y left, z up). The
sensor frame is assumed to stay aligned with LVLH up to a fixed rotation ``M`` (usually a
signed axis permutation), ``s_lvlh = M s_sensor`` **[interpretation: the chaser holds an
LVLH-fixed attitude]**; :class:`ClohessyWiltshire` applies the dynamics in LVLH and maps back.
Paper 2's lab set-up ("orbit altitude r = 0.2 m") corresponds to ``n ≈ 0``; a 400 km LEO gives
``n ≈ 1.131e-3 rad/s``.
"""

from __future__ import annotations

import logging
import math
from typing import Literal

import numpy as np

from relnav.errors import ConfigError, InputError

__all__ = [
    "EARTH_RADIUS_M",
    "MU_EARTH",
    "ClohessyWiltshire",
    "axis_permutation",
    "cw_matrix",
    "cw_stm",
    "mean_motion",
]

log = logging.getLogger(__name__)

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter μ = G·M, m³/s²."""

EARTH_RADIUS_M = 6_378_137.0
"""Earth's equatorial radius (WGS-84), m."""

_SMALL_NT = 1e-8

TranslationModel = Literal["cw", "euler"]


def mean_motion(radius_m: float, mu: float = MU_EARTH) -> float:
    """Mean motion ``n = sqrt(μ / a³)`` (rad/s) of a circular orbit of radius ``radius_m``.

    Raises
    ------
    InputError
        Non-positive or non-finite radius or ``mu``.

    Notes
    -----
    ``radius_m`` is the orbit *radius* (Earth centre to spacecraft), not the altitude. A radius
    below Earth's radius with Earth's ``μ`` (e.g. Paper 2's "r = 0.2 m") is accepted but logged
    as a warning, since it gives an absurd ``n``.
    """
    a = float(radius_m)
    mu = float(mu)
    if not (math.isfinite(a) and a > 0.0 and math.isfinite(mu) and mu > 0.0):
        raise InputError(f"orbit radius and mu must be positive and finite, got {a!r}, {mu!r}")
    if mu == MU_EARTH and a < EARTH_RADIUS_M:
        log.warning(
            "orbit radius %.6g m is below Earth's radius: pass the radius from Earth's centre "
            "(altitude + %.0f m), not the altitude",
            a,
            EARTH_RADIUS_M,
        )
    return math.sqrt(mu / a**3)


def cw_matrix(n: float) -> np.ndarray:
    """Continuous-time system matrix ``A`` ``(6, 6)`` of the CW equations in LVLH."""
    n = _check_n(n)
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3, 0] = 3.0 * n * n
    A[5, 2] = -n * n
    A[3, 4] = 2.0 * n
    A[4, 3] = -2.0 * n
    return A


def _check_n(n: float) -> float:
    n = float(n)
    if not math.isfinite(n) or n < 0.0:
        raise InputError(f"mean motion must be finite and >= 0 rad/s, got {n!r}")
    return n


def cw_stm(n: float, dt: float) -> np.ndarray:
    """Closed-form state-transition matrix ``Φ(dt)`` ``(6, 6)`` of the CW equations (LVLH).

    ``s(t + dt) = Φ s(t)``. Written with cancellation-free forms (``1 − cos x = 2 sin²(x/2)``,
    a series for ``sin x − x``); when ``n·|dt| < 1e-8`` (including ``n = 0``) the exact
    double integrator ``[[I, dt I], [0, I]]`` (the ``n → 0`` limit) is returned.

    Parameters
    ----------
    n : float
        Mean motion, rad/s (``>= 0``).
    dt : float
        Time step, s (negative steps propagate backwards).
    """
    n = _check_n(n)
    tau = float(dt)
    if not math.isfinite(tau):
        raise InputError(f"time step must be finite, got {dt!r}")
    Phi = np.eye(6)
    x = n * tau
    if abs(x) < _SMALL_NT:
        Phi[:3, 3:] = tau * np.eye(3)
        return Phi
    s, c = math.sin(x), math.cos(x)
    omc = 2.0 * math.sin(0.5 * x) ** 2  # 1 - cos x
    if abs(x) < 1e-3:
        smx = -(x**3) / 6.0 + x**5 / 120.0 - x**7 / 5040.0  # sin x - x
    else:
        smx = s - x
    s_n = s / n
    omc_n = omc / n
    # x (radial), y (along-track), z (normal)
    Phi[0] = [4.0 - 3.0 * c, 0.0, 0.0, s_n, 2.0 * omc_n, 0.0]
    Phi[1] = [6.0 * smx, 1.0, 0.0, -2.0 * omc_n, 4.0 * s_n - 3.0 * tau, 0.0]
    Phi[2] = [0.0, 0.0, c, 0.0, 0.0, s_n]
    Phi[3] = [3.0 * n * s, 0.0, 0.0, c, 2.0 * s, 0.0]
    Phi[4] = [-6.0 * n * omc, 0.0, 0.0, -2.0 * s, 4.0 * c - 3.0, 0.0]
    Phi[5] = [0.0, 0.0, -n * s, 0.0, 0.0, c]
    return Phi


_AXES = {"x": 0, "y": 1, "z": 2}


def axis_permutation(spec: str | np.ndarray | None) -> np.ndarray:
    """Rotation ``M`` ``(3, 3)`` with ``v_lvlh = M v_sensor``.

    Parameters
    ----------
    spec : str, (3, 3) array_like or None
        ``None`` or ``"x,y,z"``: identity. A string of three signed sensor axes names, in
        order, the sensor axis that is LVLH radial, along-track and orbit-normal: ``"-z,x,-y"``
        means ``x_lvlh = −z_s``, ``y_lvlh = x_s``, ``z_lvlh = −y_s``. Commas are optional
        (``"xyz"``, ``"-zx-y"``). A matrix must be a proper rotation.

    Raises
    ------
    ConfigError
        Malformed string, repeated axes, or a matrix that is not a rotation.
    """
    if spec is None:
        return np.eye(3)
    if isinstance(spec, str):
        s = spec.replace(",", "").replace(" ", "").lower()
        toks: list[tuple[float, str]] = []
        i = 0
        while i < len(s):
            sign = 1.0
            if s[i] in "+-":
                sign = -1.0 if s[i] == "-" else 1.0
                i += 1
            if i >= len(s) or s[i] not in _AXES:
                raise ConfigError(
                    f"bad LVLH axis spec {spec!r}: expected e.g. 'x,y,z' or '-z,x,-y'"
                )
            toks.append((sign, s[i]))
            i += 1
        if len(toks) != 3 or len({t[1] for t in toks}) != 3:
            raise ConfigError(f"bad LVLH axis spec {spec!r}: need each of x, y, z exactly once")
        M = np.zeros((3, 3))
        for row, (sign, ax) in enumerate(toks):
            M[row, _AXES[ax]] = sign
    else:
        M = np.asarray(spec, dtype=np.float64)
        if M.shape != (3, 3) or not np.all(np.isfinite(M)):
            raise ConfigError(f"LVLH axis matrix must be a finite (3, 3) array, got {M.shape}")
    if not np.allclose(M @ M.T, np.eye(3), atol=1e-9):
        raise ConfigError("LVLH axis matrix is not orthonormal")
    if np.linalg.det(M) < 0:
        raise ConfigError(
            f"LVLH axis spec {spec!r} is a reflection (det = -1); flip the sign of one axis"
        )
    return M


class ClohessyWiltshire:
    """CW relative translational dynamics expressed in the sensor frame.

    Parameters
    ----------
    n : float
        Mean motion, rad/s (0 = force-free double integrator).
    lvlh_axes : str or (3, 3) array_like, optional
        Sensor → LVLH rotation, see :func:`axis_permutation`.
    model : {"cw", "euler"}
        ``"cw"``: exact STM; ``"euler"``: Paper 2 eq. 38, one Euler step
        ``d + ḋΔt, ḋ + d̈Δt`` (``Φ = I + A Δt``).

    Examples
    --------
    >>> cw = ClohessyWiltshire(mean_motion(6_778_137.0))
    >>> pos, vel = cw.propagate([0.0, 10.0, 0.0], [0.0, 0.0, 0.0], 60.0)
    """

    def __init__(
        self,
        n: float = 0.0,
        *,
        lvlh_axes: str | np.ndarray | None = None,
        model: TranslationModel = "cw",
    ) -> None:
        self.n = _check_n(n)
        if model not in ("cw", "euler"):
            raise ConfigError(f"translation model must be 'cw' or 'euler', got {model!r}")
        self.model: TranslationModel = model
        self.M = axis_permutation(lvlh_axes)
        self._M6 = np.kron(np.eye(2), self.M)

    def A(self) -> np.ndarray:
        """Continuous system matrix ``(6, 6)`` in the sensor frame."""
        return self._M6.T @ cw_matrix(self.n) @ self._M6

    def stm(self, dt: float) -> np.ndarray:
        """Discrete transition ``(6, 6)`` over ``dt`` seconds in the sensor frame."""
        if self.model == "euler":
            return np.eye(6) + float(dt) * self.A()
        return self._M6.T @ cw_stm(self.n, dt) @ self._M6

    def propagate(
        self, position: np.ndarray, velocity: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Propagate position(s) ``(..., 3)`` m and velocity(ies) ``(..., 3)`` m/s by ``dt``."""
        p = np.asarray(position, dtype=np.float64)
        v = np.asarray(velocity, dtype=np.float64)
        s = np.concatenate([p, v], axis=-1) @ self.stm(dt).T
        return s[..., :3], s[..., 3:]

    def __repr__(self) -> str:
        return f"ClohessyWiltshire(n={self.n:.6g}, model={self.model!r})"
