"""Conformal geometric algebra (CGA, ``G(4,1)``) helpers for paper 2's registration.

Basis and conventions (ALGORITHMS §G.1)
---------------------------------------
Five basis vectors ``e1, e2, e3`` (Euclidean, square +1), ``e4 = e+`` (square +1) and
``e5 = e−`` (square −1), i.e. ``kingdon.Algebra(4, 1)``. The null vectors are

* ``e∞ = e− + e+ = e4 + e5`` (point at infinity) and
* ``e0 = ½(e− − e+) = ½(e5 − e4)`` (origin), with ``e∞² = e0² = 0`` and ``e∞·e0 = −1``.

A Euclidean point ``x`` embeds as ``X = x + ½‖x‖² e∞ + e0`` (:func:`up`); a sphere with centre
``c`` and radius ``ρ`` is ``S = c + ½(‖c‖² − ρ²) e∞ + e0`` (IPNS / "dual" sphere); a plane with
unit normal ``n`` at distance ``d`` from the origin is ``π = n + d e∞``. This is the convention
of ``clifford.g3c`` and of kingdon's ``Algebra(4, 1)`` with ``e4 = e+``, ``e5 = e−``.

Two representations live here:

* **NumPy fast paths** (no GA library at run time): grade-1 objects as ``(..., 5)``
  coefficient arrays over ``[e1, e2, e3, e4, e5]``; Table-1 inner products in closed form;
  batched spheres/circles through 4 points; motors as 8 coefficients over
  :data:`MOTOR_BASIS`; and a small dense 32-component geometric product (:func:`gp`, blades
  indexed by their bitmap, exactly kingdon's key order) used to build the Valkenburg–Dorst
  motor-estimation tensor once.
* **kingdon** (imported lazily — it takes seconds to import): :func:`algebra`, :func:`basis`,
  :func:`up_mv`, :func:`sphere_dual_mv` (``S* = X1∧X2∧X3∧X4``), :func:`sphere_from_dual_mv`,
  :func:`motor_mv` / :func:`mv_to_dense` define the objects; the tests check that both paths
  agree with each other and with ``clifford.g3c``.

Versors (ALGORITHMS §G.1): rotor ``R = cos(θ/2) − sin(θ/2) B = exp(−θB/2)`` with
``B = u I₃`` (``I₃ = e1e2e3``, ``u`` the unit axis; ``e3 I₃ = e12``), translator
``T = 1 − ½ t e∞``, motor ``M = T R`` (rotate, then translate), ``X' = M X M̃`` is the
embedding of ``R x + t``. With the unit quaternion ``q = (x, y, z, w)`` of the same rotation the
rotor coefficients over ``[1, e12, e13, e23]`` are ``[w, −z, y, −x]``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from relnav.errors import InputError

__all__ = [
    "E0",
    "EINF",
    "METRIC",
    "MOTOR_BASIS",
    "SphereFit",
    "algebra",
    "basis",
    "dense_to_motor",
    "down",
    "estimate_motor",
    "gp",
    "inner",
    "motor_apply",
    "motor_estimation_tensor",
    "motor_from_rt",
    "motor_mv",
    "motor_to_dense",
    "motor_to_rt",
    "mv_to_dense",
    "plane_angle",
    "plane_sphere_inner",
    "plane_vectors",
    "point_plane_inner",
    "point_point_inner",
    "point_sphere_inner",
    "reverse",
    "rotor_from_quat",
    "rotor_to_quat",
    "sphere_dual_mv",
    "sphere_from_dual_mv",
    "sphere_params",
    "sphere_sphere_inner",
    "sphere_through_points",
    "sphere_vectors",
    "spheres_through_points",
    "up",
    "up_mv",
]

METRIC = np.array([1.0, 1.0, 1.0, 1.0, -1.0])
"""Squares of ``e1 … e5``."""

EINF = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
"""``e∞ = e4 + e5`` as grade-1 coefficients."""

E0 = np.array([0.0, 0.0, 0.0, -0.5, 0.5])
"""``e0 = ½(e5 − e4)`` as grade-1 coefficients."""

MOTOR_BASIS = ("1", "e12", "e13", "e23", "e1∞", "e2∞", "e3∞", "e123∞")
"""The 8 motor basis elements: rotor part ``E_R`` then translation part ``E_T``
(``ei∞ = ei ∧ e∞``)."""

# bitmap of each grade-1 basis vector e1..e5 (kingdon keys)
_VEC_BITS = (1, 2, 4, 8, 16)


# --------------------------------------------------------------------------------------------
# grade-1 objects (NumPy)
# --------------------------------------------------------------------------------------------


def _pts(points: Any, name: str = "points") -> np.ndarray:
    P = np.asarray(points, dtype=np.float64)
    if P.ndim == 1:
        if P.shape[0] != 3:
            raise InputError(f"{name}: expected 3 coordinates, got shape {P.shape}")
        return P
    if P.shape[-1] != 3:
        raise InputError(f"{name}: expected shape (..., 3), got {P.shape}")
    return P


def up(points: Any) -> np.ndarray:
    """Conformal embedding ``X = x + ½‖x‖² e∞ + e0`` of ``(..., 3)`` points → ``(..., 5)``."""
    P = _pts(points)
    h = 0.5 * np.sum(P * P, axis=-1)
    out = np.empty((*P.shape[:-1], 5))
    out[..., :3] = P
    out[..., 3] = h - 0.5
    out[..., 4] = h + 0.5
    return out


def inner(A: Any, B: Any) -> np.ndarray:
    """Inner product of grade-1 coefficient arrays ``(..., 5)`` (metric ``diag(1,1,1,1,−1)``)."""
    return np.sum(np.asarray(A, dtype=np.float64) * METRIC * np.asarray(B, dtype=np.float64), -1)


def down(X: Any) -> np.ndarray:
    """Euclidean point of a (possibly scaled) conformal point ``(..., 5)``: ``x/(−X·e∞)``."""
    X = np.asarray(X, dtype=np.float64)
    s = -inner(X, EINF)
    with np.errstate(divide="ignore", invalid="ignore"):
        return X[..., :3] / s[..., None]


def sphere_vectors(centres: Any, radii: Any) -> np.ndarray:
    """IPNS spheres ``S = c + ½(‖c‖² − ρ²) e∞ + e0`` → ``(..., 5)`` (``ρ = 0``: a point)."""
    C = _pts(centres, "centres")
    r = np.asarray(radii, dtype=np.float64)
    S = up(C)
    S[..., 3] -= 0.5 * r**2
    S[..., 4] -= 0.5 * r**2
    return S


def plane_vectors(normals: Any, d: Any) -> np.ndarray:
    """IPNS planes ``π = n + d e∞`` (``n`` unit normal, ``d = n·x`` on the plane) → ``(..., 5)``."""
    N = _pts(normals, "normals")
    d = np.asarray(d, dtype=np.float64)
    out = np.zeros((*N.shape[:-1], 5))
    out[..., :3] = N
    out[..., 3] = d
    out[..., 4] = d
    return out


def sphere_params(S: Any) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(..., 3)`` and squared radius ``(...)`` of IPNS sphere vectors ``(..., 5)``.

    ``S`` is normalised by ``−S·e∞`` first (any non-zero scale is accepted); ``ρ² = s·s``.
    A negative ``ρ²`` is an imaginary sphere.
    """
    S = np.asarray(S, dtype=np.float64)
    s = S / (-inner(S, EINF))[..., None]
    return s[..., :3], inner(s, s)


# ---- Table 1 of paper 2 (corrected, ALGORITHMS §G.1) ----------------------------------------


def point_point_inner(a: Any, b: Any) -> np.ndarray:
    """``X_a · X_b = −½‖a − b‖²`` for ``(..., 3)`` points (broadcasting)."""
    d = _pts(a, "a") - _pts(b, "b")
    return -0.5 * np.sum(d * d, axis=-1)


def point_sphere_inner(x: Any, centre: Any, radius: Any) -> np.ndarray:
    """``X · S = ½(ρ² − ‖x − c‖²)``: 0 on the sphere, > 0 inside."""
    d = _pts(x, "x") - _pts(centre, "centre")
    return 0.5 * (np.asarray(radius, dtype=np.float64) ** 2 - np.sum(d * d, axis=-1))


def point_plane_inner(x: Any, normal: Any, d: Any) -> np.ndarray:
    """``X · π = x·n − d``: signed distance of ``x`` to the plane (``n`` unit)."""
    return np.sum(_pts(x, "x") * _pts(normal, "normal"), axis=-1) - np.asarray(d, dtype=float)


def sphere_sphere_inner(c1: Any, r1: Any, c2: Any, r2: Any) -> np.ndarray:
    """``S1 · S2 = ½(ρ1² + ρ2² − ‖c1 − c2‖²)``."""
    dd = _pts(c1, "c1") - _pts(c2, "c2")
    r1 = np.asarray(r1, dtype=np.float64)
    r2 = np.asarray(r2, dtype=np.float64)
    return 0.5 * (r1**2 + r2**2 - np.sum(dd * dd, axis=-1))


def plane_sphere_inner(normal: Any, d: Any, centre: Any) -> np.ndarray:
    """``π · S = c·n − d`` (signed distance of the sphere centre to the plane)."""
    return point_plane_inner(centre, normal, d)


def plane_angle(n1: Any, n2: Any) -> np.ndarray:
    """Angle (rad) between planes/lines: ``θ = arccos(π1·π2 / (|π1||π2|)) = arccos(n1·n2)``.

    (Paper 2 eqs. 2–3 print ``cos⁻¹θ``; the angle is the arccos.)
    """
    a = _pts(n1, "n1")
    b = _pts(n2, "n2")
    c = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.arccos(np.clip(c, -1.0, 1.0))


# ---- spheres / circles through 4 points ------------------------------------------------------


@dataclass(frozen=True)
class SphereFit:
    """Spheres (or circles) through 4 points each.

    Attributes
    ----------
    centres : (K, 3) float64
        Sphere centre, or circumcentre of the circle for coplanar quadruples (metres).
    radii : (K,) float64
        Radius (m); NaN when the points are degenerate (collinear or coincident).
    circle : (K,) bool
        The 4 points were coplanar: a circle through 3 of them was used instead.
    normals : (K, 3) float64
        Unit normal of the circle's plane (NaN for spheres).
    valid : (K,) bool
        A finite centre and radius exist.
    """

    centres: np.ndarray
    radii: np.ndarray
    circle: np.ndarray
    normals: np.ndarray
    valid: np.ndarray

    def __len__(self) -> int:
        return int(self.radii.shape[0])


_TRIPLES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])


def _circumcircles(A: np.ndarray, B: np.ndarray, C: np.ndarray):
    """Circumcentre, radius and unit normal of triangles ``(K, 3)`` each (NaN if collinear)."""
    a = B - A
    b = C - A
    axb = np.cross(a, b)
    n2 = np.sum(axb * axb, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        num = np.cross(np.sum(a * a, 1)[:, None] * b - np.sum(b * b, 1)[:, None] * a, axb)
        off = num / (2.0 * n2[:, None])
        normal = axb / np.sqrt(n2)[:, None]
    bad = ~(n2 > 0)
    off[bad] = np.nan
    normal[bad] = np.nan
    return A + off, np.linalg.norm(off, axis=1), normal


def spheres_through_points(quads: Any, *, eta: float = 1e-3) -> SphereFit:
    """Spheres through 4 points each (batched), circles when the 4 points are coplanar.

    Coplanarity test (paper 2's ``X1∧X2∧X3∧X4∧e∞ = 0``, ALGORITHMS §G.1):
    ``|det[x2−x1, x3−x1, x4−x1]| < η·s³`` with ``s`` the mean pairwise distance
    **[interpretation: η = 1e-3]**. Non-coplanar: solve ``[2xᵢᵀ, −1]·[c; k] = ‖xᵢ‖²``,
    ``ρ² = ‖c‖² − k`` (the normalised dual of ``X1∧X2∧X3∧X4``). Coplanar: the circumcircle of
    the 3 of the 4 points spanning the largest triangle.

    Parameters
    ----------
    quads : (K, 4, 3) float64
        Quadruples of points (metres). A single ``(4, 3)`` quadruple is accepted too.
    eta : float
        Relative coplanarity tolerance.

    Returns
    -------
    SphereFit
    """
    Q = np.asarray(quads, dtype=np.float64)
    if Q.ndim == 2:
        Q = Q[None]
    if Q.ndim != 3 or Q.shape[1:] != (4, 3):
        raise InputError(f"quads: expected shape (K, 4, 3), got {Q.shape}")
    K = Q.shape[0]
    centres = np.full((K, 3), np.nan)
    radii = np.full(K, np.nan)
    normals = np.full((K, 3), np.nan)
    if K == 0:
        return SphereFit(centres, radii, np.zeros(0, bool), normals, np.zeros(0, bool))
    E = Q[:, 1:] - Q[:, :1]  # (K, 3, 3)
    det = np.linalg.det(E)
    iu = np.triu_indices(4, 1)
    pair = np.linalg.norm(Q[:, iu[0]] - Q[:, iu[1]], axis=2)
    s = pair.mean(axis=1)
    coplanar = ~(np.abs(det) >= eta * s**3)
    sph = ~coplanar
    if sph.any():
        Qs = Q[sph]
        A = np.concatenate([2.0 * Qs, -np.ones((Qs.shape[0], 4, 1))], axis=2)
        rhs = np.sum(Qs * Qs, axis=2)
        try:
            sol = np.linalg.solve(A, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:  # an exactly singular quadruple: solve row by row
            sol = np.full((Qs.shape[0], 4), np.nan)
            for i in range(Qs.shape[0]):
                try:
                    sol[i] = np.linalg.solve(A[i], rhs[i])
                except np.linalg.LinAlgError:
                    pass
        c = sol[:, :3]
        r2 = np.sum(c * c, axis=1) - sol[:, 3]
        centres[sph] = c
        with np.errstate(invalid="ignore"):
            radii[sph] = np.where(r2 >= 0, np.sqrt(np.abs(r2)), np.nan)
    if coplanar.any():
        Qc = Q[coplanar]
        tri = Qc[:, _TRIPLES]  # (Kc, 4, 3, 3)
        area2 = np.linalg.norm(
            np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0]), axis=2
        )
        best = np.argmax(area2, axis=1)
        t = tri[np.arange(Qc.shape[0]), best]
        c, r, n = _circumcircles(t[:, 0], t[:, 1], t[:, 2])
        centres[coplanar] = c
        radii[coplanar] = r
        normals[coplanar] = n
    valid = np.isfinite(radii) & np.isfinite(centres).all(axis=1)
    return SphereFit(centres, radii, coplanar, normals, valid)


def sphere_through_points(
    p1: Any, p2: Any, p3: Any, p4: Any, *, eta: float = 1e-3
) -> tuple[np.ndarray, float, bool]:
    """Single-quadruple :func:`spheres_through_points`: ``(centre (3,), radius, is_circle)``.

    Raises
    ------
    InputError
        The points are collinear or coincident (no sphere or circle through them).
    """
    fit = spheres_through_points(np.stack([_pts(p) for p in (p1, p2, p3, p4)])[None], eta=eta)
    if not fit.valid[0]:
        raise InputError("sphere_through_points: the 4 points are collinear or coincident")
    return fit.centres[0], float(fit.radii[0]), bool(fit.circle[0])


# --------------------------------------------------------------------------------------------
# dense 32-component multivectors (NumPy): index = blade bitmap (kingdon's key order)
# --------------------------------------------------------------------------------------------


def _blade_gp(a: int, b: int) -> tuple[int, float]:
    """Product of basis blades given as bitmaps: ``(bitmap, sign)`` with metric ``METRIC``."""
    # reordering sign: count swaps to move b's vectors past a's
    s = 0
    x = a >> 1
    while x:
        s += bin(x & b).count("1")
        x >>= 1
    sign = -1.0 if s & 1 else 1.0
    common = a & b
    for i in range(5):
        if common >> i & 1:
            sign *= METRIC[i]
    return a ^ b, sign


@functools.cache
def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    idx = np.zeros((32, 32), dtype=np.int64)
    sgn = np.zeros((32, 32))
    for i in range(32):
        for j in range(32):
            idx[i, j], sgn[i, j] = _blade_gp(i, j)
    grade = np.array([bin(i).count("1") for i in range(32)])
    return idx, sgn, grade


def gp(A: Any, B: Any) -> np.ndarray:
    """Geometric product of dense multivectors ``(..., 32)`` (blade index = bitmap)."""
    idx, sgn, _ = _tables()
    A = np.asarray(A, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    prod = A[..., :, None] * B[..., None, :] * sgn  # (..., 32, 32)
    out = np.zeros(np.broadcast_shapes(A.shape, B.shape))
    flat_out = out.reshape(-1, 32)
    flat_prod = np.broadcast_to(prod, (*out.shape[:-1], 32, 32)).reshape(-1, 1024)
    cols = idx.reshape(-1)
    for r in range(flat_out.shape[0]):
        flat_out[r] = np.bincount(cols, weights=flat_prod[r], minlength=32)
    return out


def reverse(A: Any) -> np.ndarray:
    """Reverse ``Ã`` of dense multivectors ``(..., 32)`` (sign ``(−1)^{g(g−1)/2}`` per grade)."""
    _, _, grade = _tables()
    sign = np.where((grade * (grade - 1) // 2) % 2 == 1, -1.0, 1.0)
    return np.asarray(A, dtype=np.float64) * sign


def _vec_dense(v: Any) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros((*v.shape[:-1], 32))
    for k, bit in enumerate(_VEC_BITS):
        out[..., bit] = v[..., k]
    return out


@functools.cache
def _motor_basis_dense() -> np.ndarray:
    """The 8 :data:`MOTOR_BASIS` elements as dense ``(8, 32)`` multivectors."""
    E = np.zeros((8, 32))
    E[0, 0] = 1.0
    E[1, 0b00011] = 1.0  # e12
    E[2, 0b00101] = 1.0  # e13
    E[3, 0b00110] = 1.0  # e23
    for k, bit in enumerate((1, 2, 4)):  # ei∞ = ei e4 + ei e5
        E[4 + k, bit | 8] = 1.0
        E[4 + k, bit | 16] = 1.0
    E[7, 0b01111] = 1.0  # e123∞ = e1234 + e1235
    E[7, 0b10111] = 1.0
    return E


def motor_to_dense(m: Any) -> np.ndarray:
    """8 motor coefficients (:data:`MOTOR_BASIS`) → dense ``(32,)`` multivector."""
    return np.asarray(m, dtype=np.float64) @ _motor_basis_dense()


def dense_to_motor(A: Any) -> np.ndarray:
    """Dense even multivector ``(32,)`` → 8 motor coefficients (other blades are dropped)."""
    A = np.asarray(A, dtype=np.float64)
    return np.array(
        [A[0], A[3], A[5], A[6], A[9], A[10], A[12], A[15]]
    )  # the e∞ parts are read from the e4 blades (ei∞ = ei4 + ei5)


@functools.cache
def motor_estimation_tensor() -> np.ndarray:
    """``G[j, k, a, b] = ⟨E_j e_a Ẽ_k e_b⟩₀`` ``(8, 8, 5, 5)`` (ALGORITHMS §G.3 step 2).

    For grade-1 data ``X = Σ X^a e_a``, ``Y = Σ Y^b e_b``:
    ``⟨E_j X Ẽ_k Y⟩₀ = Σ_ab X^a Y^b G[j, k, a, b]``, so the Valkenburg–Dorst matrix of a whole
    data set only needs the ``5×5`` moment ``Σ w X ⊗ Y``. Built numerically with :func:`gp`
    (convention-proof), cached.
    """
    E = _motor_basis_dense()
    Er = reverse(E)
    ev = _vec_dense(np.eye(5))  # (5, 32)
    G = np.zeros((8, 8, 5, 5))
    for j in range(8):
        EjA = gp(E[j][None, :], ev)  # (5, 32): E_j e_a
        for k in range(8):
            EjAEk = gp(EjA, Er[k][None, :])  # (5, 32)
            for b in range(5):
                G[j, k, :, b] = gp(EjAEk, ev[b][None, :])[:, 0]
    return G


def estimate_motor(
    X: Any, Y: Any, weights: Any | None = None, *, rcond: float = 1e-10
) -> tuple[np.ndarray, dict[str, Any]]:
    """Motor ``M`` maximising ``Σ wᵢ ⟨M Xᵢ M̃ Yᵢ⟩₀`` (Valkenburg & Dorst 2011; ALGORITHMS §G.3).

    ``X``, ``Y`` are grade-1 objects (points, spheres, planes) as ``(N, 5)`` coefficient
    arrays; for normalised points/spheres the objective equals
    ``Σ wᵢ ½(ρᵢ² + ρ'ᵢ² − ‖yᵢ − (R xᵢ + t)‖²)``, so the motor is the weighted least-squares rigid
    motion taking the centres of ``X`` onto those of ``Y`` (it equals Kabsch on them).

    Steps: ``L = ½(Lraw + Lrawᵀ)`` with ``Lraw[j, k] = Σ wᵢ ⟨E_j Xᵢ Ẽ_k Yᵢ⟩₀``
    (:func:`motor_estimation_tensor`); Schur complement ``L' = L_RR − L_RT L_TT⁺ L_TR``
    (Moore–Penrose pseudo-inverse, relative cut-off ``rcond``); rotor = eigenvector of the
    largest eigenvalue of ``L'``; translation part ``τ = −L_TT⁺ L_TR r``; ``M`` normalised.

    Parameters
    ----------
    X, Y : (N, 5) float64
        Objects to move (``X``) and reference objects (``Y``), paired by row.
    weights : (N,) float64, optional
        Non-negative weights (default 1).
    rcond : float
        Relative singular-value cut-off of the pseudo-inverse.

    Returns
    -------
    m : (8,) float64
        Motor coefficients over :data:`MOTOR_BASIS` (``M X M̃ ≈ Y``).
    info : dict
        ``eigenvalues`` of ``L'`` (ascending), ``gap`` (relative gap between the two largest:
        a small gap means the rotation is poorly determined), ``L`` (8×8).

    Raises
    ------
    InputError
        Mismatched shapes, fewer than 3 pairs, non-finite values or weights summing to zero.
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 5 or X.shape != Y.shape:
        raise InputError(f"estimate_motor: X, Y must both be (N, 5), got {X.shape}, {Y.shape}")
    if X.shape[0] < 3:
        raise InputError(f"estimate_motor: need at least 3 pairs, got {X.shape[0]}")
    w = np.ones(X.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (X.shape[0],) or not (np.isfinite(w).all() and (w >= 0).all() and w.sum() > 0):
        raise InputError("estimate_motor: weights must be (N,) finite, >= 0, not all zero")
    if not (np.isfinite(X).all() and np.isfinite(Y).all()):
        raise InputError("estimate_motor: non-finite coefficients")
    A = (X * w[:, None]).T @ Y  # (5, 5) = Σ w X ⊗ Y
    Lraw = np.einsum("jkab,ab->jk", motor_estimation_tensor(), A)
    L = 0.5 * (Lraw + Lraw.T)
    LRR, LRT, LTT = L[:4, :4], L[:4, 4:], L[4:, 4:]
    Ptt = np.linalg.pinv(LTT, rcond=rcond, hermitian=True)
    Lp = LRR - LRT @ Ptt @ LRT.T
    Lp = 0.5 * (Lp + Lp.T)
    evals, evecs = np.linalg.eigh(Lp)
    r = evecs[:, -1]
    tau = -Ptt @ LRT.T @ r
    m = np.concatenate([r, tau])
    m /= np.linalg.norm(r)
    if m[0] < 0:
        m = -m
    span = max(abs(evals[-1] - evals[0]), 1e-300)
    info = {"eigenvalues": evals, "gap": float((evals[-1] - evals[-2]) / span), "L": L}
    return m, info


# ---- motors (NumPy) ------------------------------------------------------------------------


def rotor_from_quat(q: Any) -> np.ndarray:
    """Rotor coefficients over ``[1, e12, e13, e23]`` of quaternion ``(x, y, z, w)``."""
    x, y, z, w = np.asarray(q, dtype=np.float64).reshape(4)
    return np.array([w, -z, y, -x])


def rotor_to_quat(r: Any) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)``, ``w ≥ 0``, of rotor coefficients ``[1, e12, e13, e23]``."""
    a, b12, b13, b23 = np.asarray(r, dtype=np.float64).reshape(4)
    q = np.array([-b23, b13, -b12, a])
    n = np.linalg.norm(q)
    if not n > 0:
        raise InputError("rotor_to_quat: zero rotor")
    q /= n
    return -q if q[3] < 0 else q


def motor_from_rt(R: Any, t: Any) -> np.ndarray:
    """Motor ``M = T R`` (8 coefficients, :data:`MOTOR_BASIS`) of ``x ↦ R x + t``.

    Closed form: ``M = r − ½ (w t + t⌋b + t∧b) e∞`` with rotor ``r = w + b``.
    """
    from relnav.geometry.rotations import matrix_to_quat

    r = rotor_from_quat(matrix_to_quat(np.asarray(R, dtype=np.float64)))
    t = np.asarray(t, dtype=np.float64).reshape(3)
    Rd = np.zeros(32)
    Rd[[0, 3, 5, 6]] = r
    Td = np.zeros(32)
    Td[0] = 1.0
    for k, bit in enumerate((1, 2, 4)):
        Td[bit | 8] = -0.5 * t[k]
        Td[bit | 16] = -0.5 * t[k]
    return dense_to_motor(gp(Td, Rd))


def motor_to_rt(m: Any) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrix ``(3, 3)`` and translation ``(3,)`` of a motor (8 coefficients).

    The motor is normalised by ``sqrt(⟨M M̃⟩₀)`` (= the rotor norm). Decomposition
    (ALGORITHMS §G.3 step 7): rotor = the ``E_R`` part, ``T = M R̃ = 1 − ½ t e∞``, so
    ``tᵢ = −2·⟨T⟩_{eᵢ∞}``.
    """
    from relnav.geometry.rotations import quat_to_matrix

    m = np.asarray(m, dtype=np.float64).reshape(8)
    n = np.linalg.norm(m[:4])
    if not (n > 0 and np.isfinite(m).all()):
        raise InputError("motor_to_rt: motor has a zero or non-finite rotor part")
    m = m / n
    q = rotor_to_quat(m[:4])
    Md = motor_to_dense(m)
    Rd = np.zeros(32)
    Rd[[0, 3, 5, 6]] = m[:4]
    Td = gp(Md, reverse(Rd))
    t = -2.0 * np.array([Td[1 | 8], Td[2 | 8], Td[4 | 8]])
    return quat_to_matrix(q), t


def motor_apply(m: Any, points: Any) -> np.ndarray:
    """Apply a motor to ``(N, 3)`` points (fast path: via its ``R, t``; equals ``down(M X M̃)``)."""
    R, t = motor_to_rt(m)
    return _pts(points) @ R.T + t


# --------------------------------------------------------------------------------------------
# kingdon (lazy): definitions / verification
# --------------------------------------------------------------------------------------------


@functools.cache
def algebra() -> Any:
    """The ``kingdon.Algebra(4, 1)`` instance (``e4 = e+``, ``e5 = e−``); imported lazily."""
    from kingdon import Algebra

    return Algebra(4, 1)


@dataclass(frozen=True)
class _Basis:
    e1: Any
    e2: Any
    e3: Any
    e4: Any
    e5: Any
    eo: Any
    einf: Any
    I3: Any
    I5: Any


@functools.cache
def basis() -> _Basis:
    """kingdon blades ``e1 … e5``, ``eo = ½(e5 − e4)``, ``einf = e4 + e5``, ``I3``, ``I5``."""
    alg = algebra()
    b = alg.blades
    return _Basis(
        e1=b.e1,
        e2=b.e2,
        e3=b.e3,
        e4=b.e4,
        e5=b.e5,
        eo=0.5 * (b.e5 - b.e4),
        einf=b.e4 + b.e5,
        I3=b.e123,
        I5=b.e12345,
    )


def up_mv(x: Any) -> Any:
    """kingdon conformal point ``x + ½x² e∞ + e0`` of one Euclidean point ``(3,)``."""
    B = basis()
    x = _pts(x).reshape(3)
    v = float(x[0]) * B.e1 + float(x[1]) * B.e2 + float(x[2]) * B.e3
    return v + 0.5 * float(x @ x) * B.einf + B.eo


def sphere_dual_mv(p1: Any, p2: Any, p3: Any, p4: Any) -> Any:
    """OPNS sphere ``S* = X1 ∧ X2 ∧ X3 ∧ X4`` (kingdon quadvector)."""
    return up_mv(p1) ^ up_mv(p2) ^ up_mv(p3) ^ up_mv(p4)


def sphere_from_dual_mv(S_star: Any) -> tuple[np.ndarray, float]:
    """Centre ``(3,)`` and signed ``ρ²`` of an OPNS sphere ``S*`` (kingdon).

    ``S = S*·I5`` (IPNS form, any scale), normalised ``s = S/(−S·e∞)``: centre = Euclidean part,
    ``ρ² = s·s`` (paper 2 eq. 12, corrected).
    """
    B = basis()
    S = S_star * B.I5
    vec = mv_to_dense(S)
    v5 = np.array([vec[b] for b in _VEC_BITS])
    c, r2 = sphere_params(v5)
    return c, float(r2)


def motor_mv(m: Any) -> Any:
    """kingdon motor from 8 coefficients (:data:`MOTOR_BASIS`)."""
    B = basis()
    m = np.asarray(m, dtype=np.float64).reshape(8)
    b = algebra().blades
    einf = B.einf
    return (
        float(m[0])
        + float(m[1]) * b.e12
        + float(m[2]) * b.e13
        + float(m[3]) * b.e23
        + float(m[4]) * (b.e1 ^ einf)
        + float(m[5]) * (b.e2 ^ einf)
        + float(m[6]) * (b.e3 ^ einf)
        + float(m[7]) * (b.e123 ^ einf)
    )


def mv_to_dense(X: Any) -> np.ndarray:
    """Dense ``(32,)`` coefficients (index = bitmap) of a kingdon multivector (or a scalar)."""
    out = np.zeros(32)
    if np.isscalar(X):
        out[0] = float(X)
        return out
    for k, v in zip(X.keys(), X.values(), strict=True):
        out[int(k)] += float(v)
    return out
