"""Transform estimators: paper 1's adaptive recursive filters and the SVD reference."""

from relnav.estimation.base import (
    Estimate,
    TransformEstimator,
    available_estimators,
    get_estimator,
    register_estimator,
)

__all__ = [
    "Estimate",
    "TransformEstimator",
    "available_estimators",
    "get_estimator",
    "register_estimator",
]
