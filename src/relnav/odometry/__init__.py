"""Frame-to-frame odometry: :class:`Odometry` and :func:`run_sequence`."""

from relnav.odometry.odometry import Odometry, OdometryStep
from relnav.odometry.runner import OdometryRun, run_sequence

__all__ = ["Odometry", "OdometryRun", "OdometryStep", "run_sequence"]
