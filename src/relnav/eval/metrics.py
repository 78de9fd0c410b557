"""Trajectory accuracy metrics: Paper 1's odometry metrics plus the TUM/evo APE and RPE.

Pure computation (NumPy in, floats out): no file I/O, no printing, no plotting.

All trajectories are stacks of absolute poses ``(N, 4, 4)`` in one common frame, e.g.
``T_world_sensor`` or ``T_target_sensor``; the estimate and the ground truth (GT) of frame ``k``
are compared with ``Δ_k = t(T_k^GT) − t(T_k^est)`` (metres, expressed in that common frame).
Lengths are metres and angles are **degrees** in every returned dictionary
(``docs/ALGORITHMS.md`` §F).

Public functions
----------------
:func:`associate`
    One-to-one nearest-timestamp association (TUM ``associate.py`` / evo style).
:func:`align_trajectory`
    ``"none"``, ``"first"`` (evo ``--align_origin``), ``"se3"`` (Umeyama, evo ``--align``) or
    ``"sim3"`` (Umeyama with scale, evo ``--align --correct_scale``).
:func:`pose_errors`, :func:`relative_pose_errors`
    Per-frame raw errors (for plots and export).
:func:`compute_metrics`
    All scalar metrics on already associated poses.
:func:`match_trajectories`, :func:`evaluate_trajectories`
    Associate by timestamps, align, then compute.

Metric names
------------
:data:`METRIC_DOCS` is the one place that names and defines every key (unit, origin,
definition); ``relnav evaluate --metrics`` prints it. Paper 1's metrics keep the paper's
symbols (``e_T_avg`` is the paper's ``e^T_avg`` — an RMSE, which the paper calls "avg");
evo's carry evo's statistic names: ``{ape,rpe}_{trans,rot}_{rmse,mean,median,std,min,max,sse}``
(rotations in degrees, evo's ``angle_deg``). Deprecated aliases (:data:`DEPRECATED_ALIASES`)
are still written.

References
----------
Kechagias-Stamatis, Aouf, Dubanchet, J. Field Robotics (Paper 1), §3.2, eqs. 27–31.
Burgard et al., "A comparison of SLAM algorithms based on a graph of relations", IROS 2009,
doi:10.1109/IROS.2009.5354691.
Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012,
doi:10.1109/IROS.2012.6385773.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

from relnav.errors import EstimationError, InputError
from relnav.geometry.rotations import matrix_to_euler
from relnav.geometry.se3 import invert, umeyama

__all__ = [
    "ALIGN_METHODS",
    "DELTA_UNITS",
    "DEPRECATED_ALIASES",
    "EVO_KEYS",
    "METRIC_DOCS",
    "METRIC_KEYS",
    "STAT_NAMES",
    "MatchedTrajectories",
    "PoseErrors",
    "align_trajectory",
    "apply_alignment",
    "error_statistics",
    "associate",
    "compute_metrics",
    "evaluate_trajectories",
    "match_trajectories",
    "metric_units",
    "pose_errors",
    "relative_pose_errors",
    "rpe_pairs",
]

log = logging.getLogger(__name__)

AlignMethod = Literal["none", "first", "se3", "sim3"]
DeltaUnit = Literal["frames", "m", "deg", "rad"]

ALIGN_METHODS: tuple[str, ...] = ("none", "first", "se3", "sim3")
DELTA_UNITS: tuple[str, ...] = ("frames", "m", "deg", "rad")
STAT_NAMES: tuple[str, ...] = ("rmse", "mean", "median", "std", "min", "max", "sse")
"""evo's statistics (``evo.core.metrics.StatisticsType``), in evo's order."""
EVO_KEYS: tuple[str, ...] = tuple(
    f"{rel}_{stat}"
    for rel in ("ape_trans", "ape_rot", "rpe_trans", "rpe_rot")
    for stat in STAT_NAMES
)
"""evo-named keys of :func:`compute_metrics` (APE/RPE translation in m, rotation in deg)."""
DEPRECATED_ALIASES: dict[str, str] = {
    "ape_rot_rmse_deg": "ape_rot_rmse",
    "rpe_rot_rmse_deg": "rpe_rot_rmse",
    "e_R_euler_max": "e_R_euler_peak",
}
"""Old key → current key; the old keys are still written (same value)."""
RotationError = Literal["geodesic", "euler_mean_diff"]
AngleUnit = Literal["deg", "rad"]

#: Keys always present in the dictionary returned by :func:`compute_metrics`, in report order
#: (also the benchmark store's columns, so it keeps the deprecated aliases; :data:`EVO_KEYS`
#: and ``e_R_euler_peak`` are present as well).
METRIC_KEYS: tuple[str, ...] = (
    "n_frames",
    "path_length",
    "duration_s",
    "drift",
    "T_error_pct",
    "e_T_avg",
    "e_T_max",
    "e_x_max",
    "e_y_max",
    "e_z_max",
    "e_x_avg",
    "e_y_avg",
    "e_z_avg",
    "e_R_avg",
    "e_R_max",
    "e_R_euler_avg",
    "e_R_euler_max",
    "e_RT",
    "e_RT_trans",
    "e_RT_rot",
    "ape_trans_rmse",
    "ape_rot_rmse_deg",
    "rpe_trans_rmse",
    "rpe_rot_rmse_deg",
    "rpe_delta",
    "time_ms",
)

_ORTHO_TOL = 1e-5  # max |RᵀR − I| accepted for a pose's rotation block


_P1 = "paper 1 §3.2"
METRIC_DOCS: dict[str, tuple[str, str, str]] = {
    "n_frames": ("", "relnav", "associated poses compared"),
    "path_length": ("m", _P1, "L_GT = Σ ‖t_k+1 − t_k‖ of the ground truth"),
    "duration_s": ("s", "relnav", "time span of the associated poses"),
    "drift": ("m", _P1, "end-point error ‖Δ_N‖"),
    "T_error_pct": ("%", _P1, "T_error = 100 · drift / L_GT"),
    "e_T_avg": ("m", _P1 + " eq. 27", "e^T_avg = sqrt(mean ‖Δ_k‖²): an RMSE (= ape_trans_rmse)"),
    "e_T_max": ("m", _P1 + " eq. 28", "e^T_max = max ‖Δ_k‖ (= ape_trans_max)"),
    "e_x_max": ("m", _P1 + " Table A1", "max |Δ_k,x|"),
    "e_y_max": ("m", _P1 + " Table A1", "max |Δ_k,y|"),
    "e_z_max": ("m", _P1 + " Table A1", "max |Δ_k,z|"),
    "e_x_avg": ("m", _P1 + " Table A1", "mean |Δ_k,x|"),
    "e_y_avg": ("m", _P1 + " Table A1", "mean |Δ_k,y|"),
    "e_z_avg": ("m", _P1 + " Table A1", "mean |Δ_k,z|"),
    "e_R_avg": ("deg", _P1 + " eq. 29", "e^R_avg = sqrt(mean θ_k²), θ_k geodesic: an RMSE"),
    "e_R_max": ("deg", _P1 + " eq. 30", "e^R_max = max θ_k"),
    "e_R_euler_avg": ("deg", _P1 + " (legacy)", "sqrt(mean ē_k²), ē_k = mean-Euler difference"),
    "e_R_euler_peak": ("deg", _P1 + " (legacy)", "signed ē_k of largest magnitude (can be < 0)"),
    "e_RT": ("m² + deg²", _P1 + " eq. 31", "e^RT = e_RT_trans + e_RT_rot (Burgard, consecutive)"),
    "e_RT_trans": ("m²", _P1 + " eq. 31", "mean ‖t(E_k)‖² over consecutive frames"),
    "e_RT_rot": ("deg²", _P1 + " eq. 31", "mean angle(E_k)² over consecutive frames"),
    "rpe_delta": ("", "evo --delta", "RPE pair distance (unit in rpe_delta_unit)"),
    "time_ms": ("ms", "relnav", "processing time per frame"),
}
for _rel, _what, _unit in (
    ("ape_trans", "evo_ape -r trans_part: ‖t(T_gt⁻¹ T_est)‖", "m"),
    ("ape_rot", "evo_ape -r angle_deg: angle(T_gt⁻¹ T_est)", "deg"),
    ("rpe_trans", "evo_rpe -r trans_part: ‖t(E_i)‖", "m"),
    ("rpe_rot", "evo_rpe -r angle_deg: angle(E_i)", "deg"),
):
    for _stat in STAT_NAMES:
        _u = _unit + "²" if _stat == "sse" else _unit
        METRIC_DOCS[f"{_rel}_{_stat}"] = (_u, "evo", f"{_stat} of {_what}")
for _old, _new in DEPRECATED_ALIASES.items():
    METRIC_DOCS[_old] = (METRIC_DOCS[_new][0], "deprecated", f"alias of {_new}")
"""Every metric key → ``(unit, origin, definition)``: the single place metrics are named."""


def metric_units(e_rt_rot_unit: AngleUnit = "deg") -> dict[str, str]:
    """Unit of every key of :func:`compute_metrics` (``""`` for counts).

    Parameters
    ----------
    e_rt_rot_unit : {"deg", "rad"}
        Angle unit used inside ``e^RT`` (see :func:`compute_metrics`).
    """
    a2 = "deg²" if e_rt_rot_unit == "deg" else "rad²"
    units = {k: v[0] for k, v in METRIC_DOCS.items()}
    units |= {
        "n_frames": "",
        "path_length": "m",
        "duration_s": "s",
        "drift": "m",
        "T_error_pct": "%",
        "e_RT": f"m² + {a2}",
        "e_RT_trans": "m²",
        "e_RT_rot": a2,
        "ape_trans_rmse": "m",
        "ape_rot_rmse_deg": "deg",
        "rpe_trans_rmse": "m",
        "rpe_rot_rmse_deg": "deg",
        "rpe_delta": "frames",
        "time_ms": "ms",
    }
    for k in METRIC_KEYS:
        if k.startswith("e_R_"):
            units.setdefault(k, "deg")
        elif k.startswith(("e_T_", "e_x", "e_y", "e_z")):
            units.setdefault(k, "m")
    return units


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
# association
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _greedy_pairs(ci: np.ndarray, cj: np.ndarray, n_i: int, n_j: int) -> np.ndarray:
    """Accept candidate pairs in the given order when both ends are still free."""
    used_i = np.zeros(n_i, dtype=np.bool_)
    used_j = np.zeros(n_j, dtype=np.bool_)
    keep = np.zeros(ci.shape[0], dtype=np.bool_)
    for k in range(ci.shape[0]):
        i = ci[k]
        j = cj[k]
        if not used_i[i] and not used_j[j]:
            used_i[i] = True
            used_j[j] = True
            keep[k] = True
    return keep


def associate(
    t_est: np.ndarray,
    t_gt: np.ndarray,
    *,
    max_diff: float = 0.01,
    offset: float = 0.0,
    n_candidates: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Associate estimated and ground-truth timestamps one-to-one by nearest time.

    Candidate pairs ``(i, j)`` with ``|t_est[i] + offset − t_gt[j]| <= max_diff`` are accepted
    greedily in order of increasing time difference, each timestamp being used at most once
    (the TUM benchmark's ``associate.py``). Neither input needs to be sorted.

    Parameters
    ----------
    t_est : (N,) float64
        Timestamps of the estimated poses, seconds.
    t_gt : (M,) float64
        Timestamps of the ground-truth poses, seconds.
    max_diff : float
        Largest accepted time difference, seconds (evo's default 0.01).
    offset : float
        Constant added to ``t_est`` before matching, seconds (evo ``--t_offset``, TUM
        ``--offset``).
    n_candidates : int
        Ground-truth neighbours considered on each side of every estimated stamp
        **[interpretation]**: bounds the work to ``O(N log M)``; it only matters when many
        ground-truth stamps fall inside one ``max_diff`` window.

    Returns
    -------
    idx_est, idx_gt : (K,) int64
        Matched indices into ``t_est`` and ``t_gt``, sorted by ``idx_est``.

    Raises
    ------
    InputError
        Non-1-D or non-finite timestamps, negative or non-finite ``max_diff``/``offset``.
    """
    te = _as_times("t_est", t_est) + float(offset)
    tg = _as_times("t_gt", t_gt)
    if not (np.isfinite(max_diff) and max_diff >= 0):
        raise InputError(f"max_diff must be a finite number >= 0 s, got {max_diff}")
    if not np.isfinite(offset):
        raise InputError(f"offset must be finite, got {offset}")
    if n_candidates < 1:
        raise InputError(f"n_candidates must be >= 1, got {n_candidates}")
    empty = np.zeros(0, dtype=np.int64)
    if te.size == 0 or tg.size == 0:
        return empty, empty.copy()
    order = np.argsort(tg, kind="stable")
    tg_sorted = tg[order]
    pos = np.searchsorted(tg_sorted, te)
    shifts = np.arange(-n_candidates, n_candidates)
    ci = np.repeat(np.arange(te.size), shifts.size)
    cj = (pos[:, None] + shifts[None, :]).ravel()
    ok = (cj >= 0) & (cj < tg.size)
    ci, cj = ci[ok], cj[ok]
    diff = np.abs(te[ci] - tg_sorted[cj])
    ok = diff <= max_diff
    ci, cj, diff = ci[ok], cj[ok], diff[ok]
    # smallest |Δt| first; ties broken by estimate index, then ground-truth index
    srt = np.lexsort((cj, ci, diff))
    ci, cj = ci[srt].astype(np.int64), cj[srt].astype(np.int64)
    keep = _greedy_pairs(ci, cj, te.size, tg.size)
    idx_est = ci[keep]
    idx_gt = order[cj[keep]].astype(np.int64)
    srt = np.argsort(idx_est, kind="stable")
    return idx_est[srt], idx_gt[srt]


# --------------------------------------------------------------------------------------------
# alignment
# --------------------------------------------------------------------------------------------


def align_trajectory(
    est_poses: np.ndarray, gt_poses: np.ndarray, method: AlignMethod = "none"
) -> tuple[np.ndarray, np.ndarray]:
    """Express an estimated trajectory in the ground-truth frame.

    Parameters
    ----------
    est_poses, gt_poses : (N, 4, 4) float64
        Associated absolute poses (row ``k`` of both belongs to the same time).
    method : {"none", "first", "se3", "sim3"}
        ``"none"``: unchanged (the estimate already lives in the GT frame, e.g. both
        ``T_target_sensor`` starting from the same first pose). ``"first"``: left-multiply by
        ``T_gt[0] T_est[0]⁻¹`` so the first poses coincide (evo ``--align_origin``).
        ``"se3"``: least-squares rigid alignment of the positions (Umeyama, evo ``--align``;
        needs 3 poses, ill-posed for collinear positions). ``"sim3"``: the same with a scale
        ``s`` (evo ``--align --correct_scale``): positions become ``s R t_k + t``, rotations
        ``R R_k`` (the aligned poses stay rigid).

    Returns
    -------
    aligned : (N, 4, 4) float64
        The estimate in the GT frame (:func:`apply_alignment`).
    T_align : (4, 4) float64
        The applied transform (GT frame ← estimate frame); for ``"sim3"`` a similarity whose
        rotation block is ``s R``.
    """
    est = _as_poses("est_poses", est_poses)
    gt = _as_poses("gt_poses", gt_poses)
    if est.shape != gt.shape:
        raise InputError(f"est_poses {est.shape} and gt_poses {gt.shape} differ in length")
    if method == "none":
        T = np.eye(4)
    elif method == "first":
        if len(est) == 0:
            raise InputError("align='first' needs at least one pose")
        T = gt[0] @ invert(est[0])
    elif method == "se3":
        if len(est) < 3:
            raise EstimationError(f"align='se3' needs at least 3 matched poses, got {len(est)}")
        T, _ = umeyama(est[:, :3, 3], gt[:, :3, 3])
    elif method == "sim3":
        if len(est) < 3:
            raise EstimationError(f"align='sim3' needs at least 3 matched poses, got {len(est)}")
        T, _ = umeyama(est[:, :3, 3], gt[:, :3, 3], with_scale=True)
    else:
        raise InputError(f"unknown alignment {method!r}; choose one of {', '.join(ALIGN_METHODS)}")
    return apply_alignment(T, est), T


def apply_alignment(T_align: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Apply a rigid or similarity alignment ``T_align`` (rotation block ``s R``) to poses.

    Positions map to ``s R t_k + t``, rotations to ``R R_k``; for ``s = 1`` this is
    ``T_align @ poses``. Returns ``(N, 4, 4)`` rigid poses.
    """
    P = np.asarray(poses, dtype=np.float64)
    T = np.asarray(T_align, dtype=np.float64)
    sR = T[:3, :3]
    s = float(np.cbrt(np.linalg.det(sR)))
    out = P.copy()
    out[:, :3, :3] = (sR / s) @ P[:, :3, :3]
    out[:, :3, 3] = P[:, :3, 3] @ sR.T + T[:3, 3]
    return out


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


# --------------------------------------------------------------------------------------------
# scalar metrics
# --------------------------------------------------------------------------------------------


def compute_metrics(
    est_poses: np.ndarray,
    gt_poses: np.ndarray,
    *,
    times: np.ndarray | None = None,
    frame_time_s: float | np.ndarray | None = None,
    delta: float = 1,
    rpe_all_pairs: bool = False,
    rotation_error: RotationError = "geodesic",
    e_rt_rot_unit: AngleUnit = "deg",
    delta_unit: DeltaUnit = "frames",
) -> dict[str, float]:
    """All trajectory metrics of Paper 1 §3.2 plus APE/RPE, on already associated poses.

    Parameters
    ----------
    est_poses, gt_poses : (N, 4, 4) float64, N >= 2
        Estimated and ground-truth absolute poses in the same frame (e.g. both
        ``T_target_sensor``), row ``k`` of both at the same time. No alignment is done here
        (see :func:`align_trajectory`).
    times : (N,) float64, optional
        Timestamps, seconds; only used for ``duration_s`` (NaN when absent).
    frame_time_s : float or (N,) float64, optional
        Processing time per frame, seconds; ``time_ms`` is its mean in milliseconds (NaN when
        absent).
    delta : int or float
        Pair distance of the RPE (evo ``--delta``) in ``delta_unit``. ``e^RT`` always uses
        consecutive frames (Paper 1).
    delta_unit : {"frames", "m", "deg", "rad"}
        Unit of ``delta`` (evo ``--delta_unit``); see :func:`rpe_pairs`.
    rpe_all_pairs : bool
        RPE over every frame pair ``(i, i + delta)`` instead of evo's default non-overlapping
        pairs ``(0, Δ), (Δ, 2Δ), …`` (see :func:`relative_pose_errors`).
    rotation_error : {"geodesic", "euler_mean_diff"}
        Definition behind ``e_R_avg`` / ``e_R_max`` **[interpretation]**. ``"geodesic"``
        (default): ``θ_k = angle(R_k^GTᵀ R_k^est)``, ``e_R_avg = sqrt(mean θ_k²)``,
        ``e_R_max = max θ_k``. ``"euler_mean_diff"``: Paper 1's signed legacy reading
        ``ē_k = mean(eul(R_k^GT)) − mean(eul(R_k^est))`` (extrinsic xyz Euler, degrees),
        ``e_R_avg = sqrt(mean ē_k²)``, ``e_R_max`` = the signed ``ē_k`` of largest magnitude.
        Both readings are always reported as well (``e_R_*`` follows the option,
        ``e_R_euler_*`` is always the legacy one; ``ape_rot_rmse_deg`` is always geodesic).
    e_rt_rot_unit : {"deg", "rad"}
        Angle unit of the rotational term of ``e^RT`` **[interpretation]**: the paper adds
        squared metres and squared angles without saying which angle unit; degrees by default.

    Returns
    -------
    dict[str, float]
        Keys :data:`METRIC_KEYS` (units from :func:`metric_units`):

        - ``e_T_avg = sqrt(mean_k ‖Δ_k‖²)``, ``e_T_max = max_k ‖Δ_k‖`` with
          ``Δ_k = t(T_k^GT) − t(T_k^est)`` (eqs. 27–28, "avg(·)" read as the norm of the 3-axis
          error **[interpretation]**, which matches Table A1); ``e_T_avg == ape_trans_rmse``.
        - ``e_{x,y,z}_max = max_k |Δ_k,axis|``, ``e_{x,y,z}_avg = mean_k |Δ_k,axis|``.
        - ``drift = ‖Δ_N‖`` (end-point error), ``T_error_pct = 100 drift / path_length``
          (NaN for a GT path of zero length), ``path_length = Σ ‖t_{k+1}^GT − t_k^GT‖``.
        - ``e_RT = e_RT_trans + e_RT_rot`` (eq. 31, Burgard et al. 2009, consecutive frames):
          ``e_RT_trans = mean ‖t(E_k)‖²`` (m²) and ``e_RT_rot = mean angle(E_k)²`` with
          ``E_k = (δ_k^GT)⁻¹ δ_k^est``, ``δ_k = T_k⁻¹ T_{k+1}``. No square root (as printed);
          equals ``rpe_trans_rmse² + rpe_rot_rmse_deg²`` when ``delta == 1``.
        - ``{ape,rpe}_{trans,rot}_{rmse,mean,median,std,min,max,sse}``: evo's statistics of
          its APE / RPE (``translation_part`` in m, ``rotation_angle_deg`` in deg) of
          ``T_gt⁻¹ T_est``, resp. ``E_i`` over ``delta`` (:data:`EVO_KEYS`).
        - Deprecated aliases :data:`DEPRECATED_ALIASES` (same values).

    Raises
    ------
    InputError
        Shapes differ, fewer than ``max(2, delta + 1)`` poses, non-rigid or non-finite poses,
        bad ``times`` / ``frame_time_s``, unknown option values.
    """
    est = _as_poses("est_poses", est_poses)
    gt = _as_poses("gt_poses", gt_poses)
    if est.shape != gt.shape:
        raise InputError(f"est_poses {est.shape} and gt_poses {gt.shape} differ in length")
    n = len(est)
    if n < 2:
        raise InputError(f"need at least 2 associated poses to compute metrics, got {n}")
    if rotation_error not in ("geodesic", "euler_mean_diff"):
        raise InputError(
            f"rotation_error must be 'geodesic' or 'euler_mean_diff', got {rotation_error!r}"
        )
    if e_rt_rot_unit not in ("deg", "rad"):
        raise InputError(f"e_rt_rot_unit must be 'deg' or 'rad', got {e_rt_rot_unit!r}")
    if delta_unit not in DELTA_UNITS:
        raise InputError(f"unknown RPE delta unit {delta_unit!r}; choose one of {DELTA_UNITS}")
    if delta_unit == "frames":
        if isinstance(delta, bool) or int(delta) != delta or delta < 1:
            raise InputError(f"delta must be an integer >= 1 frame, got {delta}")
        delta = int(delta)
        if n <= delta:
            raise InputError(
                f"RPE over delta={delta} frames needs more than {delta} poses, got {n}"
            )
    elif not (np.isfinite(delta) and delta > 0):
        raise InputError(f"delta must be > 0 {delta_unit}, got {delta}")

    duration = float("nan")
    if times is not None:
        t = _as_times("times", times)
        if t.shape != (n,):
            raise InputError(f"times: expected shape ({n},), got {t.shape}")
        duration = float(t.max() - t.min())

    time_ms = float("nan")
    if frame_time_s is not None:
        ft = np.asarray(frame_time_s, dtype=np.float64)
        if ft.ndim > 1 or (ft.ndim == 1 and ft.shape != (n,)):
            raise InputError(f"frame_time_s: expected a scalar or shape ({n},), got {ft.shape}")
        if not (np.isfinite(ft).all() and (ft >= 0).all()):
            raise InputError("frame_time_s: processing times must be finite and >= 0 s")
        time_ms = 1000.0 * float(np.mean(ft))

    pe = pose_errors(est, gt)
    abs_delta = np.abs(pe.delta)
    path_length = float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())
    drift = float(pe.trans[-1])
    if path_length > 0:
        t_err_pct = 100.0 * drift / path_length
    else:
        log.warning("ground-truth path length is zero: T_error_pct is undefined (NaN)")
        t_err_pct = float("nan")

    eul = pe.euler_mean_diff_deg
    eul_avg = _rms(eul)
    eul_max = float(eul[int(np.argmax(np.abs(eul)))])
    if rotation_error == "geodesic":
        e_r_avg, e_r_max = _rms(pe.rot_deg), float(pe.rot_deg.max())
    else:
        e_r_avg, e_r_max = eul_avg, eul_max

    rt_trans, rt_rot_deg = relative_pose_errors(est, gt, delta=1)
    rt_rot = rt_rot_deg if e_rt_rot_unit == "deg" else np.radians(rt_rot_deg)
    e_rt_trans = float(np.mean(rt_trans**2))
    e_rt_rot = float(np.mean(rt_rot**2))

    rpe_trans, rpe_rot = (
        (rt_trans, rt_rot_deg)
        if delta == 1 and delta_unit == "frames"
        else relative_pose_errors(
            est, gt, delta=delta, all_pairs=rpe_all_pairs, delta_unit=delta_unit
        )
    )

    out: dict[str, float] = {
        "n_frames": float(n),
        "path_length": path_length,
        "duration_s": duration,
        "drift": drift,
        "T_error_pct": t_err_pct,
        "e_T_avg": _rms(pe.trans),
        "e_T_max": float(pe.trans.max()),
        "e_x_max": float(abs_delta[:, 0].max()),
        "e_y_max": float(abs_delta[:, 1].max()),
        "e_z_max": float(abs_delta[:, 2].max()),
        "e_x_avg": float(abs_delta[:, 0].mean()),
        "e_y_avg": float(abs_delta[:, 1].mean()),
        "e_z_avg": float(abs_delta[:, 2].mean()),
        "e_R_avg": e_r_avg,
        "e_R_max": e_r_max,
        "e_R_euler_avg": eul_avg,
        "e_R_euler_max": eul_max,
        "e_R_euler_peak": eul_max,
        "e_RT": e_rt_trans + e_rt_rot,
        "e_RT_trans": e_rt_trans,
        "e_RT_rot": e_rt_rot,
        "ape_trans_rmse": _rms(pe.trans),
        "ape_rot_rmse_deg": _rms(pe.rot_deg),
        "rpe_trans_rmse": _rms(rpe_trans),
        "rpe_rot_rmse_deg": _rms(rpe_rot),
        "rpe_delta": float(delta),
        "time_ms": time_ms,
    }
    for rel, errors in (
        ("ape_trans", pe.trans),
        ("ape_rot", pe.rot_deg),
        ("rpe_trans", rpe_trans),
        ("rpe_rot", rpe_rot),
    ):
        for stat, v in error_statistics(errors).items():
            out[f"{rel}_{stat}"] = v
    return out


# --------------------------------------------------------------------------------------------
# association + alignment + metrics
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MatchedTrajectories:
    """Estimated and ground-truth poses after timestamp association and alignment.

    Attributes
    ----------
    times : (K,) float64
        Ground-truth timestamps of the matched pairs, seconds.
    est_poses, gt_poses : (K, 4, 4) float64
        Aligned estimate and ground truth, row ``k`` at the same time.
    idx_est, idx_gt : (K,) int64
        Indices into the original inputs, in ground-truth time order (whatever the row order
        of the inputs).
    T_align : (4, 4) float64
        Transform applied to the estimate (GT frame ← estimate frame).
    n_est, n_gt : int
        Number of poses in the original estimate and ground truth.
    align : str
        Alignment method used.
    """

    times: np.ndarray
    est_poses: np.ndarray
    gt_poses: np.ndarray
    idx_est: np.ndarray
    idx_gt: np.ndarray
    T_align: np.ndarray
    n_est: int
    n_gt: int
    align: str


def match_trajectories(
    t_est: np.ndarray,
    est_poses: np.ndarray,
    t_gt: np.ndarray,
    gt_poses: np.ndarray,
    *,
    max_diff: float = 0.01,
    offset: float = 0.0,
    align: AlignMethod = "none",
    min_matches: int = 2,
) -> MatchedTrajectories:
    """Associate two timestamped trajectories (:func:`associate`) and align them.

    Raises
    ------
    InputError
        Timestamps and poses differ in length, or bad poses/timestamps.
    EstimationError
        Fewer than ``min_matches`` (>= 2) estimated poses matched a ground-truth timestamp;
        the message says how many matched.
    """
    te = _as_times("t_est", t_est)
    tg = _as_times("t_gt", t_gt)
    est = _as_poses("est_poses", est_poses)
    gt = _as_poses("gt_poses", gt_poses)
    if len(te) != len(est):
        raise InputError(f"t_est has {len(te)} stamps but est_poses has {len(est)} poses")
    if len(tg) != len(gt):
        raise InputError(f"t_gt has {len(tg)} stamps but gt_poses has {len(gt)} poses")
    if align not in ALIGN_METHODS:
        raise InputError(f"unknown alignment {align!r}; choose one of {', '.join(ALIGN_METHODS)}")
    for name, t in (("estimate", te), ("ground truth", tg)):
        n_dup = int(t.size - np.unique(t).size)
        if n_dup:
            log.warning(
                "%s: %d poses share their timestamp with another; such poses are matched "
                "in row order",
                name,
                n_dup,
            )
    idx_est, idx_gt = associate(te, tg, max_diff=max_diff, offset=offset)
    # time order, not file row order: the relative metrics follow the trajectory
    srt = np.lexsort((idx_est, tg[idx_gt]))
    idx_est, idx_gt = idx_est[srt], idx_gt[srt]
    k = len(idx_est)
    need = max(2, int(min_matches))
    if k < need:
        raise EstimationError(
            f"only {k} of {len(te)} estimated poses matched a ground-truth timestamp "
            f"(max_diff={max_diff:g} s, offset={offset:g} s, {len(tg)} ground-truth poses)"
        )
    if k < min(len(te), len(tg)):
        log.info(
            "matched %d of %d estimated poses (%d ground-truth poses, max_diff=%g s)",
            k,
            len(te),
            len(tg),
            max_diff,
        )
    est_m, gt_m = est[idx_est], gt[idx_gt]
    aligned, T = align_trajectory(est_m, gt_m, align)
    return MatchedTrajectories(
        times=tg[idx_gt],
        est_poses=aligned,
        gt_poses=gt_m,
        idx_est=idx_est,
        idx_gt=idx_gt,
        T_align=T,
        n_est=len(te),
        n_gt=len(tg),
        align=align,
    )


def evaluate_trajectories(
    t_est: np.ndarray,
    est_poses: np.ndarray,
    t_gt: np.ndarray,
    gt_poses: np.ndarray,
    *,
    max_diff: float = 0.01,
    offset: float = 0.0,
    align: AlignMethod = "none",
    delta: float = 1,
    rpe_all_pairs: bool = False,
    frame_time_s: float | np.ndarray | None = None,
    rotation_error: RotationError = "geodesic",
    e_rt_rot_unit: AngleUnit = "deg",
    delta_unit: DeltaUnit = "frames",
) -> dict[str, float | str]:
    """Associate by timestamp, align, and compute every metric of :func:`compute_metrics`.

    Parameters
    ----------
    t_est : (N,) float64
        Estimate timestamps, seconds.
    est_poses : (N, 4, 4) float64
        Estimated absolute poses.
    t_gt : (M,) float64
        Ground-truth timestamps, seconds.
    gt_poses : (M, 4, 4) float64
        Ground-truth absolute poses.
    max_diff, offset
        See :func:`associate` (seconds).
    align : {"none", "first", "se3", "sim3"}
        See :func:`align_trajectory`.
    delta, rpe_all_pairs, rotation_error, e_rt_rot_unit, delta_unit
        See :func:`compute_metrics`.
    frame_time_s : float or (N,) float64, optional
        Processing time per *estimated* frame, seconds.

    Returns
    -------
    dict
        :func:`compute_metrics` keys plus ``n_est``, ``n_gt``, ``n_matched`` (counts),
        ``max_diff``, ``offset`` (s), ``align`` and ``rpe_delta_unit`` (str) and
        ``align_scale`` (the ``sim3`` scale, 1 otherwise).

    Raises
    ------
    EstimationError
        Fewer than 2 matched poses (3 for ``align="se3"``); the message gives the count.
    InputError
        Malformed inputs.
    """
    m = match_trajectories(
        t_est,
        est_poses,
        t_gt,
        gt_poses,
        max_diff=max_diff,
        offset=offset,
        align=align,
        min_matches=3 if align in ("se3", "sim3") else 2,
    )
    ft = frame_time_s
    if ft is not None and np.ndim(ft) == 1:
        ft = np.asarray(ft, dtype=np.float64)
        if ft.shape != (m.n_est,):
            raise InputError(
                f"frame_time_s: expected one time per estimated pose ({m.n_est}), got {ft.shape}"
            )
        ft = ft[m.idx_est]
    out: dict[str, float | str] = dict(
        compute_metrics(
            m.est_poses,
            m.gt_poses,
            times=m.times,
            frame_time_s=ft,
            delta=delta,
            rpe_all_pairs=rpe_all_pairs,
            rotation_error=rotation_error,
            e_rt_rot_unit=e_rt_rot_unit,
            delta_unit=delta_unit,
        )
    )
    out.update(
        rpe_delta_unit=delta_unit,
        align_scale=float(np.cbrt(np.linalg.det(m.T_align[:3, :3]))),
        n_est=float(m.n_est),
        n_gt=float(m.n_gt),
        n_matched=float(len(m.idx_est)),
        max_diff=float(max_diff),
        offset=float(offset),
        align=align,
    )
    return out
