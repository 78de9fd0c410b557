"""Super4PCS-style global registration (Aiger et al. 2008; Mellado et al. 2014), ALGORITHMS §C.5.

Method string: ``s4pcs`` (spec ``paper`` / ``scale``, see below).

Registers the ``source`` cloud onto the ``target`` without an initial guess (``init`` is used
only when nothing is found):

1. **Sampling.** Both clouds are reduced to about ``sample_size`` (200) points by a voxel grid
   whose size is bisected to hit the count, one random point per voxel (as Super4PCS's
   uniform-distance sampler; seeded).
2. **Base.** In the target sample: of 1000 random triplets whose edges are shorter than
   ``overlap × diameter``, the one of largest area; then the fourth point closest to the
   triangle's plane such that the two base segments cross (line parameters in [0.1, 0.9]).
   Invariants: lengths ``d1, d2``, ratios ``r1, r2`` of the crossing point, and the angle
   between the segments.
3. **Congruent sets.** In the source sample (pairwise distance matrix): all ordered pairs with
   ``| |q_i − q_j| − d1 | ≤ δ`` (and ``d2``), their points ``e = q_i + r (q_j − q_i)``, and the
   pairs of pairs with ``|e1 − e2| ≤ δ`` (KD-tree range search). Super4PCS's filter by the angle
   between the two segments (tolerance ``2δ / min(d1, d2)`` rad) removes most false sets;
   **[interpretation]** the four cross distances must also match within ``2δ`` (a cheap
   rigidity check; Super4PCS's grid rasterisation of pair extraction is replaced by the exact
   distance matrix, which is faster at 200 points).
4. **Verification.** Kabsch transform of every congruent set (batched), rejected when the set
   does not fit within ``δ`` RMS; then the LCP score = fraction of source samples with a target
   sample within ``δ`` (numba, with early exit once the score cannot beat the best).
5. Bases are tried until ``max_bases`` (default from the overlap ``f``:
   ``max(4, ⌈log(1e-5) / log(1 − f⁴)⌉)``, 42 for ``f = 0.7``), the score reaches
   ``terminate_threshold`` or ``max_time`` seconds pass (off by default so results do not
   depend on the machine).

**Thresholds [interpretation].** Super4PCS's ``delta`` is absolute (its default 5.0 is in scene
units); paper 1 used ``δ = 0.01`` (m) and ``overlap = 0.7``. Default ``thresholds="scale"``:
``δ = delta_factor × s`` with ``s`` the mean nearest-neighbour distance of the *target sample*
(the spacing the congruent sets must tolerate between two independent samplings);
``"paper"``: ``δ = 0.01`` m. ``overlap`` defaults to paper 1's 0.7 (Super4PCS: 0.2).

**Refinement.** Paper 1 used the raw Super4PCS transform (``refine=None``, default). With
``refine="icp-point"`` (any registered method string) the estimate is refined on the full
clouds from the Super4PCS pose.

**Result fields.** ``fitness`` = fraction of (full) source points within ``δ`` of the target
after alignment (``= n_inliers / N``); ``inlier_rmse`` over them; ``n_correspondences =
n_inliers``; ``info["lcp"]`` = best sampled LCP score, ``info["n_bases"]``,
``info["n_candidates"]``, ``info["seed"]``. ``converged`` = a set scoring ≥
``terminate_threshold`` was found. No congruent set at all → ``failed``. ``timings``:
``prepare``, ``sample`` (sampling + distance matrices), ``base``, ``congruent``, ``verify``,
``refine`` (when used), ``evaluate``. The raw Super4PCS pose is ``info["T_s4pcs"]``.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Literal

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.geometry.icp_solver import start_pair
from relnav.registration.base import register_method
from relnav.registration.icp import (
    PAPER_GATE,
    PreparedCloud,
    failed_result,
    prepare_cloud,
    total_time,
)
from relnav.registration.result import RegistrationResult

__all__ = ["Super4PCS", "voxel_sample"]

log = logging.getLogger(__name__)

_SMALL_ERROR = 1e-5
_TRIANGLE_TRIALS = 1000


def voxel_sample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of about ``n`` points, one random point per voxel of a bisected voxel size.

    Returns all indices (shuffled) when the cloud has at most ``n`` points.
    """
    m = points.shape[0]
    if m <= n:
        return rng.permutation(m)
    perm = rng.permutation(m)
    P = points[perm]
    lo = P.min(axis=0)
    diag = float(np.linalg.norm(P.max(axis=0) - lo))
    a, b = 0.0, diag  # voxel size bracket: count(a) > n >= count(b)
    best = None
    for _ in range(30):
        v = 0.5 * (a + b)
        keys = np.floor((P - lo) / v).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        if first.size > n:
            a = v
        else:
            b = v
            best = first
            if first.size >= 0.95 * n:
                break
    if best is None:
        best = np.arange(min(n, m))
    return perm[np.sort(best)]


@njit(cache=True)
def _lcp_counts(
    Q: np.ndarray,
    Rs: np.ndarray,
    ts: np.ndarray,
    Px: np.ndarray,
    P: np.ndarray,
    delta: float,
    best0: int,
) -> np.ndarray:  # pragma: no cover - numba
    """For each transform, source samples with a target sample within ``delta``.

    ``P`` is sorted by x (``Px`` its x column) so each query scans a slab of width 2δ.
    Counting stops early once a transform cannot beat the best count so far (its count is
    then a lower bound, never above the best).
    """
    K = Rs.shape[0]
    m = Q.shape[0]
    d2 = delta * delta
    out = np.zeros(K, dtype=np.int64)
    best = best0
    for k in range(K):
        cnt = 0
        for i in range(m):
            if cnt + (m - i) <= best:
                break
            x0 = Rs[k, 0, 0] * Q[i, 0] + Rs[k, 0, 1] * Q[i, 1] + Rs[k, 0, 2] * Q[i, 2] + ts[k, 0]
            x1 = Rs[k, 1, 0] * Q[i, 0] + Rs[k, 1, 1] * Q[i, 1] + Rs[k, 1, 2] * Q[i, 2] + ts[k, 1]
            x2 = Rs[k, 2, 0] * Q[i, 0] + Rs[k, 2, 1] * Q[i, 1] + Rs[k, 2, 2] * Q[i, 2] + ts[k, 2]
            j = np.searchsorted(Px, x0 - delta)
            while j < Px.shape[0] and Px[j] <= x0 + delta:
                dx = P[j, 0] - x0
                dy = P[j, 1] - x1
                dz = P[j, 2] - x2
                if dx * dx + dy * dy + dz * dz <= d2:
                    cnt += 1
                    break
                j += 1
        out[k] = cnt
        if cnt > best:
            best = cnt
    return out


def _batch_kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigid transforms mapping ``src[k] (4, 3)`` onto ``dst (4, 3)``: ``(R (K,3,3), t, rms)``."""
    ms = src.mean(axis=1)
    md = dst.mean(axis=0)
    A = src - ms[:, None, :]
    B = dst - md
    H = np.einsum("kni,nj->kij", A, B)
    U, _s, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, 1, 2)
    Ut = np.swapaxes(U, 1, 2)
    det = np.linalg.det(V @ Ut)
    D = np.ones((src.shape[0], 3))
    D[:, 2] = np.where(det < 0, -1.0, 1.0)
    R = (V * D[:, None, :]) @ Ut
    t = md - np.einsum("kij,kj->ki", R, ms)
    res = np.einsum("kij,knj->kni", R, src) + t[:, None, :] - dst
    rms = np.sqrt((res**2).sum(axis=2).mean(axis=1))
    return R, t, rms


def _line_params(
    p1: np.ndarray, p2: np.ndarray, p3: np.ndarray, p4: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of lines ``p1p2``, ``p3p4``: parameters ``s, t`` and the gap (vectorised)."""
    u = p2 - p1
    v = p4 - p3
    w = p1 - p3
    a = np.einsum("...i,...i->...", u, u)
    b = np.einsum("...i,...i->...", u, v)
    c = np.einsum("...i,...i->...", v, v)
    d = np.einsum("...i,...i->...", u, w)
    e = np.einsum("...i,...i->...", v, w)
    den = a * c - b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (b * e - c * d) / den
        t = (a * e - b * d) / den
    gap = np.linalg.norm((p1 + s[..., None] * u) - (p3 + t[..., None] * v), axis=-1)
    bad = ~(den > 1e-12 * a * c)
    s = np.where(bad, np.nan, s)
    t = np.where(bad, np.nan, t)
    gap = np.where(bad, np.inf, gap)
    return s, t, gap


class Super4PCS:
    """Super4PCS-style global registration; see the module docstring.

    Parameters
    ----------
    overlap : float
        Estimated overlap ratio in (0, 1] (paper 1: 0.7).
    delta : float, optional
        Registration accuracy δ in metres (overrides ``thresholds``).
    delta_factor : float
        δ in multiples of the target sample's mean spacing (scale mode).
    thresholds : {"scale", "paper"}
        Scale-aware δ (default) or paper 1's 0.01 m.
    sample_size : int
        Points kept per cloud (Super4PCS: 200).
    max_bases : int, optional
        Bases to try (default from ``overlap``).
    max_time : float, optional
        Wall-clock limit in seconds (None: no limit; results then depend only on ``seed``).
    terminate_threshold : float
        Stop as soon as the LCP score reaches this value (Super4PCS: 1.0).
    max_candidates : int
        Congruent sets verified per base (random subset beyond that).
    refine : str, optional
        Registration method string run from the Super4PCS pose on the full clouds.
    seed : int
        Seed of the sampling and the base selection (recorded in ``info``).
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    """

    def __init__(
        self,
        *,
        overlap: float = 0.7,
        delta: float | None = None,
        delta_factor: float = 1.0,
        thresholds: Literal["scale", "paper"] = "scale",
        sample_size: int = 200,
        max_bases: int | None = None,
        max_time: float | None = None,
        terminate_threshold: float = 1.0,
        max_candidates: int = 2000,
        refine: str | None = None,
        seed: int = 0,
        min_points: int = 10,
    ) -> None:
        if not (0.0 < float(overlap) <= 1.0):
            raise ConfigError(f"overlap must be in (0, 1], got {overlap}")
        if thresholds not in ("scale", "paper"):
            raise ConfigError(f"thresholds must be 'scale' or 'paper', got {thresholds!r}")
        if delta is not None and not (float(delta) > 0 and math.isfinite(float(delta))):
            raise ConfigError(f"delta must be a positive number of metres, got {delta}")
        if not (float(delta_factor) > 0):
            raise ConfigError(f"delta_factor must be > 0, got {delta_factor}")
        if int(sample_size) < 4:
            raise ConfigError(f"sample_size must be >= 4, got {sample_size}")
        if max_bases is not None and int(max_bases) < 1:
            raise ConfigError(f"max_bases must be >= 1, got {max_bases}")
        if int(max_candidates) < 1:
            raise ConfigError(f"max_candidates must be >= 1, got {max_candidates}")
        self.overlap = float(overlap)
        self.delta = None if delta is None else float(delta)
        self.delta_factor = float(delta_factor)
        self.thresholds = thresholds
        self.sample_size = int(sample_size)
        if max_bases is None:
            est = math.log(_SMALL_ERROR) / math.log(1.0 - self.overlap**4) if overlap < 1 else 4
            max_bases = max(4, math.ceil(est))
        self.max_bases = int(max_bases)
        self.max_time = None if max_time is None else float(max_time)
        self.terminate_threshold = float(terminate_threshold)
        self.max_candidates = int(max_candidates)
        self.refine = refine
        self._refiner = None
        if refine:
            from relnav.registration.base import get_registration

            self._refiner = get_registration(refine)
        self.seed = int(seed)
        self.min_points = max(4, int(min_points))
        self.name = "s4pcs" + (":paper" if thresholds == "paper" else "")

    # ------------------------------------------------------------------ public API
    def prepare(self, points: np.ndarray, *, name: str = "cloud") -> PreparedCloud:
        """Validate a cloud and build its KD-tree (used for the final inlier statistics)."""
        return prepare_cloud(points, min_points=self.min_points, resolution=False, name=name)

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register ``source`` onto ``target`` globally (``target ≈ T_target_source @ source``).

        ``init`` is returned (with status ``failed``) when no congruent set is found.
        """
        src = self.prepare(source, name="source")
        tgt = self.prepare(target, name="target")
        result = self.register_prepared(src, tgt, init=init)
        result.timings["prepare"] = result.timings.get("prepare", 0.0) + total_time(tgt.timings)
        return result

    def register_prepared(
        self, source: PreparedCloud, target: PreparedCloud, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared clouds; source preparation time is counted."""
        head = {"seed": self.seed, "overlap": self.overlap}
        T0, timings, info, failed = start_pair(source, target, init, head)
        if failed is not None:
            return failed
        rng = np.random.default_rng(self.seed)
        tc = time.perf_counter()
        Ps = target.points[voxel_sample(target.points, self.sample_size, rng)]
        Qs = source.points[voxel_sample(source.points, self.sample_size, rng)]
        DP = np.linalg.norm(Ps[:, None, :] - Ps[None, :, :], axis=2)
        DQ = np.linalg.norm(Qs[:, None, :] - Qs[None, :, :], axis=2)
        if self.delta is not None:
            delta = self.delta
        elif self.thresholds == "paper":
            delta = PAPER_GATE
        else:
            DPn = DP + np.diag(np.full(DP.shape[0], np.inf))
            delta = self.delta_factor * float(DPn.min(axis=1).mean())
        diameter = float(DP.max())
        timings["sample"] = time.perf_counter() - tc
        info.update(delta=delta, n_sample_source=int(Qs.shape[0]), n_sample_target=int(Ps.shape[0]))
        order = np.argsort(Ps[:, 0], kind="stable")
        Psort = np.ascontiguousarray(Ps[order])
        Px = np.ascontiguousarray(Psort[:, 0])
        Qc = np.ascontiguousarray(Qs)
        m = Qs.shape[0]
        best_count = 0
        best_R, best_t, best_rms = None, None, math.inf
        n_cand_total = 0
        n_bases = 0
        t_base = t_cong = t_ver = 0.0
        t_start = time.perf_counter()
        for _b in range(self.max_bases):
            if self.max_time is not None and time.perf_counter() - t_start > self.max_time:
                break
            n_bases += 1
            tc = time.perf_counter()
            base = self._select_base(Ps, DP, self.overlap * diameter, rng)
            t_base += time.perf_counter() - tc
            if base is None:
                continue
            tc = time.perf_counter()
            quads = self._congruent(Qs, DQ, Ps, DP, base, delta, rng)
            t_cong += time.perf_counter() - tc
            if quads.shape[0] == 0:
                continue
            tc = time.perf_counter()
            R, t, rms = _batch_kabsch(Qs[quads], Ps[np.asarray(base)])
            ok = rms <= delta
            R, t, rms = R[ok], t[ok], rms[ok]
            n_cand_total += int(R.shape[0])
            if R.shape[0]:
                counts = _lcp_counts(
                    Qc,
                    np.ascontiguousarray(R),
                    np.ascontiguousarray(t),
                    Px,
                    Psort,
                    delta,
                    best_count,
                )
                k = int(np.argmax(counts))
                if counts[k] > best_count or (counts[k] == best_count and rms[k] < best_rms):
                    if counts[k] > 0:
                        best_count, best_R, best_t, best_rms = int(counts[k]), R[k], t[k], rms[k]
            t_ver += time.perf_counter() - tc
            if best_count / m >= self.terminate_threshold:
                break
        timings.update(base=t_base, congruent=t_cong, verify=t_ver)
        lcp = best_count / m
        info.update(n_bases=n_bases, n_candidates=n_cand_total, lcp=lcp)
        if best_R is None:
            return failed_result(
                "failed",
                f"no congruent 4-point set found in {n_bases} bases (δ = {delta:.4g} m)",
                T0,
                timings,
                info,
            )
        T = np.eye(4)
        T[:3, :3] = best_R
        T[:3, 3] = best_t
        info["T_s4pcs"] = T.copy()
        converged = lcp >= self.terminate_threshold
        if self._refiner is not None:
            tc = time.perf_counter()
            rr = self._refiner.register(source.points, target.points, init=T)
            timings["refine"] = time.perf_counter() - tc
            info["refine_status"] = rr.status
            if rr.ok:
                T = rr.T_target_source
        tc = time.perf_counter()
        assert target.tree is not None
        X, j, d = target.tree.nn(source.points, delta, T=T)
        inl = j >= 0
        n_in = int(inl.sum())
        rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if n_in else float("nan")
        timings["evaluate"] = time.perf_counter() - tc
        return RegistrationResult(
            T_target_source=T,
            covariance=None,
            fitness=n_in / X.shape[0],
            inlier_rmse=rmse,
            n_correspondences=n_in,
            n_inliers=n_in,
            converged=converged,
            status="ok",
            timings=timings,
            info=info,
        )

    # ------------------------------------------------------------------ 4PCS steps
    @staticmethod
    def _select_base(
        P: np.ndarray, D: np.ndarray, max_diam: float, rng: np.random.Generator
    ) -> tuple[int, int, int, int] | None:
        """A wide, nearly planar base ``(p1, p2, p3, p4)`` whose segments p1p2 and p3p4 cross.

        As Super4PCS: a random first point, the widest triangle of ``1000`` random pairs with
        it (edges ``≤ max_diam``), then the fourth point closest to the triangle's plane.
        """
        n = P.shape[0]
        if n < 4:
            return None
        for _attempt in range(10):
            ia = int(rng.integers(n))  # random first point, widest triangle from it
            bc = rng.integers(0, n, size=(_TRIANGLE_TRIALS, 2))
            b, c = bc[:, 0], bc[:, 1]
            area = 0.5 * np.linalg.norm(np.cross(P[b] - P[ia], P[c] - P[ia]), axis=1)
            valid = (
                (b != ia)
                & (c != ia)
                & (b != c)
                & (D[ia, b] <= max_diam)
                & (D[ia, c] <= max_diam)
                & (area > 0)
            )
            if not valid.any():
                continue
            k = int(np.argmax(np.where(valid, area, -1.0)))
            ib, ic = int(b[k]), int(c[k])
            pa, pb, pc = P[ia], P[ib], P[ic]
            nrm = np.cross(pb - pa, pc - pa)
            nrm /= np.linalg.norm(nrm)
            plane_d = np.abs((P - pa) @ nrm)
            cand = np.ones(n, dtype=bool)
            cand[[ia, ib, ic]] = False
            cand &= (D[ia] <= max_diam) & (D[ib] <= max_diam) & (D[ic] <= max_diam)
            if not cand.any():
                continue
            idx = np.flatnonzero(cand)
            pd = P[idx]
            min_len = 0.2 * float(max(D[ia, ib], D[ia, ic], D[ib, ic]))
            best = None
            best_score = math.inf
            # three pairings: (a,b | c,d), (a,c | b,d), (b,c | a,d)
            for p1, p2, p3 in ((ia, ib, ic), (ia, ic, ib), (ib, ic, ia)):
                s, t, gap = _line_params(
                    np.broadcast_to(P[p1], pd.shape),
                    np.broadcast_to(P[p2], pd.shape),
                    np.broadcast_to(P[p3], pd.shape),
                    pd,
                )
                ok = (
                    (s >= 0.1)
                    & (s <= 0.9)
                    & (t >= 0.1)
                    & (t <= 0.9)
                    & (np.linalg.norm(pd - P[p3], axis=1) >= min_len)
                )
                if not ok.any():
                    continue
                score = np.where(ok, plane_d[idx] + gap, math.inf)
                j = int(np.argmin(score))
                if score[j] < best_score:
                    best_score = float(score[j])
                    best = (p1, p2, p3, int(idx[j]))
            if best is not None:
                return best
        return None

    def _congruent(
        self,
        Q: np.ndarray,
        DQ: np.ndarray,
        P: np.ndarray,
        DP: np.ndarray,
        base: tuple[int, int, int, int],
        delta: float,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """Index quadruples ``(K, 4)`` of the source sample congruent to ``base``."""
        b1, b2, b3, b4 = base
        s, t, _ = _line_params(P[b1], P[b2], P[b3], P[b4])
        r1, r2 = float(s), float(t)
        d1, d2 = DP[b1, b2], DP[b3, b4]
        u = P[b2] - P[b1]
        v = P[b4] - P[b3]
        cos_b = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)))
        ang_b = math.acos(max(-1.0, min(1.0, cos_b)))
        ang_tol = 2.0 * delta / max(min(d1, d2), 1e-12)
        I1, J1 = np.nonzero(np.abs(DQ - d1) <= delta)
        I2, J2 = np.nonzero(np.abs(DQ - d2) <= delta)
        keep1 = I1 != J1
        keep2 = I2 != J2
        I1, J1, I2, J2 = I1[keep1], J1[keep1], I2[keep2], J2[keep2]
        if I1.size == 0 or I2.size == 0:
            return np.zeros((0, 4), dtype=np.int64)
        e1 = Q[I1] + r1 * (Q[J1] - Q[I1])
        e2 = Q[I2] + r2 * (Q[J2] - Q[I2])
        pairs = cKDTree(e1).sparse_distance_matrix(cKDTree(e2), delta, output_type="ndarray")
        if pairs.size == 0:
            return np.zeros((0, 4), dtype=np.int64)
        k1 = pairs["i"].astype(np.int64)
        k2 = pairs["j"].astype(np.int64)
        qi, qj, qk, ql = I1[k1], J1[k1], I2[k2], J2[k2]
        distinct = (qi != qk) & (qi != ql) & (qj != qk) & (qj != ql)
        uq = Q[qj] - Q[qi]
        vq = Q[ql] - Q[qk]
        cosq = np.einsum("ij,ij->i", uq, vq) / (
            np.linalg.norm(uq, axis=1) * np.linalg.norm(vq, axis=1)
        )
        angq = np.arccos(np.clip(cosq, -1.0, 1.0))
        ok = distinct & (np.abs(angq - ang_b) <= ang_tol)
        tol2 = 2.0 * delta
        ok &= np.abs(DQ[qi, qk] - DP[b1, b3]) <= tol2
        ok &= np.abs(DQ[qi, ql] - DP[b1, b4]) <= tol2
        ok &= np.abs(DQ[qj, qk] - DP[b2, b3]) <= tol2
        ok &= np.abs(DQ[qj, ql] - DP[b2, b4]) <= tol2
        quads = np.stack([qi[ok], qj[ok], qk[ok], ql[ok]], axis=1)
        if quads.shape[0] > self.max_candidates:
            quads = quads[rng.choice(quads.shape[0], self.max_candidates, replace=False)]
        return quads


@register_method(
    "s4pcs",
    "Super4PCS global registration (congruent 4-point sets, LCP; overlap 0.7; paper 1)",
    examples=["s4pcs", "s4pcs:paper"],
)
def _make_s4pcs(spec: str | None, **options: Any) -> Super4PCS:
    if spec:
        s = spec.strip().lower()
        if s not in ("paper", "scale"):
            raise ConfigError(f"s4pcs: spec must be 'paper' or 'scale', got {spec!r}")
        options = {**options, "thresholds": s}
    return Super4PCS(**options)
