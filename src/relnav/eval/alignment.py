"""Spatial alignment of an estimated trajectory to the ground truth: ``"none"``, ``"first"``
(evo ``--align_origin``), ``"se3"`` (Umeyama) or ``"sim3"`` (Umeyama with scale).
"""

from __future__ import annotations

import logging

import numpy as np

from relnav.errors import EstimationError, InputError
from relnav.eval.metric_names import ALIGN_METHODS, AlignMethod
from relnav.eval.pose_errors import _as_poses
from relnav.geometry.se3 import invert, umeyama

__all__ = [
    "align_trajectory",
    "apply_alignment",
]

log = logging.getLogger(__name__)


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
