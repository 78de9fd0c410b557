"""Transform estimators: paper 1's adaptive recursive filters and the SVD reference."""

from relnav.estimation.alphabeta import AlphaBetaEstimator
from relnav.estimation.base import (
    Estimate,
    TransformEstimator,
    available_estimators,
    get_estimator,
    register_estimator,
)
from relnav.estimation.hinf import HInfinityEstimator
from relnav.estimation.icp_refine import ICPRefineEstimator
from relnav.estimation.kalman import KalmanEstimator
from relnav.estimation.sdre import SDREEstimator
from relnav.estimation.svd import SVDEstimator

__all__ = [
    "AlphaBetaEstimator",
    "Estimate",
    "HInfinityEstimator",
    "ICPRefineEstimator",
    "KalmanEstimator",
    "SDREEstimator",
    "SVDEstimator",
    "TransformEstimator",
    "available_estimators",
    "get_estimator",
    "register_estimator",
]
