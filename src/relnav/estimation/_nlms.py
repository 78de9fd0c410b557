"""Shared NLMS-type sweep of the coherent αβ filter and the SDRE estimator (options and a numba
kernel over the correspondence set).
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from relnav.errors import ConfigError
from relnav.estimation._kernels import _h_apply, _ht_apply

__all__ = [
    "nlms_options",
    "run_nlms",
]

log = logging.getLogger(__name__)


def nlms_options(
    name: str, paper_literal: bool, average: bool | None, normalise: str | None
) -> tuple[bool, str]:
    """Resolve the ``average`` and ``normalise`` options of the NLMS filters (αβ, SDRE).

    Defaults: the coherent reading averages the sweeps and normalises over the set;
    ``paper_literal`` keeps one sweep's last iterate and the per-sample normaliser.
    """
    avg = (not paper_literal) if average is None else bool(average)
    if normalise is None:
        normalise = "sample" if paper_literal else "set"
    if normalise not in ("set", "sample"):
        raise ConfigError(f"{name}: normalise must be 'set' or 'sample', got {normalise!r}")
    return avg, normalise


def run_nlms(
    x: np.ndarray,
    v: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    hs: np.ndarray,
    dt: float,
    n_passes: int,
    tol: float,
    average: bool,
    normalise: str,
) -> tuple[int, float]:
    """The NLMS-type sweeps of αβ and SDRE, in place on ``x`` (12,) and ``v`` (12,).

    ``normalise="sample"``: the per-sample NLMS step ``H_u⁺ e = H_uᵀ e / (hs_u² (‖a_u‖² + 1))``.
    ``"set"`` **[interpretation]**: the same update in coordinates whitened by the used points'
    scatter ``C = L Lᵀ`` (``ã = L⁻¹ a``, rotation block ``R̂ L``), with ONE normaliser for the
    whole set, ``max_u ‖ã_u‖² + 1``. Every update is still a contraction for ``α_u < 2``, but the
    sweeps' fixed point weights each match by its gain ``α_u`` only — the per-sample normaliser
    also weights it by ``1/(‖a_u‖² + 1)``, i.e. it discounts the points far from the centroid,
    which carry the rotation — and whitening makes every direction converge at the same rate.
    """
    if normalise == "sample" or A.shape[0] < 4:
        return _nlms_kernel(x, v, A, B, alpha, beta, hs, dt, n_passes, tol, average, 0.0)
    C = A.T @ A / A.shape[0]
    lam, V = np.linalg.eigh(C)
    if not lam[0] > 1e-12 * max(lam[-1], 1e-300):
        return _nlms_kernel(x, v, A, B, alpha, beta, hs, dt, n_passes, tol, average, 0.0)
    L = V * np.sqrt(lam)  # C = L Lᵀ
    Li = (V / np.sqrt(lam)).T  # L⁻¹
    Aw = np.ascontiguousarray(A @ Li.T)
    G = np.eye(12)  # x_w = G x : rotation rows R̂ → R̂ L
    Gi = np.eye(12)
    for i in range(3):
        G[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = L.T
        Gi[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = Li.T
    xw = G @ x
    vw = G @ v
    den = float((hs.max() ** 2) * ((Aw * Aw).sum(axis=1).max() + 1.0))
    passes, step = _nlms_kernel(xw, vw, Aw, B, alpha, beta, hs, dt, n_passes, tol, average, den)
    x[:] = Gi @ xw
    v[:] = Gi @ vw
    return passes, step


@njit(cache=True)
def _nlms_kernel(
    x: np.ndarray,
    v: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    hs: np.ndarray,
    dt: float,
    n_passes: int,
    tol: float,
    average: bool,
    den_set: float = 0.0,
) -> tuple[int, float]:
    """In place: ``x⁻ = x + dt v; r = H⁺(ψ − H x⁻); x = x⁻ + α_u r; v += (β_u/dt) r``.

    ``H = hs_u·[I₃ ⊗ aᵀ, I₃]`` so ``H⁺ = [I₃ ⊗ a, I₃]ᵀ / (hs_u (‖a‖² + 1))`` (minimum-norm
    state-space residual); ``den_set > 0`` replaces the per-sample normaliser
    ``hs_u² (‖a_u‖² + 1)`` by that constant. With ``average`` the sweep's output is the mean of
    its ``n`` iterates (the filter itself continues from its last iterate) and convergence is
    tested on that mean. Returns (passes run, 2-norm of the output's change over the last
    pass); ``x`` holds the output.
    """
    n = A.shape[0]
    hx = np.empty(3)
    e = np.empty(3)
    r = np.empty(12)
    xs = np.empty(12)
    xo = x.copy()
    xsum = np.empty(12)
    step = 0.0
    passes = 0
    for _p in range(n_passes):
        passes += 1
        xs[:] = xo
        xsum[:] = 0.0
        for u in range(n):
            a = A[u]
            h = hs[u]
            for k in range(12):
                x[k] += dt * v[k]
            _h_apply(x, a, h, hx)
            for i in range(3):
                e[i] = B[u, i] - hx[i]
            if den_set > 0.0:
                den = den_set
            else:
                den = h * h * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 1.0)
            _ht_apply(e, a, h, r)
            for k in range(12):
                r[k] /= den
                x[k] += alpha[u] * r[k]
                v[k] += beta[u] / dt * r[k]
                xsum[k] += x[k]
        for k in range(12):
            xo[k] = xsum[k] / n if average else x[k]
        step = 0.0
        for k in range(12):
            step += (xo[k] - xs[k]) ** 2
        step = np.sqrt(step)
        if step <= tol:
            break
    x[:] = xo
    return passes, step
