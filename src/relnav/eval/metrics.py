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

Modules
-------
The names and units live in :mod:`relnav.eval.metric_names`, per-frame errors in
:mod:`relnav.eval.pose_errors`, association and alignment in :mod:`relnav.eval.association` and
:mod:`relnav.eval.alignment`; all are re-exported here.

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

import numpy as np

from relnav.errors import EstimationError, InputError
from relnav.eval.alignment import align_trajectory, apply_alignment
from relnav.eval.association import _greedy_pairs, associate  # noqa: F401 (old path of the kernel)
from relnav.eval.metric_names import (
    ALIGN_METHODS,
    DELTA_UNITS,
    DEPRECATED_ALIASES,
    EVO_KEYS,
    METRIC_DOCS,
    METRIC_KEYS,
    STAT_NAMES,
    AlignMethod,
    AngleUnit,
    DeltaUnit,
    RotationError,
    metric_units,
)
from relnav.eval.pose_errors import (
    PoseErrors,
    _as_poses,
    _as_times,
    _rms,
    error_statistics,
    pose_errors,
    relative_pose_errors,
    rpe_pairs,
)

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
