"""A free relative orbit: the azimuth a body of revolution hides, taken from the chaser's dynamics.

**Dynamics.** A chaser drifting on a centred, bounded relative orbit about a target whose
attitude is held in the local-vertical/local-horizontal (LVLH) frame moves, in the target frame,
as an isotropic harmonic oscillator about the target's centre of mass ``c``,

.. math::

    \\ddot r = -n^2 (r - c), \\qquad r(t) = c + A \\cos n t + B \\sin n t,

``n`` the target orbit's mean motion (rad/s). The bounded Clohessy–Wiltshire solutions
``x = a cos(nt + α)``, ``y = −2a sin(nt + α)``, ``z = b cos(nt + β)`` satisfy it on every axis
(an inspection or passive-safety ellipse); a helical approach, a manoeuvre or a tumbling target
do not, and then nothing here applies.

**What it fixes.** On a body of revolution (a capsule, an Orion) the scans do not observe the
rotation about its axis: the navigator's azimuth about the axis follows its motion model, and
the registration's pull towards the map's samples makes it lag (``docs/navigator.md``). The
radius ``ρ(t)`` and height ``z(t)`` of the sensor about the axis are observed, and the orbit ties
the azimuth to them: fitted to ``ρ`` and ``z`` alone, ``r(t)`` gives the azimuth at every frame
(up to the first frame's, which is the given initial pose).

**When** (:func:`correct_azimuth`; every test is on the estimate, none on the truth)
**[interpretation]**:

1. the map is close to a body of revolution about its best axis (symmetry ratio at most
   ``max_symmetry_ratio``, :func:`relnav.navigation.symmetry.symmetry_axis`);
2. the orbit explains the observed radius and height: their RMS misfit is at most ``max_misfit``
   times the sensor's median distance from the axis's centre;
3. the navigator's azimuth disagrees with that orbit: fitted to the whole 3-D positions, the
   orbit's RMS misfit is at least ``min_excess`` times the radius-and-height misfit.

Then every pose is turned about the axis by the azimuth the orbit gives (the first frame's
stays; near the axis, where the azimuth is undefined, the turn is interpolated in time from the
frames farther out): a rotation about the axis of a body of revolution leaves its scans
unchanged, so the corrected poses fit the scans as well as the registered ones. Otherwise the
poses are returned unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from relnav.geometry.rotations import rotvec_to_matrix
from relnav.navigation.symmetry import symmetry_axis

__all__ = ["OrbitCorrection", "correct_azimuth", "orbit_turns"]

_MIN_FRAMES = 8
_NEAR_AXIS = 0.2  # frames closer to the axis than this fraction of the median radius
_MAX_EVALUATIONS = 50  # per fit; an orbit converges in about 10, a path that is no orbit need not
_MAX_MAP_POINTS = 4000  # map points for the symmetry axis


@dataclass
class OrbitCorrection:
    """What :func:`correct_azimuth` found and did.

    Attributes
    ----------
    applied : bool
        Whether the poses were turned.
    reason : str
        Why (or why not), in words.
    axis, center : (3,) float64 or None
        The map's symmetry axis (target frame) and the orbit's centre on it, m.
    symmetry_ratio : float
        The map's symmetry ratio about that axis (NaN when none was found).
    misfit_m : float
        RMS misfit of the orbit to the radius and height about the axis, m.
    scale_m : float
        The sensor's median distance from the axis's centre, m (``max_misfit`` is relative to
        it).
    excess : float
        RMS misfit of the orbit fitted to the whole positions over ``misfit_m``.
    correction_deg : (N,) float64
        The azimuth added to each pose about the axis, degrees (zeros when not applied).
    """

    applied: bool = False
    reason: str = ""
    axis: np.ndarray | None = None
    center: np.ndarray | None = None
    symmetry_ratio: float = float("nan")
    misfit_m: float = float("nan")
    scale_m: float = float("nan")
    excess: float = float("nan")
    correction_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary; when applied, also the centre and the per-frame turns (what
        :func:`orbit_turns` rebuilds the turns from)."""
        out: dict[str, Any] = {
            "applied": self.applied,
            "reason": self.reason,
            "axis": None if self.axis is None else [float(x) for x in self.axis],
            "symmetry_ratio": float(self.symmetry_ratio),
            "misfit_m": float(self.misfit_m),
            "scale_m": float(self.scale_m),
            "excess": float(self.excess),
            "max_correction_deg": float(np.max(np.abs(self.correction_deg), initial=0.0)),
        }
        if self.applied and self.center is not None:
            out["center"] = [float(x) for x in self.center]
            out["correction_deg"] = [float(x) for x in self.correction_deg]
        return out


def orbit_turns(report: dict[str, Any]) -> np.ndarray | None:
    """The per-frame turns ``G_k`` ``(N, 4, 4)`` of an applied correction, from its
    :meth:`OrbitCorrection.as_dict` (``T' = G_k T``: a rotation by the frame's correction about
    the axis through the orbit's centre, target frame); None when none was applied."""
    if not report.get("applied") or "correction_deg" not in report:
        return None
    a = np.asarray(report["axis"], dtype=np.float64)
    c = np.asarray(report["center"], dtype=np.float64)
    angles = np.radians(np.asarray(report["correction_deg"], dtype=np.float64))
    return _turns(a, c, angles)


def _turns(axis: np.ndarray, center: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations by ``angles`` (rad) about ``axis`` through ``center``, ``(N, 4, 4)``."""
    G = np.tile(np.eye(4), (len(angles), 1, 1))
    for i, angle in enumerate(angles):
        R = rotvec_to_matrix(axis * angle)
        G[i, :3, :3] = R
        G[i, :3, 3] = center - R @ center
    return G


def _basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the axis ``a`` to a right-handed frame."""
    e1 = np.cross(a, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 0.5:
        e1 = np.cross(a, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def _orbit(q: np.ndarray, phase: np.ndarray, phi0: float) -> np.ndarray:
    """Positions about the centre in the axis frame ``(e1, e2, a)``, ``(N, 3)``.

    ``q = [s, A_ρ, A_z, B (3)]``: the centre's offset along the axis (unused here), the start's
    radius and height, and ``B``; the start's azimuth is fixed at ``phi0`` (the gauge).
    """
    A = np.array([q[1] * math.cos(phi0), q[1] * math.sin(phi0), q[2]])
    return np.outer(np.cos(phase), A) + np.outer(np.sin(phase), q[3:6])


def correct_azimuth(
    poses: np.ndarray,
    times: np.ndarray,
    map_points: np.ndarray,
    map_normals: np.ndarray,
    mean_motion: float,
    *,
    max_symmetry_ratio: float = 0.05,
    max_misfit: float = 0.005,
    min_excess: float = 3.0,
) -> tuple[np.ndarray, OrbitCorrection]:
    """Take the azimuth about a body of revolution's axis from a free relative orbit.

    Parameters
    ----------
    poses : (N, 4, 4) float64
        ``T_target_sensor`` per frame (the navigator's trajectory; the first one is the given
        initial pose).
    times : (N,) float64
        Their times, s.
    map_points, map_normals : (M, 3) float64
        The navigator's map (target frame, m) and its unit normals.
    mean_motion : float
        The target orbit's mean motion ``n``, rad/s (> 0).
    max_symmetry_ratio, max_misfit, min_excess : float
        The three tests of the module's docstring.

    Returns
    -------
    poses : (N, 4, 4) float64
        Corrected (or the input's copy).
    OrbitCorrection
    """
    T = np.array(poses, dtype=np.float64)
    n = len(T)
    out = OrbitCorrection(correction_deg=np.zeros(n))
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if not (np.isfinite(mean_motion) and mean_motion > 0):
        raise ValueError(f"mean_motion must be > 0 rad/s, got {mean_motion!r}")
    if len(t) != n:
        raise ValueError(f"{n} poses but {len(t)} times")
    P = T[:, :3, 3]
    if n < _MIN_FRAMES or not (np.all(np.isfinite(P)) and np.all(np.isfinite(t))):
        out.reason = f"too few frames with finite poses and times (need {_MIN_FRAMES})"
        return T, out
    stride = max(1, len(map_points) // _MAX_MAP_POINTS)  # an even subset bounds the cost
    sym = symmetry_axis(
        np.asarray(map_points)[::stride],
        np.asarray(map_normals)[::stride],
        max_ratio=np.inf,
        min_arc_deg=0.0,
        max_axial_fraction=1.0,
    )
    if sym is None:
        out.reason = "no axis in the map"
        return T, out
    a, c0 = sym.axis, sym.center
    out.axis, out.symmetry_ratio = a, sym.ratio
    e1, e2 = _basis(a)
    E = np.stack([e1, e2, a])  # rows: target frame -> axis frame
    phase = mean_motion * (t - t[0])

    def local(s: float) -> np.ndarray:
        return (P - (c0 + s * a)) @ E.T

    D0 = local(0.0)
    phi0 = math.atan2(D0[0, 1], D0[0, 0])
    rho, z = np.hypot(D0[:, 0], D0[:, 1]), D0[:, 2]

    def cylinder_residual(q: np.ndarray) -> np.ndarray:
        M = _orbit(q, phase, phi0)
        return np.concatenate([np.hypot(M[:, 0], M[:, 1]) - rho, M[:, 2] - (z - q[0])])

    # start: the orbit through the registered positions (right sense of motion, lagging azimuth)
    S = np.column_stack([np.cos(phase), np.sin(phase)])
    AB, *_ = np.linalg.lstsq(S, D0, rcond=None)
    q0 = np.concatenate([[0.0, rho[0], z[0]], AB[1]])
    fit = least_squares(cylinder_residual, q0, method="lm", max_nfev=_MAX_EVALUATIONS)
    r = cylinder_residual(fit.x)
    misfit = float(np.sqrt(np.mean(r**2)))

    def full_residual(p: np.ndarray) -> np.ndarray:  # p = [s, A (3), B (3)]
        M = np.outer(np.cos(phase), p[1:4]) + np.outer(np.sin(phase), p[4:7])
        return (M - local(p[0])).ravel()

    A1 = _orbit(fit.x, np.zeros(1), phi0)[0]
    p0 = np.concatenate([[fit.x[0]], A1, fit.x[3:6]])
    full = least_squares(full_residual, p0, method="lm", max_nfev=_MAX_EVALUATIONS)
    full_misfit = float(np.sqrt(np.mean(full_residual(full.x) ** 2)))
    out.misfit_m = misfit
    out.excess = full_misfit / max(misfit, 1e-12)
    out.center = c0 + fit.x[0] * a
    scale = float(np.median(np.hypot(rho, z)))
    out.scale_m = scale
    # every figure is computed (and recorded) before the three tests
    if sym.ratio > max_symmetry_ratio:
        out.reason = f"the map is no body of revolution (ratio {sym.ratio:.3g})"
        return T, out
    if not (np.isfinite(misfit) and misfit <= max_misfit * scale):
        out.reason = f"not a free orbit: radius/height misfit {misfit:.3g} m"
        return T, out
    if not out.excess >= min_excess:
        out.reason = f"the azimuth agrees with the orbit (excess {out.excess:.2f})"
        return T, out
    D = local(fit.x[0])
    M = _orbit(fit.x, phase, phi0)
    d = np.angle(np.exp(1j * (np.arctan2(M[:, 1], M[:, 0]) - np.arctan2(D[:, 1], D[:, 0]))))
    d -= d[0]
    # near the axis the azimuth is undefined (centimetres of position make degrees of azimuth):
    # there the correction, a slowly varying bias of the navigator's azimuth, is interpolated
    # in time between the frames farther out (the first frame, the given pose, always counts)
    far = np.minimum(np.hypot(D[:, 0], D[:, 1]), np.hypot(M[:, 0], M[:, 1]))
    keep = far >= _NEAR_AXIS * float(np.median(rho))
    keep[0] = True
    d = np.interp(t, t[keep], np.unwrap(d[keep]))
    T = _turns(a, out.center, d) @ T
    out.applied = True
    out.correction_deg = np.degrees(d)
    out.reason = (
        f"azimuth from the orbit: misfit {misfit:.3g} m, excess {out.excess:.1f}, "
        f"correction up to {np.max(np.abs(out.correction_deg)):.1f}°"
    )
    return T, out
