"""Paper 2's tracking chain on a sequence folder: scans → observer → pose filter.

:func:`track_sequence` builds per-frame observations from a two-sensor sequence folder with one
of paper 2's observers (:mod:`relnav.fusion.observers`: the contour model, or frame-to-frame
registration) and runs :class:`relnav.filtering.tracker.Tracker` (twistor UKF or quaternion EKF,
:mod:`relnav.filtering`) over them. Frames without an observation (a missing scan from one of the
sensors, a registration flagged as failed, a NaN observation) are **predicted through**: the
filter propagates its state and covariance and the step is flagged.

Frames
------
``s`` = primary sensor (camera) frame (x forward, y left, z up); ``b`` = target body frame of
the observer. The estimate is ``T_s_b`` (position ``d`` = origin of ``b`` in ``s``, attitude
``R_s_b``), velocity ``ḋ`` in ``s`` and body rates ``ω`` in ``b``. Observers built on a model
of the target (Paper 2's contour model, or the registration chain here) define ``b`` as the
model frame fixed to the target at the first observed frame, so ``b`` differs from the
simulator's mesh frame by a constant transform. Ground truth (sequence folders):
``T_s_target = inv(T_target_s)`` per frame; ``gt_alignment="mean"`` right-multiplies it by the
constant ``T_target_b`` that best matches the estimate (rotation: chordal mean of
``R_gt⁻¹ R_est``; translation: mean of ``R_gtᵀ (d_est − d_gt)``), ``"first"`` takes it from the
first estimated frame, ``"none"`` compares the mesh frame directly. A filter that estimates the
rotation centre (``centre_offset``) is compared with the rotation centre: ``"centre"`` keeps
only the axial part of that mean translation (the default ``"auto"`` picks it for such a
filter, ``"mean"`` otherwise). Truth velocity and body rates come from finite differences of
the aligned truth.

Euler angles are extrinsic ``xyz`` (roll about x, pitch about y, yaw about z; ``R = Rz Ry Rx``)
of ``R_s_b``, unwrapped over time (a spinning target's yaw keeps growing). Attitude errors are
the body-axis rotation vector of ``R_gtᵀ R_est`` (degrees in reports).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError, InputError, RelnavError
from relnav.filtering.pose_filter import PoseFilter
from relnav.filtering.track_result import TrackResult, TrackTruth
from relnav.filtering.tracker import FilterName, Observation, Tracker, TrackLog
from relnav.fusion.observer_noise import (
    CALIBRATION_FILTER_OPTIONS,
    ObserverNoise,
    calibrated_noise,
)
from relnav.fusion.observers import (
    ContourObserver,
    Observer,
    RegistrationObserver,
    _default_observer,
)
from relnav.geometry.rotations import project_to_so3, quat_to_matrix
from relnav.geometry.se3 import invert

__all__ = ["track_sequence"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# paper 2's chain on a sequence folder
# --------------------------------------------------------------------------------------------


def _observer_noise(
    value: ObserverNoise | Literal["reported"] | str | Path | None, rate_known: bool
) -> ObserverNoise | Literal["reported"]:
    """``track_sequence``'s ``observer_noise`` as the contour observer takes it (``None`` and
    ``"calibrated"``: :func:`relnav.fusion.observer_noise.calibrated_noise` of the loop)."""
    if value is None or (isinstance(value, str) and value == "calibrated"):
        return calibrated_noise(rate_known)
    if isinstance(value, ObserverNoise):
        return value
    if isinstance(value, str) and value == "reported":
        return "reported"
    if isinstance(value, str | Path):
        return ObserverNoise.load(value)
    raise ConfigError(
        f"observer_noise: expected a model, 'calibrated', 'reported' or a path, got {value!r}"
    )


def _align_truth(
    T_gt: np.ndarray, est_pos: np.ndarray, est_quat: np.ndarray, how: str
) -> tuple[np.ndarray, np.ndarray]:
    """Right-multiply truth poses ``(K, 4, 4)`` by a constant ``T_target_b``; returns the
    aligned poses and the alignment."""
    A = np.eye(4)
    ok = np.all(np.isfinite(est_pos), axis=1) & np.all(np.isfinite(est_quat), axis=1)
    if how == "none" or not np.any(ok):
        return T_gt.copy(), A
    R_est = quat_to_matrix(est_quat[ok])
    R_gt = T_gt[ok, :3, :3]
    rel_R = np.swapaxes(R_gt, 1, 2) @ R_est
    rel_t = np.einsum("kji,kj->ki", R_gt, est_pos[ok] - T_gt[ok, :3, 3])
    if how == "first":
        A[:3, :3] = project_to_so3(rel_R[0])
        A[:3, 3] = rel_t[0]
    elif how == "mean":
        A[:3, :3] = project_to_so3(rel_R.sum(axis=0))
        A[:3, 3] = rel_t.mean(axis=0)
    elif how == "first-rotation":
        A[:3, :3] = project_to_so3(rel_R[0])
        A[:3, 3] = rel_t.mean(axis=0)
    elif how == "centre":
        A[:3, :3] = project_to_so3(rel_R[0])
        u = _spin_axis(T_gt[:, :3, :3])
        m = rel_t.mean(axis=0)
        A[:3, 3] = m if u is None else u * float(u @ m)
    else:
        raise ConfigError(
            "gt_alignment must be 'auto', 'mean', 'first', 'first-rotation', 'centre' or "
            "'none', got " + repr(how)
        )
    return T_gt @ A, A


def _spin_axis(R_gt: np.ndarray) -> np.ndarray | None:
    """Unit spin axis ``(3,)`` of truth attitudes ``R_s_target`` ``(K, 3, 3)`` in target axes:
    the principal direction of the frame-to-frame rotation vectors ``log(R_kᵀ R_k+1)``
    (``None`` when the target does not turn)."""
    from scipy.spatial.transform import Rotation

    if len(R_gt) < 2:
        return None
    inc = Rotation.from_matrix(np.swapaxes(R_gt[:-1], 1, 2) @ R_gt[1:]).as_rotvec()
    inc = inc[np.all(np.isfinite(inc), axis=1)]
    if len(inc) == 0 or float(np.max(np.linalg.norm(inc, axis=1))) < 1e-9:
        return None
    return np.linalg.eigh(inc.T @ inc)[1][:, -1]


def _associate(t_primary: np.ndarray, t_other: np.ndarray) -> np.ndarray:
    """Index into ``t_other`` of the scan nearest each primary time within half a frame period
    (−1 when none)."""
    out = np.full(len(t_primary), -1, dtype=np.int64)
    if len(t_other) == 0 or len(t_primary) == 0:
        return out
    steps = np.diff(t_primary)
    steps = steps[steps > 0]
    tol = 0.5 * float(np.median(steps)) if len(steps) else 1e-3
    order = np.argsort(t_other)
    ts = t_other[order]
    j = (
        np.clip(np.searchsorted(ts, t_primary), 1, len(ts) - 1)
        if len(ts) > 1
        else np.zeros(len(t_primary), dtype=np.int64)
    )
    for i, tp in enumerate(t_primary):
        cands = [j[i]] if len(ts) == 1 else [j[i] - 1, j[i]]
        best = min(cands, key=lambda c: abs(ts[c] - tp))
        if abs(ts[best] - tp) <= tol:
            out[i] = order[best]
    return out


def track_sequence(
    seq_dir: str | Path,
    *,
    filter: FilterName | str = "ukf",
    observer: Observer | str | None = None,
    second_sensor: str | None = "auto",
    max_frames: int | None = None,
    require_all_sensors: bool = True,
    gt_alignment: Literal["auto", "mean", "first", "first-rotation", "centre", "none"] = "auto",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    observer_noise: ObserverNoise | Literal["reported"] | str | Path | None = None,
    **tracker_options: Any,
) -> TrackResult:
    """Track the target over a sequence folder (primary camera + optional second sensor).

    Parameters
    ----------
    seq_dir : str or Path
        Sequence folder (``scans/`` = camera; ``scans_<name>/`` = second sensor).
    filter : {"ukf", "ekf"}
    observer : Observer, {"contour", "registration"} or None
        ``None``: the contour-model chain when :mod:`relnav.fusion.reconstruction` is
        available and a second sensor exists, else :class:`RegistrationObserver`.
    second_sensor : str or None
        Name of the second sensor; ``"auto"`` = the first ``scans_<name>/`` found; ``None`` =
        camera only.
    max_frames : int, optional
        Use the first N camera frames.
    require_all_sensors : bool
        A frame where any used sensor has no scan (no scan within half a frame period, or an
        empty scan) gets no observation (predicted through, ``"flagged: missing scan"``).
    gt_alignment : {"auto", "mean", "first", "first-rotation", "centre", "none"}
        How truth is expressed in the estimate's body frame (module docstring).
        ``"first-rotation"``: rotation from the first estimated frame (exact for the contour
        and registration observers, whose body axes are by definition the sensor axes at
        their first observation and which initialize the filter there), translation the mean
        offset. ``"centre"``: the same rotation; the truth point is the target's rotation
        centre (its frame origin) moved along the spin axis only, by the mean offset's axial
        component — the point a ``centre_offset`` filter estimates (its position along the
        axis is unobservable), so that an error of the estimated centre across the axis is
        counted, not aligned away. ``"auto"`` (default): ``"centre"`` when the filter
        estimates a centre offset, else ``"mean"``.
    seed : int
        Seed of the observer's random choices (recorded in ``meta``).
    progress : callable, optional
        ``progress(done, total)``.
    observer_noise : ObserverNoise, "calibrated", "reported" or path, optional
        The contour observer's noise (:class:`ContourObserver` ``noise``): ``None`` or
        ``"calibrated"`` = :func:`relnav.fusion.observer_noise.calibrated_noise` (the model
        calibrated with ``omega0`` given, or the one without when it is not), a path =
        a JSON model (:meth:`ObserverNoise.save`). Only with the contour observer built here.
    **tracker_options
        Passed to :class:`Tracker` (``n_mean_motion``, ``orbit_radius_m``, ``q``, ``r`` …).
        With the UKF and the contour observer, ``centre_offset`` and ``observer_bias`` default
        to ``True`` (:class:`relnav.filtering.ukf.TwistorUKF`): its reference point is the first
        frame's centroid, which circles the spin axis, and its model drifts; with a calibrated
        noise model (not ``"reported"``) also the options it was calibrated with,
        ``bias_frame="body"`` and ``robust_dof=8``. Without ``omega0`` (an unknown rate)
        ``init`` defaults to ``"rate"``: the initial rate from the first two observations.
        With ``merge_slots`` > 0 the merge states replace the bias (``observer_bias`` then
        defaults to ``False``).

    Returns
    -------
    TrackResult
        With ``truth`` when the primary sensor has a ground-truth file.

    Raises
    ------
    InputError
        Missing folder / scans; unknown second sensor.
    """
    from relnav.io.sequences import ScanSequence

    if observer_noise is not None and observer is not None and observer != "contour":
        if not isinstance(observer, ContourObserver):
            raise ConfigError("observer_noise is an option of the contour observer")
    noise = _observer_noise(observer_noise, tracker_options.get("omega0") is not None)
    folder = Path(seq_dir)
    cam = ScanSequence(folder)
    if len(cam) == 0:
        raise InputError(f"{folder}: no camera scans")
    others = [s for s in ScanSequence.sensors(folder) if s]
    second: str | None
    if second_sensor == "auto":
        second = others[0] if others else None
    else:
        second = second_sensor
        if second is not None and second not in others:
            raise InputError(f"{folder}: no scans_{second}/ (sensors present: {others})")
    sec = ScanSequence(folder, sensor=second) if second else None
    n = len(cam) if max_frames is None else max(0, min(len(cam), int(max_frames)))
    times = cam.timestamps[:n]
    assoc = _associate(times, sec.timestamps) if sec is not None else None

    if observer is None:
        obs_impl: Observer = _default_observer(second, seed, noise)
    elif isinstance(observer, str):
        if observer == "contour":
            if second is None:
                raise InputError("the contour observer needs a second sensor (scans_<name>/)")
            obs_impl = ContourObserver(lidar=second, seed=seed, noise=noise)
        elif observer.startswith("registration"):
            _, _, method = observer.partition(":")
            obs_impl = RegistrationObserver(method or "icp-point", seed=seed)
        else:
            raise ConfigError(
                f"unknown observer {observer!r}: 'contour' or 'registration[:method]'"
            )
    else:
        obs_impl = observer
    if observer_noise is not None and not isinstance(obs_impl, ContourObserver):
        raise ConfigError("observer_noise is an option of the contour observer")

    if str(filter).lower() == "ukf" and isinstance(obs_impl, ContourObserver):
        # the contour model's reference point circles the spin axis and the model drifts
        tracker_options.setdefault("centre_offset", True)
        if not tracker_options.get("merge_slots"):  # the merge states replace the bias
            tracker_options.setdefault("observer_bias", True)
            if obs_impl.noise != "reported":  # the filter its noise was calibrated with
                for key, value in CALIBRATION_FILTER_OPTIONS.items():
                    tracker_options.setdefault(key, value)
    if tracker_options.get("omega0") is None and tracker_options.get("init") is None:
        tracker_options["init"] = "rate"  # an unknown rate: from the first two attitudes
    tracker = Tracker(filter, **tracker_options)
    steps = np.diff(times)
    steps = steps[steps > 0]
    tracker.reset(float(np.median(steps)) if len(steps) else None)
    f = tracker.filter
    assert f is not None
    rec = TrackLog(n)
    for k in range(n):
        scans: dict[str, np.ndarray] = {"": cam[k].points}
        missing = len(scans[""]) == 0
        if sec is not None and assoc is not None and second is not None:
            j = int(assoc[k])
            if j >= 0:
                scans[second] = sec[j].points
                missing = missing or len(scans[second]) == 0
            else:
                missing = True
        o: Observation | None = None
        msg = ""
        if missing and require_all_sensors:
            msg = "missing scan"
        else:
            prior = None
            if tracker._initialized and tracker._t is not None:
                prior = _predicted_pose(f, float(times[k]) - tracker._t)
            try:
                o = obs_impl.observe(k, scans, prior)
                if o is None:
                    msg = "no observation"
            except RelnavError as e:
                msg = str(e)
        st, ni = tracker.step(float(times[k]), o)
        if msg and st in ("predict", "waiting"):
            st = f"flagged: {msg}"
        rec.record(k, f, tracker._initialized, st, ni, o)
        rec.lam[k] = tracker.lam
        if progress is not None:
            progress(k + 1, n)

    truth = None
    gt = cam.gt_poses
    meta: dict[str, Any] = {
        "sequence": str(folder),
        "observer": getattr(obs_impl, "name", type(obs_impl).__name__),
        "second_sensor": second,
        "seed": seed,
        "gt_alignment": gt_alignment,
        "observer_stats": dict(getattr(obs_impl, "stats", {}) or {}),
    }
    if isinstance(obs_impl, ContourObserver):  # the noise the observations carried
        n_ = obs_impl.noise
        meta["observer_noise"] = n_ if isinstance(n_, str) else n_.to_dict()
    if gt_alignment == "auto":
        gt_alignment = "centre" if getattr(f, "centre_offset", False) else "mean"
        meta["gt_alignment"] = gt_alignment
    if gt is not None:
        T_s_target = invert(gt[:n])
        T_aligned, A = _align_truth(T_s_target, rec.pos, rec.quat, gt_alignment)
        truth = TrackTruth.from_poses(times, T_aligned)
        meta["T_target_body"] = A.tolist()
    return rec.result(times, tracker.filter_name, f.settings(), truth, meta)


def _predicted_pose(f: PoseFilter, dt: float) -> np.ndarray:
    """``T_s_b`` of the observer's body frame (origin = the reference point) predicted ``dt``
    seconds ahead (mean only, the filter is not changed)."""
    T = np.eye(4)
    p, q = f.predicted_reference(dt)
    T[:3, :3] = quat_to_matrix(q)
    T[:3, 3] = p
    return T
