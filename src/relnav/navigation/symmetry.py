"""Rotational symmetry of the navigator's map: the rotation a registration cannot observe.

A surface of revolution slides onto itself when rotated about its axis: every surface point's
velocity ``v(p) = a × (p − c)`` (axis ``a``, through ``c``) lies in the surface's tangent plane,
``n · v(p) = 0``. Written as a left twist ``u = [ρ, ω]`` of the target frame (``v = ρ + ω × p``,
here ``ω = a`` and ``ρ = c × a``), the normal component is linear in ``u``:
``n · v = lᵀ u`` with ``l = [n, p × n]`` (the normal line's Plücker coordinates). The twist that
moves the map least along its own normals, relative to how far it moves the points at all, is
the smallest generalised eigenvector of

.. math::

    M u = \\lambda G u, \\qquad M = \\sum_i l_i l_i^T, \\quad
    G = \\sum_i J_i^T J_i, \\quad J_i = [I, -[p_i]_\\times],

``λ`` being the mean squared normal displacement over the mean squared displacement. A body of
revolution has ``λ`` at the level of its normals' angular noise squared about its axis; a box
or an irregular body has ``λ`` of order 0.1 for every rotation.

**[interpretation]** The map's sampled positions and normals (voxel means, plane fits) alias as
information along ``u`` in a scan-to-map registration; the navigator can therefore take that
direction from its motion model (``NavigatorConfig.symmetry_*``). A map that still covers only
a small arc about the candidate axis is not declared symmetric (``min_arc_deg``): the edges of
a partial map are not evidence of a symmetry.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from relnav.geometry.rotations import hat_batch

__all__ = ["SymmetryAxis", "marginalise_direction", "stiffen_prior", "symmetry_axis"]

log = logging.getLogger(__name__)


@dataclass
class SymmetryAxis:
    """A rotational symmetry found in a map (target frame).

    Attributes
    ----------
    axis : (3,) float64
        Unit direction of the symmetry axis.
    center : (3,) float64
        Point of the axis closest to the origin, m.
    ratio : float
        Mean squared normal displacement over mean squared displacement of the map's points
        under a rotation about the axis (0 for an exact surface of revolution).
    arc_deg : float
        Azimuth about the axis covered by the map's points, degrees (10° bins).
    axial_fraction : float
        Fraction of the points whose normal is within 25° of the axis (a flat plate rotated
        about its normal slides onto itself too: not a body of revolution).
    twist : (6,) float64
        The rotation as a left twist ``[ρ (m), ω (rad)]`` of the target frame, ``ω = axis``,
        ``ρ = center × axis``.
    """

    axis: np.ndarray
    center: np.ndarray
    ratio: float
    arc_deg: float
    axial_fraction: float
    twist: np.ndarray


def _arc_deg(P: np.ndarray, axis: np.ndarray, center: np.ndarray) -> float:
    """Azimuth covered by the points about the axis, degrees (occupied 10° bins)."""
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 0.5:
        e1 = np.cross(axis, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    d = P - center
    az = np.arctan2(d @ e2, d @ e1)
    bins = np.floor((az + math.pi) / math.radians(10.0)).astype(np.int64) % 36
    return 10.0 * len(np.unique(bins))


def _normal_equations(
    L: np.ndarray, X: np.ndarray, S: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted ``M = Σ w l lᵀ`` and ``G = Σ w JᵀJ`` (``J = [I, −[x]×]``) of the eigenproblem."""
    M = (L * w[:, None]).T @ L
    G = np.zeros((6, 6))
    G[:3, :3] = float(w.sum()) * np.eye(3)
    G[:3, 3:] = -np.einsum("n,nij->ij", w, S)
    G[3:, :3] = G[:3, 3:].T
    G[3:, 3:] = np.einsum("n,nji,njk->ik", w, S, S)
    return M, G


def _normalised_residuals(L: np.ndarray, X: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Each point's normal displacement under the twist ``u`` over the (weighted) RMS
    displacement of all points."""
    disp = u[:3] + np.cross(u[3:], X)
    rms = math.sqrt(float(np.sum(w * np.sum(disp**2, axis=1))) / max(float(w.sum()), 1e-300))
    return (L @ u) / max(rms, 1e-300)


def symmetry_axis(
    points: np.ndarray,
    normals: np.ndarray,
    *,
    max_ratio: float,
    min_arc_deg: float,
    max_axial_fraction: float = 0.5,
    irls: int = 0,
    min_points: int = 50,
) -> SymmetryAxis | None:
    """The map's axis of rotational symmetry, or ``None`` when it has none.

    Parameters
    ----------
    points : (N, 3) float64
        Map points (target frame), m.
    normals : (N, 3) float64
        Their unit normals (sign arbitrary).
    max_ratio : float
        Largest ratio ``λ`` (mean squared normal displacement over mean squared displacement)
        of a symmetric map.
    min_arc_deg : float
        Smallest azimuth about the axis the map's points must cover, degrees.
    max_axial_fraction : float
        Largest fraction of points whose normal is within 25° of the axis (a plate, not a
        body of revolution, when more).
    irls : int
        Iteratively reweighted passes (0: the plain eigenproblem, ratio the mean squared
        normal displacement over the mean squared displacement; ``> 0``: the points are
        reweighted by their normal displacement and the ratio is the squared robust (median)
        normal displacement over the RMS displacement).
    min_points : int
        Fewer points (or a degenerate cloud): ``None``.

    Returns
    -------
    SymmetryAxis or None
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    Nn = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(Nn), axis=1)
    P, Nn = P[ok], Nn[ok]
    nn = np.linalg.norm(Nn, axis=1)
    P, Nn = P[nn > 0.5], Nn[nn > 0.5] / nn[nn > 0.5, None]
    if len(P) < max(min_points, 6):
        return None
    c0 = P.mean(0)
    X = P - c0  # centred for conditioning; the twist is moved back to the map frame below
    L = np.hstack([Nn, np.cross(X, Nn)])
    S = hat_batch(X)
    w = np.ones(len(X))
    lam = U = None
    for _ in range(1 + irls):
        M, G = _normal_equations(L, X, S, w)
        try:
            lam, U = scipy.linalg.eigh(M, G)
        except (np.linalg.LinAlgError, ValueError):
            return None
        if not irls:
            break
        # [interpretation] rims and edges of the map have poor normals: reweight the points
        # by their normal displacement under the best rotation (Cauchy, 3 robust sigmas)
        e = _normalised_residuals(L, X, U[:, 0], w)
        s = 1.4826 * float(np.median(np.abs(e)))
        if not s > 0:
            break
        w = 1.0 / (1.0 + (e / (3.0 * s)) ** 2)
    assert lam is not None and U is not None
    M, G = _normal_equations(L, X, S, np.ones(len(X)))
    for k in range(3):  # the smallest eigen-directions: the first that is a rotation
        u = U[:, k]
        w = float(np.linalg.norm(u[3:]))
        if w < 1e-12:
            continue
        a = u[3:] / w
        c = np.cross(a, u[:3] / w)  # the axis point nearest the centroid (rho = c x a)
        ur = np.concatenate([np.cross(c, a), a])  # pure rotation: the screw's pitch dropped
        if irls:  # robust: the median normal displacement over the RMS displacement
            e = _normalised_residuals(L, X, ur, np.ones(len(X)))
            ratio = (1.4826 * float(np.median(np.abs(e)))) ** 2
        else:
            ratio = float(ur @ M @ ur) / float(ur @ G @ ur)
        if ratio > max_ratio:
            continue
        arc = _arc_deg(X, a, c)
        if arc < min_arc_deg:
            log.debug("symmetry candidate ratio %.2e over only %.0f° of arc", ratio, arc)
            continue
        axial = float(np.mean(np.abs(Nn @ a) > math.cos(math.radians(25.0))))
        if axial > max_axial_fraction:
            log.debug("symmetry candidate ratio %.2e is a plate (%.2f axial)", ratio, axial)
            continue
        center = c + c0 - a * float(a @ (c + c0))
        return SymmetryAxis(
            axis=a,
            center=center,
            ratio=ratio,
            arc_deg=arc,
            axial_fraction=axial,
            twist=np.concatenate([np.cross(center, a), a]),
        )
    return None


def marginalise_direction(H: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The information ``H`` (6×6) with the direction ``u`` marginalised out.

    ``H' = H − H u uᵀ H / (uᵀ H u)``: ``H' u = 0`` (the measurement says nothing along ``u``)
    and the other directions keep the information they have with ``u`` unknown (Schur
    complement). ``H`` is returned unchanged when ``uᵀ H u`` is not positive.
    """
    Hu = H @ u
    q = float(u @ Hu)
    if not (np.isfinite(q) and q > 0):
        return H
    out = H - np.outer(Hu, Hu) / q
    return 0.5 * (out + out.T)


def stiffen_prior(Lam: np.ndarray, u: np.ndarray, gain: float) -> np.ndarray:
    """The prior's information ``Λ`` (6×6) with its part along ``u`` multiplied by ``1 + gain``.

    ``Λ' = Λ + gain · Λ u uᵀ Λ / (uᵀ Λ u)``: the rank-one part of ``Λ`` that measures the
    component along ``u`` (in the prior's own metric) is scaled; other directions keep ``Λ``.
    """
    Lu = Lam @ u
    q = float(u @ Lu)
    if gain <= 0 or not (np.isfinite(q) and q > 0):
        return Lam
    out = Lam + gain * np.outer(Lu, Lu) / q
    return 0.5 * (out + out.T)
