"""Shared parts of the adapters of external registration libraries (see
:mod:`relnav.registration.external` for the methods and their behaviour): checked
imports, option checks, the information matrix and its degeneracy, the evaluation of a
result on the relnav side, and :class:`_ExternalBase`, which every adapter extends."""

from __future__ import annotations

import hashlib
import importlib
import logging
import math
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.rotations import hat
from relnav.geometry.se3 import adjoint
from relnav.registration.icp import PreparedCloud, check_init, prepare_cloud
from relnav.registration.result import RegistrationResult, RegistrationStatus

__all__ = [
    "require",
    "information_degeneracy",
    "twist_covariance_from_hessian",
]

log = logging.getLogger(__name__)

_DISTRIBUTIONS = {
    "open3d": "open3d-cpu",
    "kiss_icp": "kiss-icp",
    "small_gicp": "small_gicp",
    "kiss_matcher": "kiss-matcher",
}


def require(module: str, method: str) -> ModuleType:
    """Import the optional dependency ``module`` needed by ``method``.

    Raises
    ------
    ConfigError
        The module is not installed (or cannot be imported); the message names the
        ``[baselines]`` extra.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        dist = _DISTRIBUTIONS.get(module, module)
        raise ConfigError(
            f"method {method!r} needs the optional dependency {dist}: "
            f"pip install 'relnav[baselines]' ({type(e).__name__}: {e})"
        ) from None


# --------------------------------------------------------------------------- shared helpers


def _positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise ConfigError(
            f"{name} must be a {'non-negative' if allow_zero else 'positive'} number, got {value!r}"
        )
    return v


def _flag(
    status: RegistrationStatus, message: str, T: np.ndarray, timings: dict, info: dict
) -> RegistrationResult:
    log.debug("registration %s: %s", status, message)
    return RegistrationResult(
        T_target_source=np.array(T, dtype=np.float64),
        status=status,
        message=message,
        timings=timings,
        info=info,
    )


def _total(t: dict[str, float]) -> float:
    return float(sum(t.values()))


def twist_covariance_from_hessian(H: np.ndarray, T: np.ndarray) -> np.ndarray | None:
    """Covariance of relnav's twist from a small_gicp Hessian.

    small_gicp linearises ``T · exp(δ)`` (RIGHT perturbation, source frame) with
    ``δ = [φ (rotation), ρ (translation)]``. relnav uses a LEFT perturbation in the target frame
    ordered ``[ρ, φ]``: ``C = Ad_T P H⁻¹ Pᵀ Ad_Tᵀ`` with ``P`` the block swap.

    Parameters
    ----------
    H : (6, 6) float64
        small_gicp's ``RegistrationResult.H``.
    T : (4, 4) float64
        The estimate ``T_target_source``.

    Returns
    -------
    (6, 6) float64 or None
        None when ``H`` is not finite or not positive definite.
    """
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (6, 6) or not np.isfinite(H).all():
        return None
    Hs = 0.5 * (H + H.T)
    lam, V = np.linalg.eigh(Hs)
    if not lam[0] > 1e-14 * max(lam[-1], 1e-300):
        return None
    C_rot_first = (V / lam) @ V.T
    perm = np.r_[3:6, 0:3]
    C_right = C_rot_first[np.ix_(perm, perm)]
    A = adjoint(T)
    C = A @ C_right @ A.T
    return 0.5 * (C + C.T)


def information_degeneracy(A: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """``λmin/λmax`` of an information matrix re-expressed about ``centre``, rotation × radius.

    ``A`` (6×6) is the information of a twist ``[ρ, φ]`` about the frame origin. A cloud far
    from its frame origin (a target 20 m or 20 km ahead of the sensor) couples rotation and
    translation through the lever arm, so ``A`` is first moved to the cloud centre
    (``Ad_Cᵀ A Ad_C``, ``C`` the translation to ``centre``) and the rotation block scaled by the
    cloud radius (m); the ratio is then scale-free and ~0 only for real degeneracies (e.g. a
    single plane under point-to-plane). Returns 0 for non-finite input.
    """
    Ad = np.eye(6)
    Ad[:3, 3:] = hat(np.asarray(centre, dtype=np.float64))
    Ac = Ad.T @ A @ Ad
    scale = np.r_[np.ones(3), np.full(3, 1.0 / max(radius, 1e-12))]
    As = Ac * scale[:, None] * scale[None, :]
    if not np.isfinite(As).all():
        return 0.0
    ev = np.linalg.eigvalsh(0.5 * (As + As.T))
    return float(max(ev[0], 0.0) / ev[-1]) if ev[-1] > 0 else 0.0


def _information(
    moved: np.ndarray, normals: np.ndarray | None, radius: float
) -> tuple[np.ndarray, float]:
    """Gauss–Newton information ``JᵀJ`` (left perturbation, ``[ρ, φ]``) and degeneracy ratio."""
    if normals is None:
        n = moved.shape[0]
        s = moved.sum(axis=0)
        A = np.zeros((6, 6))
        A[:3, :3] = n * np.eye(3)
        A[:3, 3:] = -hat(s)
        A[3:, :3] = hat(s)
        A[3:, 3:] = np.sum(moved * moved) * np.eye(3) - moved.T @ moved
    else:
        J = np.hstack([normals, np.cross(moved, normals)])
        A = J.T @ J
    return A, information_degeneracy(A, moved.mean(axis=0), radius)


# --------------------------------------------------------------------------- dense scans

DENSE_POINTS = 5_000
"""Scans with more points get the peers' own range-based downsampling (module docstring)."""


def _dense_points(v: Any) -> int | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
        raise ConfigError(f"dense_points must be a positive integer or None, got {v!r}")
    return int(v)


def _is_dense(n: int, threshold: int | None) -> bool:
    return threshold is not None and n > threshold


def _max_range(points: np.ndarray) -> float:
    return float(np.sqrt(np.einsum("ij,ij->i", points, points).max())) if points.size else 0.0


@dataclass
class _Fit:
    fitness: float = 0.0
    rmse: float = float("nan")
    n_inliers: int = 0
    covariance: np.ndarray | None = None
    degeneracy_ratio: float = float("nan")


def _evaluate(
    T: np.ndarray,
    source: np.ndarray,
    target: PreparedCloud,
    gate: float,
    *,
    normals: np.ndarray | None = None,
    radius: float,
    covariance: bool = True,
) -> _Fit:
    """Fitness, RMSE, covariance and degeneracy ratio at the final estimate (see module doc)."""
    if source.shape[0] == 0 or target.tree is None:
        return _Fit()
    moved = source @ T[:3, :3].T + T[:3, 3]
    d, j = target.tree.query(moved, k=1, distance_upper_bound=gate)
    keep = np.isfinite(d)
    n_in = int(keep.sum())
    fit = _Fit(fitness=n_in / source.shape[0], n_inliers=n_in)
    if n_in == 0:
        return fit
    fit.rmse = float(np.sqrt(np.mean(d[keep] ** 2)))
    p = moved[keep]
    q = target.points[j[keep]]
    nrm = None
    if normals is not None:
        nrm = normals[j[keep]]
        good = np.isfinite(nrm).all(axis=1)
        if good.sum() >= 6:
            p, q, nrm = p[good], q[good], nrm[good]
        else:
            nrm = None
    A, ratio = _information(p, nrm, radius)
    fit.degeneracy_ratio = ratio
    if covariance:
        if nrm is None:
            r2 = float(np.sum((p - q) ** 2))
            dof = 3 * p.shape[0] - 6
        else:
            r2 = float(np.sum(np.einsum("ij,ij->i", p - q, nrm) ** 2))
            dof = p.shape[0] - 6
        if dof > 0 and ratio > 1e-14:
            lam, V = np.linalg.eigh(0.5 * (A + A.T))
            if lam[0] > 0:
                C = (V / lam) @ V.T * (r2 / dof)
                fit.covariance = 0.5 * (C + C.T)
    return fit


def _fingerprint(points: np.ndarray) -> str:
    P = np.ascontiguousarray(points, dtype=np.float64)
    h = hashlib.blake2b(P.tobytes(), digest_size=16)
    h.update(str(P.shape).encode())
    return h.hexdigest()


class _ExternalBase:
    """Validation, timing and exception handling shared by the adapters."""

    name: str = ""
    #: the final status is "degenerate" below this λmin/λmax of the scaled information matrix
    degeneracy_ratio: float = 1e-9
    min_points: int = 6

    def _validate(
        self, source: Any, target: Any, init: Any, timings: dict, info: dict
    ) -> tuple[PreparedCloud, PreparedCloud, np.ndarray] | RegistrationResult:
        t0 = time.perf_counter()
        T0, msg = check_init(init)
        if T0 is None:
            return _flag("failed", msg, np.eye(4), timings, info)
        src = source if isinstance(source, PreparedCloud) else self._prepare(source, "source")
        tgt = target if isinstance(target, PreparedCloud) else self._prepare(target, "target")
        timings["prepare"] = time.perf_counter() - t0
        info.update(
            n_source=int(src.points.shape[0]),
            n_target=int(tgt.points.shape[0]),
            n_dropped_source=src.n_dropped,
            n_dropped_target=tgt.n_dropped,
        )
        for cloud, nm in ((src, "source"), (tgt, "target")):
            if not cloud.ok:
                m = cloud.message
                if m.startswith("cloud"):
                    m = nm + m[len("cloud") :]
                elif not m.startswith(nm):
                    m = f"{nm}: {m}"
                return _flag(cloud.status, m, T0, timings, info)  # type: ignore[arg-type]
        if not (np.isfinite(src.resolution) and src.resolution > 0):
            return _flag("degenerate", "source resolution is undefined", T0, timings, info)
        info["resolution"] = src.resolution
        return src, tgt, T0

    def _prepare(self, points: Any, name: str) -> PreparedCloud:
        return prepare_cloud(points, min_points=self.min_points, resolution=True, name=name)

    def _finish(
        self,
        T: np.ndarray,
        source_points: np.ndarray,
        target: PreparedCloud,
        gate: float,
        radius: float,
        *,
        converged: bool,
        timings: dict,
        info: dict,
        normals: np.ndarray | None = None,
        n_correspondences: int | None = None,
        covariance: np.ndarray | None = None,
        compute_covariance: bool = True,
        fallback: np.ndarray | None = None,
    ) -> RegistrationResult:
        """Evaluate ``T`` and build the result; a non-``ok`` result carries ``fallback``
        (the initial guess; identity by default) and keeps ``T`` in ``info["T_estimate"]``."""
        fallback = np.eye(4) if fallback is None else fallback
        t0 = time.perf_counter()
        if not np.isfinite(T).all():
            return _flag(
                "failed", "the library returned a non-finite transform", fallback, timings, info
            )
        fit = _evaluate(
            T,
            source_points,
            target,
            gate,
            normals=normals,
            radius=radius,
            covariance=compute_covariance and covariance is None,
        )
        timings["evaluate"] = time.perf_counter() - t0
        info["gate"] = gate
        info["degeneracy_ratio"] = fit.degeneracy_ratio
        status: RegistrationStatus = "ok"
        message = ""
        if fit.n_inliers < 3:
            status, message = (
                "failed",
                f"{fit.n_inliers} source points within {gate:.3g} m of the target after alignment",
            )
        elif fit.degeneracy_ratio < self.degeneracy_ratio:
            status = "degenerate"
            message = f"geometry does not fix 6 DoF (λmin/λmax = {fit.degeneracy_ratio:.2e})"
        cov = covariance if covariance is not None else fit.covariance
        if status != "ok":
            info["T_estimate"] = np.array(T, dtype=np.float64)
        return RegistrationResult(
            T_target_source=np.array(T if status == "ok" else fallback, dtype=np.float64),
            covariance=cov,
            fitness=fit.fitness,
            inlier_rmse=fit.rmse,
            n_correspondences=fit.n_inliers if n_correspondences is None else n_correspondences,
            n_inliers=fit.n_inliers,
            converged=bool(converged),
            status=status,
            timings=timings,
            message=message,
            info=info,
        )

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register ``source`` onto ``target``: ``target ≈ T_target_source @ source``.

        Parameters
        ----------
        source, target : (N, 3), (M, 3) float64
            Clouds in metres in their sensor frames (odometry: scan ``k+1`` and scan ``k``).
        init : (4, 4) float64, optional
            Initial guess of ``T_target_source`` (identity when omitted).
        """
        timings: dict[str, float] = {}
        info: dict[str, Any] = {"method": self.name}
        v = self._validate(source, target, init, timings, info)
        if isinstance(v, RegistrationResult):
            return v
        src, tgt, T0 = v
        try:
            return self._run(src, tgt, T0, timings, info)
        except Exception as e:  # library errors must not stop a run: flag them
            log.warning("%s raised %s: %s", self.name, type(e).__name__, e)
            self._on_error()
            return _flag("failed", f"{type(e).__name__}: {e}", T0, timings, info)

    def _on_error(self) -> None:
        """Reset internal state after a library error (stateful adapters)."""

    def _run(
        self, src: PreparedCloud, tgt: PreparedCloud, T0: np.ndarray, timings: dict, info: dict
    ) -> RegistrationResult:  # pragma: no cover - abstract
        raise NotImplementedError
