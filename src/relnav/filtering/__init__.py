"""General filters for a tumbling target's relative state: twistor UKF, quaternion EKF, tracker.

Not tied to either paper's front end: the filters take per-frame pose observations (position of a
reference point and attitude of the target in the sensor frame) and estimate position, velocity,
attitude and body rate with their covariance. Paper 2's chain (:mod:`relnav.fusion`) feeds them
contour-model observations; the navigator's relative state (:mod:`relnav.navigation.state`) feeds
them its own poses.

Why a package of its own and not :mod:`relnav.estimation`: ``estimation`` holds paper 1's
*transform estimators* — correspondences of one scan pair in, one rigid transform out, behind
the :class:`~relnav.estimation.base.TransformEstimator` registry the odometry chain plugs in.
The filters here run over time on a 12-dof body state (``d, ḋ, q, ω``) with orbital (CW)
dynamics; they share neither input, output nor interface with those estimators.

Modules: :mod:`~relnav.filtering.dynamics` (Clohessy–Wiltshire), :mod:`~relnav.filtering.noise`
(noise settings), :mod:`~relnav.filtering.pose_filter` (common base), :mod:`~relnav.filtering.ukf`
(twistor UKF), :mod:`~relnav.filtering.ekf` (quaternion EKF), :mod:`~relnav.filtering.tracker`
(:class:`Observation`, :class:`Tracker`), :mod:`~relnav.filtering.track_result` (output
containers), :mod:`~relnav.filtering.multiple_model` (a bank of filters mixed by likelihood).

Entry points are re-exported lazily (``import relnav.filtering`` stays cheap)::

    from relnav.filtering import Tracker, TwistorUKF
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "ClohessyWiltshire": "relnav.filtering.dynamics",
    "mean_motion": "relnav.filtering.dynamics",
    "TwistorUKF": "relnav.filtering.ukf",
    "QuaternionEKF": "relnav.filtering.ekf",
    "Observation": "relnav.filtering.tracker",
    "Tracker": "relnav.filtering.tracker",
    "make_filter": "relnav.filtering.tracker",
    "TrackResult": "relnav.filtering.track_result",
    "TrackTruth": "relnav.filtering.track_result",
    "mix_tracks": "relnav.filtering.multiple_model",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'relnav.filtering' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)
