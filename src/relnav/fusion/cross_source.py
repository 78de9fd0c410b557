"""Paper 2's cross-source registration: CGA point-to-sphere matching (ALGORITHMS §G.1–G.3).

Registers a sparse LIDAR cloud (paper 2's reference ``P``) with a dense depth-camera cloud
(paper 2's moving ``Q``). relnav's convention is kept: ``source = LIDAR``, ``target = camera``
and the result is ``T_target_source = T_camera_lidar`` (``p_camera = T @ p_lidar``). Internally
the motor is estimated in paper 2's direction (eq. 14: it moves the camera spheres onto the
LIDAR samples, ``M = T_lidar_camera``) and inverted at the end.

Algorithm (paper 2 §2.2.2 steps 1–5 with the readings of ALGORITHMS §G.2; every
**[interpretation]** is a keyword option):

1. **Centroids.** Both clouds are centred on their centroids ``P_c``, ``Q_c``.
2. **Farthest point sampling** of the LIDAR cloud *starting from the centroid*: the first
   sample is the point farthest from ``P_c``, each next one the point farthest from the centroid
   and all samples so far. The FPS order is the order in which samples are tried.
3. **Shell candidates.** For a sample ``p_l`` at ``ρ_l = ‖p_l − P_c‖`` the camera candidates
   are ``C_l = {q : |‖q − Q_c‖ − ρ_l| < τ}``. Paper 2 sets ``τ = T`` = mean point spacing of the
   camera cloud; **[interpretation]** ``τ = tol_factor·max(Tr_camera, Tr_lidar)``
   (``tol_factor = 2``) because the LIDAR's own spacing and noise dominate in practice
   (``tol`` fixes it in metres; ``tol_factor=1`` with a dense LIDAR is the paper's value).
4. **d⁴ check** (eq. 13) of each candidate against ``p_l`` and the already accepted pairs
   ``(p_j, c_j)``: distance to the centroid (step 3), pair distances ``|‖q − c_j‖ − ‖p_l − p_j‖|
   < τ``, cosines of the angle at the centroid ``|Δcos| ≤ cos_tol`` (**[interpretation]**
   absolute 0.1 — "10 %" of a cosine near 0 is meaningless) and areas of the triangles with two
   accepted points ``|ΔA| ≤ 0.1·A + ½τ·(longest side)`` (**[interpretation]**: 10 % plus the
   area change of moving one vertex by ``τ``); only the ``n_check`` (3) most recent accepted
   pairs are used.

   The very first samples have nothing to be checked against (any point of the shell passes), so
   **[interpretation: paper 2 is silent]** the correspondence of *seed pairs* of well separated
   early samples (``n_seed_pairs`` = 6 pairs among the first 12 FPS samples with the largest
   ``ρ_a ρ_b sin∠``, ``sin∠ > 0.3``) is searched exhaustively: every pair of
   shell candidates ``(q_a, q_b)`` passing the d⁴ test with the looser tolerance
   ``hyp_tol_factor·τ`` (2τ; on a ``τ``-voxel subsample of the camera cloud) gives a rotation
   hypothesis (TRIAD of the triangles ``(0, p_a, p_b)``,
   ``(0, q_a, q_b)``); hypotheses are scored by how many of the next ``n_score`` FPS samples land
   within ``3τ`` of a camera point, the best ``n_refine`` are rescored on ``4·n_score`` samples
   (``info["hypothesis_score"]``; ``info["rival_score"]`` is the best score of the hypotheses
   more than ``ambiguity_deg`` (30°) away from the winner — close scores mean a near-symmetric
   view, where the global search can pick a flipped solution: give ``init`` or
   ``max_rotation_deg`` when the sensors' mounting is known).
   The best hypothesis only *gates* the search: candidates for ``p_l`` are taken within
   ``gate_factor·τ`` (1.5τ) of its predicted position, then the d⁴ check above decides.
   ``max_rotation_deg`` (with ``init``'s rotation, identity by default) restricts the hypotheses
   when the sensors' relative attitude is roughly known; ``init`` alone skips the search.
5. **Feature sphere.** A sample is retained when at least 4 candidates pass; the 4 are chosen
   mutually farthest apart (FPS inside the candidate set, ALGORITHMS default;
   ``quad_select="consistent"`` first keeps the ``keep_frac`` of the candidates with the smallest
   d⁴ residual) and the sphere
   through them is fitted (:func:`relnav.geometry.cga.spheres_through_points`). Candidates lie
   on a small, locally almost flat patch of the surface, where a sphere through 4 noisy points is
   ill-conditioned (its centre lies far off the surface), so **[interpretation]** the 4 points
   count as coplanar — and the circle through the 3 spanning the largest triangle is used —
   when the 4th is closer than ``τ`` to the plane of the other three (``coplanar="tolerance"``;
   ``coplanar="relative"`` is ALGORITHMS' ``|det| < 1e-3·s³``). A sphere/circle whose centre is
   farther than ``max_centre_factor`` (2) × the spread of its 4 points from their mean is
   rejected. Sampling stops when ``m`` (15) samples are retained.
6. **Motor** (§G.3): ``M = argmax Σ wᵢ ⟨M Sᵢ M̃ Pᵢ⟩₀`` (Valkenburg–Dorst eigenproblem,
   :func:`relnav.geometry.cga.estimate_motor`), ``wᵢ = 1``: the least-squares motion of the
   sphere centres onto the LIDAR samples. ``refine`` (default 1) repeats steps 4–6 once with the
   estimated motion as the gate (**[interpretation]**: tightens the correspondences; 0 = paper).

Result: ``fitness`` = fraction of LIDAR points within ``3τ`` of a camera point after alignment,
``inlier_rmse`` = RMS of those nearest-neighbour distances (m), ``n_correspondences`` = samples
tried, ``n_inliers`` = samples retained (``m``), ``info`` holds the matched samples, sphere
centres/radii, circle flags, ``τ``, the hypothesis count, the sample RMSE and the seed.
Status: ``degenerate`` when a cloud is empty or smaller than ``m``, all (LIDAR) points are
coplanar within ``τ``, or fewer than ``min_retained`` (3) samples are retained (no overlap);
``failed`` when the final fitness is below ``min_fitness`` (0.2). Never raises on bad data.

References
----------
Li, Zhuang, Peng, Zhao, *Pose estimation of non-cooperative space targets based on cross-source
point cloud fusion*, Remote Sens. 13, 4239 (2021), doi:10.3390/rs13214239.
Valkenburg & Dorst, *Estimating motors from a variety of geometric data in 3D conformal
geometric algebra*, in Guide to Geometric Algebra in Practice, Springer (2011).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.geometry import cga
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import from_rt, invert
from relnav.registration.base import register_method
from relnav.registration.result import RegistrationResult

__all__ = [
    "CrossSourceRegistration",
    "SphereMatches",
    "cross_source_register",
    "fps_from_centroid",
    "motor_from_matches",
]

log = logging.getLogger(__name__)

Coplanar = Literal["tolerance", "relative"]


# --------------------------------------------------------------------------------------------
# farthest point sampling from the centroid
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _fps_centroid_kernel(P: np.ndarray, c: np.ndarray, n: int) -> np.ndarray:  # pragma: no cover
    N = P.shape[0]
    out = np.empty(n, dtype=np.int64)
    d = np.empty(N)
    for i in range(N):
        e0 = P[i, 0] - c[0]
        e1 = P[i, 1] - c[1]
        e2 = P[i, 2] - c[2]
        d[i] = e0 * e0 + e1 * e1 + e2 * e2
    for s in range(n):
        best = -1
        bestd = -1.0
        for i in range(N):
            if d[i] > bestd:
                bestd = d[i]
                best = i
        out[s] = best
        d[best] = -1.0
        b0 = P[best, 0]
        b1 = P[best, 1]
        b2 = P[best, 2]
        for i in range(N):
            if d[i] < 0.0:
                continue
            e0 = P[i, 0] - b0
            e1 = P[i, 1] - b1
            e2 = P[i, 2] - b2
            dd = e0 * e0 + e1 * e1 + e2 * e2
            if dd < d[i]:
                d[i] = dd
    return out


def fps_from_centroid(points: np.ndarray, n: int) -> np.ndarray:
    """Farthest point sampling seeded with the centroid: ``min(n, N)`` indices in order.

    The centroid acts as an already selected point, so the first index is the point farthest
    from the centroid (paper 2 §2.2.2 step 2). Deterministic (ties → lowest index).
    """
    P = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    n = int(min(max(n, 0), P.shape[0]))
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    return _fps_centroid_kernel(P, P.mean(axis=0), n)


# --------------------------------------------------------------------------------------------
# matches and motor
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SphereMatches:
    """Retained LIDAR samples and their camera feature spheres (original frames, metres).

    Attributes
    ----------
    lidar_points : (m, 3) float64
        Samples ``p_l`` (LIDAR frame).
    centres : (m, 3) float64
        Sphere/circle centres ``c_l`` (camera frame).
    radii : (m,) float64
        Sphere/circle radii (m).
    circle : (m,) bool
        A circle (coplanar quadruple) rather than a sphere.
    quads : (m, 4, 3) float64
        The 4 camera points of each sphere (camera frame).
    sample_index : (m,) int64
        Index of each sample in the LIDAR cloud.
    """

    lidar_points: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    circle: np.ndarray
    quads: np.ndarray
    sample_index: np.ndarray

    def __len__(self) -> int:
        return int(self.lidar_points.shape[0])


def motor_from_matches(
    matches: SphereMatches, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Motor moving the camera spheres onto the LIDAR samples (ALGORITHMS §G.3).

    Returns
    -------
    T_camera_lidar : (4, 4) float64
        Inverse of the motor's rigid motion (relnav's ``T_target_source``).
    motor : (8,) float64
        ``M = T_lidar_camera`` over :data:`relnav.geometry.cga.MOTOR_BASIS`.
    info : dict
        ``gap`` of the eigenproblem and ``sample_rmse`` = RMS ``‖M(c_l) − p_l‖`` (m).
    """
    S = cga.sphere_vectors(matches.centres, matches.radii)
    X = cga.up(matches.lidar_points)
    motor, info = cga.estimate_motor(S, X, weights)
    R, t = cga.motor_to_rt(motor)
    res = matches.centres @ R.T + t - matches.lidar_points
    rmse = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return invert(from_rt(R, t)), motor, {"gap": info["gap"], "sample_rmse": rmse}


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def _clean(points: Any, name: str) -> tuple[np.ndarray, int, str]:
    try:
        P = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        return np.zeros((0, 3)), 0, f"{name}: not a numeric array"
    if P.size == 0:
        return np.zeros((0, 3)), 0, ""
    if P.ndim != 2 or P.shape[1] != 3:
        return np.zeros((0, 3)), 0, f"{name}: expected shape (N, 3), got {P.shape}"
    ok = np.isfinite(P).all(axis=1)
    return np.ascontiguousarray(P[ok]), int((~ok).sum()), ""


def _triad(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(H, 3, 3)`` (columns) from vector pairs ``(H, 3)``."""
    a = u / np.linalg.norm(u, axis=-1, keepdims=True)
    n = np.cross(u, v)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    b = np.cross(n, a)
    return np.stack([a, b, n], axis=-1)


def _fps_small(X: np.ndarray, k: int) -> np.ndarray:
    """FPS of ``k`` rows of a small array, starting from the row farthest from the mean."""
    idx = [int(np.argmax(np.sum((X - X.mean(0)) ** 2, axis=1)))]
    d = np.sum((X - X[idx[0]]) ** 2, axis=1)
    for _ in range(k - 1):
        j = int(np.argmax(d))
        idx.append(j)
        d = np.minimum(d, np.sum((X - X[j]) ** 2, axis=1))
    return np.asarray(idx)


def _tri_area(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)


# --------------------------------------------------------------------------------------------
# the registration
# --------------------------------------------------------------------------------------------


class CrossSourceRegistration:
    """Paper 2's CGA point-to-sphere registration (see the module docstring).

    ``register(source=LIDAR, target=camera)`` returns ``T_camera_lidar``.

    Parameters
    ----------
    m : int
        Samples to retain (paper 2: 15; 10 faster/less accurate, 20 no gain).
    seed : int
        Seeds the random subsampling of over-large candidate sets (recorded in ``info``).
    tol : float, optional
        Matching tolerance ``τ`` in metres (overrides ``tol_factor``).
    tol_factor : float
        ``τ = tol_factor·max(Tr_camera, Tr_lidar)`` when ``tol`` is not given.
    cos_tol : float
        Absolute tolerance on the centroid-angle cosines of the d⁴ check.
    area_tol : float
        Relative tolerance on triangle areas of the d⁴ check.
    n_check : int
        Most recent accepted pairs each candidate is checked against.
    gate_factor : float
        Candidates are searched within ``gate_factor·τ`` of a sample's predicted position.
    coplanar : {"tolerance", "relative"}
        Coplanarity rule of the 4 sphere points (see module docstring).
    eta : float
        Relative coplanarity tolerance for ``coplanar="relative"``.
    max_centre_factor : float
        Reject spheres whose centre is farther than this × the 4 points' spread from their mean.
    max_samples : int, optional
        FPS samples tried at most (default ``max(200, 20·m)``).
    n_seed_pairs : int
        Seed pairs whose hypotheses are pooled.
    n_score, n_refine : int
        Samples scoring each hypothesis, hypotheses rescored on ``4·n_score`` samples.
    max_candidates : int
        Shell candidates per seed sample kept (random subset beyond; seeded).
    max_rotation_deg : float, optional
        Only hypotheses within this angle of the prior rotation (``init`` or identity).
    ambiguity_deg : float
        Rival hypotheses (``info["rival_score"]``) are at least this far from the winner.
    hyp_tol_factor : float
        Tolerance of the seed-pair d⁴ test in multiples of ``τ``.
    refine : int
        Extra matching passes gated by the current motor estimate.
    quad_select : {"farthest", "consistent"}
        How the 4 sphere points are picked among the candidates (module docstring, step 5).
    keep_frac : float
        Fraction of the candidates kept by ``quad_select="consistent"``.
    min_retained : int
        Fewer retained samples → ``degenerate``.
    min_fitness : float
        Final fitness below this → ``failed``.
    """

    name = "cga-sphere"

    def __init__(
        self,
        *,
        m: int = 15,
        seed: int = 0,
        tol: float | None = None,
        tol_factor: float = 2.0,
        cos_tol: float = 0.1,
        area_tol: float = 0.1,
        n_check: int = 3,
        gate_factor: float = 1.5,
        coplanar: Coplanar = "tolerance",
        eta: float = 1e-3,
        max_centre_factor: float = 2.0,
        max_samples: int | None = None,
        n_seed_pairs: int = 6,
        n_score: int = 12,
        n_refine: int = 10,
        max_candidates: int = 400,
        max_rotation_deg: float | None = None,
        ambiguity_deg: float = 30.0,
        hyp_tol_factor: float = 2.0,
        refine: int = 1,
        quad_select: Literal["farthest", "consistent"] = "farthest",
        keep_frac: float = 0.5,
        min_retained: int = 3,
        min_fitness: float = 0.2,
    ) -> None:
        if int(m) != m or m < 3:
            raise ConfigError(f"m must be an integer >= 3, got {m}")
        if tol is not None and not (float(tol) > 0 and math.isfinite(float(tol))):
            raise ConfigError(f"tol must be a positive number of metres, got {tol}")
        for nm, v in (
            ("tol_factor", tol_factor),
            ("cos_tol", cos_tol),
            ("gate_factor", gate_factor),
            ("eta", eta),
            ("max_centre_factor", max_centre_factor),
        ):
            if not (float(v) > 0 and math.isfinite(float(v))):
                raise ConfigError(f"{nm} must be a positive number, got {v}")
        if not 0 <= float(area_tol) < 1:
            raise ConfigError(f"area_tol must be in [0, 1), got {area_tol}")
        if coplanar not in ("tolerance", "relative"):
            raise ConfigError(f"coplanar must be 'tolerance' or 'relative', got {coplanar!r}")
        for nm, v in (
            ("n_check", n_check),
            ("n_seed_pairs", n_seed_pairs),
            ("n_score", n_score),
            ("n_refine", n_refine),
            ("max_candidates", max_candidates),
            ("min_retained", min_retained),
        ):
            if int(v) != v or v < 1:
                raise ConfigError(f"{nm} must be a positive integer, got {v}")
        if int(refine) != refine or refine < 0:
            raise ConfigError(f"refine must be a non-negative integer, got {refine}")
        if max_rotation_deg is not None and not float(max_rotation_deg) > 0:
            raise ConfigError(f"max_rotation_deg must be > 0, got {max_rotation_deg}")
        if not 0 <= float(min_fitness) <= 1:
            raise ConfigError(f"min_fitness must be in [0, 1], got {min_fitness}")
        self.m = int(m)
        self.seed = int(seed)
        self.tol = None if tol is None else float(tol)
        self.tol_factor = float(tol_factor)
        self.cos_tol = float(cos_tol)
        self.area_tol = float(area_tol)
        self.n_check = int(n_check)
        self.gate_factor = float(gate_factor)
        self.coplanar = coplanar
        self.eta = float(eta)
        self.max_centre_factor = float(max_centre_factor)
        self.max_samples = int(max_samples) if max_samples is not None else max(200, 20 * self.m)
        self.n_seed_pairs = int(n_seed_pairs)
        self.n_score = int(n_score)
        self.n_refine = int(n_refine)
        self.max_candidates = int(max_candidates)
        self.max_rotation_deg = None if max_rotation_deg is None else float(max_rotation_deg)
        self.refine = int(refine)
        if not 0 < float(ambiguity_deg) < 180:
            raise ConfigError(f"ambiguity_deg must be in (0, 180), got {ambiguity_deg}")
        self.ambiguity_deg = float(ambiguity_deg)
        if not float(hyp_tol_factor) >= 1:
            raise ConfigError(f"hyp_tol_factor must be >= 1, got {hyp_tol_factor}")
        self.hyp_tol_factor = float(hyp_tol_factor)
        if quad_select not in ("farthest", "consistent"):
            raise ConfigError(
                f"quad_select must be 'farthest' or 'consistent', got {quad_select!r}"
            )
        if not 0 < float(keep_frac) <= 1:
            raise ConfigError(f"keep_frac must be in (0, 1], got {keep_frac}")
        self.quad_select = quad_select
        self.keep_frac = float(keep_frac)
        self.min_retained = int(min_retained)
        self.min_fitness = float(min_fitness)

    def __repr__(self) -> str:
        return f"CrossSourceRegistration(m={self.m}, seed={self.seed}, tol={self.tol})"

    # ---------------------------------------------------------------------------------------

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register the LIDAR cloud ``source`` onto the camera cloud ``target``.

        Parameters
        ----------
        source : (N, 3) float64
            LIDAR points, LIDAR frame (m).
        target : (M, 3) float64
            Camera points, camera frame (m).
        init : (4, 4) float64, optional
            Prior ``T_camera_lidar``; its rotation replaces the hypothesis search (or, with
            ``max_rotation_deg``, centres the allowed rotations). Its translation is not used
            (the centroids fix the coarse translation).

        Returns
        -------
        RegistrationResult
            ``T_target_source = T_camera_lidar``; see the module docstring for the fields.
        """
        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        info: dict[str, Any] = {"seed": self.seed, "m": self.m}
        P, bad_p, msg_p = _clean(source, "source (LIDAR)")
        Q, bad_q, msg_q = _clean(target, "target (camera)")
        info.update(n_lidar=int(P.shape[0]), n_camera=int(Q.shape[0]))
        info.update(dropped_nonfinite_lidar=bad_p, dropped_nonfinite_camera=bad_q)

        def flagged(status: str, message: str) -> RegistrationResult:
            timings["total"] = time.perf_counter() - t_start
            log.info("cga-sphere: %s: %s", status, message)
            return RegistrationResult(
                T_target_source=np.eye(4),
                status=status,  # type: ignore[arg-type]
                message=message,
                timings=timings,
                info=info,
            )

        if msg_p or msg_q:
            return flagged("failed", msg_p or msg_q)
        R_prior: np.ndarray | None = None
        if init is not None:
            T0 = np.asarray(init, dtype=np.float64)
            if T0.shape != (4, 4) or not np.isfinite(T0).all():
                return flagged("failed", f"init must be a finite 4x4 matrix, got {T0.shape}")
            R_prior = T0[:3, :3]
        need = max(self.m, 4)
        if P.shape[0] < need or Q.shape[0] < need:
            return flagged(
                "degenerate",
                f"too few points: LIDAR {P.shape[0]}, camera {Q.shape[0]} (need >= m = {need})",
            )

        # 1. centroids, resolution, tolerance
        t0 = time.perf_counter()
        Pc, Qc = P.mean(axis=0), Q.mean(axis=0)
        P0, Q0 = P - Pc, Q - Qc
        tree_q = cKDTree(Q0)
        tr_q = mean_resolution(Q)
        tr_p = mean_resolution(P)
        if not (math.isfinite(tr_q) and math.isfinite(tr_p)):
            return flagged("degenerate", "a cloud has fewer than 2 distinct points")
        tau = self.tol if self.tol is not None else self.tol_factor * max(tr_q, tr_p)
        info.update(tau=tau, resolution_camera=tr_q, resolution_lidar=tr_p)
        for nm, C in (("LIDAR", P0), ("camera", Q0)):
            ev = np.linalg.eigvalsh(C.T @ C / C.shape[0])
            if math.sqrt(max(ev[0], 0.0)) < 0.25 * tau or ev[1] < (0.25 * tau) ** 2:
                return flagged(
                    "degenerate",
                    f"{nm} points are coplanar/collinear within the tolerance "
                    f"(thickness {math.sqrt(max(ev[0], 0.0)):.3g} m, tau {tau:.3g} m)",
                )
        timings["prepare"] = time.perf_counter() - t0

        # 2. FPS from the centroid
        t0 = time.perf_counter()
        order = fps_from_centroid(P, min(self.max_samples, P.shape[0]))
        timings["fps"] = time.perf_counter() - t0

        # 3.-4. rotation hypothesis (gate)
        t0 = time.perf_counter()
        rng = np.random.default_rng(self.seed)
        if R_prior is not None and self.max_rotation_deg is None:
            R_h = R_prior
            info["n_hypotheses"] = 0
        else:
            R_h, n_hyp, score, rival = self._hypothesis(P0[order], Q0, tree_q, tau, rng, R_prior)
            info["n_hypotheses"] = n_hyp
            info["hypothesis_score"] = score
            info["rival_score"] = rival
            if R_h is None:
                timings["hypotheses"] = time.perf_counter() - t0
                return flagged(
                    "degenerate",
                    "no consistent seed correspondence (no overlap, or tolerance too small)",
                )
        timings["hypotheses"] = time.perf_counter() - t0

        # 4.-6. d⁴ matching, feature spheres, motor
        t0 = time.perf_counter()
        t_h = np.zeros(3)  # centred-frame translation of the gate (camera0 = R lidar0 + t)
        matches, n_tried = self._match(P0, Q0, tree_q, order, R_h, t_h, tau, Pc, Qc)
        T = None
        motor = None
        minfo: dict[str, Any] = {}
        for _ in range(self.refine + 1):
            if len(matches) < self.min_retained:
                break
            T, motor, minfo = motor_from_matches(matches)
            if _ == self.refine:
                break
            # gate with the current estimate, in centred coordinates
            R_h = T[:3, :3]
            t_h = T[:3, 3] + R_h @ Pc - Qc
            matches, n_tried = self._match(P0, Q0, tree_q, order, R_h, t_h, tau, Pc, Qc)
        timings["match_estimate"] = time.perf_counter() - t0
        info.update(
            samples_tried=n_tried,
            retained=len(matches),
            n_circles=int(matches.circle.sum()) if len(matches) else 0,
            matches=matches,
        )
        if T is None or len(matches) < self.min_retained:
            return flagged(
                "degenerate",
                f"only {len(matches)} samples passed the d4 check (need >= {self.min_retained}):"
                " little or no overlap between the clouds",
            )
        info.update(motor=motor, **minfo)

        # result statistics
        t0 = time.perf_counter()
        Pt = P @ T[:3, :3].T + T[:3, 3]
        d, _ = cKDTree(Q).query(Pt, distance_upper_bound=3.0 * tau)
        inl = np.isfinite(d)
        fitness = float(inl.mean())
        rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("nan")
        timings["evaluate"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start
        status = "ok"
        message = ""
        if fitness < self.min_fitness:
            status = "failed"
            message = f"fitness {fitness:.3f} < min_fitness {self.min_fitness}"
        if len(matches) < self.m:
            message = (message + "; " if message else "") + (
                f"only {len(matches)} of m = {self.m} samples retained"
            )
        return RegistrationResult(
            T_target_source=T if status == "ok" else np.eye(4),
            fitness=fitness,
            inlier_rmse=rmse,
            n_correspondences=int(n_tried),
            n_inliers=len(matches),
            converged=status == "ok",
            status=status,  # type: ignore[arg-type]
            timings=timings,
            message=message,
            info=info if status == "ok" else {**info, "T_rejected": T},
        )

    # ---------------------------------------------------------------------------------------

    def _hypothesis(
        self,
        S: np.ndarray,
        Q0: np.ndarray,
        tree_q: cKDTree,
        tau: float,
        rng: np.random.Generator,
        R_prior: np.ndarray | None,
    ) -> tuple[np.ndarray | None, int, float, float]:
        """Best rotation ``camera0 ≈ R lidar0`` (centred), hypothesis count, score, rival score."""
        # camera candidates on a tau-voxel subsample (one point per voxel)
        keys = np.floor(Q0 / tau).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        Qv = Q0[np.sort(first)]
        rho_q = np.linalg.norm(Qv, axis=1)
        rho_s = np.linalg.norm(S, axis=1)
        k = min(12, S.shape[0])
        pairs = []
        for a in range(k):
            for b in range(a + 1, k):
                sin = np.linalg.norm(np.cross(S[a], S[b])) / max(rho_s[a] * rho_s[b], 1e-300)
                if sin > 0.3:
                    pairs.append((rho_s[a] * rho_s[b] * sin, a, b))
        pairs.sort(reverse=True)
        pairs = pairs[: self.n_seed_pairs]
        th = self.hyp_tol_factor * tau
        hyps = []
        for _, a, b in pairs:
            ca = np.flatnonzero(np.abs(rho_q - rho_s[a]) < th)
            cb = np.flatnonzero(np.abs(rho_q - rho_s[b]) < th)
            if ca.size == 0 or cb.size == 0:
                continue
            if ca.size > self.max_candidates:
                ca = rng.choice(ca, self.max_candidates, replace=False)
            if cb.size > self.max_candidates:
                cb = rng.choice(cb, self.max_candidates, replace=False)
            qa, qb = Qv[ca], Qv[cb]
            dab = np.linalg.norm(S[a] - S[b])
            cos_p = S[a] @ S[b] / (rho_s[a] * rho_s[b])
            D = np.linalg.norm(qa[:, None, :] - qb[None, :, :], axis=2)
            cos_q = (qa @ qb.T) / np.outer(np.linalg.norm(qa, axis=1), np.linalg.norm(qb, axis=1))
            area_p = 0.5 * np.linalg.norm(np.cross(S[a], S[b]))
            area_q = 0.5 * np.linalg.norm(np.cross(qa[:, None, :], qb[None, :, :]), axis=2)
            ok = (
                (np.abs(D - dab) < th)
                & (np.abs(cos_q - cos_p) <= self.cos_tol)
                & (np.abs(area_q - area_p) <= self.area_tol * area_p + 0.5 * th * dab)
            )
            ia, ib = np.nonzero(ok)
            if ia.size == 0:
                continue
            Fq = _triad(qa[ia], qb[ib])
            Fp = _triad(S[a][None], S[b][None])[0]
            hyps.append(Fq @ Fp.T)
        if not hyps:
            return None, 0, 0.0, -math.inf
        H = np.concatenate(hyps, axis=0)
        if R_prior is not None and self.max_rotation_deg is not None:
            ang = np.asarray(rotation_angle(np.einsum("ji,hjk->hik", R_prior, H)))
            H = H[ang <= math.radians(self.max_rotation_deg)]
            if H.shape[0] == 0:
                return None, 0, 0.0, -math.inf
        n_hyp = int(H.shape[0])

        def score(Hs: np.ndarray, pts: np.ndarray) -> np.ndarray:
            X = np.einsum("hij,nj->hni", Hs, pts).reshape(-1, 3)
            d, _ = tree_q.query(X, distance_upper_bound=3.0 * tau)
            d = np.minimum(d, 3.0 * tau).reshape(Hs.shape[0], -1)
            return np.sum(d < 3.0 * tau, axis=1) - d.mean(axis=1) / (3.0 * tau)

        s1 = score(H, S[: min(S.shape[0], self.n_score)])
        order = np.argsort(-s1, kind="stable")
        top = order[: self.n_refine]
        S2 = S[: min(S.shape[0], 4 * self.n_score)]
        s2 = score(H[top], S2)
        best = int(top[int(np.argmax(s2))])
        # best rival: the best-scoring hypotheses at least `ambiguity_deg` away from the winner
        ang = np.asarray(rotation_angle(np.einsum("ji,hjk->hik", H[best], H[order])))
        far = order[ang > math.radians(self.ambiguity_deg)][: self.n_refine]
        rival = float(np.max(score(H[far], S2))) if far.size else -math.inf
        return H[best], n_hyp, float(np.max(s2)), rival

    def _match(
        self,
        P0: np.ndarray,
        Q0: np.ndarray,
        tree_q: cKDTree,
        order: np.ndarray,
        R_h: np.ndarray,
        t_h: np.ndarray,
        tau: float,
        Pc: np.ndarray,
        Qc: np.ndarray,
    ) -> tuple[SphereMatches, int]:
        """d⁴-checked sequential matching of FPS samples to camera feature spheres."""
        acc_p: list[np.ndarray] = []  # accepted lidar samples (centred)
        acc_c: list[np.ndarray] = []  # their sphere centres (centred camera)
        out_c, out_r, out_circ, out_quad, out_idx = [], [], [], [], []
        qn = np.linalg.norm(Q0, axis=1)
        gate = self.gate_factor * tau
        n_tried = 0
        for i in order:
            if len(acc_p) >= self.m:
                break
            n_tried += 1
            p = P0[i]
            rho = float(np.linalg.norm(p))
            cand = np.asarray(tree_q.query_ball_point(R_h @ p + t_h, gate), dtype=np.int64)
            if cand.size < 4:
                continue
            shell = np.abs(qn[cand] - rho)
            keep = shell < tau  # shell: P_i·P_c
            cand, resid = cand[keep], shell[keep] / tau
            if cand.size >= 4 and acc_p:
                q = Q0[cand]
                Pj = np.asarray(acc_p[-self.n_check :])
                Cj = np.asarray(acc_c[-self.n_check :])
                # pair distances P_i·P_j
                dp = np.linalg.norm(Pj - p, axis=1)
                dq = np.linalg.norm(q[:, None, :] - Cj[None], axis=2)
                dres = np.abs(dq - dp)
                ok = np.all(dres < tau, axis=1)
                resid = resid + dres.mean(axis=1) / tau
                # centroid angles ∠P_i P_c
                if rho > 0:
                    cp = (Pj @ p) / np.maximum(np.linalg.norm(Pj, axis=1) * rho, 1e-300)
                    nq = np.maximum(np.linalg.norm(q, axis=1), 1e-300)
                    cq = (q @ Cj.T) / np.outer(nq, np.maximum(np.linalg.norm(Cj, axis=1), 1e-300))
                    ok &= np.all(np.abs(cq - cp) <= self.cos_tol, axis=1)
                # triangle areas ⌊P_i P_j P_k⌋
                for j in range(len(Pj)):
                    for k in range(j + 1, len(Pj)):
                        ap = float(_tri_area(p, Pj[j], Pj[k]))
                        side = max(dp[j], dp[k], float(np.linalg.norm(Pj[j] - Pj[k])))
                        aq = _tri_area(q, Cj[j][None], Cj[k][None])
                        ok &= np.abs(aq - ap) <= self.area_tol * ap + 0.5 * tau * side
                cand, resid = cand[ok], resid[ok]
            if cand.size < 4:
                continue
            if self.quad_select == "consistent" and cand.size > 8:
                best = np.argsort(resid, kind="stable")[: max(8, int(self.keep_frac * cand.size))]
                cand = cand[best]
            q = Q0[cand]
            quad = q[_fps_small(q, 4)]
            fit = self._sphere(quad, tau)
            if fit is None:
                continue
            c, r, circ = fit
            acc_p.append(p)
            acc_c.append(c)
            out_c.append(c + Qc)
            out_r.append(r)
            out_circ.append(circ)
            out_quad.append(quad + Qc)
            out_idx.append(int(i))
        n = len(acc_p)
        matches = SphereMatches(
            lidar_points=np.asarray(acc_p).reshape(n, 3) + Pc,
            centres=np.asarray(out_c).reshape(n, 3),
            radii=np.asarray(out_r, dtype=np.float64).reshape(n),
            circle=np.asarray(out_circ, dtype=bool).reshape(n),
            quads=np.asarray(out_quad).reshape(n, 4, 3),
            sample_index=np.asarray(out_idx, dtype=np.int64).reshape(n),
        )
        return matches, n_tried

    def _sphere(self, quad: np.ndarray, tau: float) -> tuple[np.ndarray, float, bool] | None:
        """Sphere (or circle) through 4 points with the coplanarity rule and centre check."""
        if self.coplanar == "tolerance":
            e = quad[1:] - quad[0]
            n = np.cross(e[0], e[1])
            nn = float(np.linalg.norm(n))
            flat = nn == 0.0 or abs(float(n @ e[2])) / nn < tau
            fit = cga.spheres_through_points(quad[None], eta=math.inf if flat else 0.0)
        else:
            fit = cga.spheres_through_points(quad[None], eta=self.eta)
        if not fit.valid[0]:
            return None
        c = fit.centres[0]
        mean = quad.mean(axis=0)
        spread = float(np.max(np.linalg.norm(quad - mean, axis=1)))
        if np.linalg.norm(c - mean) > self.max_centre_factor * max(spread, 1e-12):
            return None
        return c, float(fit.radii[0]), bool(fit.circle[0])


def cross_source_register(
    camera_pts: np.ndarray,
    lidar_pts: np.ndarray,
    *,
    m: int = 15,
    seed: int = 0,
    init: np.ndarray | None = None,
    **options: Any,
) -> RegistrationResult:
    """Register a LIDAR cloud onto a depth-camera cloud with paper 2's CGA method.

    Parameters
    ----------
    camera_pts : (M, 3) float64
        Dense camera points, camera frame (m) — the target.
    lidar_pts : (N, 3) float64
        Sparse LIDAR points, LIDAR frame (m) — the source.
    m : int
        Samples retained (paper 2: 15).
    seed : int
        Recorded in the result; seeds candidate subsampling.
    init : (4, 4) float64, optional
        Prior ``T_camera_lidar`` (rotation used as the gate).
    **options
        Further :class:`CrossSourceRegistration` options.

    Returns
    -------
    RegistrationResult
        ``T_target_source = T_camera_lidar``, ``inlier_rmse`` = RMSE (m).

    Examples
    --------
    >>> res = cross_source_register(camera_points, lidar_points, m=15, seed=0)  # doctest: +SKIP
    >>> fused = np.vstack([camera_points, transform_points(res.T_target_source, lidar_points)])
    """
    reg = CrossSourceRegistration(m=m, seed=seed, **options)
    return reg.register(lidar_pts, camera_pts, init=init)


@register_method(
    "cga-sphere",
    "Paper 2: CGA point-to-sphere cross-source registration (source = LIDAR, target = camera)",
    examples=["cga-sphere"],
)
def _make_cga_sphere(spec: str | None, **options: Any) -> CrossSourceRegistration:
    if spec:
        raise ConfigError(f"cga-sphere takes no spec, got {spec!r} (use options, e.g. m=15)")
    return CrossSourceRegistration(**options)
