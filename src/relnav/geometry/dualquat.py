"""Unit dual quaternions and the Cayley transform ("twist") of Paper 2 (ALGORITHMS.md §G.6).

Storage
-------
A dual quaternion ``q̂ = q + ε q_d`` (``ε² = 0``) is a float64 array of shape ``(..., 8)``:
``[qx, qy, qz, qw, dx, dy, dz, dw]`` — real part first, each part in the package's ``(x, y, z, w)``
quaternion order. For a rigid transform ``p' = R p + t`` (``T = [[R, t], [0, 1]]``, e.g.
``T_a_b``) the unit dual quaternion is ``q̂ = q + ε ½ t ⊗ q`` with ``t`` a pure quaternion
(Paper 2 eq. 28 prints ``½ dᵀ Δt q``; read as ``½ d q`` **[interpretation]**). Composition
follows matrix order: ``dq(T1 @ T2) = dq(T1) ⊗ dq(T2)``. ``q̂`` and ``−q̂`` are the same pose.

Cayley transform
----------------
``B = (q̂ − 1)(q̂ + 1)⁻¹`` and its inverse ``q̂ = (1 + B)(1 − B)⁻¹`` (Paper 2 eqs. 29, 33), in
dual-quaternion arithmetic. For a unit ``q̂`` the result is a *pure* dual quaternion, stored as
six numbers ``[B_r (3), B_d (3)]`` (vector parts of the real and dual halves). The real half is
``tan(φ/4) u`` (= modified Rodrigues parameters of the rotation by ``φ`` about ``u``); for small
motions ``B ≈ ¼ [φ u, t]``. The transform is singular at ``q = −1`` (``φ = 2π``):
:func:`cayley` maps its input to the hemisphere ``q_w ≥ 0`` first unless ``hemisphere=False``.
"""

from __future__ import annotations

import numpy as np

from relnav.errors import InputError
from relnav.geometry.rotations import matrix_to_quat, quat_to_matrix

__all__ = [
    "cayley",
    "cayley_inverse",
    "cayley_mean",
    "dq_canonical",
    "dq_conjugate",
    "dq_from_matrix",
    "dq_from_rt",
    "dq_identity",
    "dq_inverse",
    "dq_multiply",
    "dq_normalize",
    "dq_to_matrix",
    "dq_to_rt",
    "dq_transform_points",
    "quat_cayley",
    "quat_cayley_inverse",
    "quat_cayley_mean",
    "quat_conjugate",
    "quat_inverse",
]

_CONJ = np.array([-1.0, -1.0, -1.0, 1.0])


def _as_dq(a: np.ndarray, name: str = "dual quaternion") -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape[-1:] != (8,):
        raise InputError(f"{name} must have shape (..., 8), got {a.shape}")
    return a


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of ``(..., 4)`` xyzw quaternions (same as ``rotations.quat_multiply``,
    without its axis shuffling: this is the hot path of the UKF)."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 1] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 2] = aw * bz + ax * by - ay * bx + az * bw
    out[..., 3] = aw * bw - ax * bx - ay * by - az * bz
    return out


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate ``q*`` of quaternion(s) ``(..., 4)`` in ``(x, y, z, w)`` order."""
    return np.asarray(q, dtype=np.float64) * _CONJ


def quat_inverse(q: np.ndarray) -> np.ndarray:
    """Inverse ``q* / |q|²`` of (not necessarily unit) quaternion(s) ``(..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    return quat_conjugate(q) / np.sum(q * q, axis=-1, keepdims=True)


def dq_identity() -> np.ndarray:
    """The identity dual quaternion ``1`` ``(8,)``."""
    out = np.zeros(8)
    out[3] = 1.0
    return out


def dq_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Product ``a ⊗ b = a_r b_r + ε (a_r b_d + a_d b_r)`` of dual quaternions ``(..., 8)``."""
    a = _as_dq(a)
    b = _as_dq(b)
    real = qmul(a[..., :4], b[..., :4])
    dual = qmul(a[..., :4], b[..., 4:]) + qmul(a[..., 4:], b[..., :4])
    return np.concatenate([real, dual], axis=-1)


def dq_conjugate(a: np.ndarray) -> np.ndarray:
    """Quaternion conjugate of both parts, ``q* + ε q_d*`` — the inverse of a *unit* ``a``."""
    a = _as_dq(a)
    return np.concatenate([quat_conjugate(a[..., :4]), quat_conjugate(a[..., 4:])], axis=-1)


def dq_inverse(a: np.ndarray) -> np.ndarray:
    """General inverse ``q⁻¹ − ε q⁻¹ q_d q⁻¹`` (requires a non-zero real part)."""
    a = _as_dq(a)
    ri = quat_inverse(a[..., :4])
    di = -qmul(qmul(ri, a[..., 4:]), ri)
    return np.concatenate([ri, di], axis=-1)


def dq_canonical(a: np.ndarray) -> np.ndarray:
    """The representative of ``±a`` with real scalar part ``q_w ≥ 0`` (same pose)."""
    a = _as_dq(a)
    return np.where(a[..., 3:4] < 0.0, -a, a)


def dq_normalize(a: np.ndarray) -> np.ndarray:
    """Nearest unit dual quaternion: ``q/|q|`` and the dual part made orthogonal to it.

    Enforces ``|q| = 1`` and ``q·q_d = 0`` (the two unit constraints), keeping the
    translation ``2 q_d q*`` of the normalized input.
    """
    a = _as_dq(a)
    n = np.linalg.norm(a[..., :4], axis=-1, keepdims=True)
    if np.any(n <= 0.0) or not np.all(np.isfinite(n)):
        raise InputError("dual quaternion with a zero or non-finite real part cannot be normalized")
    r = a[..., :4] / n
    d = a[..., 4:] / n
    d = d - np.sum(r * d, axis=-1, keepdims=True) * r
    return np.concatenate([r, d], axis=-1)


def dq_from_rt(quat_xyzw: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Unit dual quaternion of ``p' = R(q) p + t``: ``q + ε ½ t ⊗ q``.

    Parameters
    ----------
    quat_xyzw : (..., 4) array_like
        Rotation quaternion(s) (normalized here).
    t : (..., 3) array_like
        Translation(s), metres.

    Returns
    -------
    (..., 8) ndarray
    """
    q = np.asarray(quat_xyzw, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if q.shape[-1:] != (4,) or t.shape[-1:] != (3,):
        raise InputError(f"expected quaternion (..., 4) and translation (..., 3), got {q.shape}")
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    tq = np.concatenate([t, np.zeros((*t.shape[:-1], 1))], axis=-1)
    qd = 0.5 * qmul(tq, q)
    q, qd = np.broadcast_arrays(q, qd)
    return np.concatenate([q, qd], axis=-1)


def dq_to_rt(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation quaternion ``(..., 4)`` (``w ≥ 0``) and translation ``2 q_d ⊗ q*`` ``(..., 3)``."""
    a = _as_dq(a)
    t = 2.0 * qmul(a[..., 4:], quat_conjugate(a[..., :4]))[..., :3]
    q = a[..., :4]
    q = np.where(q[..., 3:4] < 0.0, -q, q)
    return q, t


def dq_from_matrix(T: np.ndarray) -> np.ndarray:
    """Unit dual quaternion(s) of rigid transform(s) ``(..., 4, 4)``."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise InputError(f"transform must have shape (..., 4, 4), got {T.shape}")
    return dq_from_rt(matrix_to_quat(T[..., :3, :3]), T[..., :3, 3])


def dq_to_matrix(a: np.ndarray) -> np.ndarray:
    """Rigid transform(s) ``(..., 4, 4)`` of unit dual quaternion(s)."""
    q, t = dq_to_rt(a)
    T = np.zeros((*q.shape[:-1], 4, 4))
    T[..., :3, :3] = quat_to_matrix(q)
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def dq_transform_points(a: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply one unit dual quaternion to points ``(N, 3)``: ``R p + t``."""
    q, t = dq_to_rt(_as_dq(a).reshape(8))
    return np.asarray(points, dtype=np.float64) @ quat_to_matrix(q).T + t


def _pure(v6: np.ndarray) -> np.ndarray:
    v6 = np.asarray(v6, dtype=np.float64)
    if v6.shape[-1:] != (6,):
        raise InputError(f"twist must have shape (..., 6), got {v6.shape}")
    z = np.zeros((*v6.shape[:-1], 1))
    return np.concatenate([v6[..., :3], z, v6[..., 3:], z], axis=-1)


def cayley(
    a: np.ndarray, *, hemisphere: bool = True, full: bool = False, general: bool = False
) -> np.ndarray:
    """Cayley transform ``B = (q̂ − 1)(q̂ + 1)⁻¹`` of unit dual quaternion(s).

    Parameters
    ----------
    a : (..., 8) array_like
        Unit dual quaternion(s).
    hemisphere : bool
        Map ``a`` to ``q_w ≥ 0`` first (default), so the result is finite for every pose and
        ``|B_r| ≤ 1`` (rotation angle ≤ π). With ``False`` the literal transform of ``a`` is
        returned (infinite at ``q = −1``).
    full : bool
        Return all 8 components (scalar parts included, ≈ 0 for unit input) instead of 6;
        implies ``general``.
    general : bool
        Evaluate the literal dual-quaternion expression (valid for any invertible ``q̂ + 1``)
        instead of the closed form for unit input ``B_r = v/(1 + w)``,
        ``B_d = (1 − B_r) q_d (q + 1)⁻¹``. Both agree to rounding on unit input.

    Returns
    -------
    (..., 6) ndarray
        ``[B_r, B_d]``: ``B_r = tan(φ/4) u``; ``B ≈ ¼ [φ u, t]`` for small motions.
    """
    a = _as_dq(a)
    if hemisphere:
        a = dq_canonical(a)
    if full or general:
        one = dq_identity()
        with np.errstate(divide="ignore", invalid="ignore"):
            B = dq_multiply(a - one, dq_inverse(a + one))
        return B if full else B[..., [0, 1, 2, 4, 5, 6]]
    q = a[..., :4]
    with np.errstate(divide="ignore", invalid="ignore"):
        qp1 = q.copy()
        qp1[..., 3] += 1.0
        inv_qp1 = quat_inverse(qp1)
        br = q[..., :3] / qp1[..., 3:4]
        one_m_br = np.concatenate([-br, np.ones((*br.shape[:-1], 1))], axis=-1)
        bd = qmul(qmul(one_m_br, a[..., 4:]), inv_qp1)[..., :3]
    return np.concatenate([br, bd], axis=-1)


def cayley_inverse(B: np.ndarray, *, general: bool = False) -> np.ndarray:
    """Inverse Cayley transform ``q̂ = (1 + B)(1 − B)⁻¹`` of twist(s) ``(..., 6)``.

    Always a unit dual quaternion, with ``q_w ≥ 0`` when ``|B_r| ≤ 1``;
    ``cayley_inverse(0)`` is the identity. Closed form: ``q = [2 B_r, 1 − |B_r|²]/(1 + |B_r|²)``,
    ``q_d = (1 + q) B_d (1 − B_r)⁻¹``; ``general=True`` evaluates the literal expression.
    """
    Bq = _pure(B)
    if general:
        one = dq_identity()
        return dq_multiply(one + Bq, dq_inverse(one - Bq))
    br = Bq[..., :4]
    n2 = np.sum(br * br, axis=-1, keepdims=True)
    den = 1.0 + n2
    q = np.concatenate([2.0 * br[..., :3], 1.0 - n2], axis=-1) / den
    inv_1mb = np.concatenate([br[..., :3], np.ones((*br.shape[:-1], 1))], axis=-1) / den
    qp1 = q.copy()
    qp1[..., 3] += 1.0
    qd = qmul(qmul(qp1, Bq[..., 4:]), inv_1mb)
    return np.concatenate([q, qd], axis=-1)


def cayley_mean(
    dqs: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    init: np.ndarray | None = None,
    tol: float = 1e-10,
    max_iter: int = 10,
) -> tuple[np.ndarray, int, bool]:
    """Weighted mean of poses by iterating in Cayley coordinates (ALGORITHMS.md §G.6 step 3).

    ``B̄ = Σ wᵢ cayley(m⁻¹ ⊗ q̂ᵢ)``, ``m ← m ⊗ cayley_inverse(B̄)`` until ``|B̄| < tol`` or
    ``max_iter`` iterations.

    Parameters
    ----------
    dqs : (M, 8) array_like
        Unit dual quaternions.
    weights : (M,) array_like, optional
        Weights summing to 1 (may contain negative entries, as UKF mean weights can);
        default uniform.
    init : (8,) array_like, optional
        Starting mean (default ``dqs[0]``).
    tol : float
        Stop when the norm of the mean twist is below this.
    max_iter : int
        Maximum number of iterations.

    Returns
    -------
    mean : (8,) ndarray
        Unit dual quaternion, ``q_w ≥ 0``.
    n_iter : int
        Iterations done.
    converged : bool
        ``|B̄| < tol`` reached.
    """
    X = _as_dq(dqs, "dqs").reshape(-1, 8)
    m = X.shape[0]
    if m == 0:
        raise InputError("cayley_mean needs at least one dual quaternion")
    w = np.full(m, 1.0 / m) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (m,):
        raise InputError(f"weights must have shape ({m},), got {w.shape}")
    mean = dq_canonical(X[0] if init is None else _as_dq(init).reshape(8))
    for it in range(1, max_iter + 1):
        Bi = cayley(dq_multiply(dq_conjugate(mean), X))
        Bbar = w @ Bi
        mean = dq_normalize(dq_multiply(mean, cayley_inverse(Bbar)))
        if float(np.linalg.norm(Bbar)) < tol:
            return dq_canonical(mean), it, True
    return dq_canonical(mean), max_iter, False


# --- rotation-only (real part) versions: the real part of a dual-quaternion product depends only
# on the real parts, so these equal the real halves of cayley / cayley_inverse / cayley_mean.


def quat_cayley(q: np.ndarray) -> np.ndarray:
    """Real half ``B_r = (q − 1)(q + 1)⁻¹ = v / (1 + w)`` of the Cayley transform of unit
    quaternion(s) ``(..., 4)`` xyzw, after mapping to ``w ≥ 0`` (= modified Rodrigues
    parameters ``tan(φ/4) u``)."""
    q = np.asarray(q, dtype=np.float64)
    s = np.where(q[..., 3:4] < 0.0, -1.0, 1.0)
    return s * q[..., :3] / (1.0 + s * q[..., 3:4])


def quat_cayley_inverse(b: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) ``(1 + b)(1 − b)⁻¹ = [2b, 1 − |b|²] / (1 + |b|²)`` of ``(..., 3)``."""
    b = np.asarray(b, dtype=np.float64)
    n2 = np.sum(b * b, axis=-1, keepdims=True)
    return np.concatenate([2.0 * b, 1.0 - n2], axis=-1) / (1.0 + n2)


def quat_cayley_mean(
    quats: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    init: np.ndarray | None = None,
    tol: float = 1e-10,
    max_iter: int = 10,
) -> tuple[np.ndarray, int, bool]:
    """Rotation part of :func:`cayley_mean`: weighted mean of unit quaternions ``(M, 4)``.

    Returns ``(mean (4,) with w ≥ 0, n_iter, converged)``.
    """
    X = np.asarray(quats, dtype=np.float64).reshape(-1, 4)
    m = X.shape[0]
    if m == 0:
        raise InputError("quat_cayley_mean needs at least one quaternion")
    w = np.full(m, 1.0 / m) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (m,):
        raise InputError(f"weights must have shape ({m},), got {w.shape}")
    mean = np.asarray(X[0] if init is None else init, dtype=np.float64).reshape(4)
    mean = mean / np.linalg.norm(mean)
    for it in range(1, max_iter + 1):
        bbar = w @ quat_cayley(qmul(quat_conjugate(mean), X))
        mean = qmul(mean, quat_cayley_inverse(bbar))
        mean = mean / np.linalg.norm(mean)
        if float(np.linalg.norm(bbar)) < tol:
            return (-mean if mean[3] < 0 else mean), it, True
    return (-mean if mean[3] < 0 else mean), max_iter, False
