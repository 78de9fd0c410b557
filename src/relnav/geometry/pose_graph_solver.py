"""SE(3) pose graph: relative-pose edges, unary priors, robust (Geman–McClure) edges.

Used by the navigator's revisits (:mod:`relnav.navigation.pose_graph`) and by paper 2's
multi-view contour model (:class:`relnav.fusion.reconstruction.ContourModel`).

Conventions: an edge ``(i, j, Z, Ω)`` measures ``Z ≈ X_i⁻¹ X_j`` with a right perturbation,
``X_i⁻¹ X_j = Z exp(ε)``, ``ε ~ N(0, Ω⁻¹)``, twists ``[ρ (m), φ (rad)]``; the residual is
``r = log(Z⁻¹ X_i⁻¹ X_j)``. The optimiser is Gauss–Newton on right perturbations
``X ← X exp(δ)`` with the first-order inverse right Jacobian, per-edge robust weights
(iteratively reweighted, the kernel graduated from wide to tight) and sparse normal equations
(:mod:`scipy.sparse`): dependency-free. :func:`scipy.optimize.least_squares` was not used because
its robust loss acts on each residual component, not on an edge's χ².
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from relnav.geometry.lie import exp_se3, log_se3
from relnav.geometry.rotations import hat_batch
from relnav.geometry.se3 import invert

__all__ = ["PoseGraph", "PoseGraphResult"]

log = logging.getLogger(__name__)


@dataclass
class PoseGraphResult:
    """Outcome of :meth:`PoseGraph.optimize`.

    Attributes
    ----------
    poses : (N, 4, 4) float64
        Optimised node poses.
    weights : (E,) float64
        Final robust weight of each edge (1 for non-robust edges).
    chi2 : (E,) float64
        Final ``rᵀ Ω r`` of each edge.
    iterations : int
        Gauss–Newton iterations run.
    time_s : float
        Wall-clock time of the optimisation, s.
    """

    poses: np.ndarray
    weights: np.ndarray
    chi2: np.ndarray
    iterations: int
    time_s: float


@dataclass
class _Edge:
    i: int
    j: int
    Z: np.ndarray
    info: np.ndarray
    robust: bool


class PoseGraph:
    """SE(3) pose graph: nodes ``X_i`` (``T_target_sensor``), relative-pose edges, robust loops.

    Examples
    --------
    >>> g = PoseGraph()
    >>> a, b = g.add_node(np.eye(4)), g.add_node(np.eye(4))
    >>> g.add_edge(a, b, np.eye(4), np.eye(6))
    >>> g.optimize().poses.shape
    (2, 4, 4)
    """

    def __init__(self) -> None:
        self.nodes: list[np.ndarray] = []
        self.edges: list[_Edge] = []

    def add_node(self, pose: np.ndarray) -> int:
        """Add a node at its initial pose (4×4); returns its index."""
        self.nodes.append(np.array(pose, dtype=np.float64))
        return len(self.nodes) - 1

    def add_edge(
        self, i: int, j: int, Z: np.ndarray, information: np.ndarray, *, robust: bool = False
    ) -> None:
        """Add the measurement ``Z ≈ X_i⁻¹ X_j`` with its information (6×6, right perturbation,
        ``[ρ, φ]``, 1/m² and 1/rad²); ``robust`` edges get the Geman–McClure kernel."""
        if not (0 <= i < len(self.nodes) and 0 <= j < len(self.nodes)) or i == j:
            raise ValueError(f"edge ({i}, {j}) between unknown or equal nodes")
        L = np.asarray(information, dtype=np.float64)
        if L.shape != (6, 6) or not np.all(np.isfinite(L)):
            raise ValueError("an edge's information must be a finite 6×6 matrix")
        self.edges.append(_Edge(i, j, np.array(Z, dtype=np.float64), 0.5 * (L + L.T), robust))

    def add_prior(self, j: int, T: np.ndarray, information: np.ndarray) -> None:
        """Add the unary measurement ``T ≈ X_j`` (right perturbation, information 6×6)."""
        if not 0 <= j < len(self.nodes):
            raise ValueError(f"prior on unknown node {j}")
        L = np.asarray(information, dtype=np.float64)
        if L.shape != (6, 6) or not np.all(np.isfinite(L)):
            raise ValueError("a prior's information must be a finite 6×6 matrix")
        self.edges.append(_Edge(-1, j, np.array(T, dtype=np.float64), 0.5 * (L + L.T), False))

    def optimize(
        self,
        *,
        fixed: tuple[int, ...] = (0,),
        kernel: float = 5.0,
        kernel_start: float = 100.0,
        kernel_decay: float = 0.6,
        max_iter: int = 30,
        tolerance: float = 1e-4,
    ) -> PoseGraphResult:
        """Gauss–Newton with iteratively reweighted robust edges.

        Parameters
        ----------
        fixed : tuple of int
            Nodes held at their initial pose (the gauge).
        kernel : float
            Geman–McClure scale ``c`` on the Mahalanobis distance ``√χ²`` of a robust edge:
            weight ``(c² / (c² + χ²))²``.
        kernel_start, kernel_decay : float
            Graduated non-convexity: the scale starts at ``kernel_start`` and is multiplied by
            ``kernel_decay`` per iteration down to ``kernel`` (a loop edge far from a drifted
            initial guess is not rejected before the graph has moved toward it).
        max_iter : int
            Iterations at most.
        tolerance : float
            Stop (once the kernel is at ``kernel``) when the largest update is below this
            (m and rad).

        Returns
        -------
        PoseGraphResult
        """
        t0 = time.perf_counter()
        n = len(self.nodes)
        E = len(self.edges)
        # node 0 of the extended arrays is the fixed origin of unary priors (edge i = -1)
        X = np.concatenate([np.eye(4)[None], np.stack(self.nodes)]) if n else np.eye(4)[None]
        ei = np.array([e.i + 1 for e in self.edges], dtype=np.int64)
        ej = np.array([e.j + 1 for e in self.edges], dtype=np.int64)
        Zi = np.stack([invert(e.Z) for e in self.edges]) if E else np.zeros((0, 4, 4))
        Om = np.stack([e.info for e in self.edges]) if E else np.zeros((0, 6, 6))
        robust = np.array([e.robust for e in self.edges], dtype=bool)
        fixed_set = {k + 1 for k in fixed} | {0}
        col = -np.ones(n + 1, dtype=np.int64)
        free = np.array([k not in fixed_set for k in range(n + 1)])
        col[free] = np.arange(int(free.sum()))
        m = 6 * int(free.sum())
        c = max(float(kernel_start), float(kernel))
        it = 0
        weights = np.ones(E)
        chi2 = np.zeros(E)
        blk = np.arange(6)
        while E and m:
            it += 1
            r, chi2, weights = self._evaluate(X, ei, ej, Zi, Om, robust, c)
            Jinv = np.eye(6)[None] + 0.5 * _ad_batch(r)
            Jj = Jinv
            Ji = -Jinv @ _adjoint_batch(_inv_batch(X[ej]) @ X[ei])
            W = weights[:, None, None] * Om
            g = np.zeros(m)
            rows, cols, vals = [], [], []
            for na, Ja in ((ei, Ji), (ej, Jj)):
                ca = col[na]
                ok = ca >= 0
                gv = np.einsum("eji,ejk,ek->ei", Ja[ok], W[ok], r[ok])
                np.add.at(g, (6 * ca[ok])[:, None] + blk, gv)
                for nb, Jb in ((ei, Ji), (ej, Jj)):
                    cb = col[nb]
                    okb = ok & (cb >= 0)
                    if not okb.any():
                        continue
                    Hab = np.einsum("eji,ejk,ekl->eil", Ja[okb], W[okb], Jb[okb])
                    rr = (6 * ca[okb])[:, None, None] + blk[None, :, None]
                    cc = (6 * cb[okb])[:, None, None] + blk[None, None, :]
                    rows.append(np.broadcast_to(rr, Hab.shape).ravel())
                    cols.append(np.broadcast_to(cc, Hab.shape).ravel())
                    vals.append(Hab.ravel())
            H = sp.csc_matrix(
                (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, m)
            )
            # a tiny relative damping keeps a node without any edge solvable
            H = H + sp.diags(1e-9 * H.diagonal() + 1e-12, format="csc")
            delta = spla.spsolve(H, -g).reshape(-1, 6)
            if not np.all(np.isfinite(delta)):
                log.warning("pose graph: non-finite update, optimisation stopped")
                break
            for k in np.flatnonzero(free):
                X[k] = X[k] @ exp_se3(delta[col[k]])
            at_kernel = c <= kernel
            c = max(c * kernel_decay, kernel)
            if (at_kernel and float(np.max(np.abs(delta))) < tolerance) or it >= max_iter:
                break
        if E:
            _, chi2, weights = self._evaluate(X, ei, ej, Zi, Om, robust, c)
        return PoseGraphResult(X[1:].copy(), weights, chi2, it, time.perf_counter() - t0)

    @staticmethod
    def _evaluate(
        X: np.ndarray,
        ei: np.ndarray,
        ej: np.ndarray,
        Zi: np.ndarray,
        Om: np.ndarray,
        robust: np.ndarray,
        c: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals ``(E, 6)``, their χ² and the robust weights at kernel scale ``c``."""
        Ek = Zi @ _inv_batch(X[ei]) @ X[ej]
        r = np.stack([log_se3(T) for T in Ek])
        chi2 = np.einsum("ei,eij,ej->e", r, Om, r)
        w = np.where(robust, (c * c / (c * c + chi2)) ** 2, 1.0)
        return r, chi2, w


def _inv_batch(T: np.ndarray) -> np.ndarray:
    """Inverses of rigid transforms ``(K, 4, 4)``."""
    out = np.zeros_like(T)
    Rt = np.transpose(T[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("kij,kj->ki", Rt, T[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def _adjoint_batch(T: np.ndarray) -> np.ndarray:
    """Adjoints ``(K, 6, 6)`` of ``(K, 4, 4)`` transforms (see :func:`adjoint`)."""
    A = np.zeros((len(T), 6, 6))
    R = T[:, :3, :3]
    A[:, :3, :3] = R
    A[:, 3:, 3:] = R
    A[:, :3, 3:] = hat_batch(T[:, :3, 3]) @ R
    return A


def _ad_batch(xi: np.ndarray) -> np.ndarray:
    """Small adjoints ``ad(ξ) = [[φ×, ρ×], [0, φ×]]`` (K, 6, 6) of twists ``[ρ, φ]`` (K, 6)."""
    A = np.zeros((len(xi), 6, 6))
    P = hat_batch(xi[:, 3:])
    A[:, :3, :3] = P
    A[:, 3:, 3:] = P
    A[:, :3, 3:] = hat_batch(xi[:, :3])
    return A
