"""Repeated surface points: when every scan samples the same points of the target.

A simulator that samples one model cloud of the target once and renders every scan from it
(paper 1's data generation: hidden point removal per pose, then range noise) gives scans whose
points are the *same surface points* from frame to frame. There the in-plane position of each
point is measured, and point-to-point registration onto the map's points is nearly exact, while
the navigator's point-to-plane solver (a weak in-plane pull, ``map.inplane_sigma``) lets the pose
slide along the surface. **[measured]** On sim-bennu the first step (no motion prior yet) slid
0.72 m, and the map kept the error: APE 0.82 m against KISS-ICP's 0.30 m.

Per frame (:class:`RepeatedPoints`, option ``solver.repeat_refine`` of the navigator):

1. **Same rays?** (:meth:`RepeatedPoints.observe_rays`) A sensor with a fixed ray pattern (a
   flash LIDAR's pixels, a scanner's beams) fires the same directions every frame; when it
   moves slowly its points nearly repeat in the target frame too, but they are new surface
   samples, and a point-to-point fit aliases towards "no motion". The rays repeat when at least
   ``RAY_FRACTION`` of the scan's directions lie within 1 % of the angular point spacing (``s₀``
   over the median range) of the previous scan's (measured on the suite: flash sequences
   0.42–1.0 per frame, paper 1's presets at most 0.03). Then nothing else is done.
2. **Refine** the point-to-plane answer point to point (:meth:`RepeatedPoints.refine`) with the
   whole scan (before the point budget ``map.max_points``: a repeated point is an exact constraint,
   so all of them are used; sim-eoi's 3 500-point scans: APE 0.032 → 0.014 m, 30 → 47 ms per
   frame): isotropic information ``I / σ²``, ``σ = repeat_refine · s₀``, on every map point,
   started at the point-to-plane answer (point to point from the prediction loses the capsule
   of sim-orion, APE 0.08 → 78.7 m: its first step settles at "no motion").
3. **Evidence** (:meth:`RepeatedPoints.evidence`): the fraction of the scan whose points lie on
   the ray of a point of the previous accepted scan (within ``σ`` across the ray, ``s₀`` along it).
   A LIDAR's noise is along its rays, so a surface point seen again lies on the same ray line up to
   the pose error; a fresh sample is that close across the ray with probability about ``π (σ/s₀)²``.
   The previous scan is taken whole, before the point budget, so that a random budget does not hide
   the repetition. The point-to-point answer is kept when the fraction is at least
   ``solver.repeat_fraction`` (measured: fresh samples 0.01–0.08, repeated points 0.63–1.0 per
   frame).
4. **Cost**: a second solve on frames whose rays do not repeat; after ``PATIENCE`` tested frames
   in a row without repetition, the test runs on every ``RETEST``-th frame only.

**[measured]** Suite APE (m), ``solver.repeat_refine`` 0 → 0.1 (``python benchmarks/nav/nav_suite.py
--out bench/nav --methods relnav``): sim-eoi 0.053 → 0.014, sim-helical 0.085 → 0.030, sim-voyager
0.048 → 0.036, sim-orion 0.542 → 0.076, sim-bennu 0.817 → 0.141; the other 12 sequences are
unchanged to the last digit (the flash sequences never try it, the ``-resample`` presets never keep
it). Without the ray test the flash sequences were lost (eros-ellipse-64 58 m). 0.1 is the only
``σ`` tried. A per-voxel variant (point-to-point information for map voxels whose points scatter
below ``voxel/√12``) was tried first: sim-orion 0.13–0.15 m but sim-bennu 1.14 m (the first step's
error is made before any voxel has repeated), and on sim-eoi the voxel (9 mm) is smaller than the
noise (1 cm), so repetition is invisible at that scale.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from relnav.geometry.kdtree import kd_build_select, kd_knn_within, kd_query
from relnav.navigation.gicp import ScanToMapFit
from relnav.navigation.options import SolverOptions
from relnav.navigation.voxel_map import VoxelMap, even_subset

Register = Callable[..., ScanToMapFit]
"""The solver's registration onto the map,
:meth:`relnav.navigation.solver.MapSolver.register_on_map`: ``(P, information, T0, T_pred, Lam,
gate, rng, from_means=...) → ScanToMapFit``."""

__all__ = ["PATIENCE", "RAY_FRACTION", "RETEST", "RepeatedPoints"]

RAY_FRACTION = 0.2
_EYE = np.eye(4)
PATIENCE = 3
RETEST = 10


@njit(cache=True)
def _on_previous_rays(
    X_prev: np.ndarray, X: np.ndarray, j: np.ndarray, origin: np.ndarray, sig2: float
) -> int:  # pragma: no cover - numba
    """How many points ``X`` (target frame) have one of their neighbours ``X_prev[j]``
    (``-1``: none) within ``√sig2`` (m) across the ray from ``origin`` through the point."""
    count = 0
    for i in range(len(X)):
        r0, r1, r2 = X[i, 0] - origin[0], X[i, 1] - origin[1], X[i, 2] - origin[2]
        nr = max(math.sqrt(r0 * r0 + r1 * r1 + r2 * r2), 1e-12)
        r0, r1, r2 = r0 / nr, r1 / nr, r2 / nr
        for k in range(j.shape[1]):
            if j[i, k] < 0:
                continue
            q = j[i, k]
            d0, d1, d2 = X_prev[q, 0] - X[i, 0], X_prev[q, 1] - X[i, 1], X_prev[q, 2] - X[i, 2]
            along = d0 * r0 + d1 * r1 + d2 * r2
            if d0 * d0 + d1 * d1 + d2 * d2 - along * along < sig2:
                count += 1
                break
    return count


class RepeatedPoints:
    """The navigator's test for repeated surface points and its point-to-point refinement.

    Parameters
    ----------
    options : SolverOptions
        The navigator's ``solver`` options (``repeat_refine``, ``repeat_fraction``,
        ``repeat_max_points``, ``min_points``).

    Attributes
    ----------
    full_scan : (N, 3) float64
        The frame's finite points before the point budget (sensor frame, m), :meth:`set_scan`.
    frame : int
        The frame's index, :meth:`set_scan`.
    """

    def __init__(self, options: SolverOptions) -> None:
        self.options = options
        self.full_scan = np.zeros((0, 3))
        self.frame = 0
        self.same_rays = False
        self.ray_fraction = float("nan")
        self.misses = 0  # tested frames in a row without repeated points
        self._rays: tuple[np.ndarray, ...] | None = None  # numba KD-tree of the directions
        self._cloud: tuple[np.ndarray, np.ndarray] | None = None
        self._tree: tuple[np.ndarray, ...] | None = None  # the previous scan, target frame
        self._iso: np.ndarray | None = None
        self._iso_sigma = 0.0

    def set_scan(self, P_full: np.ndarray, frame: int) -> None:
        """The frame being tracked: its finite points before the point budget (sensor frame,
        m) and its index."""
        self.full_scan, self.frame = P_full, int(frame)

    def observe_rays(self, P: np.ndarray, spacing0: float, ranges: np.ndarray, rng: float) -> bool:
        """Record the scan's directions (``P``: sensor frame, m; ``spacing0``: ``s₀``, m;
        ``ranges``: the points' ranges ``|P|`` (N,), m, and ``rng`` their median); whether they
        repeat the previous scan's (see the module doc). Sets :attr:`same_rays` and
        :attr:`ray_fraction`; nothing is done with ``solver.repeat_refine`` off."""
        if self.options.repeat_refine <= 0:
            return False
        u = P / np.maximum(ranges, 1e-12)[:, None]
        self.same_rays = False
        if self._rays is not None and len(P):
            eps = 0.01 * spacing0 / max(rng, 1e-12)
            _, j, _ = kd_query(*self._rays, u, _EYE, eps, False)
            self.ray_fraction = float(np.count_nonzero(j >= 0)) / len(P)
            self.same_rays = self.ray_fraction >= RAY_FRACTION
        self._rays = kd_build_select(np.ascontiguousarray(u), 16) if len(P) else None
        return self.same_rays

    def remember(self, P_full: np.ndarray, pose: np.ndarray) -> None:
        """Keep an accepted scan (all its finite points, sensor frame) and its pose
        ``T_target_sensor`` for the next frame's evidence."""
        self._cloud, self._tree = (P_full, pose.copy()), None

    def should_test(self, frame: int) -> bool:
        """Whether to refine this frame (``solver.repeat_refine`` on, rays not repeated, not resting
        after ``PATIENCE`` misses unless the frame is a ``RETEST``-th)."""
        if self.options.repeat_refine <= 0 or self.same_rays:
            return False
        return self.misses < PATIENCE or frame % RETEST == 0

    def apply(
        self,
        P: np.ndarray,
        fit: ScanToMapFit,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        primary: bool,
        voxel_map: VoxelMap,
        spacing0: float,
        register: Register,
    ) -> tuple[ScanToMapFit, float, bool]:
        """The navigator's hook: refine the point-to-plane registration ``fit`` when this
        frame is tested (:meth:`should_test`) and keep the point-to-point answer if the
        evidence reaches ``solver.repeat_fraction``.

        Parameters
        ----------
        P, T_pred, Lam, gate, rng :
            As in :meth:`refine`.
        fit : ScanToMapFit
            The point-to-plane registration.
        primary : bool
            The frame's first registration (under the motion model's prior): only these
            count towards ``PATIENCE``.
        voxel_map, spacing0, register :
            The map registered onto, ``s₀`` (m) and the solver's registration onto it.

        Returns
        -------
        fit : ScanToMapFit
            The registration kept.
        fraction : float
            The evidence (NaN when not tested).
        repeated : bool
            Whether the point-to-point answer was kept.
        """
        c = self.options
        if not self.should_test(self.frame) or fit.n_pairs < c.min_points:
            return fit, float("nan"), False
        full = self.full_scan  # repeated points are exact constraints: use them all,
        if c.repeat_max_points > 0:  # up to a cap (an even subset keeps exact repeats)
            full = even_subset(full, c.repeat_max_points)
        trial, frac = self.refine(
            full if len(full) > len(P) else P,
            fit.T,
            T_pred,
            Lam,
            gate,
            rng,
            voxel_map,
            spacing0,
            register,
        )
        repeated = frac >= c.repeat_fraction
        if primary:
            self.misses = 0 if repeated else self.misses + 1
        return (trial if repeated else fit), frac, repeated

    def refine(
        self,
        P: np.ndarray,
        T0: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        voxel_map: VoxelMap,
        spacing0: float,
        register: Register,
    ) -> tuple[ScanToMapFit, float]:
        """Point-to-point registration of ``P`` (sensor frame) onto the map from ``T0``, under
        the prior ``(T_pred, Lam)``; and the evidence (:meth:`evidence`) at its answer.

        Parameters
        ----------
        P : (N, 3) float64
            Scan points, sensor frame, m.
        T0, T_pred : (4, 4) float64
            Start (the point-to-plane answer) and the motion model's prediction.
        Lam : (6, 6) float64
            Information of the prediction (left twist, target frame).
        gate : float
            Pair gate, m.
        rng : float
            The scan's median range, m (rotation tolerance).
        voxel_map, spacing0, register :
            The map registered onto, ``s₀`` (m) and the solver's registration onto it.

        Returns
        -------
        fit : ScanToMapFit
            The point-to-point registration.
        fraction : float
            Fraction of the scan on the previous scan's rays (0 without a previous scan).
        """
        sig = self.options.repeat_refine * spacing0
        iso = self._isotropic(len(voxel_map), sig)
        # point to point onto the same surface samples: from the voxel means
        fit = register(P, iso, T0, T_pred, Lam, gate, rng, from_means=True)
        return fit, self.evidence(P, fit.T, sig, spacing0)

    def _isotropic(self, m: int, sig: float) -> np.ndarray:
        """``I / sig²`` for ``m`` map points, ``(m, 3, 3)`` (kept between frames: the map grows
        by a few voxels per frame)."""
        if self._iso is None or len(self._iso) < m or self._iso_sigma != sig:
            self._iso = np.ascontiguousarray(np.broadcast_to(np.eye(3) / sig**2, (2 * m, 3, 3)))
            self._iso_sigma = sig
        return self._iso[:m]

    def evidence(self, P: np.ndarray, T: np.ndarray, sig: float, spacing0: float) -> float:
        """Fraction of the scan ``P`` (sensor frame, pose ``T``) whose points lie on the ray of
        a point of the previous accepted scan: within ``sig`` (m) of it across the ray and
        ``spacing0`` (``s₀``, m) along it (0 without a previous scan)."""
        if self._cloud is None or not len(P):
            return 0.0
        Q, T_prev = self._cloud
        if not len(Q):
            return 0.0
        if self._tree is None:
            X_prev = np.ascontiguousarray(Q @ T_prev[:3, :3].T + T_prev[:3, 3])
            self._tree = (X_prev, *kd_build_select(X_prev, 16))
        X_prev, *tree = self._tree
        X = np.ascontiguousarray(P @ T[:3, :3].T + T[:3, 3])
        _, j = kd_knn_within(*tree, X, min(4, len(X_prev)), np.full(len(X), spacing0**2))
        hits = _on_previous_rays(X_prev, X, j, np.ascontiguousarray(T[:3, 3]), sig**2)
        return float(hits) / len(P)
