"""Frame-to-frame odometry: :class:`Odometry`, :func:`run_sequence` and the tracker protocol."""

from relnav.odometry.odometry import Odometry, OdometryStep
from relnav.odometry.runner import OdometryRun, run_sequence
from relnav.odometry.tracker import CAPABILITIES, Tracker, TrackerEntry

__all__ = [
    "CAPABILITIES",
    "Odometry",
    "OdometryRun",
    "OdometryStep",
    "Tracker",
    "TrackerEntry",
    "run_sequence",
]
