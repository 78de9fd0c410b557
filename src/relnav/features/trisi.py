"""TriSI (Guo et al. 2013) and spin images (Johnson & Hebert 1999).

Both are built by one spin-image kernel. For a keypoint ``p``, a unit axis ``a`` and a support
point ``q`` (``‖q − p‖ ≤ r``), ``v = q − p`` has spin coordinates ``β = a·v`` (signed height
along the axis) and ``α = sqrt(‖v‖² − β²)`` (distance to the axis).

Two binning conventions (``layout``):

* ``layout="guo"`` (default; **[interpretation]**, ALGORITHMS §A.5): 15 × 15 = 225 cells as in
  Guo et al. 2016's evaluation and Paper 1's TriSI length 675 = 3 × 225. Spherical support
  ``‖v‖ ≤ r`` (keypoint included), ``n_alpha`` cells over ``α ∈ [0, r)`` (size ``r/n_alpha``)
  and ``n_beta`` cells over ``β ∈ [−r, r)`` (size ``2r/n_beta``). Bilinear interpolation between
  **cell centres** (Johnson & Hebert 1999); a weight falling outside the grid is given to the
  nearest edge cell, so no mass is lost. Flattened β-major (row = β cell ascending, column = α
  cell ascending). Support-angle test ``n_q·n_p ≥ cos θ_max`` (signed, Johnson & Hebert).
* ``layout="pcl"`` (spin image only): PCL 1.13 ``SpinImageEstimation`` (rectangular, not
  radial/angular), ``image_width = w`` (default 8), rule for rule
  (``pcl/features/impl/spin_image.hpp``, ``computeSiForPoint``): node spacing
  ``s = r/(w√2)``; ``w + 1`` α nodes at ``j·s`` and ``2w + 1`` β nodes at ``(i − w)·s``;
  support = the points of the radius-``r`` search that lie in the **cylinder**
  ``α < w·s`` and ``|β| < w·s`` (``= r/√2``; others are dropped, not clamped); points at the
  keypoint's position (the keypoint itself, ``‖v‖ = 0``) are skipped; the support-angle test is
  ``|n_q·n_p| ≥ cos θ_max`` (opposite normals kept) and only applies for ``θ_max < 90°``;
  bilinear weights onto the 4 surrounding nodes; flattened **α-major** (``j·(2w+1) + i``) →
  ``(w+1)(2w+1) = 153`` values for ``w = 8``, normalised to unit sum. Verified against PCL's
  output (``tests/data/pcl``, ``benchmarks/paper1/pcl_reference``).

``interpolation="nearest"`` puts each point in the single nearest cell / node instead.

TriSI: three spin images, one around each axis ``x, y, z`` of the RoPS LRF
(:func:`relnav.geometry.lrf.rops_lrf`; point-based by default as ALGORITHMS §A.5,
``lrf="local_mesh"`` for the local-mesh frame that RoPS uses by default), concatenated
``[x, y, z]`` → 675, no PCA compression.
TriSI always uses the ``"guo"`` convention: it is Guo et al.'s descriptor and Paper 1 reports its
length as 675 = 3 × 15 × 15, which the PCL grid (153 per image) cannot give; PCL has no TriSI.
Spin image: one image around the keypoint normal (``spin``), optionally with a support angle.

References
----------
Y. Guo, F. Sohel, M. Bennamoun, M. Lu, J. Wan, "TriSI: A distinctive local surface descriptor
for 3D modeling and object recognition", GRAPP 2013. doi:10.5220/0004277600860093
A. E. Johnson, M. Hebert, "Using spin images for efficient object recognition in cluttered 3D
scenes", IEEE TPAMI 21(5), 1999. doi:10.1109/34.765655
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.features.base import MIN_SUPPORT, register_descriptor
from relnav.geometry.lrf import check_points, check_rops_lrf, rops_lrf_csr, support_csr

__all__ = ["SpinGrid", "spin", "spin_grid", "trisi"]

log = logging.getLogger(__name__)


class SpinGrid(NamedTuple):
    """Spin-image grid: node ``j`` of α is at ``a0 + j·da`` (``j < na``), likewise for β.

    ``a_max`` / ``b_max``: support points with ``α ≥ a_max`` or ``|β| ≥ b_max`` are dropped
    (``inf`` for the ``"guo"`` layout, which clamps instead); ``pcl``: PCL's rules (keypoint
    skipped, ``|cos|`` support angle, α-major output).
    """

    a0: float
    da: float
    na: int
    b0: float
    db: float
    nb: int
    a_max: float = np.inf
    b_max: float = np.inf
    pcl: bool = False

    @property
    def size(self) -> int:
        """Values per image ``na · nb``."""
        return self.na * self.nb


def spin_grid(
    radius: float, *, layout: str = "guo", n_alpha: int = 15, n_beta: int = 15, width: int = 8
) -> SpinGrid:
    """The :class:`SpinGrid` of a layout (see the module docstring), lengths in metres."""
    r = float(radius)
    if layout == "guo":
        if int(n_alpha) < 1 or int(n_beta) < 1:
            raise ConfigError(f"spin image needs n_alpha, n_beta ≥ 1, got {n_alpha}, {n_beta}")
        da = r / int(n_alpha)
        db = 2.0 * r / int(n_beta)
        return SpinGrid(0.5 * da, da, int(n_alpha), -r + 0.5 * db, db, int(n_beta))
    if layout == "pcl":
        if int(width) < 1:
            raise ConfigError(f"spin image width must be ≥ 1, got {width}")
        w = int(width)
        step = r / (w * np.sqrt(2.0))
        lim = step * w
        return SpinGrid(0.0, step, w + 1, -lim, step, 2 * w + 1, lim, lim, True)
    raise ConfigError(f"unknown spin image layout {layout!r}; use 'guo' or 'pcl'")


@njit(cache=True, error_model="numpy")
def _spin_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    axes: np.ndarray,
    valid: np.ndarray,
    a0: float,
    da: float,
    na: int,
    b0: float,
    db: float,
    nb: int,
    a_max: float,
    b_max: float,
    pcl: bool,
    bilinear: bool,
    normals: np.ndarray,
    cos_min: float,
    use_angle: bool,
) -> np.ndarray:
    K = kp.shape[0]
    A = axes.shape[1]
    S = na * nb
    out = np.full((K, A * S), np.nan)
    img = np.zeros((nb, na))
    for k in range(K):
        if not valid[k]:
            continue
        s0 = offsets[k]
        s1 = offsets[k + 1]
        pi = kp[k]
        p = P[pi]
        for ax in range(A):
            e0 = axes[k, ax, 0]
            e1 = axes[k, ax, 1]
            e2 = axes[k, ax, 2]
            img[:, :] = 0.0
            total = 0.0
            for t in range(s0, s1):
                qi = flat[t]
                if use_angle:
                    c = (
                        normals[qi, 0] * normals[pi, 0]
                        + normals[qi, 1] * normals[pi, 1]
                        + normals[qi, 2] * normals[pi, 2]
                    )
                    if pcl:
                        c = abs(c)
                    if not (c >= cos_min):
                        continue
                v0 = P[qi, 0] - p[0]
                v1 = P[qi, 1] - p[1]
                v2 = P[qi, 2] - p[2]
                d2 = v0 * v0 + v1 * v1 + v2 * v2
                if pcl and d2 == 0.0:
                    continue  # PCL skips the keypoint itself (and exact duplicates)
                beta = e0 * v0 + e1 * v1 + e2 * v2
                a2 = d2 - beta * beta
                alpha = np.sqrt(a2) if a2 > 0.0 else 0.0
                if alpha >= a_max or abs(beta) >= b_max:
                    continue  # outside PCL's cylinder
                u = (alpha - a0) / da
                w = (beta - b0) / db
                if bilinear:
                    fj = np.floor(u)
                    fi = np.floor(w)
                    fu = u - fj
                    fw = w - fi
                    j0 = int(fj)
                    i0 = int(fi)
                    j1 = j0 + 1
                    i1 = i0 + 1
                    # weights falling outside the grid go to the nearest edge cell
                    j0 = 0 if j0 < 0 else (na - 1 if j0 > na - 1 else j0)
                    j1 = 0 if j1 < 0 else (na - 1 if j1 > na - 1 else j1)
                    i0 = 0 if i0 < 0 else (nb - 1 if i0 > nb - 1 else i0)
                    i1 = 0 if i1 < 0 else (nb - 1 if i1 > nb - 1 else i1)
                    img[i0, j0] += (1.0 - fw) * (1.0 - fu)
                    img[i0, j1] += (1.0 - fw) * fu
                    img[i1, j0] += fw * (1.0 - fu)
                    img[i1, j1] += fw * fu
                else:
                    jj = int(np.floor(u + 0.5))
                    ii = int(np.floor(w + 0.5))
                    jj = 0 if jj < 0 else (na - 1 if jj > na - 1 else jj)
                    ii = 0 if ii < 0 else (nb - 1 if ii > nb - 1 else ii)
                    img[ii, jj] += 1.0
                total += 1.0
            if total <= 0.0:
                out[k, :] = np.nan
                break
            base = ax * S
            for i in range(nb):
                for j in range(na):
                    if pcl:
                        out[k, base + j * nb + i] = img[i, j] / total
                    else:
                        out[k, base + i * na + j] = img[i, j] / total
    return out


def _interp_flag(interpolation: str) -> bool:
    if interpolation not in ("bilinear", "nearest"):
        raise ConfigError(
            f"spin image interpolation must be 'bilinear' or 'nearest', got {interpolation!r}"
        )
    return interpolation == "bilinear"


def _check_radius(radius: float, what: str) -> float:
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"{what} radius must be positive and finite, got {radius}")
    return float(radius)


@register_descriptor(
    "trisi",
    dim=675,
    radius_factor=20.0,
    needs_normals=False,
    description="TriSI: 3 spin images (15x15) around the RoPS LRF axes, 675",
)
def trisi(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    *,
    radius: float,
    normals: np.ndarray | None = None,
    n_alpha: int = 15,
    n_beta: int = 15,
    interpolation: str = "bilinear",
    triangles: np.ndarray | None = None,
    lrf: str = "points",
    tree: cKDTree | None = None,
    degenerate_tol: float = 1e-10,
) -> np.ndarray:
    """TriSI descriptors: spin images around the x, y and z axes of the RoPS LRF.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres (Paper 1: ``20·Tr``).
    normals : ignored
        TriSI needs no normals (accepted for the registry signature).
    n_alpha, n_beta : int
        Cells per image along ``α ∈ [0, r)`` and ``β ∈ [−r, r)`` (default 15 × 15; other
        values change the length ``3·n_alpha·n_beta`` and only work when called directly).
    interpolation : {"bilinear", "nearest"}
        Vote spreading (module docstring).
    triangles : (M, 3) int, optional
        Mesh triangles: use the mesh RoPS LRF.
    lrf : {"points", "local_mesh"}
        RoPS frame without ``triangles`` (:func:`relnav.geometry.lrf.rops_lrf`).
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points``.
    degenerate_tol : float
        As in :func:`relnav.geometry.lrf.rops_lrf`.

    Returns
    -------
    (K, 3·n_alpha·n_beta) float32
        ``[x-image, y-image, z-image]``, each summing to 1; NaN rows for fewer than 5 support
        points (keypoint included) or an undefined LRF.
    """
    P, kp = check_points(points, keypoint_idx)
    radius = _check_radius(radius, "TriSI")
    grid = spin_grid(radius, layout="guo", n_alpha=n_alpha, n_beta=n_beta)
    bilinear = _interp_flag(interpolation)
    check_rops_lrf(lrf, None)
    if kp.size == 0:
        return np.zeros((0, 3 * grid.size), dtype=np.float32)
    flat, offsets = support_csr(P, kp, radius, tree)
    lrfs = rops_lrf_csr(
        P, kp, flat, offsets, radius, triangles, float(degenerate_tol), lrf, None, tree
    )
    valid = np.isfinite(lrfs).all(axis=(1, 2)) & (np.diff(offsets) >= MIN_SUPPORT)
    axes = np.ascontiguousarray(np.where(valid[:, None, None], lrfs, 0.0))
    out = _spin_kernel(
        P,
        kp,
        flat,
        offsets,
        axes,
        valid,
        *grid,
        bilinear,
        np.zeros((1, 3)),
        -2.0,
        False,
    )
    log.debug("trisi: %d of %d keypoints invalid", int((~valid).sum()), kp.size)
    return out.astype(np.float32)


@register_descriptor(
    "spin",
    dim=225,
    radius_factor=20.0,
    needs_normals=True,
    description="Spin image around the normal (Johnson & Hebert 1999), 15x15 = 225",
)
def spin(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    *,
    radius: float,
    normals: np.ndarray | None,
    layout: str = "guo",
    n_alpha: int = 15,
    n_beta: int = 15,
    width: int = 8,
    interpolation: str = "bilinear",
    support_angle_deg: float | None = None,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """Spin images around the keypoint normals.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres.
    normals : (N, 3) float64
        Unit normals (same frame as ``points``); the image axis is the keypoint normal, so its
        orientation sets the sign of ``β``.
    layout : {"guo", "pcl"}
        ``"guo"``: ``n_alpha × n_beta`` cells (default 15 × 15 = 225, the registered length);
        ``"pcl"``: PCL ``SpinImageEstimation`` of ``width`` (``(w+1)(2w+1)``, 153 for ``w = 8``;
        cylinder support, keypoint skipped, α-major; module docstring). Lengths other than
        225 only work when this function is called directly.
    n_alpha, n_beta : int
        Cells of the ``"guo"`` layout.
    width : int
        ``image_width`` of the ``"pcl"`` layout.
    interpolation : {"bilinear", "nearest"}
        Vote spreading.
    support_angle_deg : float, optional
        If given, only support points whose normal is within this angle of the keypoint normal
        vote (Johnson & Hebert's support angle; ``layout="pcl"``: within this angle of the
        keypoint normal *or its opposite*, as PCL); disabled by default (PCL default).
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points``.

    Returns
    -------
    (K, D) float32
        Unit-sum images; NaN rows for fewer than 5 support points (keypoint included), a
        non-finite keypoint normal or (``"pcl"``) no point left in the cylinder.
    """
    P, kp = check_points(points, keypoint_idx)
    radius = _check_radius(radius, "spin image")
    if normals is None:
        raise InputError("spin image needs normals")
    Nrm = np.ascontiguousarray(normals, dtype=np.float64)
    if Nrm.shape != P.shape:
        raise InputError(f"normals must have the shape of points {P.shape}, got {Nrm.shape}")
    grid = spin_grid(radius, layout=layout, n_alpha=n_alpha, n_beta=n_beta, width=width)
    bilinear = _interp_flag(interpolation)
    if kp.size == 0:
        return np.zeros((0, grid.size), dtype=np.float32)
    flat, offsets = support_csr(P, kp, radius, tree)
    n_kp = Nrm[kp]
    norm = np.linalg.norm(n_kp, axis=1)
    valid = np.isfinite(n_kp).all(axis=1) & (norm > 0) & (np.diff(offsets) >= MIN_SUPPORT)
    with np.errstate(invalid="ignore", divide="ignore"):
        axes = np.where(valid[:, None], n_kp / norm[:, None], 0.0)
        unit = Nrm / np.linalg.norm(Nrm, axis=1, keepdims=True)
    use_angle = support_angle_deg is not None
    cos_min = float(np.cos(np.deg2rad(support_angle_deg))) if use_angle else -2.0
    out = _spin_kernel(
        P,
        kp,
        flat,
        offsets,
        np.ascontiguousarray(axes[:, None, :]),
        valid,
        *grid,
        bilinear,
        np.ascontiguousarray(unit),
        cos_min,
        use_angle,
    )
    log.debug("spin: %d of %d keypoints invalid", int((~valid).sum()), kp.size)
    return out.astype(np.float32)
