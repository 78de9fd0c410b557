"""Paper 1's adaptive H∞ filter over correspondences (eqs. 13–16; ALGORITHMS §D.2, §D.4).

Simon's (2006, ch. 11) H∞ filter with ``F = Φ = I``, ``S̄ = Q = dt·I₁₂`` and ``θ = g``, for each
correspondence ``u`` (ascending descriptor distance; ``H_u`` from the target point ``a_u`` of
``P_k``, measurement ``ψ_u = b_u`` of ``P_{k+1}``)::

    L = (I − θ S̄ P + H_uᵀ V_u⁻¹ H_u P)⁻¹
    K = P L H_uᵀ V_u⁻¹
    x = x + K (ψ_u − H_u x)
    P = P L + W

Implemented in the algebraically identical symmetric form ``Z = P⁻¹ − θ S̄ + H_uᵀ V_u⁻¹ H_u``,
``P L = Z⁻¹``, ``K = Z⁻¹ H_uᵀ V_u⁻¹``, ``P ← Z⁻¹ + W``. ``Z ≻ 0`` is Simon's existence
condition. It is checked at every step by a Cholesky factorisation of ``Z − θS̄`` , i.e. with a
safety margin equal to the H∞ term itself **[interpretation]**: the strict test lets ``P⁻¹`` in
not-yet-observed directions shrink by ``θ dt`` per step and, with a large ``p0``, drives ``P`` to
overflow within a few steps; with the margin ``λ_min(Z) > θ dt`` stays bounded away from zero.
When the test fails, ``θ`` is halved **for that step** until it holds (after 60 halvings θ = 0,
which always holds). A warning is logged once per estimate with the number of affected steps,
also reported in ``info["theta_halvings"]``. At Paper 1's values (``θ dt = 1e-6``, ``p₀ = 1``) it
never triggers.

``paper_literal=True`` uses the printed measurement matrix ``H = M·H_u`` (eq. 10) with
``V = M σ_v² I₃`` and, by default, ``M = 10·Σ d`` (eq. 11 as printed).

The filter's own output is ``T_source_target``; the single inversion to ``T_target_source`` is in
:mod:`relnav.estimation._recursive`.

Notes
-----
Why H∞ coincides with Kalman at Paper 1's values (issue 9; test
``test_hinf_coincides_with_kalman_at_paper_parameters``). The only differences from the Kalman
filter are ``−θ S̄ = −θ·dt·I`` in ``Z`` and ``W`` added after instead of before the update.
``P⁻¹ ⪰ I/p₀`` and only grows as matches are absorbed, so every gain changes by a relative
``≤ θ·dt·p₀ = 1e-6``: one sweep or converged, H∞ and Kalman agree to ~1e-6 in the state
(measured: 1.6e-7 one sweep, 8e-8 converged) and their T_error to the printed digits. The gap
is linear in ``θ·dt`` (×100 for ``dt = 1e-3``), and converged sweeps restarted from ``P = p₀I``
have the weighted least-squares fit as fixed point whatever ``θ``, so even ``θ·dt = 0.1`` moves
the converged rotation by only ~1e-4 rad. Paper 1's tables, where H∞ sits with αβ/SDRE and
Kalman differs (Sim-Voyager HoD-S 2.10 / 1.31 %), therefore cannot come from eqs. 13–16 at the
printed ``g = 0.1``, ``dt = 1e-5``; they need other, unprinted differences (e.g. different
``σ``'s or ``P₀`` for H∞, or a different ``Q``). We keep the printed filter and its own bound.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from numba import njit

from relnav.estimation._recursive import (
    RecursiveEstimator,
    _check_positive,
    _cholesky,
    _h_apply,
    _p_ht,
    _RunOutput,
    _spd_inverse,
)
from relnav.estimation.base import register_estimator

__all__ = ["HInfinityEstimator"]

log = logging.getLogger(__name__)

_MAX_HALVINGS = 60


@njit(cache=True)
def _hinf_kernel(
    x: np.ndarray,
    P: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    M: np.ndarray,
    sv2: float,
    sw2: float,
    c0: float,
    n_passes: int,
    tol: float,
    literal: bool,
    p0: float,
    reset: bool,
) -> tuple[bool, int, float, int, float]:
    """Run the H∞ updates in place on ``x`` (12,) and ``P`` (12, 12); ``c0 = θ·dt``.

    Returns (ok, passes run, last-pass state change, steps where θ had to be halved,
    smallest θ·dt used).
    """
    n = A.shape[0]
    L = np.zeros((12, 12))
    Pinv = np.empty((12, 12))
    Z = np.empty((12, 12))
    Zinv = np.empty((12, 12))
    Linv = np.empty((12, 12))
    K = np.empty((12, 3))
    hx = np.empty(3)
    xs = np.empty(12)
    vals = np.empty(4)
    idx = np.empty(4, dtype=np.int64)
    step = 0.0
    passes = 0
    n_halved = 0
    c_min = c0
    for _p in range(n_passes):
        passes += 1
        xs[:] = x
        if reset and _p > 0:
            for r in range(12):
                for q in range(12):
                    P[r, q] = 0.0
                P[r, r] = p0
        for u in range(n):
            a = A[u]
            hs = M[u] if literal else 1.0
            v = M[u] * sv2
            if not _spd_inverse(P, L, Pinv, Linv):
                return False, passes, step, n_halved, c_min
            c = c0
            halved = False
            z_ok = False
            for _h in range(_MAX_HALVINGS + 1):
                for r in range(12):
                    for q in range(12):
                        Z[r, q] = Pinv[r, q]
                    Z[r, r] -= c
                # + Hᵀ V⁻¹ H : row i of H touches columns 3i..3i+2 and 9+i
                for i in range(3):
                    idx[0] = 3 * i
                    idx[1] = 3 * i + 1
                    idx[2] = 3 * i + 2
                    idx[3] = 9 + i
                    vals[0] = hs * a[0]
                    vals[1] = hs * a[1]
                    vals[2] = hs * a[2]
                    vals[3] = hs
                    for p in range(4):
                        for q in range(4):
                            Z[idx[p], idx[q]] += vals[p] * vals[q] / v
                # existence test with margin: Z − c I ≻ 0 (⇒ Z ≻ 0 with λ_min(Z) > c)
                for r in range(12):
                    Z[r, r] -= c
                chol_ok = _cholesky(Z, L)
                for r in range(12):
                    Z[r, r] += c
                if chol_ok:
                    z_ok = True
                    break
                halved = True
                c = 0.5 * c if _h < _MAX_HALVINGS - 1 else 0.0
            if not z_ok:
                return False, passes, step, n_halved, c_min
            if halved:
                n_halved += 1
                if c < c_min:
                    c_min = c
            if not _spd_inverse(Z, L, Zinv, Linv):
                return False, passes, step, n_halved, c_min
            _p_ht(Zinv, a, hs, K)
            _h_apply(x, a, hs, hx)
            for i in range(3):
                hx[i] = (B[u, i] - hx[i]) / v
            for r in range(12):
                x[r] += K[r, 0] * hx[0] + K[r, 1] * hx[1] + K[r, 2] * hx[2]
            for r in range(12):
                for q in range(12):
                    P[r, q] = Zinv[r, q]
                P[r, r] += sw2
        step = 0.0
        for k in range(12):
            step += (x[k] - xs[k]) ** 2
        step = np.sqrt(step)
        if step <= tol:
            break
    return True, passes, step, n_halved, c_min


@register_estimator("hinf", "Paper 1 adaptive H-infinity filter over correspondences (§D.4)")
class HInfinityEstimator(RecursiveEstimator):
    """Adaptive H∞ filter of Paper 1 (coherent §D.4 by default).

    Parameters
    ----------
    theta : float
        H∞ performance bound ``θ`` (Paper 1's ``g``), default 0.1.
    dt : float
        ``S̄ = Q = dt·I₁₂``, default 1e-5 (Paper 1).
    sigma_v, sigma_w : float
        Noise scales as for Kalman (not given for H∞ in Paper 1; Kalman's 1 and 5e-3 reused,
        **[interpretation]**). ``V_u = M_u σ_v² I₃``, ``W = σ_w² I₁₂``.
    reset_covariance : bool, optional
        Restart every sweep after the first from ``P = p₀ I`` at the current state
        **[interpretation]**. Default True (coherent), False with ``paper_literal=True``.
        Carrying ``P`` over counts every correspondence again at each sweep, so the prior's
        weight only decays like 1/sweeps and the filter creeps towards the least-squares fit;
        restarting makes each sweep a regularised step from the current estimate (a proximal
        iteration) that converges geometrically to the same ``1/M_u``-weighted fit.
    p0 : float
        ``P₀ = p₀ I₁₂`` **[interpretation]**, default 1.
    **kwargs
        Common options of :class:`~relnav.estimation._recursive.RecursiveEstimator`
        (``covariance`` default ``"filter"``: ``P`` mapped to the twist of ``T_target_source``).
    """

    name = "hinf"
    _has_state_covariance = True
    _default_covariance = "filter"

    def __init__(
        self,
        *,
        theta: float = 0.1,
        dt: float = 1e-5,
        sigma_v: float = 1.0,
        sigma_w: float = 5e-3,
        p0: float = 1.0,
        reset_covariance: bool | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self.theta = _check_positive("theta", theta, allow_zero=True)
        self.dt = _check_positive("dt", dt, allow_zero=True)
        self.sigma_v = _check_positive("sigma_v", sigma_v)
        self.sigma_w = _check_positive("sigma_w", sigma_w, allow_zero=True)
        self.p0 = _check_positive("p0", p0)
        self.reset_covariance = (
            (not self.paper_literal) if reset_covariance is None else bool(reset_covariance)
        )

    def _options(self) -> dict[str, Any]:
        return {
            "theta": self.theta,
            "dt": self.dt,
            "sigma_v": self.sigma_v,
            "sigma_w": self.sigma_w,
            "p0": self.p0,
            "reset_covariance": self.reset_covariance,
        }

    def _run(self, x0: np.ndarray, a: np.ndarray, b: np.ndarray, m: np.ndarray) -> _RunOutput:
        x = x0.copy()
        P = self.p0 * np.eye(12)
        ok, passes, step, n_halved, c_min = _hinf_kernel(
            x,
            P,
            a,
            b,
            m,
            self.sigma_v**2,
            self.sigma_w**2,
            self.theta * self.dt,
            self.n_passes,
            self.tol,
            self.paper_literal,
            self.p0,
            self.reset_covariance,
        )
        if n_halved:
            theta_min = c_min / self.dt if self.dt > 0 else 0.0
            log.warning(
                "hinf: existence condition P⁻¹ − θS̄ + HᵀV⁻¹H > 0 failed at %d step(s); "
                "θ halved for those steps (smallest θ used: %.3g, requested %.3g)",
                n_halved,
                theta_min,
                self.theta,
            )
        if not ok:
            x[:] = np.nan
        info = {"theta_halvings": int(n_halved)}
        return _RunOutput(x=x, P=P, passes=passes, last_sweep_step=step, info=info)
