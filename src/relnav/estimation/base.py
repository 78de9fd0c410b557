"""TransformEstimator protocol, the :class:`Estimate` result, and the estimator registry.

An estimator turns correspondences between a source and a target cloud into one rigid
transform ``T_target_source`` (``target ≈ T @ source``). Paper 1's recursive filters consume the
correspondences one by one (ALGORITHMS §D); ``svd`` is the non-recursive Kabsch reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from relnav.errors import ConfigError
from relnav.matching.correspondences import Correspondences

__all__ = [
    "Estimate",
    "EstimateStatus",
    "TransformEstimator",
    "available_estimators",
    "estimator_factory",
    "get_estimator",
    "options_repr",
    "register_estimator",
]

EstimateStatus = Literal["ok", "degenerate", "failed"]


@dataclass
class Estimate:
    """Output of a :class:`TransformEstimator`.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        Estimated rigid transform (identity when ``status != "ok"``).
    covariance : (6, 6) float64 or None
        Covariance of the twist ``[rho, phi]`` (m, rad) when the estimator provides one.
    n_used : int
        Correspondences consumed.
    status : {"ok", "degenerate", "failed"}
        ``degenerate``: too few / collinear / coplanar correspondences to fix 6 DoF.
    converged : bool
        Whether the estimator considers its estimate converged.
    info : dict
        Estimator-specific diagnostics (e.g. final residual).
    """

    T_target_source: np.ndarray
    covariance: np.ndarray | None = None
    n_used: int = 0
    status: EstimateStatus = "ok"
    converged: bool = True
    info: dict = field(default_factory=dict)


class TransformEstimator(Protocol):
    """Anything with ``estimate(src_pts, tgt_pts, corr) -> Estimate``."""

    name: str

    def estimate(
        self, src_pts: np.ndarray, tgt_pts: np.ndarray, corr: Correspondences
    ) -> Estimate: ...


_REGISTRY: dict[str, tuple[Callable[..., TransformEstimator], str]] = {}


def register_estimator(
    name: str, description: str
) -> Callable[[Callable[..., TransformEstimator]], Callable[..., TransformEstimator]]:
    """Class decorator registering an estimator factory under ``name``."""

    def deco(cls: Callable[..., TransformEstimator]) -> Callable[..., TransformEstimator]:
        _REGISTRY[name] = (cls, description)
        return cls

    return deco


def _load_all() -> None:
    from relnav.estimation import alphabeta, hinf, icp_refine, kalman, sdre, svd  # noqa: F401


def available_estimators() -> dict[str, str]:
    """Registered estimator names with their one-line description."""
    _load_all()
    return {k: v[1] for k, v in _REGISTRY.items()}


def estimator_factory(name: str) -> Callable[..., TransformEstimator] | None:
    """The factory (class) registered as estimator ``name``, ``None`` if there is none."""
    _load_all()
    entry = _REGISTRY.get(name)
    return None if entry is None else entry[0]


def get_estimator(name: str, **options: object) -> TransformEstimator:
    """Instantiate the estimator registered as ``name`` with ``options``."""
    _load_all()
    if name not in _REGISTRY:
        raise ConfigError(f"unknown estimator {name!r}; available: {', '.join(sorted(_REGISTRY))}")
    try:
        return _REGISTRY[name][0](**options)
    except TypeError as e:
        raise ConfigError(f"bad options for estimator {name!r}: {e}") from None


def options_repr(estimator: Any) -> str:
    """``ClassName(option=value, ...)`` from ``estimator.options()``."""
    opts = ", ".join(f"{k}={v!r}" for k, v in estimator.options().items())
    return f"{type(estimator).__name__}({opts})"
