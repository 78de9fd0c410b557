"""A cloud validated and prepared once for the ICP family: finite points, KD-tree, resolution,
radius, normals (:func:`prepare_cloud`), and the check of an initial guess (:func:`check_init`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.kdtree import KDTree
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.normals import estimate_normals

__all__ = ["PreparedCloud", "check_init", "prepare_cloud"]

log = logging.getLogger(__name__)


@dataclass
class PreparedCloud:
    """Per-cloud data shared by the ICP family (reusable across pairs, e.g. in odometry).

    Attributes
    ----------
    points : (N, 3) float64
        Finite points of the cloud (its own frame, m).
    tree : KDTree or None
        KD-tree of ``points`` (None when the cloud is unusable).
    resolution : float
        Mean resolution ``Tr`` (m); NaN when not computed or fewer than 2 distinct points.
    radius : float
        RMS distance of the points to their centroid (m).
    normals : (N, 3) float64 or None
        Unit normals (NaN rows where undefined), when requested.
    status : {"ok", "degenerate", "failed"}
        ``degenerate`` for empty/tiny/coincident/collinear clouds; ``failed`` for bad shapes.
    message : str
        Reason for a non-``ok`` status.
    n_dropped : int
        Non-finite input points that were dropped.
    timings : dict[str, float]
        Seconds spent preparing the cloud.
    """

    points: np.ndarray
    tree: KDTree | None = None
    resolution: float = float("nan")
    radius: float = float("nan")
    normals: np.ndarray | None = None
    status: str = "ok"
    message: str = ""
    n_dropped: int = 0
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """``status == "ok"``."""
        return self.status == "ok"


def prepare_cloud(
    points: Any,
    *,
    min_points: int = 6,
    normals: Literal["none", "pca"] | np.ndarray = "none",
    normal_k: int = 10,
    resolution: bool = True,
    name: str = "cloud",
) -> PreparedCloud:
    """Validate a cloud and precompute its KD-tree, resolution and (optionally) normals.

    Parameters
    ----------
    points : array-like, (N, 3)
        Points in metres; non-finite rows are dropped.
    min_points : int
        Fewer finite points → ``degenerate``.
    normals : {"none", "pca"} or (N, 3) array
        ``"pca"``: PCA normals from ``normal_k`` nearest neighbours (oriented to the origin);
        an array: given normals (rows matching ``points``; non-finite rows become NaN).
    normal_k : int
        Neighbours for PCA normals (ALGORITHMS §C.2: 10).
    resolution : bool
        Compute ``Tr`` (skipped when the caller uses absolute thresholds only).
    name : str
        Used in messages (``"source"``/``"target"``).

    Returns
    -------
    PreparedCloud
        Never raises for bad data: the status says what is wrong.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    try:
        P = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        return PreparedCloud(np.zeros((0, 3)), status="failed", message=f"{name}: {e}")
    if P.size == 0:
        return PreparedCloud(np.zeros((0, 3)), status="degenerate", message=f"{name} is empty")
    if P.ndim != 2 or P.shape[1] != 3:
        return PreparedCloud(
            np.zeros((0, 3)),
            status="failed",
            message=f"{name} must have shape (N, 3), got {P.shape}",
        )
    finite = np.isfinite(P).all(axis=1)
    n_dropped = int((~finite).sum())
    given_normals = None
    if isinstance(normals, np.ndarray) or (not isinstance(normals, str) and normals is not None):
        given_normals = np.asarray(normals, dtype=np.float64)
        if given_normals.shape != P.shape:
            return PreparedCloud(
                np.zeros((0, 3)),
                status="failed",
                message=f"{name} normals shape {given_normals.shape} != points {P.shape}",
            )
        given_normals = given_normals[finite]
    if n_dropped:
        P = P[finite]
        log.debug("%s: dropped %d non-finite points", name, n_dropped)
    P = np.ascontiguousarray(P)
    base = {"n_dropped": n_dropped, "timings": timings}
    n = P.shape[0]
    if n < min_points:
        msg = f"{name} has {n} finite points (< {min_points})"
        return PreparedCloud(P, status="degenerate", message=msg, **base)
    c = P.mean(axis=0)
    Q = P - c
    ev = np.linalg.eigvalsh(Q.T @ Q / n)
    radius = float(math.sqrt(max(ev.sum(), 0.0)))
    scale = max(1.0, float(np.abs(c).max()))
    if ev[2] <= (1e-9 * scale) ** 2:
        msg = f"{name}: all points coincide"
        return PreparedCloud(P, radius=radius, status="degenerate", message=msg, **base)
    if ev[1] <= 1e-10 * ev[2]:
        msg = f"{name}: points are collinear"
        return PreparedCloud(P, radius=radius, status="degenerate", message=msg, **base)
    tree = KDTree(P)
    timings["tree"] = time.perf_counter() - t0
    tr = float("nan")
    if resolution:
        t1 = time.perf_counter()
        _, _, dd = tree.nn(P, exclude_self=True)
        if not (dd > 0).all():  # duplicates: fall back to the distinct-point definition
            tr = mean_resolution(P)
        else:
            tr = float(dd.mean())
        timings["resolution"] = time.perf_counter() - t1
    N = None
    if given_normals is not None:
        nrm = np.linalg.norm(given_normals, axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            N = given_normals / nrm
        N[~np.isfinite(N).all(axis=1)] = np.nan
    elif normals == "pca":
        t1 = time.perf_counter()
        N = estimate_normals(P, k=int(normal_k))
        timings["normals"] = time.perf_counter() - t1
    elif normals != "none":
        raise ConfigError(f"normals must be 'none', 'pca' or an array, got {normals!r}")
    return PreparedCloud(P, tree, tr, radius, N, **base)


def check_init(init: Any) -> tuple[np.ndarray | None, str]:
    """Validate an initial guess: returns ``(T, "")`` or ``(None, reason)``.

    ``None`` means identity. A valid guess is a finite ``4x4`` rigid transform (rotation
    orthonormal to 1e-6, determinant +1, last row ``[0, 0, 0, 1]``).
    """
    if init is None:
        return np.eye(4), ""
    try:
        T = np.array(init, dtype=np.float64)
    except (TypeError, ValueError) as e:
        return None, f"init is not a numeric array: {e}"
    if T.shape != (4, 4):
        return None, f"init must be 4x4, got shape {T.shape}"
    if not np.isfinite(T).all():
        return None, "init has non-finite entries"
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > 1e-6
        or np.linalg.det(R) < 0
        or np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-12
    ):
        return None, "init is not a rigid transform"
    return T, ""
