"""Target attitude over time: static, constant spin, torque-free tumbling.

Every function returns ``R_W_target`` of shape ``(N, 3, 3)`` at the given frame times: the
rotation mapping target-body coordinates to the world frame ``W`` (centred on the target's
centre of mass). ``W`` is treated as inertial for the attitude dynamics **[interpretation: the
LVLH frame rotates at the orbital rate n ≈ 1e-3 rad/s; over a few minutes of inspection this
is negligible against the tumbling rates simulated, and users who want it can add it as a
spin about z of rate −n]**.

The tumbling model integrates Euler's equations ``I ω̇ = −ω × (I ω)`` (body frame) together
with the quaternion kinematics ``q̇ = ½ q ⊗ [ω, 0]`` (``xyzw``, Hamilton, body rate) using SciPy's
``solve_ivp`` (DOP853, ``rtol = 1e-10``), renormalising the quaternion at every output.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from relnav.errors import ConfigError, InputError
from relnav.geometry.rotations import (
    matrix_to_quat,
    quat_multiply,
    quat_to_matrix,
    rotvec_to_matrix,
)

__all__ = [
    "ATTITUDE_KINDS",
    "angular_momentum_world",
    "make_attitude",
    "rotational_energy",
    "spin",
    "static",
    "tumble",
]

log = logging.getLogger(__name__)

ATTITUDE_KINDS = ("static", "spin", "tumble")

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _times(times: np.ndarray) -> np.ndarray:
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(t)):
        raise InputError("attitude: times must be finite")
    return t


def _R0(R0: np.ndarray | None) -> np.ndarray:
    if R0 is None:
        return np.eye(3)
    R = np.asarray(R0, dtype=np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9):
        raise InputError("attitude: R0 must be a 3x3 rotation matrix")
    return R


def _axis(axis: str | Sequence[float]) -> np.ndarray:
    if isinstance(axis, str):
        key = axis.lower().lstrip("+")
        if key not in _AXES:
            raise InputError(f"spin axis must be x, y, z or a 3-vector, got {axis!r}")
        return np.array(_AXES[key])
    a = np.asarray(axis, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) < 1e-12:
        raise InputError(f"spin axis must be a non-zero 3-vector, got {axis!r}")
    return a / np.linalg.norm(a)


def static(times: np.ndarray, R0: np.ndarray | None = None) -> np.ndarray:
    """Constant attitude ``R0`` (default identity) at every time: ``(N, 3, 3)``."""
    t = _times(times)
    return np.broadcast_to(_R0(R0), (len(t), 3, 3)).copy()


def spin(
    times: np.ndarray,
    *,
    axis: str | Sequence[float] = "z",
    rate_deg_s: float = 5.0,
    R0: np.ndarray | None = None,
) -> np.ndarray:
    """Constant-rate spin about a fixed world axis: ``R(t) = Rot(axis, ω t) R0``.

    Parameters
    ----------
    times : (N,) float
        Times (s).
    axis : {"x", "y", "z"} or (3,) float
        Spin axis in ``W`` (normalised).
    rate_deg_s : float
        Spin rate (deg/s, right-handed about ``axis``).
    R0 : (3, 3) float, optional
        Attitude at ``t = 0``.
    """
    t = _times(times)
    a = _axis(axis)
    ang = np.deg2rad(rate_deg_s) * t
    return rotvec_to_matrix(ang[:, None] * a[None, :]) @ _R0(R0)


def _inertia(inertia: Sequence[float] | np.ndarray) -> np.ndarray:
    J = np.asarray(inertia, dtype=np.float64)
    if J.shape == (3,):
        J = np.diag(J)
    if J.shape != (3, 3) or not np.all(np.isfinite(J)):
        raise InputError("inertia must be 3 principal moments or a 3x3 matrix (kg m²)")
    if not np.allclose(J, J.T, rtol=1e-9, atol=1e-12):
        raise InputError("inertia tensor must be symmetric")
    ev = np.linalg.eigvalsh(J)
    if ev.min() <= 0:
        raise InputError(f"inertia tensor must be positive definite, eigenvalues {ev}")
    # triangle inequality of the principal moments (physical rigid body)
    if ev[0] + ev[1] < ev[2] * (1 - 1e-9):
        raise InputError(
            f"principal moments {ev} violate the triangle inequality I1 + I2 >= I3; "
            "not a physical rigid body"
        )
    return J


def tumble(
    times: np.ndarray,
    *,
    inertia: Sequence[float] | np.ndarray = (1.0, 2.0, 3.0),
    omega0_deg_s: Sequence[float] = (2.0, 0.5, 4.0),
    R0: np.ndarray | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    return_omega: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Torque-free tumbling of a rigid body with inertia ``I`` from body rate ``ω0``.

    Parameters
    ----------
    times : (N,) float
        Output times (s); integration starts at ``t = 0`` (the epoch of ``R0`` and ``ω0``).
    inertia : (3,) or (3, 3) float
        Principal moments or full inertia tensor in the body frame (kg m²; only ratios matter).
    omega0_deg_s : (3,) float
        Initial angular velocity in the body frame (deg/s).
    R0 : (3, 3) float, optional
        ``R_W_target`` at ``t = 0`` (default identity).
    rtol, atol : float
        ``solve_ivp`` tolerances.
    return_omega : bool
        Also return the body rates ``(N, 3)`` (rad/s).

    Returns
    -------
    (N, 3, 3) float64
        ``R_W_target`` at ``times`` (and ``ω_body`` ``(N, 3)`` rad/s if ``return_omega``).
    """
    t = _times(times)
    J = _inertia(inertia)
    Jinv = np.linalg.inv(J)
    w0 = np.deg2rad(np.asarray(omega0_deg_s, dtype=np.float64).reshape(-1))
    if w0.shape != (3,) or not np.all(np.isfinite(w0)):
        raise InputError(f"omega0_deg_s must be 3 finite numbers, got {omega0_deg_s!r}")
    q0 = matrix_to_quat(_R0(R0))
    if len(t) == 0:
        out = np.zeros((0, 3, 3))
        return (out, np.zeros((0, 3))) if return_omega else out

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        q, w = y[:4], y[4:]
        qdot = 0.5 * quat_multiply(q, np.array([w[0], w[1], w[2], 0.0]))
        wdot = Jinv @ (-np.cross(w, J @ w))
        return np.concatenate([qdot, wdot])

    if np.any(t < 0):
        raise InputError("tumble: times must be >= 0 (integration starts at t = 0)")
    order = np.argsort(t, kind="stable")
    ts = t[order]
    t_end = float(ts[-1])
    y0 = np.concatenate([q0, w0])
    if t_end == 0.0:
        Y = np.tile(y0, (len(t), 1))
    else:
        sol = solve_ivp(
            rhs,
            (0.0, t_end),
            y0,
            method="DOP853",
            t_eval=ts,
            rtol=rtol,
            atol=atol,
        )
        if not sol.success:  # pragma: no cover - DOP853 on a smooth ODE
            raise InputError(f"tumble integration failed: {sol.message}")
        Ys = sol.y.T
        Y = np.empty_like(Ys)
        Y[order] = Ys
    q = Y[:, :4] / np.linalg.norm(Y[:, :4], axis=1, keepdims=True)
    R = quat_to_matrix(q)
    return (R, Y[:, 4:].copy()) if return_omega else R


def rotational_energy(omega_body: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """Kinetic energy ``½ ωᵀ I ω`` per row of body rates ``(N, 3)`` (rad/s)."""
    J = _inertia(inertia)
    w = np.asarray(omega_body, dtype=np.float64).reshape(-1, 3)
    return 0.5 * np.einsum("ni,ij,nj->n", w, J, w)


def angular_momentum_world(
    R_W_target: np.ndarray, omega_body: np.ndarray, inertia: np.ndarray
) -> np.ndarray:
    """Angular momentum in ``W``: ``L = R I ω`` ``(N, 3)`` (constant for a torque-free body)."""
    J = _inertia(inertia)
    w = np.asarray(omega_body, dtype=np.float64).reshape(-1, 3)
    return np.einsum("nij,nj->ni", np.asarray(R_W_target), w @ J.T)


def make_attitude(kind: str, times: np.ndarray, **params: Any) -> np.ndarray:
    """``R_W_target`` ``(N, 3, 3)`` for attitude ``kind`` in :data:`ATTITUDE_KINDS`.

    ``static``: ``R0``; ``spin``: ``axis``, ``rate_deg_s``, ``R0``; ``tumble``: ``inertia``,
    ``omega0_deg_s``, ``R0``. Bad kinds or parameters raise :class:`ConfigError`.
    """
    fns = {"static": static, "spin": spin, "tumble": tumble}
    if kind not in fns:
        raise ConfigError(
            f"unknown attitude kind {kind!r}; choose one of {', '.join(ATTITUDE_KINDS)}"
        )
    try:
        out = fns[kind](times, **params)
    except InputError as e:
        raise ConfigError(f"attitude {kind!r}: {e}") from None
    except TypeError as e:
        raise ConfigError(f"attitude {kind!r}: {e}") from None
    return out  # type: ignore[return-value]
