"""Global re-localisation of relnav's navigator against its own model (paper 1's pipeline).

When the navigator has lost the target, the constant-velocity prediction is no longer a usable
starting point for its local registration. The scan is then located on the map from scratch
with paper 1's descriptor pipeline, and the answer is checked by the navigator's own
registration before it is believed:

1. **Describe** the map (voxel means, target frame; voxelised at the first scan's spacing
   ``s₀`` and capped at ``reloc.max_map_points`` keypoints, the whole downsampled map kept as
   support) and the scan (sensor frame) with the same descriptor and the same support radius in
   metres (``reloc.radius`` × ``s₀``). The map's description is cached until the map changes
   (it does not while the navigator is lost).
2. **Match** every scan descriptor to its nearest map descriptor with paper 1's gate ``τ``
   (:func:`relnav.matching.nn.match_descriptors`).
3. **Select** a geometrically consistent set of matches (pairwise distances preserved within
   ``ε = reloc_epsilon`` × ``s₀``): the exact maximum clique of the consistency graph
   (``reloc.method="clique"``, :func:`max_clique`) or paper 1's geometric consistency grouping
   (``"gcc"``, every seed). The ``reloc.candidates`` largest disjoint sets each give a candidate
   pose by Kabsch.
4. **Verify** each candidate with the navigator's own robust registration, started at the
   candidate under the first frame's weak prior with a tight gate (``reloc.gate`` × ``s₀``). A
   candidate is accepted only if its overlap is at least ``solver.min_overlap``, its robust RMS is
   at most ``reloc.rms_ratio`` × the median RMS of the recent ``ok`` steps, its information is not
   degenerate, and it fits the scan better than the prediction does (more scan points within 3σ of
   the model, registered the same way from the prediction). The best accepted candidate wins unless
   the scan is **ambiguous** on the map (:meth:`Relocalizer._ambiguous`: quarter and half turns of
   it converge to another pose that fits as well; a near-symmetric target).

**When** (evidence only, :meth:`Relocalizer.check`): after ``reloc.lost_after`` consecutive frames
that were not ``ok`` (then every ``reloc.every`` frames while lost), and on a *suspect step*: an
``ok`` step whose robust RMS exceeds ``reloc.rms_ratio`` × the recent steps' median and that is
a jump (recovered under the weak prior, a χ² against the motion model above ``reloc.chi2``, or
a step while lost), or whose RMS exceeds ``reloc.suspect_ratio`` × that median whatever its χ²,
or whose overlap falls below ``reloc.overlap_ratio`` × the recent median (at least 0.99 on
every right step of the suite; 0.55–0.80 at kidnaps). **[interpretation, measured]** A kidnap
(frames missing, the target far from the prediction) is usually *not* a failed step: the
registration settles on a wrong pose that fits the scan 2–3× worse than the recent steps (χ²
sometimes small: the prior holds the pose), the map is corrupted, and every later step tracks
it without complaint. A suspect step that the relocaliser does not confirm is therefore
flagged ``failed`` (pose = prediction, map untouched), at most ``reloc.max_doubt`` times in a row
(then the navigator's own judgement stands again: a helical approach sees new surfaces whose
RMS stays above a stale median, and a frozen map would never catch up).

An accepted relocalisation returns an ``ok`` result with ``info["relocalised"] = True`` and a
message; :class:`~relnav.navigation.navigator.Navigator` resets its motion filter for it
(``reloc.velocity``), then updates it at the verified pose and inserts the scan into the map.
``timings["relocalise"]`` holds each attempt's time. On the navigation suite's 17 unmodified
sequences and the 4 held-out ones the relocaliser never triggers (same poses with it on and
off; ``benchmarks/nav/nav_relocalize.py --unmodified``).
"""

from __future__ import annotations

import logging
import math
import statistics
import time
from collections import deque
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.features import compute as compute_descriptors
from relnav.features import get_descriptor, voxel_downsample
from relnav.geometry.normals import estimate_normals
from relnav.geometry.rotations import rotvec_to_matrix
from relnav.geometry.se3 import kabsch
from relnav.matching.correspondences import Correspondences
from relnav.matching.gcc import consistency_bitset, geometric_consistency_grouping
from relnav.matching.nn import match_descriptors
from relnav.navigation.solver import median_range, rms_radius
from relnav.odometry.step_check import step_difference
from relnav.registration.result import RegistrationResult

if TYPE_CHECKING:
    from relnav.navigation.options import RelocOptions
    from relnav.navigation.solver import MapSolver

__all__ = ["DescribedCloud", "Relocalizer", "candidate_poses", "describe", "max_clique"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------- max clique
@njit(cache=True)
def _degeneracy_order(adj: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Vertices in smallest-last order (repeatedly remove a vertex of least remaining degree)."""
    n = adj.shape[0]
    deg = np.zeros(n, np.int64)
    for i in range(n):
        for j in range(n):
            if adj[i, j] and i != j:
                deg[i] += 1
    removed = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    for k in range(n):
        best, bd = -1, n + 1
        for i in range(n):
            if not removed[i] and deg[i] < bd:
                best, bd = i, deg[i]
        order[k] = best
        removed[best] = True
        for j in range(n):
            if adj[best, j] and not removed[j]:
                deg[j] -= 1
    return order


@njit(cache=True)
def _max_clique_kernel(
    adj: np.ndarray, max_nodes: int
) -> tuple[np.ndarray, bool]:  # pragma: no cover - numba
    """Largest clique of ``adj`` by branch and bound (explicit stack); ``exact`` is False when
    the search stopped after ``max_nodes`` expansions (the best clique found so far)."""
    n = adj.shape[0]
    best = np.empty(n, np.int64)
    best_size = 0
    if n == 0:
        return best[:0].copy(), True
    order = _degeneracy_order(adj)
    pos = np.empty(n, np.int64)
    for k in range(n):
        pos[order[k]] = k
    cand = np.empty((n + 1, n), np.int64)
    cnt = np.zeros(n + 1, np.int64)
    ptr = np.zeros(n + 1, np.int64)
    clique = np.empty(n + 1, np.int64)
    nodes = 0
    exact = True
    # each vertex with its neighbours later in the degeneracy order: every clique once
    for k in range(n - 1, -1, -1):
        v = order[k]
        m = 0
        for u in range(n):
            if u != v and adj[v, u] and pos[u] > k:
                cand[0, m] = u
                m += 1
        if m + 1 <= best_size:
            continue
        clique[0] = v
        if best_size < 1:
            best_size = 1
            best[0] = v
        cnt[0], ptr[0] = m, 0
        depth = 0
        while depth >= 0:
            if ptr[depth] >= cnt[depth] or depth + 1 + cnt[depth] - ptr[depth] <= best_size:
                depth -= 1
                continue
            u = cand[depth, ptr[depth]]
            ptr[depth] += 1
            clique[depth + 1] = u
            size = depth + 2
            if size > best_size:
                best_size = size
                best[:size] = clique[:size]
            mm = 0
            for j in range(ptr[depth], cnt[depth]):
                w = cand[depth, j]
                if adj[u, w]:
                    cand[depth + 1, mm] = w
                    mm += 1
            nodes += 1
            if nodes > max_nodes:
                exact = False
                return best[:best_size].copy(), exact
            if mm > 0 and size + mm > best_size:
                depth += 1
                cnt[depth], ptr[depth] = mm, 0
    return best[:best_size].copy(), exact


def max_clique(adjacency: np.ndarray, *, max_nodes: int = 200_000) -> tuple[np.ndarray, bool]:
    """Largest clique of an undirected graph (exact branch and bound, bounded effort).

    Parameters
    ----------
    adjacency : (n, n) bool
        Symmetric adjacency matrix (the diagonal is ignored).
    max_nodes : int
        Search-tree expansions at most; beyond, the best clique found so far is returned.

    Returns
    -------
    members : (m,) int64
        Vertices of the clique, ascending.
    exact : bool
        True when the search finished (``members`` is a maximum clique).

    Notes
    -----
    Vertices are visited in degeneracy (smallest-last) order and each search is restricted to a
    vertex's later neighbours, with the bound "clique size + candidates left ≤ best" (Carraghan
    and Pardalos 1990). Consistency graphs of descriptor matches are sparse, so the search is
    short.
    """
    A = np.ascontiguousarray(adjacency, dtype=np.bool_)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"adjacency must be square, got shape {A.shape}")
    members, exact = _max_clique_kernel(A, int(max_nodes))
    return np.sort(members), bool(exact)


def _adjacency(bits: np.ndarray, n: int) -> np.ndarray:
    """Boolean adjacency (diagonal cleared) from a packed consistency bitset."""
    b = np.unpackbits(bits.view(np.uint8), axis=1, bitorder="little")[:, :n].astype(bool)
    np.fill_diagonal(b, False)
    return b


# --------------------------------------------------------------------------------- description
@dataclass
class DescribedCloud:
    """A cloud with descriptors at some of its points.

    Attributes
    ----------
    points : (N, 3) float64
        The cloud (its own frame), m.
    keypoints : (K,) int64
        Indices of the described points.
    descriptors : (K, D) float32
        One row per keypoint (NaN rows invalid).
    """

    points: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray


def describe(
    points: np.ndarray,
    descriptor: str,
    radius: float,
    *,
    viewpoints: np.ndarray | None = None,
    max_keypoints: int | None = None,
    seed: int = 0,
) -> DescribedCloud:
    """Descriptors of a cloud at (a seeded random subset of) its points.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, m.
    descriptor : str
        Registered descriptor name (:func:`relnav.features.get_descriptor`).
    radius : float
        Support radius, m; normals (when the descriptor needs them) use ``radius / 2``.
    viewpoints : (V, 3) float64, optional
        Where the cloud was seen from: each normal is oriented towards its nearest viewpoint
        (the sensor origin when omitted, as for a scan in its own frame).
    max_keypoints : int, optional
        Describe at most this many points (seeded random subset); all when omitted.
    seed : int
        Seed of that subset.
    """
    P = np.ascontiguousarray(points, dtype=np.float64)
    spec = get_descriptor(descriptor)
    kp = np.arange(len(P), dtype=np.int64)
    if max_keypoints is not None and len(P) > max_keypoints:
        rng = np.random.default_rng(seed)
        kp = np.sort(rng.choice(len(P), int(max_keypoints), replace=False)).astype(np.int64)
    normals = None
    if spec.needs_normals:
        normals = estimate_normals(P, radius=0.5 * radius)
        if viewpoints is not None and len(viewpoints):
            _, j = cKDTree(viewpoints).query(P)
            flip = np.einsum("ij,ij->i", normals, viewpoints[j] - P) < 0
            normals[flip] *= -1.0
    D = compute_descriptors(spec.name, P, radius=radius, keypoints=kp, normals=normals)
    return DescribedCloud(P, kp, D)


def candidate_poses(
    scan: DescribedCloud,
    model: DescribedCloud,
    *,
    tau: float,
    epsilon: float,
    method: str = "clique",
    n_candidates: int = 3,
    min_size: int = 4,
) -> list[tuple[np.ndarray, int]]:
    """Candidate poses ``T_model_scan`` from descriptor matches and geometric consistency.

    Parameters
    ----------
    scan, model : DescribedCloud
        The scan (sensor frame) and the model (target frame), described alike.
    tau : float
        Descriptor-distance gate of the nearest-neighbour matching (paper 1: 1).
    epsilon : float
        Consistency tolerance on pairwise distances, m.
    method : {"clique", "gcc"}
        Maximum clique of the consistency graph, or paper 1's greedy grouping (every seed).
    n_candidates : int
        Disjoint consistent sets tried, largest first.
    min_size : int
        Smallest consistent set that gives a candidate.

    Returns
    -------
    list of (T (4, 4), support)
        Candidate poses with the size of their consistent set, largest first.
    """
    corr = match_descriptors(
        scan.descriptors,
        model.descriptors,
        tau=tau,
        src_keypoints=scan.keypoints,
        tgt_keypoints=model.keypoints,
    )
    out: list[tuple[np.ndarray, int]] = []
    alive = np.ones(len(corr), dtype=bool)
    for _ in range(int(n_candidates)):
        idx = np.flatnonzero(alive)
        if idx.size < min_size:
            break
        sub = corr.subset(idx)
        if method == "clique":
            bits = consistency_bitset(
                scan.points[sub.src_idx], model.points[sub.tgt_idx], epsilon=epsilon
            )
            members, _ = max_clique(_adjacency(bits, len(sub)))
        elif method == "gcc":
            best, _ = geometric_consistency_grouping(
                scan.points,
                model.points,
                sub,
                epsilon=epsilon,
                min_cluster_size=min_size - 1,
                seeds="all",
            )
            members = _members_of(sub, best)
        else:
            raise ValueError(f"unknown relocalisation method {method!r}")
        if members.size < min_size:
            break
        src = scan.points[sub.src_idx[members]]
        dst = model.points[sub.tgt_idx[members]]
        if len(np.unique(sub.src_idx[members])) >= 3:
            out.append((kabsch(src, dst), int(members.size)))
        alive[idx[members]] = False
    return out


def _distance(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (deg) between two poses."""
    angle, dist = step_difference(A, B)
    return dist, math.degrees(angle)


def _members_of(sub: Correspondences, chosen: Correspondences) -> np.ndarray:
    """Positions in ``sub`` of the correspondences in ``chosen`` (same pairs)."""
    key = sub.src_idx * (int(sub.tgt_idx.max(initial=0)) + 1) + sub.tgt_idx
    ck = chosen.src_idx * (int(sub.tgt_idx.max(initial=0)) + 1) + chosen.tgt_idx
    return np.flatnonzero(np.isin(key, ck))


# --------------------------------------------------------------------------------- relocaliser
class Relocalizer:
    """The navigator's loss detection and global re-localisation (see the module doc).

    Parameters
    ----------
    options : RelocOptions
        The navigator's ``reloc`` options.
    solver : MapSolver
        The navigator's registration onto its map (the map, ``s₀``, the weak prior and the
        solver's acceptance options: ``solver.min_points``, ``min_overlap``,
        ``min_degeneracy``).
    start_position : (3,) float64
        The sensor's start position, target frame, m: the viewpoint of the map's description
        before any step was accepted.
    """

    def __init__(self, options: RelocOptions, solver: MapSolver, start_position: np.ndarray):
        get_descriptor(options.descriptor)  # ConfigError now, not at the first loss
        self.options = options
        self.solver = solver
        self.start_position = np.array(start_position, dtype=float)
        self.lost = 0
        self._doubted = 0
        self._since_attempt = 0
        self._recent_rms: deque[float] = deque(maxlen=20)  # finite values only
        self._recent_overlap: deque[float] = deque(maxlen=20)
        self._views: list[np.ndarray] = []
        self._map_version = 0
        self._model: tuple[int, DescribedCloud] | None = None
        self.attempts = 0
        self.successes = 0

    # ------------------------------------------------------------------ the hook
    def map_changed(self) -> None:
        """The map was rebuilt (the start-up's refinement): describe it again when needed."""
        self._map_version += 1

    def check(
        self,
        P: np.ndarray,
        T_pred: np.ndarray,
        result: RegistrationResult,
        timings: dict,
        frame: int,
    ) -> RegistrationResult:
        """Judge frame ``frame``'s registration; relocalise when lost or on a suspect jump.

        Returns ``result`` unchanged, a relocalised ``ok`` result (``info["relocalised"]``:
        the navigator resets its motion filter before it takes it), or ``result`` flagged
        ``failed`` (a suspect jump the relocaliser did not confirm).
        """
        c = self.options
        info = result.info
        rms = float(info.get("robust_rms_sigma", float("nan")))
        ref = float(statistics.median(self._recent_rms)) if self._recent_rms else float("nan")
        jump = bool(info.get("recovered")) or info.get("chi2_motion", 0.0) > c.chi2 or self.lost > 0
        overlap = float(info.get("overlap", 1.0))
        ref_overlap = (
            float(statistics.median(self._recent_overlap)) if self._recent_overlap else 1.0
        )
        suspect = (
            result.status == "ok"
            and np.isfinite(ref)
            and self._doubted < c.max_doubt
            and (
                (jump and not rms <= c.rms_ratio * ref)
                or not rms <= c.suspect_ratio * ref
                or overlap < c.overlap_ratio * ref_overlap
            )
        )
        out = result
        if suspect or (result.status != "ok" and self.lost + 1 >= c.lost_after):
            due = suspect or self._since_attempt + 1 >= c.every
            if due:
                self._since_attempt = 0
                ts = time.perf_counter()
                found = self._relocalise(P, T_pred, ref, timings, frame)
                timings["relocalise"] = time.perf_counter() - ts
                if found is not None:
                    out = found
                elif suspect:
                    self._doubted += 1
                    out = replace(
                        result,
                        T_target_source=T_pred,
                        status="failed",
                        message=(
                            f"suspect step (robust RMS {rms:.2f}, overlap {overlap:.2f}; recent "
                            f"steps {ref:.2f}, {ref_overlap:.2f}), not confirmed by relocalisation"
                        ),
                    )
            else:
                self._since_attempt += 1
        if out.status == "ok":
            self.lost = 0
            self._doubted = 0
            self._since_attempt = 0
            self._map_version += 1
            r = float(out.info.get("robust_rms_sigma", float("nan")))
            if np.isfinite(r):
                self._recent_rms.append(r)
            self._recent_overlap.append(float(out.info.get("overlap", 1.0)))
            self._views.append(out.T_target_source[:3, 3].copy())
        else:
            self.lost += 1
        return out

    # ------------------------------------------------------------------ the work
    def _ambiguous(
        self, P: np.ndarray, best: dict[str, Any], gate: float, rng: float, radius: float
    ) -> dict[str, Any] | None:
        """Another pose that explains the scan as well as ``best`` does, or None.

        **[interpretation, measured]** A near-symmetric target (a box-shaped satellite seen
        through 30–70 points) fits a sparse scan as well at a quarter or half turn: the
        descriptor pipeline may find only the wrong one, and its fit is then as good as the
        recent steps'. The verified pose is therefore registered again from the scan's
        quarter, half and three-quarter turns about the map's principal axes (through its
        centroid) and about the scan's (through the scan's centroid): a start that converges
        at least 0.5 m or 5° away with a fitness at least ``1 − a`` times the best's and an RMS
        at most ``1 + a`` times its RMS (``a = reloc_ambiguity``) makes the relocalisation
        ambiguous, and it is not used. Measured on envisat-tumble-64 (50 points per scan): a
        quarter turn fitted with RMS 0.53, the half turn 0.60, the true pose 0.88 (σ units).
        """
        c, solver = self.options, self.solver
        T = best["T"]
        X = P @ T[:3, :3].T + T[:3, 3]
        M = self._model_description().points
        pivots = []
        for Y in (M, X):  # the target's own axes, then the scan's
            cen = Y.mean(0)
            _, _, Vt = np.linalg.svd(Y - cen, full_matrices=False)
            pivots += [(cen, axis) for axis in Vt]
        for cen, axis in pivots:
            for k in (1, 2, 3):
                R = rotvec_to_matrix(0.5 * math.pi * k * axis / np.linalg.norm(axis))
                G = np.eye(4)
                G[:3, :3] = R
                G[:3, 3] = cen - R @ cen
                T0 = G @ T
                fit = solver.solve(P, T0, solver.weak_prior(T0), gate, rng, radius, primary=False)
                if not fit["usable"] or not np.all(np.isfinite(fit["T"])):
                    continue
                dt, dr = _distance(fit["T"], T)
                if (
                    (dt > 0.5 or dr > 5.0)
                    and fit["fitness"] >= (1.0 - c.ambiguity) * best["fitness"]
                    and fit["rms"] <= (1.0 + c.ambiguity) * best["rms"]
                ):
                    return fit
        return None

    def _model_description(self) -> DescribedCloud:
        """The map's description (cached until the map changes)."""
        if self._model is not None and self._model[0] == self._map_version:
            return self._model[1]
        c, solver = self.options, self.solver
        assert solver.map is not None
        s0 = solver.spacing0
        M = voxel_downsample(solver.map.means, s0)
        views = np.array(self._views[-500:]) if self._views else None
        if views is None:
            views = self.start_position[None]
        model = describe(
            M,
            c.descriptor,
            c.radius * s0,
            viewpoints=views,
            max_keypoints=c.max_map_points,
            seed=self._map_version,
        )
        self._model = (self._map_version, model)
        return model

    def locate(
        self, P: np.ndarray, T_pred: np.ndarray, ref_rms: float | None = None, frame: int = 0
    ) -> tuple[dict[str, Any] | None, str]:
        """Locate the scan ``P`` (sensor frame) on the map; nothing in the navigator changes.

        Parameters
        ----------
        P : (N, 3) float64
            Scan points, sensor frame, m.
        T_pred : (4, 4) float64
            The motion model's prediction ``T_target_sensor`` (a candidate must fit better).
        ref_rms : float, optional
            Robust RMS of the recent ``ok`` steps (σ units); their median by default.
        frame : int
            The frame's index (the scan's description's seed, the log).

        Returns
        -------
        fit : dict or None
            The verified registration (``T``, ``H``, ``fitness``, ``rms``, ``overlap``, …, and
            ``support``: the consistent matches of its candidate), None when refused.
        why : str
            What happened (for the log and the step's message).
        """
        c, solver = self.options, self.solver
        if solver.map is None or len(P) < solver.config.solver.min_points:
            return None, "no map or too few points"
        if ref_rms is None:
            ref_rms = (
                float(statistics.median(self._recent_rms)) if self._recent_rms else float("nan")
            )
        s0 = solver.spacing0
        model = self._model_description()
        scan = describe(
            P,
            c.descriptor,
            c.radius * s0,
            max_keypoints=c.max_scan_points,
            seed=frame,
        )
        cands = candidate_poses(
            scan,
            model,
            tau=c.tau,
            epsilon=c.epsilon * s0,
            method=c.method,
            n_candidates=c.candidates,
            min_size=c.min_support,
        )
        if not cands:
            return None, "no consistent set of descriptor matches"
        rng = median_range(P)
        radius = max(rms_radius(P), s0)
        gate = max(c.gate * s0, 2.0 * solver.map.voxel_size)
        pred = solver.solve(P, T_pred, solver.weak_prior(T_pred), gate, rng, radius, primary=False)
        limit = c.rms_ratio * ref_rms if np.isfinite(ref_rms) else c.rms_ratio
        best: dict[str, Any] | None = None
        for T0, support in cands:
            fit = solver.solve(P, T0, solver.weak_prior(T0), gate, rng, radius, primary=False)
            ok = (
                fit["usable"]
                and np.all(np.isfinite(fit["T"]))
                and fit["overlap"] >= solver.config.solver.min_overlap
                and fit["cond"] >= solver.config.solver.min_degeneracy
                and fit["rms"] <= limit
                and fit["fitness"] > pred["fitness"]
            )
            log.debug(
                "frame %d: candidate of %d matches: overlap %.2f fitness %.2f rms %.2f (%s); "
                "prediction fitness %.2f",
                frame,
                support,
                fit["overlap"],
                fit["fitness"],
                fit["rms"],
                "verified" if ok else "refused",
                pred["fitness"],
            )
            if ok and (best is None or fit["fitness"] > best["fitness"]):
                best = {**fit, "support": support, "gate": gate, "n_candidates": len(cands)}
        if best is None:
            return None, f"none of {len(cands)} candidates verified"
        other = self._ambiguous(P, best, gate, rng, radius)
        if other is not None:
            dt, dr = _distance(other["T"], best["T"])
            return None, (
                f"ambiguous: a pose {dt:.2f} m / {dr:.1f}° away fits as well (fitness "
                f"{other['fitness']:.2f}, RMS {other['rms']:.2f} against {best['fitness']:.2f}, "
                f"{best['rms']:.2f})"
            )
        return best, "verified"

    def _relocalise(
        self, P: np.ndarray, T_pred: np.ndarray, ref_rms: float, timings: dict, frame: int
    ) -> RegistrationResult | None:
        """:meth:`locate`: an ``ok`` result at the verified pose, or None (the reason is
        logged)."""
        solver = self.solver
        self.attempts += 1
        best, why = self.locate(P, T_pred, ref_rms, frame)
        if best is None:
            log.info("frame %d: no relocalisation (%s)", frame, why)
            return None
        assert solver.map is not None
        gate = best["gate"]
        self.successes += 1
        T, H = best["T"], best["H"] / best["var_factor"]
        info = {
            "method": "relnav",
            "information": H,
            "iterations": best["iterations"],
            "overlap": best["overlap"],
            "chi2_motion": best["chi2"],
            "degeneracy": best["cond"],
            "gate": gate,
            "map_voxels": len(solver.map),
            "robust_rms_sigma": best["rms"],
            "variance_factor": best["var_factor"],
            "recovered": False,
            "relocalised": True,
            "reloc_support": best["support"],
            "reloc_candidates": best["n_candidates"],
        }
        jump, ang = _distance(T, T_pred)
        log.info(
            "frame %d: relocalised (%d consistent matches, fitness %.2f, %.2f m / %.1f° from "
            "the prediction)",
            frame,
            best["support"],
            best["fitness"],
            jump,
            ang,
        )
        message = (
            f"relocalised against the model ({best['support']} consistent matches, "
            f"{jump:.2f} m / {ang:.1f}° from the prediction)"
        )
        return solver.fit_result(best, T, H, solver.weak_prior(T), "ok", message, timings, info)
