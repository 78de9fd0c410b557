"""The target model of relnav's navigator: a voxel map of surface statistics in the target frame.

Each occupied voxel (edge ``voxel_size`` metres, fixed in the target frame) keeps the running
first and second moments of the scan points that fell into it, so that it describes a small
patch of surface: its mean ``μ`` (m) and covariance ``C`` (m²). Registration uses each voxel as
a Gaussian (generalised ICP against voxel distributions, as VGICP/NDT do): the information
matrix :meth:`VoxelMap.information` is a plane-like ``Ω = V diag(1/λ₁', 1/λ₂', 1/λ₃') Vᵀ`` built
from ``C``'s eigen-decomposition with floors, weak in the patch's plane and strong along its
normal.

The map is bounded: a voxel's moments saturate at ``max_weight`` observations (older points are
forgotten geometrically, so a patch built during drift is pulled to where new scans put it) and,
above ``max_voxels``, the voxels seen least recently are dropped.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["VoxelMap"]


class VoxelMap:
    """Voxel map of surface moments in the target frame.

    Parameters
    ----------
    voxel_size : float
        Voxel edge, metres.
    max_weight : float
        Observations after which a voxel's moments are scaled down (exponential forgetting).
    max_voxels : int
        Bound on the number of voxels; the least recently updated ones go first.
    noise_floor : float
        Smallest standard deviation (m) along a patch's normal (sensor noise and map blur).
    """

    def __init__(
        self,
        voxel_size: float,
        *,
        max_weight: float = 20.0,
        max_voxels: int = 200_000,
        noise_floor: float = 0.02,
        inplane_sigma: float | None = None,
        k_neighbors: int = 10,
    ) -> None:
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be a positive number of metres, got {voxel_size}")
        self.voxel_size = float(voxel_size)
        self.max_weight = float(max_weight)
        self.max_voxels = int(max_voxels)
        self.noise_floor = float(noise_floor)
        self.inplane_sigma = float(inplane_sigma) if inplane_sigma else 2.0 * self.voxel_size
        self.k_neighbors = int(k_neighbors)
        self._index: dict[tuple[int, int, int], int] = {}
        cap = 1024
        self._w = np.zeros(cap)
        self._s1 = np.zeros((cap, 3))
        self._s2 = np.zeros((cap, 3, 3))
        self._seen = np.zeros(cap, dtype=np.int64)
        self._keys = np.zeros((cap, 3), dtype=np.int64)
        self.n = 0
        self._mean: np.ndarray | None = None
        self._info: np.ndarray | None = None
        self._normal: np.ndarray | None = None
        self._tree: cKDTree | None = None
        self._info_all: np.ndarray | None = None
        self._normal_all: np.ndarray | None = None
        self._touched: set[int] = set()
        self._stale_all = True

    def __len__(self) -> int:
        return self.n

    # ------------------------------------------------------------------ update
    def insert(self, points: np.ndarray, frame: int) -> None:
        """Add points (target frame, m) observed at ``frame``."""
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(P):
            return
        keys = np.floor(P / self.voxel_size).astype(np.int64)
        uniq, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.ravel()
        slots = np.empty(len(uniq), dtype=np.int64)
        for u, key in enumerate(map(tuple, uniq.tolist())):
            i = self._index.get(key)
            if i is None:
                i = self._append(key)
            slots[u] = i
        w_add = np.bincount(inv, minlength=len(uniq)).astype(float)
        s1_add = np.zeros((len(uniq), 3))
        np.add.at(s1_add, inv, P)
        s2_add = np.zeros((len(uniq), 3, 3))
        np.add.at(s2_add, inv, P[:, :, None] * P[:, None, :])
        w_old = self._w[slots]
        over = (w_old + w_add) > self.max_weight
        scale = np.ones(len(uniq))
        scale[over] = np.maximum(self.max_weight - w_add[over], 0.0) / np.maximum(
            w_old[over], 1e-12
        )
        w_new = w_old * scale + w_add
        cap = np.minimum(1.0, self.max_weight / np.maximum(w_new, 1e-12))  # one big batch
        self._w[slots] = w_new * cap
        self._s1[slots] = (self._s1[slots] * scale[:, None] + s1_add) * cap[:, None]
        self._s2[slots] = (self._s2[slots] * scale[:, None, None] + s2_add) * cap[:, None, None]
        self._seen[slots] = frame
        self._touched.update(slots.tolist())
        if self.n > self.max_voxels:
            self._evict()
        self._mean = self._info = self._normal = self._tree = None

    def _append(self, key: tuple[int, int, int]) -> int:
        if self.n == len(self._w):
            cap = 2 * len(self._w)
            self._w = np.resize(self._w, cap)
            self._s1 = np.resize(self._s1, (cap, 3))
            self._s2 = np.resize(self._s2, (cap, 3, 3))
            self._seen = np.resize(self._seen, cap)
            self._keys = np.resize(self._keys, (cap, 3))
        i = self.n
        self._w[i] = 0.0
        self._s1[i] = 0.0
        self._s2[i] = 0.0
        self._keys[i] = key
        self._index[key] = i
        self.n += 1
        return i

    def _evict(self) -> None:
        keep = np.sort(np.argsort(-self._seen[: self.n], kind="stable")[: self.max_voxels])
        self._w = self._w[keep].copy()
        self._s1 = self._s1[keep].copy()
        self._s2 = self._s2[keep].copy()
        self._seen = self._seen[keep].copy()
        self._keys = self._keys[keep].copy()
        self.n = len(keep)
        self._index = {tuple(k): i for i, k in enumerate(self._keys[: self.n].tolist())}
        self._stale_all = True

    # ------------------------------------------------------------------ queries
    @property
    def weights(self) -> np.ndarray:
        """``(M,)`` observations per voxel (after forgetting)."""
        return self._w[: self.n]

    @property
    def last_seen(self) -> np.ndarray:
        """``(M,)`` frame index of each voxel's last update."""
        return self._seen[: self.n]

    @property
    def means(self) -> np.ndarray:
        """``(M, 3)`` voxel means in the target frame, m."""
        if self._mean is None:
            self._compute()
        assert self._mean is not None
        return self._mean

    @property
    def information(self) -> np.ndarray:
        """``(M, 3, 3)`` information matrices of the voxel Gaussians, 1/m²."""
        if self._info is None:
            self._compute()
        assert self._info is not None
        return self._info

    @property
    def normals(self) -> np.ndarray:
        """``(M, 3)`` unit normals (eigenvector of the smallest covariance eigenvalue)."""
        if self._normal is None:
            self._compute()
        assert self._normal is not None
        return self._normal

    @property
    def tree(self) -> cKDTree:
        """KD-tree over :attr:`means` (rebuilt after each update, on first use)."""
        if self._tree is None:
            self._compute()
        assert self._tree is not None
        return self._tree

    def _compute(self) -> None:
        n = self.n
        w = self._w[:n]
        mu = np.ascontiguousarray(self._s1[:n] / w[:, None])
        tree = cKDTree(mu)
        if self._info_all is None or len(self._info_all) < n or self._stale_all:
            affected = np.arange(n)
        else:
            touched = np.fromiter(self._touched, dtype=np.int64)
            if len(touched):
                _, nb = tree.query(mu[touched], k=min(self.k_neighbors, n))
                affected = np.unique(np.concatenate([touched, np.asarray(nb).ravel()]))
            else:
                affected = touched
        if self._info_all is None or len(self._info_all) < len(self._w):
            info_all = np.zeros((len(self._w), 3, 3))
            nrm_all = np.zeros((len(self._w), 3))
            if self._info_all is not None:
                m = len(self._info_all)
                info_all[:m] = self._info_all
                nrm_all[:m] = self._normal_all
            self._info_all, self._normal_all = info_all, nrm_all
        if len(affected):
            info, nrm = neighbourhood_information(
                mu, affected, tree, self.k_neighbors, self.inplane_sigma, self.noise_floor
            )
            self._info_all[affected] = info
            self._normal_all[affected] = nrm
        self._touched = set()
        self._stale_all = False
        self._mean = mu
        self._tree = tree
        self._info = self._info_all[:n]
        self._normal = self._normal_all[:n]


def neighbourhood_information(
    points: np.ndarray,
    which: np.ndarray,
    tree: cKDTree,
    k: int,
    inplane_sigma: float,
    noise_floor: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Plane-like information matrices from the ``k`` nearest neighbours of ``points[which]``.

    The covariance ``C`` of a point's ``k``-neighbourhood gives its normal ``n`` (eigenvector of
    the smallest eigenvalue ``λ₀``); the returned information is
    ``Ω = n nᵀ / (λ₀ + σ_n²) + (I − n nᵀ) / σ_p²``: strong along the normal, weak (``σ_p =
    inplane_sigma``) along the surface, so a sparse sample does not pull the scan onto its own
    sample positions **[interpretation: GICP's plane regularisation with physical scales]**.
    With fewer than 3 points in the map, ``Ω = I / σ_p²``.

    Parameters
    ----------
    points : (M, 3) float64
        Map points, m.
    which : (Q,) int
        Indices of the points to compute.
    tree : cKDTree
        Tree over ``points``.
    k : int
        Neighbourhood size (the point itself included).
    inplane_sigma, noise_floor : float
        ``σ_p`` and ``σ_n`` in metres.

    Returns
    -------
    info : (Q, 3, 3) float64
        Information matrices, 1/m².
    normals : (Q, 3) float64
        Unit normals (sign arbitrary).
    """
    M = len(points)
    Q = len(which)
    kk = min(k, M)
    if kk < 3:
        normals = np.zeros((Q, 3))
        normals[:, 2] = 1.0
        return np.repeat(np.eye(3)[None] / inplane_sigma**2, Q, axis=0), normals
    _, nb = tree.query(points[which], k=kk)
    N = points[nb]  # (Q, k, 3)
    Nc = N - N.mean(axis=1, keepdims=True)
    C = np.einsum("mki,mkj->mij", Nc, Nc) / kk
    lam, V = np.linalg.eigh(C)
    nrm = V[:, :, 0]
    l0 = np.maximum(lam[:, 0], 0.0) + noise_floor**2
    nn = nrm[:, :, None] * nrm[:, None, :]
    info = nn / l0[:, None, None] + (np.eye(3)[None] - nn) / inplane_sigma**2
    return info, np.ascontiguousarray(nrm)
