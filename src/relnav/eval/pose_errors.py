"""Per-frame trajectory errors on associated poses ``(N, 4, 4)``: absolute errors
(:func:`pose_errors`), relative-pose pairs and errors (:func:`rpe_pairs`,
:func:`relative_pose_errors`), evo's error statistics, and the input validation shared by the
metric modules. Lengths in metres, angles in degrees.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from relnav.errors import EstimationError, InputError
from relnav.eval.metric_names import DELTA_UNITS, STAT_NAMES, DeltaUnit
from relnav.geometry.rotations import matrix_to_euler
from relnav.geometry.se3 import invert

__all__ = [
    "PoseErrors",
    "error_statistics",
    "pose_errors",
    "relative_pose_errors",
    "rpe_pairs",
]

log = logging.getLogger(__name__)


_ORTHO_TOL = 1e-5  # max |RᵀR − I| accepted for a pose's rotation block


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------


def _as_poses(name: str, poses: np.ndarray) -> np.ndarray:
    """Validate a pose stack ``(N, 4, 4)``; :class:`InputError` naming ``name`` otherwise."""
    P = np.asarray(poses, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (4, 4):
        raise InputError(f"{name}: expected poses of shape (N, 4, 4), got {P.shape}")
    if not np.isfinite(P).all():
        k = int(np.flatnonzero(~np.isfinite(P).reshape(len(P), -1).all(axis=1))[0])
        raise InputError(f"{name}: pose {k} contains non-finite values")
    bottom = np.abs(P[:, 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1)
    R = P[:, :3, :3]
    ortho = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R) if len(P) else np.zeros(0)
    bad = (bottom > 1e-9) | (ortho > _ORTHO_TOL) | (det <= 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{name}: pose {k} is not a rigid transform "
            f"(|RᵀR − I| = {ortho[k]:.2e}, det R = {det[k]:.3f}, bottom row error {bottom[k]:.1e})"
        )
    return P


def _as_times(name: str, t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1:
        raise InputError(f"{name}: expected a 1-D array of timestamps, got shape {t.shape}")
    if not np.isfinite(t).all():
        raise InputError(f"{name}: timestamps contain non-finite values")
    return t


def _rotation_angle(R: np.ndarray) -> np.ndarray:
    """Geodesic angle (radians, ``[0, π]``) of rotation matrices ``(..., 3, 3)``.

    Uses ``atan2(|vee(R − Rᵀ)|/2, (tr R − 1)/2)``, accurate near 0 and π (unlike ``arccos``).
    """
    s = 0.5 * np.sqrt(
        (R[..., 2, 1] - R[..., 1, 2]) ** 2
        + (R[..., 0, 2] - R[..., 2, 0]) ** 2
        + (R[..., 1, 0] - R[..., 0, 1]) ** 2
    )
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(s, c)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def error_statistics(errors: np.ndarray) -> dict[str, float]:
    """evo's statistics of a 1-D error array: rmse, mean, median, std (population), min, max,
    sse (sum of squares); NaN for an empty array."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if not e.size:
        return dict.fromkeys(STAT_NAMES, float("nan"))
    return {
        "rmse": _rms(e),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "min": float(np.min(e)),
        "max": float(np.max(e)),
        "sse": float(np.sum(np.square(e))),
    }


# --------------------------------------------------------------------------------------------
# per-frame errors
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PoseErrors:
    """Per-frame absolute errors of an estimate against the ground truth.

    Attributes
    ----------
    delta : (N, 3) float64
        ``t(T_k^GT) − t(T_k^est)``, metres, in the common (GT) frame.
    trans : (N,) float64
        ``‖delta_k‖``, metres (equals the translation norm of ``T_gt⁻¹ T_est``).
    rot_deg : (N,) float64
        Geodesic angle of ``R_gtᵀ R_est``, degrees, in ``[0, 180]``.
    euler_mean_diff_deg : (N,) float64
        Signed legacy quantity ``mean(eul(R_gt)) − mean(eul(R_est))``, degrees (extrinsic
        ``"xyz"`` Euler angles); see ``docs/ALGORITHMS.md`` §F.2.
    """

    delta: np.ndarray
    trans: np.ndarray
    rot_deg: np.ndarray
    euler_mean_diff_deg: np.ndarray


def pose_errors(est_poses: np.ndarray, gt_poses: np.ndarray) -> PoseErrors:
    """Per-frame absolute translation and rotation errors (see :class:`PoseErrors`)."""
    est = _as_poses("est_poses", est_poses)
    gt = _as_poses("gt_poses", gt_poses)
    if est.shape != gt.shape:
        raise InputError(f"est_poses {est.shape} and gt_poses {gt.shape} differ in length")
    delta = gt[:, :3, 3] - est[:, :3, 3]
    trans = np.linalg.norm(delta, axis=1)
    R_err = np.swapaxes(gt[:, :3, :3], 1, 2) @ est[:, :3, :3]
    rot_deg = np.degrees(_rotation_angle(R_err))
    if len(est):
        eul_gt = np.degrees(matrix_to_euler(gt[:, :3, :3], "xyz")).mean(axis=1)
        eul_est = np.degrees(matrix_to_euler(est[:, :3, :3], "xyz")).mean(axis=1)
        eul = eul_gt - eul_est
    else:
        eul = np.zeros(0)
    return PoseErrors(delta=delta, trans=trans, rot_deg=rot_deg, euler_mean_diff_deg=eul)


def rpe_pairs(
    poses: np.ndarray,
    delta: float,
    unit: DeltaUnit = "frames",
    *,
    all_pairs: bool = False,
    rel_tol: float = 0.1,
) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)`` of the RPE, as evo's ``id_pairs_from_delta`` chooses them.

    Parameters
    ----------
    poses : (N, 4, 4) float64
        The poses the pairs are chosen on (evo: the estimate, after alignment).
    delta : float
        Pair distance: frames (integer), metres of travelled path, or degrees/radians of
        accumulated rotation.
    unit : {"frames", "m", "deg", "rad"}
        Unit of ``delta`` (evo ``--delta_unit f|m|d|r``).
    all_pairs : bool
        Every start index instead of consecutive, non-overlapping pairs (evo ``--all_pairs``);
        for metres/angles a pair is kept when its distance is within ``rel_tol · delta``.
    rel_tol : float
        evo's ``rel_delta_tol`` (0.1).

    Returns
    -------
    i, j : (M,) int64
    """
    n = len(poses)
    if unit not in DELTA_UNITS:
        raise InputError(f"unknown RPE delta unit {unit!r}; choose one of {', '.join(DELTA_UNITS)}")
    if not np.isfinite(delta) or delta <= 0:
        raise InputError(f"RPE delta must be > 0, got {delta}")
    if unit == "frames":
        if int(delta) != delta:
            raise InputError(f"RPE delta in frames must be an integer, got {delta}")
        d = int(delta)
        i = np.arange(n - d) if all_pairs else np.arange(0, n, d)[:-1]
        i = i[i + d < n]
        return i.astype(np.int64), (i + d).astype(np.int64)
    if unit == "m":
        step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    else:
        if (unit == "deg" and delta > 180) or (unit == "rad" and delta > np.pi):
            raise InputError(f"RPE delta angle must be within [0, 180] deg, got {delta} {unit}")
        step = _rotation_angle(np.swapaxes(poses[:-1, :3, :3], 1, 2) @ poses[1:, :3, :3])
        delta = float(np.radians(delta)) if unit == "deg" else float(delta)
    tol = rel_tol * delta
    if all_pairs:
        if unit == "m":
            dist = np.concatenate([[0.0], np.cumsum(step)])
            ii, jj = [], []
            for a in range(n - 1):
                rest = dist[a + 1 :] - dist[a]
                c = int(np.argmin(np.abs(rest - delta)))
                if abs(rest[c] - delta) <= tol:
                    ii.append(a)
                    jj.append(a + 1 + c)
            return np.asarray(ii, dtype=np.int64), np.asarray(jj, dtype=np.int64)
        # angles: direct relative angle between the two poses (evo's all-pairs reading)
        ii, jj = [], []
        for a in range(n - 1):
            ang = _rotation_angle(np.swapaxes(poses[a, :3, :3], 0, 1) @ poses[a + 1 :, :3, :3])
            hit = np.flatnonzero((ang >= delta - tol) & (ang <= delta + tol)) + a + 1
            ii.extend([a] * hit.size)
            jj.extend(hit.tolist())
        return np.asarray(ii, dtype=np.int64), np.asarray(jj, dtype=np.int64)
    ii, jj = [], []
    start, acc = 0, 0.0
    for k, dk in enumerate(step):
        acc += float(dk)
        if acc >= delta:
            ii.append(start)
            jj.append(k + 1)
            start, acc = k + 1, 0.0
    return np.asarray(ii, dtype=np.int64), np.asarray(jj, dtype=np.int64)


def relative_pose_errors(
    est_poses: np.ndarray,
    gt_poses: np.ndarray,
    *,
    delta: float = 1,
    all_pairs: bool = False,
    delta_unit: DeltaUnit = "frames",
) -> tuple[np.ndarray, np.ndarray]:
    """Relative pose errors over ``delta`` frames (evo RPE, Burgard's ``δ ⊖ δ*``).

    ``E_i = (T_gt,i⁻¹ T_gt,i+Δ)⁻¹ (T_est,i⁻¹ T_est,i+Δ)``.

    Parameters
    ----------
    est_poses, gt_poses : (N, 4, 4) float64
        Associated absolute poses.
    delta : int or float
        Frame offset ``Δ >= 1``, or metres / degrees / radians (``delta_unit``).
    all_pairs : bool
        ``False`` (evo's default): consecutive, non-overlapping pairs ``i = 0, Δ, 2Δ, …``;
        ``True``: every ``i = 0 … N−1−Δ`` (evo ``--all_pairs``). Identical for ``Δ = 1``.
    delta_unit : {"frames", "m", "deg", "rad"}
        Unit of ``delta``; pairs are chosen on the estimate as evo does (:func:`rpe_pairs`).

    Returns
    -------
    trans : (M,) float64
        ``‖t(E_i)‖``, metres.
    rot_deg : (M,) float64
        Geodesic angle of ``R(E_i)``, degrees.
    """
    est = _as_poses("est_poses", est_poses)
    gt = _as_poses("gt_poses", gt_poses)
    if est.shape != gt.shape:
        raise InputError(f"est_poses {est.shape} and gt_poses {gt.shape} differ in length")
    if delta_unit == "frames":
        if int(delta) != delta or delta < 1:
            raise InputError(f"delta must be an integer >= 1 frame, got {delta}")
        delta = int(delta)
        if len(est) <= delta:
            raise InputError(f"relative errors over delta={delta} frames need > {delta} poses")
    i, j = rpe_pairs(est, delta, delta_unit, all_pairs=all_pairs)
    if i.size == 0:
        raise EstimationError(
            f"RPE delta {delta:g} {delta_unit} gives no pose pair (the estimate moves less); "
            "use a smaller --delta"
        )
    d_gt = invert(gt[i]) @ gt[j]
    d_est = invert(est[i]) @ est[j]
    E = invert(d_gt) @ d_est
    return np.linalg.norm(E[:, :3, 3], axis=1), np.degrees(_rotation_angle(E[:, :3, :3]))
