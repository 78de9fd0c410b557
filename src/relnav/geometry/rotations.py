"""Rotations: quaternions ``(x, y, z, w)``, rotation vectors, Euler angles, SO(3) projection."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "angle_between_rotations",
    "euler_to_matrix",
    "hat",
    "hat_batch",
    "matrix_to_euler",
    "matrix_to_quat",
    "matrix_to_rotvec",
    "project_to_so3",
    "quat_multiply",
    "quat_to_matrix",
    "random_rotation",
    "rotation_angle",
    "rotvec_to_matrix",
]


def hat(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix ``[v]x`` of a 3-vector, so that ``hat(v) @ u == cross(v, u)``."""
    x, y, z = np.asarray(v, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def hat_batch(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrices ``(N, 3, 3)`` of the vectors ``(N, 3)`` (:func:`hat` of each)."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` (or ``(N, 3, 3)``) of unit quaternion(s) ``(x, y, z, w)``."""
    return Rotation.from_quat(np.asarray(q, dtype=np.float64)).as_matrix()


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of rotation matrix/matrices."""
    q = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    return np.where(q[..., 3:4] < 0, -q, q)


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrix of rotation vector(s) ``w`` (axis * angle, radians)."""
    return Rotation.from_rotvec(np.asarray(w, dtype=np.float64)).as_matrix()


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, radians) of rotation matrix/matrices."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()


def euler_to_matrix(angles: np.ndarray, seq: str = "xyz") -> np.ndarray:
    """Rotation matrix from Euler angles in radians (SciPy ``seq`` convention)."""
    return Rotation.from_euler(seq, np.asarray(angles, dtype=np.float64)).as_matrix()


def matrix_to_euler(R: np.ndarray, seq: str = "xyz") -> np.ndarray:
    """Euler angles in radians (SciPy ``seq`` convention) of a rotation matrix."""
    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_euler(seq)


def quat_multiply(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Hamilton product ``q1 ⊗ q2`` of quaternions in ``(x, y, z, w)`` order."""
    x1, y1, z1, w1 = np.moveaxis(np.asarray(q1, dtype=np.float64), -1, 0)
    x2, y2, z2, w2 = np.moveaxis(np.asarray(q2, dtype=np.float64), -1, 0)
    return np.stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ],
        axis=-1,
    )


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to a ``3x3`` matrix, by SVD polar decomposition.

    ``R = U diag(1, 1, det(U Vᵀ)) Vᵀ`` so that a reflection is never returned.
    """
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ D @ Vt


def rotation_angle(R: np.ndarray) -> np.ndarray | float:
    """Geodesic angle (radians, in ``[0, π]``) of rotation matrix/matrices ``R``."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R, axis1=-2, axis2=-1)
    ang = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    return float(ang) if np.ndim(ang) == 0 else ang


def angle_between_rotations(R1: np.ndarray, R2: np.ndarray) -> np.ndarray | float:
    """Geodesic angle (radians) of ``R1ᵀ R2``."""
    R1 = np.asarray(R1, dtype=np.float64)
    R2 = np.asarray(R2, dtype=np.float64)
    return rotation_angle(np.swapaxes(R1, -1, -2) @ R2)


def random_rotation(rng: np.random.Generator | int | None = None) -> np.ndarray:
    """Uniformly random rotation matrix (Haar measure), seeded."""
    rng = np.random.default_rng(rng)
    return Rotation.random(random_state=rng).as_matrix()
