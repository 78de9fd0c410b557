"""The navigator's registration of a scan onto its map (:class:`MapSolver`).

One registration is robust generalised ICP of the scan onto the map's points under the motion
model's prior (:func:`~relnav.navigation.gicp.solve_scan_to_map`), optionally refined point to
point on repeated points (:class:`~relnav.navigation.repeated.RepeatedPoints`), with its quality
figures (overlap, fitness, χ² against the prior, degeneracy, robust RMS). The navigator, its
start-up window and its relocaliser all register through one :class:`MapSolver`, so that they
share the solver's settings and the map without reaching into the navigator.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav._threads import thread_pool
from relnav.geometry.eigen import inverse
from relnav.geometry.lie import exp_se3, log_se3
from relnav.geometry.se3 import invert
from relnav.navigation.gicp import (
    ScanToMapFit,
    degeneracy,
    left_information,
    motion_chi2,
    normal_information,
    robust_cost,
    solve_scan_to_map,
    variance_factor,
)
from relnav.navigation.options import NavigatorConfig
from relnav.navigation.repeated import RepeatedPoints
from relnav.navigation.voxel_map import VoxelMap
from relnav.odometry.step_check import step_difference
from relnav.registration.result import RegistrationResult

__all__ = ["MapSolver", "median", "median_range", "point_spacing", "rms_radius"]


def median(x: np.ndarray) -> float:
    """``np.median`` of a 1-D array of finite values (the same value, without its overhead:
    the navigator takes a scan's median range every frame)."""
    n = len(x)
    if n == 0:
        return float("nan")
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)


def median_range(P: np.ndarray) -> float:
    """The median range ``|p|`` of the points ``P`` (N, 3), m (NaN for no point)."""
    return median(np.linalg.norm(P, axis=1))


@njit(cache=True)
def _rms_radius_nb(P: np.ndarray) -> float:  # pragma: no cover - numba
    n = P.shape[0]
    c0 = c1 = c2 = 0.0
    for i in range(n):
        c0 += P[i, 0]
        c1 += P[i, 1]
        c2 += P[i, 2]
    c0, c1, c2 = c0 / n, c1 / n, c2 / n
    s = 0.0
    for i in range(n):
        d0, d1, d2 = P[i, 0] - c0, P[i, 1] - c1, P[i, 2] - c2
        s += d0 * d0 + d1 * d1 + d2 * d2
    return math.sqrt(s / n)


def rms_radius(P: np.ndarray) -> float:
    """RMS distance of the points ``P`` (N, 3) from their centroid (m): the scan's lever arm
    (NaN for no point)."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    return float(_rms_radius_nb(P)) if len(P) else float("nan")


def point_spacing(P: np.ndarray) -> float:
    """Median nearest-neighbour distance of a cloud ``P`` (N, 3) (m)."""
    d, _ = cKDTree(P).query(P, k=2)
    s = float(np.median(d[:, 1]))
    return s if s > 0 else float(np.mean(d[:, 1]))


class MapSolver:
    """Registration of scans onto the navigator's map with the navigator's solver settings.

    Parameters
    ----------
    config : NavigatorConfig
        The navigator's options (solver, map and repeated-point fields).
    repeats : RepeatedPoints
        The repeated-point test and refinement applied to registrations onto :attr:`map`.

    Attributes
    ----------
    map : VoxelMap or None
        The map scans are registered onto (None before the first usable frame).
    spacing0 : float
        The first usable scan's point spacing ``s₀`` (m): the unit of the scale-free options.
    first_sigma : tuple of float
        The first frame's weak prior, 1σ translation (m) and rotation (rad).
    """

    def __init__(self, config: NavigatorConfig, repeats: RepeatedPoints) -> None:
        self.config = config
        self.repeats = repeats
        self.map: VoxelMap | None = None
        self.spacing0 = float("nan")
        self.first_sigma = (float("nan"), float("nan"))

    def fit_result(
        self,
        fit: dict[str, Any],
        T: np.ndarray,
        H: np.ndarray,
        prior: np.ndarray,
        status: str,
        message: str,
        timings: dict[str, float],
        info: dict[str, Any],
    ) -> RegistrationResult:
        """The step's :class:`RegistrationResult` from a registration ``fit`` (:meth:`solve`):
        pose ``T``, covariance ``(H + prior)⁻¹`` of the scan's information ``H`` and the
        prior's (left twist, target frame; ``None`` when singular)."""
        inv, ok = inverse(np.ascontiguousarray(H + prior, dtype=np.float64))
        cov = inv if ok else None
        return RegistrationResult(
            T_target_source=T,
            covariance=cov,
            fitness=fit["fitness"],
            inlier_rmse=fit["rms"],
            n_correspondences=int(fit["n_pairs"]),
            n_inliers=int(fit["n_inliers"]),
            converged=fit["iterations"] < self.config.solver.max_iter,
            status=status,  # type: ignore[arg-type]
            timings=timings,
            message=message,
            info=info,
        )

    def stability(
        self,
        P: np.ndarray,
        fit: dict[str, Any],
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        info: dict[str, Any],
    ) -> tuple[dict[str, Any], bool]:
        """Register ``P`` again from the answer ``fit`` displaced along its weakest direction.

        **[interpretation]** A step whose answer depends on where the solver starts is not
        determined by the scan. The weakest direction is the smallest eigenvector of the answer's
        information ``H / σ̂² + Λ`` (left twist, target frame) with rotations scaled by the lever
        arm ``radius`` (m); the start is displaced by ``integrity.stability_k`` σ along it, at most
        ``integrity.stability_cap`` map voxels (metres of translation, or of arc at ``radius``). The
        second answer goes through the same point-to-point refinement on repeated points as the
        first. The answers' distance is measured in the same information (σ). Returns the
        better-fitting answer (lower robust RMS, the first on ties) and whether the step is
        unstable: the distance exceeds ``integrity.stability_gate`` (``stability_apart``) and,
        with ``integrity.stability_flag="limits"``, the two answers' sensor poses are also farther
        apart than the flag limits (``stability_separation_m``, ``stability_separation_deg``).
        """
        c = self.config
        assert self.map is not None
        H_post = fit["H"] / fit["var_factor"] + Lam
        H_post = 0.5 * (H_post + H_post.T)
        sc = np.array([1.0, 1.0, 1.0, radius, radius, radius])  # y = sc * ξ, metres
        Hs = H_post / sc[:, None] / sc[None, :]
        ev, U = np.linalg.eigh(Hs)
        if not np.all(np.isfinite(ev)) or ev[0] <= 0:
            return fit, False
        sig_w = 1.0 / math.sqrt(float(ev[0]))
        shift = min(
            c.integrity.stability_k * sig_w, c.integrity.stability_cap * self.map.voxel_size
        )
        xi0 = U[:, 0] * shift / sc
        T0 = exp_se3(xi0) @ fit["T"]
        T_c = exp_se3(xi0) @ T_pred if c.integrity.stability_mode == "prior" else T_pred
        alt = self.register_on_map(
            P,
            self.map.information,
            T0,
            T_c,
            Lam,
            gate,
            rng,
            kernel_scale=c.integrity.stability_kernel,
        )
        # the same pipeline as the first answer: refined point to point on repeated points
        alt, _, _ = self.repeats.apply(
            P, alt, T_c, Lam, gate, rng, False, self.map, self.spacing0, self.register_on_map
        )
        d = log_se3(alt.T @ invert(fit["T"]))
        dist = math.sqrt(max(float(d @ H_post @ d), 0.0))
        rms_alt = alt.rms
        info.update(
            stability_distance=dist,
            stability_start_sigma=shift / sig_w,
            stability_start=shift,
            stability_follow=dist / max(math.sqrt(float(xi0 @ H_post @ xi0)), 1e-300),
            stability_shift=d.copy(),
            stability_rms=rms_alt,
        )
        # how far apart the two answers put the sensor (m) and turn it (deg)
        angle, sep_t = step_difference(fit["T"], alt.T)
        sep_r = math.degrees(angle)
        apart = dist > c.integrity.stability_gate
        info.update(
            stability_separation_m=sep_t, stability_separation_deg=sep_r, stability_apart=apart
        )
        if apart and rms_alt < fit["rms"]:
            fit = dict(fit, T=alt.T, rms=rms_alt)
        unstable = apart
        if c.integrity.stability_flag == "limits":
            unstable = apart and (
                sep_t > c.integrity.flag_limit_t or sep_r > c.integrity.flag_limit_r_deg
            )
        return fit, unstable

    def weak_prior(self, T_pred: np.ndarray, rotation: np.ndarray | None = None) -> np.ndarray:
        """Information (left, target frame) of the first frame's weak motion prior; with
        ``rotation`` (3×3, rad², body frame: a measured attitude's covariance) that instead of
        the weak rotation block."""
        st, sr = self.first_sigma
        S = np.diag([st**2] * 3 + [sr**2] * 3)
        if rotation is not None:
            S[3:, 3:] = rotation
        return left_information(T_pred, S)

    def register_on_map(
        self,
        P: np.ndarray,
        info: np.ndarray,
        T0: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        kernel_scale: float = 1.0,
        voxel_map: VoxelMap | None = None,
        from_means: bool = False,
    ) -> ScanToMapFit:
        """Robust GICP of the scan ``P`` (sensor frame, m) onto the map's points with the
        per-point information ``info`` ``(M, 3, 3)``, from ``T0``, under the prior ``(T_pred,
        Lam)`` (left twist information, target frame); ``gate`` the pair gate (m), ``rng`` the
        scan's median range (m, for the rotation tolerance); ``voxel_map`` another map than
        the navigator's (its information is then ``info``); ``from_means``: residuals from the
        voxel means, not the map's patch points. The solver's options come from the configuration
        (:func:`~relnav.navigation.gicp.solve_scan_to_map`)."""
        c = self.config
        target = self.map if voxel_map is None else voxel_map
        assert target is not None
        v = target.voxel_size
        return solve_scan_to_map(
            P,
            target,
            np.ascontiguousarray(T0),
            np.ascontiguousarray(T_pred),
            np.ascontiguousarray(Lam),
            gate,
            float(c.solver.kernel) * kernel_scale,
            int(c.solver.max_iter),
            c.solver.tolerance * v,
            c.solver.tolerance * v / max(rng, 1.0),
            c0=float(c.solver.kernel_start) * kernel_scale,
            decay=float(c.solver.kernel_decay),
            information=info,
            from_means=from_means,
        )

    def solve(
        self,
        P: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        primary: bool = True,
        Lam_fit: np.ndarray | None = None,
        voxel_map: VoxelMap | None = None,
        start: np.ndarray | None = None,
    ) -> dict[str, Any]:
        """One registration onto the map and its quality figures (``rng``: the scan's median
        range, ``radius``: its lever arm, both m; ``primary``: the frame's first registration, under
        the motion model's prior). With ``solver.repeat_refine`` the answer is refined point to
        point when the scan repeats the previous scan's surface points
        (:mod:`relnav.navigation.repeated`). ``Lam_fit``: the prior's information inside the solver
        when it differs from ``Lam`` (the χ² against the motion model uses ``Lam``);
        ``voxel_map``: register onto that map instead of the navigator's."""
        target = self.map if voxel_map is None else voxel_map
        assert target is not None
        Lf = Lam if Lam_fit is None else Lam_fit
        T0 = T_pred if start is None else start
        fit = self.register_on_map(
            P, target.information, T0, T_pred, Lf, gate, rng, voxel_map=target
        )
        return self._figures(P, fit, T_pred, Lam, Lf, gate, rng, radius, primary, voxel_map)

    def solve_starts(
        self,
        P: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        Lam_fit: np.ndarray,
        starts: list[np.ndarray],
    ) -> list[dict[str, Any]]:
        """The frame's registration from the prediction (as :meth:`solve` with ``primary``) and,
        when that one is usable, from the other ``starts`` (4, 4) (as :meth:`solve` with
        ``start``): the answers in that order, or the first alone.

        **[interpretation]** With ``prior.jitter_screen`` = n > 1 the other starts are screened:
        each is registered on every n-th scan point only, and the ``prior.jitter_screen_keep``
        that fit those points best (lowest robust RMS) are registered on the whole scan from
        where they ended; only these answers follow the first. With n = 1 every start is
        registered on the whole scan.

        With ``solver.threads`` > 1 the registrations run together in a
        :func:`~relnav._threads.thread_pool` (the compiled solver releases the interpreter; the
        others' are then wasted when the first is not usable); the refinements and figures
        follow in order in this thread, so the answers are the same for any number of threads.
        """
        assert self.map is not None
        info = self.map.information  # refreshes all the map's lazy arrays, before any thread
        pr = self.config.prior
        n_screen = int(pr.jitter_screen)
        screen = n_screen > 1 and len(starts) > pr.jitter_screen_keep
        Q = np.ascontiguousarray(P[::n_screen]) if screen else P

        def register(T0: np.ndarray) -> ScanToMapFit:
            return self.register_on_map(P, info, T0, T_pred, Lam_fit, gate, rng)

        def register_screened(T0: np.ndarray) -> ScanToMapFit:
            return self.register_on_map(Q, info, T0, T_pred, Lam_fit, gate, rng)

        def figures(fit: ScanToMapFit, primary: bool) -> dict[str, Any]:
            return self._figures(
                P, fit, T_pred, Lam, Lam_fit, gate, rng, radius, primary, None, objective=True
            )

        solve_other = register_screened if screen else register
        pool = thread_pool(self.config.solver.threads)
        if pool is not None:
            jobs = [pool.submit(register, T_pred), *(pool.submit(solve_other, T) for T in starts)]
            first_fit, others = jobs[0].result(), [j.result() for j in jobs[1:]]
        else:
            first_fit, others = register(T_pred), []
        first = figures(first_fit, True)
        if not first["usable"]:
            return [first]
        if pool is None:
            others = [solve_other(T0) for T0 in starts]
        if not screen:
            return [first, *(figures(fit, False) for fit in others)]
        best = sorted(range(len(others)), key=lambda j: others[j].rms)[: pr.jitter_screen_keep]
        kept = [others[j].T for j in best]
        refined = list(pool.map(register, kept)) if pool is not None else map(register, kept)
        return [first, *(figures(fit, False) for fit in refined)]

    def _figures(
        self,
        P: np.ndarray,
        fit: ScanToMapFit,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        Lf: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        primary: bool,
        voxel_map: VoxelMap | None,
        objective: bool = False,
    ) -> dict[str, Any]:
        """:meth:`solve`'s answer from its registration ``fit``: the repeated-points refinement
        (onto the navigator's map only) and the quality figures; with ``objective`` (the answers
        :meth:`solve_starts` returns, compared by :func:`~relnav.navigation.multistart.kept_answer`)
        also ``"objective"``: the robust cost at the final pairs,
        :func:`~relnav.navigation.gicp.robust_cost`, plus ``"chi2"``, the answer's χ² against the
        prior ``Lam`` (NaN otherwise)."""
        c = self.config
        target = self.map if voxel_map is None else voxel_map
        assert target is not None
        repeat_frac, repeated = float("nan"), False
        if voxel_map is None:  # the repeated-points test compares with the navigator's map
            fit, repeat_frac, repeated = self.repeats.apply(
                P,
                fit,
                T_pred,
                Lf,
                gate,
                rng,
                primary,
                self.map,
                self.spacing0,
                self.register_on_map,
            )
        n = len(P)
        if c.solver.information == "normal":
            H_cov = normal_information(
                P,
                fit.T,
                fit.idx,
                fit.d2,
                target.normals,
                target.information,
                target.inplane_sigma**2,
                float(c.solver.kernel) ** 2,
            )
        else:
            H_cov = fit.H
        has = fit.d2 >= 0
        inl = has & (fit.d2 < 9.0)
        rms = fit.rms if fit.sw > 0 else float("nan")
        chi2 = motion_chi2(fit.T, T_pred, Lam)
        return {
            "T": fit.T,
            "H": H_cov,
            "n_pairs": fit.n_pairs,
            "iterations": fit.iterations,
            "overlap": float(has.sum()) / n,
            "fitness": float(inl.sum()) / n,
            "n_inliers": int(inl.sum()),
            "chi2": chi2,
            "objective": (
                robust_cost(fit.d2, float(c.solver.kernel)) + chi2 if objective else math.nan
            ),
            "cond": degeneracy(H_cov, radius),
            "rms": rms,
            "var_factor": variance_factor(rms),
            "usable": bool(
                fit.n_pairs >= c.solver.min_points and has.sum() >= c.solver.min_overlap * n
            ),
            "repeat_fraction": repeat_frac,
            "repeated": repeated,
        }

    def map_options(self) -> dict[str, Any]:
        """The navigator's patch and weighting parameters of a :class:`VoxelMap` (metres from
        the multiples of ``s₀``), shared by its map and the pose graph's keyframe maps."""
        c, s0 = self.config, self.spacing0
        return {
            "max_weight": c.map.max_voxel_weight,
            "noise_floor": c.map.noise_floor * s0,
            "inplane_sigma": c.map.inplane_sigma * s0,
            "k_neighbors": c.map.k_neighbors,
            "nonplanar_gain": c.map.nonplanar_gain,
            "surface": c.map.surface,
            "curvature_sigma": c.map.curvature_sigma,
            "quadric_reach": c.map.quadric_reach * s0,
            "patch_point": c.map.patch_point,
            "patch_point_reach": c.map.patch_point_reach * s0,
        }

    def new_map(self) -> VoxelMap:
        """An empty map with the navigator's parameters (voxel ``voxel_factor · s₀``)."""
        c = self.config
        return VoxelMap(
            c.map.voxel_factor * self.spacing0, max_voxels=c.map.max_voxels, **self.map_options()
        )
