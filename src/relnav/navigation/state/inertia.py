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
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from relnav.errors import InputError
from relnav.filtering.pose_filter import canon_q, quat_delta
from relnav.filtering.ukf import euler_rates, torque_free_acceleration
from relnav.geometry.dualquat import qmul

__all__ = ["InertiaFit", "fit_inertia", "rate_sweep_deg", "refine_inertia"]

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
    rows = []
    for a, b in _windows(t, window_s):
        # Euler's equations integrated over a window [a, b] (no derivative of noisy rates):
        # J (ω_b − ω_a) = ∫ (J ω) × ω dt, linear in J, the integral by the trapezoid rule
        A = np.empty((3, 6))
        for i, E in enumerate(_BASIS):
            torque = np.cross(w[a : b + 1] @ E, w[a : b + 1])
            A[:, i] = E @ (w[b] - w[a]) - trapezoid(torque, t[a : b + 1], axis=0)
        rows.append(A)
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
    return InertiaFit(J, _rate_miss(t, w, J, window_s), sweep)


def _windows(t: np.ndarray, window_s: float) -> list[tuple[int, int]]:
    """First and last indices ``(a, b)`` of the window of ``window_s`` s centred on each time of
    ``t`` (increasing), for the times with samples on both sides within it."""
    out = []
    for k in range(len(t)):
        a = int(np.searchsorted(t, t[k] - 0.5 * window_s))
        b = int(np.searchsorted(t, t[k] + 0.5 * window_s, side="right")) - 1
        if a < k < b:
            out.append((a, b))
    return out


def _rate_miss(t: np.ndarray, w: np.ndarray, J: np.ndarray, window_s: float) -> float:
    """RMS per axis of the mean angular acceleration (rad/s²) that the torque-free model with
    inertia ``J`` misses over windows of ``window_s`` s of the rates ``w`` ``(K, 3)``."""
    miss = []
    for a, b in _windows(t, window_s):
        w_dot = torque_free_acceleration(w[a : b + 1], J)
        miss.append((w[b] - w[a] - trapezoid(w_dot, t[a : b + 1], axis=0)) / (t[b] - t[a]))
    return float(np.sqrt(np.mean(np.square(miss)))) if miss else float("nan")


def _inertias(p: np.ndarray, V0: np.ndarray) -> np.ndarray:
    """Inertias ``(m, 3, 3)`` (det 1) of parameters ``p`` ``(m, ≥ 11)``: columns 6–8 turn the
    principal axes ``V0`` (rotation vector), columns 9–10 are two log principal moments."""
    R = Rotation.from_rotvec(p[:, 6:9]).as_matrix() @ V0
    m = np.exp(np.column_stack([p[:, 9], p[:, 10], -p[:, 9] - p[:, 10]]))
    return np.einsum("nij,nj,nkj->nik", R, m, R)


def _torque_free_attitudes(
    p: np.ndarray, t: np.ndarray, q0: np.ndarray, V0: np.ndarray
) -> np.ndarray:
    """Attitudes ``(m, K, 4)`` (xyzw) of torque-free motions at times ``t`` ``(K,)``, one per
    parameter row of ``p`` ``(m, 11)``: ``q0 ⊗ exp(p[:, :3])`` at ``t[0]``, body rate
    ``p[:, 3:6]`` (rad/s) and inertia :func:`_inertias`. Propagated as
    :class:`~relnav.filtering.ukf.TwistorUKF` does (Runge–Kutta steps of at most 1 s for the rate,
    the attitude by the mean of a step's first and last rates)."""
    J = _inertias(p, V0)
    q = qmul(np.broadcast_to(q0, (len(p), 4)), Rotation.from_rotvec(p[:, :3]).as_quat())
    w = p[:, 3:6].copy()
    out = np.empty((len(p), len(t), 4))
    out[:, 0] = q
    for k in range(1, len(t)):
        dt = float(t[k] - t[k - 1])
        x = euler_rates(w, J, dt)
        q = canon_q(qmul(q, quat_delta(0.5 * (w + x), dt)))
        w = x
        out[:, k] = q
    return out


def refine_inertia(
    fit: InertiaFit,
    times: np.ndarray,
    quats: np.ndarray,
    filtered: np.ndarray,
    rates: np.ndarray,
    *,
    window_s: float = 40.0,
) -> InertiaFit | None:
    """An inertia fit refined on the attitudes themselves (output error).

    **[interpretation]** :func:`fit_inertia` reads the shape from a filter's rates, which lag
    the truth and carry its constant-rate model; on a near-axisymmetric tumble the precession
    rate (and so the axial moment) comes out biased. Here the initial attitude, the initial
    rate and the inertia (its principal axes and two moment ratios, started from ``fit``) are
    the least-squares torque-free motion through the observed attitudes, with a robust loss
    (soft L1 at three robust σ of the observations).

    Parameters
    ----------
    fit : InertiaFit
        The rate fit to start from.
    times : (K,) float64
        Times, s (increasing).
    quats : (K, 4) float64
        Observed attitudes ``R_sensor_body`` (xyzw; NaN rows skipped).
    filtered, rates : (K, 4), (K, 3) float64
        A filter's attitudes (xyzw) and body rates (rad/s), those ``fit`` came from: the
        motion starts from their first row, the observations' robust σ is their spread about
        ``filtered`` and the refined fit's residual is its miss on ``rates`` (as in
        :func:`fit_inertia`).
    window_s : float
        The residual's window, s.

    Returns
    -------
    InertiaFit or None
        The refined fit, or None when fewer than 12 attitudes are observed, the filter's first
        row is not finite or the solution is not finite.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    Q = np.asarray(quats, dtype=np.float64)
    if Q.shape != (len(t), 4):
        raise InputError(f"quats must be ({len(t)}, 4), got {Q.shape}")
    ok = np.all(np.isfinite(Q), axis=1)
    if ok.sum() < 12:
        return None
    F = np.asarray(filtered, dtype=np.float64)
    w = np.asarray(rates, dtype=np.float64)
    if F.shape != Q.shape or w.shape != (len(t), 3):
        raise InputError(f"filtered and rates must be ({len(t)}, 4) and ({len(t)}, 3)")
    if not (np.all(np.isfinite(F[0])) and np.all(np.isfinite(w[0]))):
        return None  # no filter state to start the motion from
    lam, V0 = np.linalg.eigh(fit.inertia)
    s = np.log(lam) - np.mean(np.log(lam))
    p0 = np.r_[np.zeros(3), w[0], np.zeros(3), s[:2]]
    conj = np.array([-1.0, -1.0, -1.0, 1.0])

    def misfit(qp: np.ndarray) -> np.ndarray:  # (m, 3 n_obs), rad
        dq = canon_q(qmul(qp * conj, Q[ok][None]))
        return Rotation.from_quat(dq.reshape(-1, 4)).as_rotvec().reshape(len(qp), -1)

    def residuals(P: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            qp = _torque_free_attitudes(P, t, F[0], V0)[:, ok]
        bad = ~np.all(np.isfinite(qp), axis=(1, 2))
        qp[bad] = F[0]  # a diverging motion (a wild step): far from every observation
        r = misfit(qp)
        r[bad] = np.pi
        return r

    spread = misfit(F[ok][None])[0]
    scale = max(1.4826 * float(np.median(np.abs(spread[np.isfinite(spread)]))), 1e-6)
    steps = np.r_[[1e-5] * 3, np.maximum(1e-6 * np.abs(p0[3:6]), 1e-9), [1e-5] * 5]

    last: dict[str, np.ndarray] = {}  # least_squares asks for the Jacobian where fun just ran

    def fun(p: np.ndarray) -> np.ndarray:
        last["p"], last["r"] = p.copy(), residuals(p[None])[0] / scale
        return last["r"]

    def jac(p: np.ndarray) -> np.ndarray:
        if "p" in last and np.array_equal(last["p"], p):
            r0, r = last["r"], residuals(p + np.diag(steps)) / scale
        else:
            r = residuals(np.vstack([p, p + np.diag(steps)])) / scale
            r0, r = r[0], r[1:]
        return ((r - r0) / steps[:, None]).T

    # plain least squares from the rate fit (a robust loss from there converges slowly or
    # not at all), then a robust pass from its answer
    sol = least_squares(fun, p0, jac=jac, x_scale="jac")
    sol = least_squares(
        fun, sol.x, jac=jac, loss="soft_l1", f_scale=3.0, x_scale="jac", max_nfev=50
    )
    if not np.all(np.isfinite(sol.x)):
        return None
    J = _inertias(sol.x[None], V0)[0]
    J = J / float(np.prod(np.linalg.eigvalsh(J))) ** (1.0 / 3.0)
    good = np.all(np.isfinite(w), axis=1)
    return InertiaFit(J, _rate_miss(t[good], w[good], J, window_s), fit.sweep_deg)
