"""A tumbling target's inertia, identified from its estimated body rates.

**Dynamics.** A rigid body free of torques obeys Euler's equations,

.. math::

    J \\dot\\omega = (J \\omega) \\times \\omega,
    \\qquad J (\\omega(t_b) - \\omega(t_a)) = \\int_{t_a}^{t_b} (J \\omega) \\times \\omega \\, dt,

``ω`` the body rate (rad/s, body axes) and ``J`` the inertia tensor in the same axes. The
integral form is linear in ``J``'s six entries and needs no derivative of noisy rates: windows
of a run of rates ``ω(t)`` give a homogeneous least-squares problem ``A j = 0`` whose solution
is the right singular vector of ``A`` with the smallest singular value (Aghili & Parsa,
*Motion and parameter estimation of space objects using laser-vision data*, JGCD 2009, use
Euler's equations in a filter instead). Only the inertia's *shape* is observable: ``J`` is
returned with a determinant of 1.

**When.** On a spin about a principal axis ``ω`` stays fixed in the body and ``J ω ∥ ω`` is all
the data say: the inertia is then neither identifiable nor needed (``ω̇ = 0``). The rate's
direction must sweep at least ``min_sweep_deg`` in the body for a fit **[interpretation]**.

References: ``docs/results/nav/state_hold_point.md`` (the tumbling sequences).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.integrate import trapezoid

from relnav.errors import InputError
from relnav.fusion.ukf import torque_free_acceleration

__all__ = ["InertiaFit", "fit_inertia", "rate_sweep_deg"]

log = logging.getLogger(__name__)

# J = Σ j_i E_i over fit_inertia's six unknowns J11, J22, J33, J12, J13, J23: (6, 3, 3)
_BASIS = np.zeros((6, 3, 3))
for _i, (_r, _c) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
    _BASIS[_i, _r, _c] = _BASIS[_i, _c, _r] = 1.0
del _i, _r, _c


@dataclass(frozen=True)
class InertiaFit:
    """An identified inertia.

    Attributes
    ----------
    inertia : (3, 3) float64
        ``J`` in the rates' axes, symmetric positive definite, ``det J = 1``.
    residual : float
        RMS per axis, over the fit's windows, of the mean angular acceleration the torque-free
        model misses, ``(ω_b − ω_a − ∫ J⁻¹((Jω) × ω) dt) / (t_b − t_a)``, rad/s² (with the
        rates' own noise).
    sweep_deg : float
        How far the rate's direction swept in the body (:func:`rate_sweep_deg`), deg.
    """

    inertia: np.ndarray
    residual: float
    sweep_deg: float

    @property
    def principal(self) -> np.ndarray:
        """Principal moments ``(3,)``, ascending (product 1)."""
        return np.linalg.eigvalsh(self.inertia)


def rate_sweep_deg(omega: np.ndarray) -> float:
    """Largest angle (deg) between a body rate of ``omega`` ``(K, 3)`` and their mean direction
    (NaN rows and zero rates ignored; 0 with fewer than two)."""
    w = np.asarray(omega, dtype=np.float64)
    n = np.linalg.norm(w, axis=1)
    ok = np.isfinite(n) & (n > 0.0)
    if ok.sum() < 2:
        return 0.0
    u = w[ok] / n[ok, None]
    m = u.mean(axis=0)
    if not np.linalg.norm(m) > 0.0:
        return 180.0
    m /= np.linalg.norm(m)
    return float(np.degrees(np.arccos(np.clip(u @ m, -1.0, 1.0))).max())


def fit_inertia(
    times: np.ndarray,
    omega: np.ndarray,
    *,
    window_s: float = 40.0,
    min_sweep_deg: float = 10.0,
) -> InertiaFit | None:
    """The inertia shape that makes ``omega(t)`` a torque-free motion.

    Parameters
    ----------
    times : (K,) float64
        Times, s (increasing).
    omega : (K, 3) float64
        Body rates, rad/s (e.g. a filter's estimates; NaN rows are skipped).
    window_s : float
        Span of each window of the integral form, s (default 40: a filter's rate is smooth
        over tens of seconds, not from frame to frame).
    min_sweep_deg : float
        Least sweep of the rate's direction in the body (:func:`rate_sweep_deg`) for a fit.

    Returns
    -------
    InertiaFit or None
        None when the rates do not reveal the inertia (a spin, too few rates, or no positive
        definite solution).

    Raises
    ------
    InputError
        Shapes that do not match, or a window that is not positive.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    w = np.asarray(omega, dtype=np.float64)
    if w.shape != (len(t), 3):
        raise InputError(f"omega must be ({len(t)}, 3), got {w.shape}")
    if not (np.isfinite(window_s) and window_s > 0.0):
        raise InputError(f"window_s must be > 0 s, got {window_s!r}")
    finite = np.all(np.isfinite(w), axis=1) & np.isfinite(t)
    t, w = t[finite], w[finite]
    sweep = rate_sweep_deg(w)
    if sweep < min_sweep_deg:
        log.debug("rate sweeps %.1f deg in the body: inertia not identifiable", sweep)
        return None
    rows, spans = [], []
    for k in range(len(t)):
        # Euler's equations integrated over a window [a, b] (no derivative of noisy rates):
        # J (ω_b − ω_a) = ∫ (J ω) × ω dt, linear in J, the integral by the trapezoid rule
        a = int(np.searchsorted(t, t[k] - 0.5 * window_s))
        b = int(np.searchsorted(t, t[k] + 0.5 * window_s, side="right")) - 1
        if a >= k or b <= k:
            continue
        A = np.empty((3, 6))
        for i, E in enumerate(_BASIS):
            torque = np.cross(w[a : b + 1] @ E, w[a : b + 1])
            A[:, i] = E @ (w[b] - w[a]) - trapezoid(torque, t[a : b + 1], axis=0)
        rows.append(A)
        spans.append((a, b))
    if len(rows) < 3:
        return None
    _, _, Vt = np.linalg.svd(np.vstack(rows))
    J = np.tensordot(Vt[-1], _BASIS, axes=1)
    if np.trace(J) < 0.0:
        J = -J
    lam = np.linalg.eigvalsh(J)
    if not lam.min() > 0.0:
        log.debug("inertia fit not positive definite (eigenvalues %s)", lam)
        return None
    J = J / float(np.prod(lam)) ** (1.0 / 3.0)
    miss = []
    for a, b in spans:  # the mean angular acceleration the model misses over each window
        w_dot = torque_free_acceleration(w[a : b + 1], J)
        drift = w[b] - w[a] - trapezoid(w_dot, t[a : b + 1], axis=0)
        miss.append(drift / (t[b] - t[a]))
    return InertiaFit(J, float(np.sqrt(np.mean(np.square(miss)))), sweep)
