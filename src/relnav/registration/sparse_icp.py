"""Sparse ICP (Bouaziz, Tagliasacchi & Pauly 2013), point-to-point and point-to-plane (§C.4).

Method strings: ``sicp-point``, ``sicp-plane`` (spec ``paper`` / ``scale``, see below).

Sparse ICP minimises ``Σ_i ‖R x_i + t − y_i‖₂^p`` (point-to-point) or
``Σ_i |n_i·(R x_i + t − y_i)|^p`` (point-to-plane) with ``0 < p ≤ 1`` by ADMM, following the
structure of OpenGP/sparseicp ``ICP.h`` (ALGORITHMS §C.4 pseudo-code): for each ICP iteration
the nearest neighbours ``y_i`` are fixed, then ``max_outer`` ADMM rounds of {``max_inner`` ×
(shrink ``z``, rigid fit), multiplier update ``λ += μ (X − y − z)``, ``μ ← α μ``} run until the
primal and dual residuals fall below ``stop``. The ℓp proximal step (``shrink``) uses
``B_a = (2(1−p)/μ)^{1/(2−p)}``, ``h_a = B_a + (p/μ) B_a^{p−1}``; ``z = 0`` when ``‖h‖ ≤ h_a``,
otherwise ``z = β h`` with ``shrink_iterations`` fixed-point steps
``β ← 1 − (p/μ)‖h‖^{p−2} β^{p−1}`` from ``β₀ = (B_a/‖h‖ + 1)/2``. The multipliers persist
across ICP iterations and ``μ`` restarts at ``mu`` each ICP iteration (as OpenGP). The rigid
fits are Arun/Umeyama SVD (point-to-point) and the linearised point-to-plane solve centred on
the source centroid with a Rodrigues rotation (ALGORITHMS §C.2), with the right-hand side
shifted by ``u = z − λ/μ``. The inner loops run in numba.

Defaults are paper 1's (Langlois' code): ``p = 0.5``, ``mu = 10``, ``max_icp = 20``; the rest
from OpenGP (``alpha = 1.2``, ``max_mu = 1e5``, ``max_outer = 100``, ``max_inner = 1``,
``stop = 1e-5``, 3 shrink iterations, PCA normals with k = 10).

**Scale [interpretation].** ``h_a`` and ``stop`` are lengths in the cloud's units, so the same
parameters behave differently on a 1 m and an 800 m target (with ``mu = 10, p = 0.5``,
residuals above ≈ 0.32 units are treated as outliers from the first round). With
``thresholds="scale"`` (default) both clouds are divided by the target's bounding-box diagonal
``L`` before the solve (translations are scaled back), i.e. the parameters are in units of
the target size; ``thresholds="paper"`` works in metres as paper 1 did (its targets were a
few metres across). With p < 1 and a far-off start every residual may shrink to ``z = h``
and the motion collapses to the identity — paper 1 observed exactly that (ALGORITHMS §C.4).

**Result fields.** Sparse ICP uses every nearest neighbour (no gate unless
``max_correspondence_distance`` is given): ``n_correspondences`` = pairs used at the final
estimate; ``n_inliers`` = pairs closer than ``inlier_distance`` (``inlier_factor·Tr`` =
3 Tr by default, paper mode 0.01 m); ``fitness = n_inliers / N_source``;
``inlier_rmse`` over those; ``covariance`` as :mod:`relnav.registration.icp` (left
perturbation ``[ρ, φ]`` in the target frame, from the inliers). ``converged`` is OpenGP's
``max|X − X_prev| < stop`` between ICP iterations. ``timings``: ``prepare`` (KD-tree,
resolution, normals), ``nn`` (nearest neighbours), ``solve`` (the ADMM rounds, numba),
``covariance``; ``info["n_rigid_fits"]`` counts the rigid fits.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Literal

import numpy as np
from numba import njit

from relnav.errors import ConfigError
from relnav.geometry.eigen import jacobi_eigh
from relnav.geometry.icp_kernels import horn_rotation, rodrigues_nb, transform_nb
from relnav.geometry.icp_solver import (
    PAPER_GATE,
    register_clouds,
    start_pair,
    with_normals,
)
from relnav.geometry.prepared_cloud import PreparedCloud, prepare_cloud
from relnav.registration.base import register_variants
from relnav.registration.icp import ICP, failed_result
from relnav.registration.result import RegistrationResult

__all__ = ["SparseICP", "shrink"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- numba kernels


@njit(cache=True)
def _shrink_scale(hn: float, mu: float, p: float, ba: float, ha: float, n_iter: int) -> float:
    """Scale ``β`` of the ℓp proximal step for a residual of norm ``hn`` (0 below ``h_a``)."""
    if hn <= ha:
        return 0.0
    beta = (ba / hn + 1.0) / 2.0
    k = (p / mu) * hn ** (p - 2.0)
    if p == 0.5:  # fast path of the default: β^(p−1) = 1/√β
        for _ in range(n_iter):
            if beta <= 0.0:
                return 0.0
            beta = 1.0 - k / math.sqrt(beta)
    elif p == 1.0:
        for _ in range(n_iter):
            beta = 1.0 - k
    else:
        for _ in range(n_iter):
            if beta <= 0.0:
                return 0.0
            beta = 1.0 - k * beta ** (p - 1.0)
    return max(beta, 0.0)


@njit(cache=True)
def _shrink_consts(mu: float, p: float) -> tuple[float, float]:
    ba = ((2.0 / mu) * (1.0 - p)) ** (1.0 / (2.0 - p))
    if ba > 0.0:
        ha = ba + (p / mu) * ba ** (p - 1.0)
    else:  # p == 1: soft thresholding at 1/mu
        ha = 1.0 / mu
    return ba, ha


@njit(cache=True)
def _apply(X: np.ndarray, R: np.ndarray, t: np.ndarray) -> None:
    for i in range(X.shape[0]):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        for a in range(3):
            X[i, a] = R[a, 0] * x0 + R[a, 1] * x1 + R[a, 2] * x2 + t[a]


@njit(cache=True)
def _max_step(X: np.ndarray, Xo: np.ndarray) -> float:
    """Largest point displacement ``max_i ‖X_i − Xo_i‖`` (m); then ``Xo ← X``."""
    dual = 0.0
    for i in range(X.shape[0]):
        d = 0.0
        for a in range(3):
            d += (X[i, a] - Xo[i, a]) ** 2
        dual = max(dual, math.sqrt(d))
    Xo[:, :] = X
    return dual


@njit(cache=True)
def _kabsch(X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``(R, t)`` with ``U ≈ R X + t`` (Horn's quaternion method)."""
    n = X.shape[0]
    mx = np.zeros(3)
    mu_ = np.zeros(3)
    for i in range(n):
        for a in range(3):
            mx[a] += X[i, a]
            mu_[a] += U[i, a]
    mx /= n
    mu_ /= n
    H = np.zeros((3, 3))
    for i in range(n):
        for a in range(3):
            xa = X[i, a] - mx[a]
            for b in range(3):
                H[a, b] += xa * (U[i, b] - mu_[b])
    R = horn_rotation(H)
    t = np.empty(3)
    for a in range(3):
        t[a] = mu_[a] - (R[a, 0] * mx[0] + R[a, 1] * mx[1] + R[a, 2] * mx[2])
    return R, t


@njit(cache=True)
def _compose_left(R: np.ndarray, t: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``[R t; 0 1] @ T`` for a 4x4 ``T`` (plain loops)."""
    out = np.eye(4)
    for a in range(3):
        for b in range(4):
            out[a, b] = R[a, 0] * T[0, b] + R[a, 1] * T[1, b] + R[a, 2] * T[2, b]
        out[a, 3] += t[a]
    return out


@njit(cache=True)
def _plane_fit(
    X: np.ndarray, Y: np.ndarray, N: np.ndarray, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """One linearised step of ``min Σ ((R x + t − y)·n − u)²`` centred on the mean of X."""
    n = X.shape[0]
    c = np.zeros(3)
    for i in range(n):
        for a in range(3):
            c[a] += X[i, a]
    c /= n
    A = np.zeros((6, 6))
    b = np.zeros(6)
    a6 = np.empty(6)
    for i in range(n):
        nx, ny, nz = N[i, 0], N[i, 1], N[i, 2]
        x0, x1, x2 = X[i, 0] - c[0], X[i, 1] - c[1], X[i, 2] - c[2]
        r = (X[i, 0] - Y[i, 0]) * nx + (X[i, 1] - Y[i, 1]) * ny + (X[i, 2] - Y[i, 2]) * nz - u[i]
        a6[0] = x1 * nz - x2 * ny
        a6[1] = x2 * nx - x0 * nz
        a6[2] = x0 * ny - x1 * nx
        a6[3] = nx
        a6[4] = ny
        a6[5] = nz
        for p in range(6):
            b[p] -= a6[p] * r
            for q in range(6):
                A[p, q] += a6[p] * a6[q]
    w, V = jacobi_eigh(A)
    ok = True
    x = np.zeros(6)
    wmax = w.max()
    if wmax <= 0.0:
        return np.eye(3), np.zeros(3), False
    for k in range(6):
        if w[k] > wmax * 1e-12:
            coef = 0.0
            for p in range(6):
                coef += V[p, k] * b[p]
            for p in range(6):
                x[p] += V[p, k] * coef / w[k]
        else:
            ok = False
    R = rodrigues_nb(x[:3])
    t = np.empty(3)
    for a in range(3):
        t[a] = c[a] + x[3 + a] - (R[a, 0] * c[0] + R[a, 1] * c[1] + R[a, 2] * c[2])
    return R, t, ok


@njit(cache=True)
def _admm_point(
    X: np.ndarray,
    Q: np.ndarray,
    C: np.ndarray,
    p: float,
    mu0: float,
    alpha: float,
    max_mu: float,
    max_outer: int,
    max_inner: int,
    stop: float,
    n_shrink: int,
    penalty: bool,
) -> tuple[np.ndarray, int]:
    """ADMM rounds of point-to-point Sparse ICP with fixed matches ``Q``; updates X, C in place.

    Returns the accumulated increment (4x4) and the number of rigid fits.
    """
    n = X.shape[0]
    Tacc = np.eye(4)
    Z = np.zeros((n, 3))
    U = np.empty((n, 3))
    Xo = X.copy()
    mu = mu0
    fits = 0
    for _outer in range(max_outer):
        dual = 0.0
        ba, ha = _shrink_consts(mu, p)
        for _inner in range(max_inner):
            for i in range(n):
                h0 = X[i, 0] - Q[i, 0] + C[i, 0] / mu
                h1 = X[i, 1] - Q[i, 1] + C[i, 1] / mu
                h2 = X[i, 2] - Q[i, 2] + C[i, 2] / mu
                s = _shrink_scale(math.sqrt(h0 * h0 + h1 * h1 + h2 * h2), mu, p, ba, ha, n_shrink)
                Z[i, 0], Z[i, 1], Z[i, 2] = s * h0, s * h1, s * h2
                for a in range(3):
                    U[i, a] = Q[i, a] + Z[i, a] - C[i, a] / mu
            R, t = _kabsch(X, U)
            _apply(X, R, t)
            fits += 1
            Tacc = _compose_left(R, t, Tacc)
            dual = _max_step(X, Xo)
            if dual < stop:
                break
        primal = 0.0
        for i in range(n):
            pn = 0.0
            for a in range(3):
                pa = X[i, a] - Q[i, a] - Z[i, a]
                if not penalty:
                    C[i, a] += mu * pa
                pn += pa * pa
            primal = max(primal, math.sqrt(pn))
        if mu < max_mu:
            mu *= alpha
        if primal < stop and dual < stop:
            break
    return Tacc, fits


@njit(cache=True)
def _admm_plane(
    X: np.ndarray,
    Q: np.ndarray,
    Nq: np.ndarray,
    C: np.ndarray,
    p: float,
    mu0: float,
    alpha: float,
    max_mu: float,
    max_outer: int,
    max_inner: int,
    stop: float,
    n_shrink: int,
    penalty: bool,
) -> tuple[np.ndarray, int, bool]:
    """ADMM rounds of point-to-plane Sparse ICP (scalar residuals); updates X, C in place."""
    n = X.shape[0]
    Tacc = np.eye(4)
    Z = np.zeros(n)
    u = np.empty(n)
    Xo = X.copy()
    mu = mu0
    fits = 0
    full_rank = True
    for _outer in range(max_outer):
        dual = 0.0
        ba, ha = _shrink_consts(mu, p)
        for _inner in range(max_inner):
            for i in range(n):
                r = (
                    (X[i, 0] - Q[i, 0]) * Nq[i, 0]
                    + (X[i, 1] - Q[i, 1]) * Nq[i, 1]
                    + (X[i, 2] - Q[i, 2]) * Nq[i, 2]
                )
                h = r + C[i] / mu
                Z[i] = _shrink_scale(abs(h), mu, p, ba, ha, n_shrink) * h
                u[i] = Z[i] - C[i] / mu
            R, t, ok = _plane_fit(X, Q, Nq, u)
            full_rank = full_rank and ok
            _apply(X, R, t)
            fits += 1
            Tacc = _compose_left(R, t, Tacc)
            dual = _max_step(X, Xo)
            if dual < stop:
                break
        primal = 0.0
        for i in range(n):
            r = (
                (X[i, 0] - Q[i, 0]) * Nq[i, 0]
                + (X[i, 1] - Q[i, 1]) * Nq[i, 1]
                + (X[i, 2] - Q[i, 2]) * Nq[i, 2]
            )
            pa = r - Z[i]
            if not penalty:
                C[i] += mu * pa
            primal = max(primal, abs(pa))
        if mu < max_mu:
            mu *= alpha
        if primal < stop and dual < stop:
            break
    return Tacc, fits, full_rank


def shrink(h: np.ndarray, mu: float, p: float, iterations: int = 3) -> np.ndarray:
    """ℓp proximal operator ``argmin_z ‖z‖^p + μ/2 ‖z − h‖²`` applied to each row of ``h``.

    Parameters
    ----------
    h : (N, D) or (N,) float64
        Rows (vectors) or scalars.
    mu : float
        ADMM penalty (> 0).
    p : float
        Norm exponent, ``0 < p ≤ 1``.
    iterations : int
        Fixed-point iterations on the scale ``β`` (OpenGP: 3).

    Returns
    -------
    ndarray
        ``z`` with the shape of ``h``.
    """
    h = np.asarray(h, dtype=np.float64)
    rows = h.reshape(h.shape[0], -1)
    ba, ha = _shrink_consts(float(mu), float(p))
    norms = np.linalg.norm(rows, axis=1)
    s = np.array([_shrink_scale(float(v), float(mu), float(p), ba, ha, iterations) for v in norms])
    return (rows * s[:, None]).reshape(h.shape)


# --------------------------------------------------------------------------- the method


class SparseICP:
    """Sparse ICP (ℓp, ADMM), point-to-point or point-to-plane; see the module docstring.

    Parameters
    ----------
    variant : {"point", "plane"}
        Residual type.
    p : float
        Norm exponent, ``0 < p ≤ 1`` (paper 1 / Langlois: 0.5).
    mu : float
        Initial ADMM penalty (10).
    alpha : float
        Penalty growth per ADMM round (1.2).
    max_mu : float
        Penalty cap (1e5).
    max_icp : int
        ICP (correspondence) iterations (paper 1: 20).
    max_outer, max_inner : int
        ADMM rounds per ICP iteration and rigid fits per round (100, 1).
    stop : float
        Primal/dual/ICP stop threshold, in normalised units (``thresholds="scale"``) or
        metres (``"paper"``).
    shrink_iterations : int
        Fixed-point iterations of the shrink operator (3).
    thresholds : {"scale", "paper"}
        Scale-aware normalisation (default) or paper 1's metres, see the module docstring.
    use_penalty : bool
        OpenGP's "penalty" mode: no multiplier update.
    max_correspondence_distance : float, optional
        Optional gate (m) on the nearest neighbours (Sparse ICP itself uses none).
    inlier_distance : float, optional
        Distance (m) defining ``n_inliers``/``fitness``; default ``inlier_factor·Tr``
        (scale) or 0.01 m (paper).
    inlier_factor : float
        See ``inlier_distance``.
    normal_k : int
        Neighbours of the target's PCA normals (point-to-plane).
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    """

    def __init__(
        self,
        variant: Literal["point", "plane"] = "point",
        *,
        p: float = 0.5,
        mu: float = 10.0,
        alpha: float = 1.2,
        max_mu: float = 1e5,
        max_icp: int = 20,
        max_outer: int = 100,
        max_inner: int = 1,
        stop: float = 1e-5,
        shrink_iterations: int = 3,
        thresholds: Literal["scale", "paper"] = "scale",
        use_penalty: bool = False,
        max_correspondence_distance: float | None = None,
        inlier_distance: float | None = None,
        inlier_factor: float = 3.0,
        normal_k: int = 10,
        min_points: int = 6,
    ) -> None:
        if variant not in ("point", "plane"):
            raise ConfigError(f"Sparse ICP variant must be 'point' or 'plane', got {variant!r}")
        if not (0.0 < float(p) <= 1.0):
            raise ConfigError(f"p must be in (0, 1], got {p}")
        if thresholds not in ("scale", "paper"):
            raise ConfigError(f"thresholds must be 'scale' or 'paper', got {thresholds!r}")
        for nm, v in (("mu", mu), ("alpha", alpha), ("max_mu", max_mu), ("stop", stop)):
            if not (float(v) > 0 and math.isfinite(float(v))):
                raise ConfigError(f"{nm} must be a positive number, got {v}")
        for nm, v in (("max_icp", max_icp), ("max_outer", max_outer), ("max_inner", max_inner)):
            if int(v) < 1:
                raise ConfigError(f"{nm} must be >= 1, got {v}")
        if max_correspondence_distance is not None and not float(max_correspondence_distance) > 0:
            raise ConfigError(
                f"max_correspondence_distance must be > 0, got {max_correspondence_distance}"
            )
        self.variant = variant
        self.p = float(p)
        self.mu = float(mu)
        self.alpha = float(alpha)
        self.max_mu = float(max_mu)
        self.max_icp = int(max_icp)
        self.max_outer = int(max_outer)
        self.max_inner = int(max_inner)
        self.stop = float(stop)
        self.shrink_iterations = int(shrink_iterations)
        self.thresholds = thresholds
        self.use_penalty = bool(use_penalty)
        self.max_correspondence_distance = (
            None if max_correspondence_distance is None else float(max_correspondence_distance)
        )
        self.inlier_distance = None if inlier_distance is None else float(inlier_distance)
        self.inlier_factor = float(inlier_factor)
        self.normal_k = int(normal_k)
        self.min_points = max(3, int(min_points))
        self.name = f"sicp-{variant}" + (":paper" if thresholds == "paper" else "")
        # covariance / degeneracy helper (same definitions as the ICP family)
        self._icp = ICP("plane" if variant == "plane" else "point", min_points=self.min_points)

    def prepare(
        self, points: np.ndarray, *, normals: np.ndarray | None = None, name: str = "cloud"
    ) -> PreparedCloud:
        """Validate a cloud, build its KD-tree, resolution and (point-to-plane) normals."""
        nm: Any = normals if normals is not None else ("pca" if self.variant == "plane" else "none")
        return prepare_cloud(
            points,
            min_points=self.min_points,
            normals=nm,
            normal_k=self.normal_k,
            resolution=self.thresholds == "scale" and self.inlier_distance is None,
            name=name,
        )

    def register(
        self,
        source: np.ndarray,
        target: np.ndarray,
        *,
        init: np.ndarray | None = None,
        target_normals: np.ndarray | None = None,
    ) -> RegistrationResult:
        """Register ``source`` onto ``target`` (``target ≈ T_target_source @ source``).

        ``target_normals`` (M, 3) replaces the PCA normals of point-to-plane.
        """
        return register_clouds(
            self,
            source,
            target,
            init=init,
            target_normals=target_normals,
            resolution=self.thresholds == "scale" and self.inlier_distance is None,
        )

    def register_prepared(
        self, source: PreparedCloud, target: PreparedCloud, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared clouds (see :meth:`prepare`); source timings are counted."""
        head = {"variant": self.variant, "thresholds": self.thresholds, "p": self.p}
        T0, timings, info, failed = start_pair(source, target, init, head, {"n_iterations": 0})
        if failed is not None:
            return failed
        assert target.tree is not None
        if self.variant == "plane":
            target = with_normals(target, min_points=self.min_points, normal_k=self.normal_k)
        # scale normalisation
        if self.thresholds == "scale":
            lo, hi = target.points.min(axis=0), target.points.max(axis=0)
            L = float(np.linalg.norm(hi - lo))
        else:
            L = 1.0
        if self.inlier_distance is not None:
            inlier_d = self.inlier_distance
        elif self.thresholds == "paper":
            inlier_d = PAPER_GATE
        else:
            tr = source.resolution
            if not np.isfinite(tr):
                tr = prepare_cloud(source.points, min_points=self.min_points).resolution
            inlier_d = self.inlier_factor * tr
        gate = self.max_correspondence_distance or math.inf
        info.update(scale=L, inlier_distance=inlier_d, gate=gate)

        Y = target.points
        Nn = target.normals
        X = transform_nb(source.points, T0)  # current transformed source, metres
        Xs = X / L
        n = X.shape[0]
        C = np.zeros((n, 3)) if self.variant == "point" else np.zeros(n)
        T = T0.copy()
        Xo2 = Xs.copy()
        t_nn = t_solve = 0.0
        converged = False
        full_rank = True
        fits = 0
        it = 0
        status, message = "ok", ""
        for it in range(1, self.max_icp + 1):
            tc = time.perf_counter()
            _, j, d = target.tree.nn(source.points, gate, T=T)
            sel = j >= 0
            if Nn is not None:
                sel[sel] = np.isfinite(Nn[j[sel], 0])
            t_nn += time.perf_counter() - tc
            if int(sel.sum()) < (6 if self.variant == "plane" else 3):
                status = "failed"
                message = f"ICP iteration {it}: {int(sel.sum())} usable nearest neighbours"
                it -= 1
                break
            tc = time.perf_counter()
            js = j[sel]
            Q = np.ascontiguousarray(Y[js] / L)
            Xsel = np.ascontiguousarray(Xs[sel])
            Csel = np.ascontiguousarray(C[sel])
            mu_max = self.max_mu
            if self.variant == "point":
                Tinc, nf = _admm_point(
                    Xsel,
                    Q,
                    Csel,
                    self.p,
                    self.mu,
                    self.alpha,
                    mu_max,
                    self.max_outer,
                    self.max_inner,
                    self.stop,
                    self.shrink_iterations,
                    self.use_penalty,
                )
                ok = True
            else:
                Tinc, nf, ok = _admm_plane(
                    Xsel,
                    Q,
                    np.ascontiguousarray(Nn[js]),
                    Csel,
                    self.p,
                    self.mu,
                    self.alpha,
                    mu_max,
                    self.max_outer,
                    self.max_inner,
                    self.stop,
                    self.shrink_iterations,
                    self.use_penalty,
                )
            C[sel] = Csel
            full_rank = full_rank and ok
            fits += nf
            # apply the increment (normalised units) to every source point
            Tm = Tinc.copy()
            Tm[:3, 3] *= L
            T = Tm @ T
            Xs = transform_nb(source.points, T) / L
            t_solve += time.perf_counter() - tc
            step = float(np.sqrt(((Xs - Xo2) ** 2).sum(axis=1)).max())
            Xo2 = Xs.copy()
            if step < self.stop:
                converged = True
                break
        info["n_iterations"] = int(it)
        info["n_rigid_fits"] = int(fits)
        timings["nn"] = t_nn
        timings["solve"] = t_solve
        if status != "ok":
            info["T_estimate"] = T
            return failed_result(status, message, T0, timings, info)
        tc = time.perf_counter()
        X, j, d = target.tree.nn(source.points, gate, T=T)
        used = j >= 0
        inl = used & (d <= inlier_d)
        if Nn is not None:
            inl[inl] = np.isfinite(Nn[j[inl], 0])
        si = np.flatnonzero(inl)
        ti = j[si].astype(np.int64)
        n_in = int(si.size)
        rmse = float(np.sqrt(np.mean(d[si] ** 2))) if n_in else float("nan")
        cov, ratio = self._icp._covariance(X, target, si, ti, source.radius)
        timings["covariance"] = time.perf_counter() - tc
        info["information_ratio"] = ratio
        info["T_estimate"] = T
        if not full_rank or (n_in >= 6 and not ratio > self._icp.degeneracy_ratio):
            status = "degenerate"
            message = f"{self.name}: geometry does not constrain 6 DoF (ratio {ratio:.3g})"
        return RegistrationResult(
            T_target_source=T if status == "ok" else T0.copy(),
            covariance=cov,
            fitness=n_in / n,
            inlier_rmse=rmse,
            n_correspondences=int(used.sum()),
            n_inliers=n_in,
            converged=converged,
            status=status,  # type: ignore[arg-type]
            timings=timings,
            message=message,
            info=info,
        )


register_variants(
    SparseICP,
    {
        "sicp-point": (
            "point",
            "Sparse ICP point-to-point (Bouaziz et al. 2013; ℓp ADMM, p=0.5, 20 iterations; "
            "paper 1)",
        ),
        "sicp-plane": (
            "plane",
            "Sparse ICP point-to-plane (Bouaziz et al. 2013; ℓp ADMM, p=0.5, 20 iterations; "
            "paper 1)",
        ),
    },
)
