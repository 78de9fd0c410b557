"""Correspondence groupers by name: ``"gcc"``, ``"ransac"``, ``"clgv"``, ``"none"``.

A grouper selects the geometrically trustworthy subset of putative correspondences::

    grouper = get_grouper("gcc", epsilon_factor=2.0)
    kept = grouper.select(src_pts, tgt_pts, corr, resolution=Tr)

The distance tolerance (GCC ε, RANSAC/CLGV inlier threshold θ) is ``epsilon`` metres when given,
otherwise ``epsilon_factor · resolution`` (Paper 1: ``2·Tr``, ``Tr`` the mean nearest-neighbour
distance of the source cloud). After each call, ``grouper.info`` holds the diagnostics of the
last selection (tolerance used, seed, cluster/iteration counts).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.matching.clgv import clgv_vote
from relnav.matching.correspondences import Correspondences
from relnav.matching.gcc import geometric_consistency_grouping
from relnav.matching.ransac import ransac_search

__all__ = [
    "ClgvGrouper",
    "GccGrouper",
    "Grouper",
    "NoGrouper",
    "RansacGrouper",
    "available_groupers",
    "get_grouper",
    "grouper_factory",
    "register_grouper",
]

logger = logging.getLogger(__name__)

_NO_PTS = np.zeros((0, 3))


class Grouper(Protocol):
    """Anything with a ``name`` and ``select(src_pts, tgt_pts, corr, *, resolution)``."""

    name: str
    info: dict[str, Any]

    def select(
        self,
        src_pts: np.ndarray,
        tgt_pts: np.ndarray,
        corr: Correspondences,
        *,
        resolution: float | None,
    ) -> Correspondences: ...


_REGISTRY: dict[str, tuple[Callable[..., Grouper], str]] = {}


def register_grouper(
    name: str, description: str
) -> Callable[[Callable[..., Grouper]], Callable[..., Grouper]]:
    """Class decorator registering a grouper factory under ``name``."""

    def deco(cls: Callable[..., Grouper]) -> Callable[..., Grouper]:
        _REGISTRY[name] = (cls, description)
        return cls

    return deco


def available_groupers() -> dict[str, str]:
    """Registered grouper names with their one-line description."""
    return {k: v[1] for k, v in _REGISTRY.items()}


def grouper_factory(name: str) -> Callable[..., Grouper] | None:
    """The factory (class) registered as grouper ``name``, ``None`` if there is none."""
    entry = _REGISTRY.get(name)
    return None if entry is None else entry[0]


def get_grouper(name: str, **options: Any) -> Grouper:
    """Instantiate the grouper registered as ``name`` with ``options``.

    Raises
    ------
    ConfigError
        Unknown name, unknown option or invalid option value.
    """
    if name not in _REGISTRY:
        raise ConfigError(f"unknown grouper {name!r}; available: {', '.join(sorted(_REGISTRY))}")
    try:
        return _REGISTRY[name][0](**options)
    except TypeError as e:
        raise ConfigError(f"bad options for grouper {name!r}: {e}") from None


@dataclass(kw_only=True)
class _Tolerance:
    """Shared ``epsilon`` / ``epsilon_factor`` handling.

    Parameters
    ----------
    epsilon : float, optional
        Absolute tolerance in metres; overrides ``epsilon_factor``.
    epsilon_factor : float
        Tolerance in multiples of the resolution passed to ``select`` (Paper 1: 2).
    """

    name: str = field(default="", init=False)
    epsilon: float | None = None
    epsilon_factor: float = 2.0

    def _check_tolerance(self) -> None:
        if self.epsilon is not None and not (
            np.isfinite(self.epsilon) and float(self.epsilon) >= 0
        ):
            raise ConfigError(f"{self.name}: epsilon must be a distance >= 0 m")
        if not (np.isfinite(self.epsilon_factor) and self.epsilon_factor > 0):
            raise ConfigError(f"{self.name}: epsilon_factor must be > 0")

    def tolerance(self, resolution: float | None) -> float:
        """``epsilon`` if set, else ``epsilon_factor · resolution`` (metres)."""
        if self.epsilon is not None:
            return float(self.epsilon)
        if resolution is None or not (np.isfinite(resolution) and resolution > 0):
            raise InputError(
                f"{self.name}: resolution must be a positive finite distance in metres "
                f"(got {resolution}) unless an absolute epsilon is configured"
            )
        return float(self.epsilon_factor) * float(resolution)


@register_grouper("gcc", "geometric consistency grouping, largest cluster (Chen & Bhanu 2007)")
@dataclass(kw_only=True)
class GccGrouper(_Tolerance):
    """GCC (ALGORITHMS §B.2): :func:`~relnav.matching.gcc.geometric_consistency_grouping`.

    Options: ``epsilon`` / ``epsilon_factor`` (ε), ``min_cluster_size`` (3), ``pcl_bug``,
    ``strict``, ``seeds`` ("untaken" | "all") — see that function.
    """

    min_cluster_size: int = 3
    pcl_bug: bool = False
    strict: bool = False
    seeds: str = "untaken"
    info: dict[str, Any] = field(default_factory=dict, init=False)

    def __post_init__(self) -> None:
        self.name = "gcc"
        self._check_tolerance()
        # validate the remaining options now rather than at the first select()
        geometric_consistency_grouping(
            _NO_PTS, _NO_PTS, Correspondences.empty(), epsilon=1.0, **self._options()
        )

    def _options(self) -> dict[str, Any]:
        return {
            "min_cluster_size": self.min_cluster_size,
            "pcl_bug": self.pcl_bug,
            "strict": self.strict,
            "seeds": self.seeds,
        }

    def select(
        self,
        src_pts: np.ndarray,
        tgt_pts: np.ndarray,
        corr: Correspondences,
        *,
        resolution: float | None,
    ) -> Correspondences:
        """Largest consistent cluster (empty when none exceeds ``min_cluster_size``)."""
        eps = self.tolerance(resolution)
        best, clusters = geometric_consistency_grouping(
            src_pts,
            tgt_pts,
            corr,
            epsilon=eps,
            **self._options(),
        )
        self.info = {
            "epsilon": eps,
            "n_clusters": len(clusters),
            "cluster_sizes": [len(c) for c in clusters],
            "n_selected": len(best),
        }
        return best


@register_grouper("ransac", "3-point RANSAC on correspondences, inliers of the best hypothesis")
@dataclass(kw_only=True)
class RansacGrouper(_Tolerance):
    """RANSAC (ALGORITHMS §B.3): :func:`~relnav.matching.ransac.ransac_search`.

    Options: ``epsilon`` / ``epsilon_factor`` (θ, default ``2·Tr``), ``max_iter`` (50 000),
    ``adaptive``, ``confidence``, ``min_area``, ``seed``. ``info["T_target_source"]`` holds the
    transform re-fitted on the inliers.
    """

    max_iter: int = 50_000
    adaptive: bool = False
    confidence: float = 0.99
    min_area: float = 1e-6
    seed: int | None = 0
    info: dict[str, Any] = field(default_factory=dict, init=False)

    def __post_init__(self) -> None:
        self.name = "ransac"
        self._check_tolerance()
        ransac_search(_NO_PTS, _NO_PTS, Correspondences.empty(), threshold=1.0, **self._options())

    def _options(self) -> dict[str, Any]:
        return {
            "max_iter": self.max_iter,
            "adaptive": self.adaptive,
            "confidence": self.confidence,
            "min_area": self.min_area,
            "seed": self.seed,
        }

    def select(
        self,
        src_pts: np.ndarray,
        tgt_pts: np.ndarray,
        corr: Correspondences,
        *,
        resolution: float | None,
    ) -> Correspondences:
        """Inliers of the best hypothesis (empty on failure)."""
        thr = self.tolerance(resolution)
        r = ransac_search(
            src_pts,
            tgt_pts,
            corr,
            threshold=thr,
            **self._options(),
        )
        self.info = {
            **r.info,
            "seed": r.seed,
            "n_iterations": r.n_iterations,
            "n_degenerate": r.n_degenerate,
            "n_selected": len(r.inliers),
            "T_target_source": r.T_target_source,
        }
        return r.inliers


@register_grouper("clgv", "local and global voting (Buch et al. 2014) [interpretation]")
@dataclass(kw_only=True)
class ClgvGrouper(_Tolerance):
    """CLGV (ALGORITHMS §B.4, **[interpretation]**): :func:`~relnav.matching.clgv.clgv_vote`.

    Options: ``epsilon`` / ``epsilon_factor`` (ε), ``k``, ``n_hypotheses``, ``top_fraction``,
    ``keep_ratio``, ``seed``.
    """

    k: int = 10
    n_hypotheses: int = 1000
    top_fraction: float = 0.1
    keep_ratio: float = 0.5
    seed: int | None = 0
    info: dict[str, Any] = field(default_factory=dict, init=False)

    def __post_init__(self) -> None:
        self.name = "clgv"
        self._check_tolerance()
        clgv_vote(_NO_PTS, _NO_PTS, Correspondences.empty(), epsilon=1.0, **self._options())

    def _options(self) -> dict[str, Any]:
        return {
            "k": self.k,
            "n_hypotheses": self.n_hypotheses,
            "top_fraction": self.top_fraction,
            "keep_ratio": self.keep_ratio,
            "seed": self.seed,
        }

    def select(
        self,
        src_pts: np.ndarray,
        tgt_pts: np.ndarray,
        corr: Correspondences,
        *,
        resolution: float | None,
    ) -> Correspondences:
        """Correspondences with a high local × global vote (empty on failure)."""
        eps = self.tolerance(resolution)
        r = clgv_vote(
            src_pts,
            tgt_pts,
            corr,
            epsilon=eps,
            **self._options(),
        )
        self.info = {
            **r.info,
            "seed": r.seed,
            "n_valid_hypotheses": r.n_valid_hypotheses,
            "n_selected": len(r.selected),
        }
        return r.selected


@register_grouper("none", "no grouping: every putative correspondence is kept")
@dataclass(kw_only=True)
class NoGrouper:
    """Pass-through (ablation): returns ``corr`` unchanged."""

    name: str = field(default="none", init=False)
    info: dict[str, Any] = field(default_factory=dict, init=False)

    def select(
        self,
        src_pts: np.ndarray,
        tgt_pts: np.ndarray,
        corr: Correspondences,
        *,
        resolution: float | None = None,
    ) -> Correspondences:
        """``corr`` itself."""
        self.info = {"n_selected": len(corr)}
        return corr
