"""Chaser (sensor) trajectories around a target and the sensor pointing.

Every trajectory is a pure function of a frame count (or of frame times for the dynamical
Clohessy–Wiltshire case) returning positions ``p_W`` of shape ``(N, 3)`` in metres, expressed
in the world frame ``W`` centred on the target's centre of mass. For orbital cases ``W`` has the
LVLH/Hill axes: ``x`` radial (outward), ``y`` along-track, ``z`` orbit normal.

Geometric paths (forward–backward, curved, ellipse, helix, V-bar/R-bar) are sampled at constant
speed along the path: frame ``k`` of ``N`` sits at the normalised path parameter
``u_k = k / (N - 1)``. Closed paths (one full ellipse) therefore return exactly to their start.

Pointing: :func:`look_at` turns positions into sensor attitudes ``R_W_sensor`` with the sensor's
boresight ``+x`` towards the target and ``+z`` as close as possible to a chosen ``up`` axis
(REP-103 sensor frame: x forward, y left, z up); :func:`pointing_poses` adds seeded attitude
jitter and returns the full ``T_W_sensor``.

References: Clohessy & Wiltshire (1960); ``docs/ALGORITHMS.md`` §G.5 for the closed-form
state-transition matrix; Paper 1 §3 (Kechagias-Stamatis et al.) for the scenario shapes.
"""

from __future__ import annotations

import contextvars
import inspect
import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.geometry.rotations import rotvec_to_matrix

__all__ = [
    "MU_EARTH",
    "TRAJECTORIES",
    "clohessy_wiltshire",
    "curved_forward_backward",
    "cw_propagate",
    "cw_stm",
    "ellipse_of_inspection",
    "elliptic_orbit",
    "forward_backward",
    "frame_times",
    "helical_approach",
    "look_at",
    "make_trajectory",
    "mean_motion",
    "path_length",
    "pointing_poses",
    "rbar_approach",
    "stationary",
    "trajectory_kinds",
    "trajectory_params",
    "vbar_approach",
]

log = logging.getLogger(__name__)

MU_EARTH = 3.986004418e14
"""Earth's gravitational parameter ``μ = G M`` in m³/s²."""

ArrayLike3 = Sequence[float] | np.ndarray


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def _vec3(v: ArrayLike3, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


def _check_frames(n: int) -> int:
    if int(n) != n or n < 1:
        raise InputError(f"number of frames must be a positive integer, got {n!r}")
    return int(n)


_KEEP: contextvars.ContextVar[int | None] = contextvars.ContextVar("relnav_traj_keep", default=None)
"""Only the first ``_KEEP`` frames of an ``N``-frame path are computed (set by
:func:`make_trajectory`'s ``n_keep``): simulating 2 frames of a 1e8-frame path costs nothing."""


def _kept(n: int) -> int:
    keep = _KEEP.get()
    return n if keep is None else min(n, keep)


def _param(n: int) -> np.ndarray:
    """Normalised path parameter ``u_k = k / (N - 1)`` in ``[0, 1]`` (``[0]`` for one frame);
    only the first :func:`_kept` values (bit-identical to those of the whole path)."""
    m = _kept(n)
    if n <= 1:
        return np.zeros(1)
    if m == n:
        return np.linspace(0.0, 1.0, n)
    return np.arange(m, dtype=np.float64) * (1.0 / (n - 1))  # = linspace(0, 1, n)[:m]


def _fold(u: np.ndarray) -> np.ndarray:
    """Forward–backward triangle wave: ``0 → 1`` on the first half, ``1 → 0`` on the second."""
    return 1.0 - np.abs(1.0 - 2.0 * u)


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    nv = float(np.linalg.norm(v))
    if nv < 1e-12:
        raise InputError(f"{name} must be a non-zero vector")
    return v / nv


def path_length(positions: np.ndarray) -> float:
    """Length of the polyline through ``positions`` ``(N, 3)``, in metres (0 for ``N < 2``)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def frame_times(n_frames: int, dt: float, t0: float = 0.0) -> np.ndarray:
    """Frame times ``t0 + k dt`` (s), ``k = 0 … N-1``."""
    n = _check_frames(n_frames)
    if not dt > 0:
        raise InputError(f"dt must be > 0 s, got {dt!r}")
    return t0 + dt * np.arange(_kept(n), dtype=np.float64)


# --------------------------------------------------------------------------------------------
# geometric paths
# --------------------------------------------------------------------------------------------


def forward_backward(
    n_frames: int,
    *,
    start: ArrayLike3 = (-6.0, 0.0, 0.0),
    end: ArrayLike3 = (-2.3, 0.0, 0.0),
) -> np.ndarray:
    """Straight forward–backward path: ``start → end → start`` at constant speed.

    Parameters
    ----------
    n_frames : int
        Number of frames ``N``; with ``N`` odd the turning point ``end`` is sampled exactly
        and the path length is ``2 |end − start|``.
    start, end : (3,) float
        Endpoints in ``W`` (m).

    Returns
    -------
    (N, 3) float64
        Positions in ``W`` (m).
    """
    n = _check_frames(n_frames)
    a, b = _vec3(start, "start"), _vec3(end, "end")
    s = _fold(_param(n))
    return a[None, :] + s[:, None] * (b - a)[None, :]


def _arc(
    u: np.ndarray, a: np.ndarray, b: np.ndarray, sagitta: float, normal: np.ndarray
) -> np.ndarray:
    """Circular arc from ``a`` to ``b`` bulging by ``sagitta`` to the left of travel."""
    chord_vec = b - a
    c = float(np.linalg.norm(chord_vec))
    if c < 1e-12:
        raise InputError("curved path: start and end must differ")
    if abs(sagitta) < 1e-12:
        return a[None, :] + u[:, None] * chord_vec[None, :]
    e1 = chord_vec / c
    nrm = normal - np.dot(normal, e1) * e1
    nrm = _unit(nrm, "normal (must not be parallel to end − start)")
    left = np.cross(nrm, e1)  # to the left of the travel direction about `normal`
    s = float(sagitta)
    radius = (c * c / 4.0 + s * s) / (2.0 * abs(s))
    theta = 4.0 * np.arctan(2.0 * abs(s) / c)  # central angle, valid for any sagitta
    mid = a + 0.5 * chord_vec
    sign = np.sign(s)
    centre = mid + sign * left * (abs(s) - radius)
    # angle measured in the plane (e1, sign*left) from the centre
    r0 = a - centre
    phi0 = np.arctan2(np.dot(r0, sign * left), np.dot(r0, e1))
    phi = phi0 - theta * u  # sweep from a to b
    return (
        centre[None, :]
        + radius * np.cos(phi)[:, None] * e1[None, :]
        + radius * np.sin(phi)[:, None] * (sign * left)[None, :]
    )


def curved_forward_backward(
    n_frames: int,
    *,
    start: ArrayLike3 = (-3.0, -2.5, 0.0),
    end: ArrayLike3 = (-3.0, 2.5, 0.0),
    sagitta: float = -1.5,
    normal: ArrayLike3 = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """Curved forward–backward path: a circular arc ``start → end`` and back on the same arc.

    The arc lies in the plane through ``start`` and ``end`` perpendicular to ``normal`` and
    bulges by ``sagitta`` (m) to the left of the direction of travel (right if negative); its
    one-way length is ``R θ`` with ``R = (c²/4 + s²) / (2|s|)`` and ``θ = 4 atan(2|s|/c)``
    for chord ``c``. With the defaults the arc bulges towards the target at the origin.

    Returns
    -------
    (N, 3) float64
        Positions in ``W`` (m), constant speed along the arc.
    """
    n = _check_frames(n_frames)
    a, b = _vec3(start, "start"), _vec3(end, "end")
    nrm = _vec3(normal, "normal")
    return _arc(_fold(_param(n)), a, b, float(sagitta), nrm)


def _ellipse_axes(tilt_deg: float, rotation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """In-plane unit axes (radial-like, along-track-like) of a tilted, rotated ellipse."""
    tilt, rot = np.deg2rad(tilt_deg), np.deg2rad(rotation_deg)
    # start in the LVLH x–y plane: minor axis along x (radial), major along y (along-track);
    # tilt = rotation about the major (y) axis, moving the minor axis out of plane;
    # rotation = rotation of the result about z.
    ex = np.array([np.cos(tilt), 0.0, -np.sin(tilt)])
    ey = np.array([0.0, 1.0, 0.0])
    cz, sz = np.cos(rot), np.sin(rot)
    Rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ ex, Rz @ ey


def elliptic_orbit(
    n_frames: int,
    *,
    semi_major: float = 50.0,
    semi_minor: float = 25.0,
    loops: float = 2.5,
    tilt_deg: float = 0.0,
    rotation_deg: float = 0.0,
    phase_deg: float = 0.0,
    center: ArrayLike3 = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Ellipse around the target, any number of loops (Paper 1 scenarios 5–7 use 2.5).

    Position ``c + b cos φ e_x + a sin φ e_y`` with ``φ = φ0 + 2π loops u``, ``u ∈ [0, 1]``:
    the major semi-axis ``a`` lies along ``e_y`` (along-track, like the 2:1 natural
    Clohessy–Wiltshire ellipse), the minor ``b`` along ``e_x`` (radial), the plane tilted by
    ``tilt_deg`` about the major axis and the whole ellipse turned by ``rotation_deg`` about
    ``z``. The ellipse is sampled uniformly in the angle ``φ`` (not in arc length)
    **[interpretation: the natural motion of a CW ellipse is uniform in orbital phase]**.

    Returns
    -------
    (N, 3) float64
        Positions in ``W`` (m); the last frame is at ``φ0 + 2π loops``.
    """
    n = _check_frames(n_frames)
    if not (semi_major > 0 and semi_minor > 0):
        raise InputError(
            f"ellipse semi-axes must be > 0 m, got semi_major={semi_major}, semi_minor={semi_minor}"
        )
    if not loops > 0:
        raise InputError(f"loops must be > 0, got {loops}")
    ex, ey = _ellipse_axes(tilt_deg, rotation_deg)
    c = _vec3(center, "center")
    phi = np.deg2rad(phase_deg) + 2.0 * np.pi * loops * _param(n)
    return (
        c[None, :]
        + semi_minor * np.cos(phi)[:, None] * ex[None, :]
        + semi_major * np.sin(phi)[:, None] * ey[None, :]
    )


def ellipse_of_inspection(
    n_frames: int,
    *,
    semi_major: float = 60.0,
    semi_minor: float = 30.0,
    tilt_deg: float = 0.0,
    rotation_deg: float = 0.0,
    phase_deg: float = 0.0,
    center: ArrayLike3 = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Ellipse of inspection: one closed loop of :func:`elliptic_orbit` (returns to start).

    The default 2:1 shape (along-track 60 m, radial 30 m) is the natural CW inspection
    ellipse; its perimeter is ≈ 291 m, Paper 1's *Sim-EoI* length.
    """
    return elliptic_orbit(
        n_frames,
        semi_major=semi_major,
        semi_minor=semi_minor,
        loops=1.0,
        tilt_deg=tilt_deg,
        rotation_deg=rotation_deg,
        phase_deg=phase_deg,
        center=center,
    )


def helical_approach(
    n_frames: int,
    *,
    radius_start: float = 40.0,
    radius_end: float = 20.0,
    height_start: float = 30.0,
    height_end: float = 0.0,
    turns: float = 1.0,
    phase_deg: float = 0.0,
) -> np.ndarray:
    """Helical approach: one (or ``turns``) revolution(s) about ``z`` while closing in.

    ``ρ(u) = ρ0 + (ρ1 − ρ0) u``, ``z(u) = h0 + (h1 − h0) u``, ``φ(u) = φ0 + 2π turns u``;
    position ``(ρ cos φ, ρ sin φ, z)``. Paper 1's *Sim-Helical* is a 360° rotation with
    simultaneous translation in all three axes.

    Returns
    -------
    (N, 3) float64
        Positions in ``W`` (m).
    """
    n = _check_frames(n_frames)
    if radius_start < 0 or radius_end < 0:
        raise InputError("helix radii must be >= 0 m")
    u = _param(n)
    rho = radius_start + (radius_end - radius_start) * u
    z = height_start + (height_end - height_start) * u
    phi = np.deg2rad(phase_deg) + 2.0 * np.pi * turns * u
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def _approach(n: int, start: float, stop: float, profile: str, axis: int) -> np.ndarray:
    n = _check_frames(n)
    if profile == "linear":
        s = start + (stop - start) * _param(n)
    elif profile == "exponential":
        if start == 0 or stop == 0 or np.sign(start) != np.sign(stop):
            raise InputError("exponential approach needs start and stop of the same sign, ≠ 0")
        s = start * (stop / start) ** _param(n)
    else:
        raise InputError(f"approach profile must be 'linear' or 'exponential', got {profile!r}")
    p = np.zeros((s.size, 3))
    p[:, axis] = s
    return p


def vbar_approach(
    n_frames: int, *, start: float = -50.0, stop: float = -5.0, profile: str = "linear"
) -> np.ndarray:
    """V-bar approach: straight along the along-track axis ``y`` from ``start`` to ``stop`` (m).

    ``profile="linear"`` moves at constant speed; ``"exponential"`` closes the distance by a
    constant ratio per frame (a glideslope-like braking approach).
    """
    return _approach(n_frames, start, stop, profile, axis=1)


def rbar_approach(
    n_frames: int, *, start: float = -50.0, stop: float = -5.0, profile: str = "linear"
) -> np.ndarray:
    """R-bar approach: straight along the radial axis ``x`` from ``start`` to ``stop`` (m).

    Negative values approach from below (Earth side), as most R-bar dockings do.
    """
    return _approach(n_frames, start, stop, profile, axis=0)


def stationary(n_frames: int, *, position: ArrayLike3 = (-5.0, 0.0, 0.0)) -> np.ndarray:
    """A sensor holding ``position`` (m, ``W``) in every frame (e.g. Paper 2's lab rig)."""
    return np.tile(_vec3(position, "position"), (_kept(_check_frames(n_frames)), 1))


# --------------------------------------------------------------------------------------------
# Clohessy–Wiltshire
# --------------------------------------------------------------------------------------------


def mean_motion(semi_major_axis: float, mu: float = MU_EARTH) -> float:
    """Mean motion ``n = sqrt(μ / a³)`` (rad/s) of a circular orbit of radius ``a`` (m)."""
    if not semi_major_axis > 0:
        raise InputError(f"semi-major axis must be > 0 m, got {semi_major_axis}")
    return float(np.sqrt(mu / semi_major_axis**3))


def cw_stm(n: float, tau: float) -> np.ndarray:
    """Clohessy–Wiltshire state-transition matrix ``Φ(τ)`` ``(6, 6)``.

    State ``s = [x y z ẋ ẏ ż]`` in LVLH (x radial, y along-track, z orbit normal), mean motion
    ``n`` (rad/s), time step ``τ`` (s): ``s(t + τ) = Φ(τ) s(t)``. Uses the exact closed form
    of ``docs/ALGORITHMS.md`` §G.5, and the ``n → 0`` limit (double integrator) when
    ``n τ < 1e-8``.
    """
    if n < 0:
        raise InputError(f"mean motion must be >= 0 rad/s, got {n}")
    nt = n * tau
    if abs(nt) < 1e-8:
        Phi = np.eye(6)
        Phi[0:3, 3:6] = tau * np.eye(3)
        return Phi
    s, c = np.sin(nt), np.cos(nt)
    return np.array(
        [
            [4 - 3 * c, 0, 0, s / n, 2 / n * (1 - c), 0],
            [6 * (s - nt), 1, 0, -2 / n * (1 - c), (4 * s - 3 * nt) / n, 0],
            [0, 0, c, 0, 0, s / n],
            [3 * n * s, 0, 0, c, 2 * s, 0],
            [-6 * n * (1 - c), 0, 0, -2 * s, 4 * c - 3, 0],
            [0, 0, -n * s, 0, 0, c],
        ],
        dtype=np.float64,
    )


def _cw_state(state0: ArrayLike3) -> np.ndarray:
    """A CW state ``[x y z ẋ ẏ ż]`` as a ``(6,)`` array; :class:`InputError` otherwise."""
    s0 = np.asarray(state0, dtype=np.float64).reshape(-1)
    if s0.shape != (6,) or not np.all(np.isfinite(s0)):
        raise InputError(
            f"CW initial state must be 6 finite numbers [x y z vx vy vz], got {state0}"
        )
    return s0


def cw_propagate(times: np.ndarray, state0: ArrayLike3, *, n: float) -> np.ndarray:
    """CW states ``(N, 6)`` at ``times`` (s, relative to the epoch of ``state0``).

    Each state is ``Φ(t_k) s0`` (closed form, no accumulation of integration error).
    """
    s0 = _cw_state(state0)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    return np.stack([cw_stm(n, float(tk)) @ s0 for tk in t]) if len(t) else np.zeros((0, 6))


def _burn_list(burns: Sequence[Sequence[float]]) -> list[tuple[float, np.ndarray]]:
    """Validated impulsive burns ``[(t, Δv (3,)), ...]`` sorted by time."""
    out = []
    for b in burns:
        try:
            v = np.asarray(b, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            v = np.full(0, np.nan)
        if v.shape != (4,) or not np.all(np.isfinite(v)) or v[0] < 0:
            raise InputError(f"a burn is [t (s, >= 0), dvx, dvy, dvz (m/s)], got {b!r}")
        out.append((float(v[0]), v[1:].copy()))
    return sorted(out, key=lambda tb: tb[0])


def clohessy_wiltshire(
    times: np.ndarray,
    *,
    state0: Sequence[float] = (20.0, 0.0, 10.0, 0.0, -0.04524, 0.0),
    mean_motion_rad_s: float | None = None,
    semi_major_axis: float = 6_778_137.0,
    mu: float = MU_EARTH,
    burns: Sequence[Sequence[float]] = (),
) -> np.ndarray:
    """Relative orbit from the closed-form Clohessy–Wiltshire solution: positions ``(N, 3)``.

    Parameters
    ----------
    times : (N,) float
        Frame times (s) since the epoch of ``state0``.
    state0 : (6,) float
        Initial LVLH state ``[x y z ẋ ẏ ż]`` (m, m/s). The default is a bounded 2:1 ellipse for
        a 400 km LEO (``ẏ0 = −2 n x0``).
    mean_motion_rad_s : float, optional
        Mean motion ``n`` (rad/s); ``0`` gives straight-line (free-space) motion. Default:
        computed from ``semi_major_axis`` and ``mu``.
    semi_major_axis : float
        Radius of the circular reference orbit (m), default 400 km altitude LEO.
    mu : float
        Gravitational parameter (m³/s²).
    burns : sequence of (4,) float
        Impulsive manoeuvres ``[t, Δvx, Δvy, Δvz]``: at time ``t`` (s) the chaser's LVLH
        velocity changes by ``Δv`` (m/s), the motion a constant-velocity model does not
        predict. A frame at the burn's time sees the state before it. Default: none.
    """
    n = float(mean_motion(semi_major_axis, mu) if mean_motion_rad_s is None else mean_motion_rad_s)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    plan = _burn_list(burns)
    if not plan:
        return cw_propagate(t, state0, n=n)[:, :3]
    s = _cw_state(state0)
    out = np.zeros((len(t), 3))
    epoch, after = 0.0, np.ones(len(t), dtype=bool)  # times not yet placed
    for t_burn, dv in [*plan, (np.inf, np.zeros(3))]:
        seg = after & (t <= t_burn)
        if seg.any():
            out[seg] = cw_propagate(t[seg] - epoch, s, n=n)[:, :3]
        after &= ~seg
        if np.isfinite(t_burn):  # the state just after the burn: the next segment's epoch
            s = cw_stm(n, t_burn - epoch) @ s
            s[3:] += dv
            epoch = t_burn
    return out


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------

TRAJECTORIES: dict[str, Callable[..., np.ndarray]] = {
    "forward-backward": forward_backward,
    "curved-forward-backward": curved_forward_backward,
    "ellipse-of-inspection": ellipse_of_inspection,
    "elliptic-orbit": elliptic_orbit,
    "helical-approach": helical_approach,
    "cw": clohessy_wiltshire,
    "vbar": vbar_approach,
    "rbar": rbar_approach,
    "static": stationary,
}
"""Trajectory kinds by name. All take the frame count, except ``cw`` which takes frame times."""

_TIME_BASED = {"cw"}


def trajectory_kinds() -> list[str]:
    """Names accepted by :func:`make_trajectory`."""
    return sorted(TRAJECTORIES)


def trajectory_params(kind: str) -> dict[str, Any]:
    """Keyword parameters (with defaults) of trajectory ``kind``."""
    if kind not in TRAJECTORIES:
        raise ConfigError(
            f"unknown trajectory kind {kind!r}; choose one of {', '.join(trajectory_kinds())}"
        )
    sig = inspect.signature(TRAJECTORIES[kind])
    return {
        k: p.default for k, p in sig.parameters.items() if p.kind is inspect.Parameter.KEYWORD_ONLY
    }


def make_trajectory(
    kind: str,
    n_frames: int,
    dt: float,
    params: dict[str, Any] | None = None,
    *,
    n_keep: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Frame times ``(N,)`` (s) and positions ``(N, 3)`` (m, ``W``) of trajectory ``kind``.

    ``n_keep`` computes only the first ``n_keep`` frames of the ``n_frames``-frame path
    (identical values, time and memory independent of ``n_frames``). Unknown kinds or
    parameter names raise :class:`ConfigError` listing the accepted ones.
    """
    token = _KEEP.set(None if n_keep is None else max(int(n_keep), 1))
    try:
        return _make_trajectory(kind, n_frames, dt, params)
    finally:
        _KEEP.reset(token)


def _make_trajectory(
    kind: str, n_frames: int, dt: float, params: dict[str, Any] | None
) -> tuple[np.ndarray, np.ndarray]:
    params = dict(params or {})
    allowed = trajectory_params(kind)
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise ConfigError(
            f"trajectory {kind!r}: unknown parameter(s) {', '.join(unknown)}; "
            f"accepted: {', '.join(allowed) or '(none)'}"
        )
    times = frame_times(n_frames, dt)
    fn = TRAJECTORIES[kind]
    try:
        pos = fn(times, **params) if kind in _TIME_BASED else fn(n_frames, **params)
    except TypeError as e:  # wrong value types reaching numpy
        raise ConfigError(f"trajectory {kind!r}: bad parameter value: {e}") from None
    except InputError as e:
        raise ConfigError(f"trajectory {kind!r}: {e}") from None
    pos = np.asarray(pos, dtype=np.float64)
    if not np.all(np.isfinite(pos)):
        raise ConfigError(f"trajectory {kind!r} produced non-finite positions; check parameters")
    return times, pos


# --------------------------------------------------------------------------------------------
# pointing
# --------------------------------------------------------------------------------------------


def look_at(
    positions: np.ndarray,
    target: ArrayLike3 | float = (0.0, 0.0, 0.0),
    up: ArrayLike3 = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """Sensor attitudes ``R_W_sensor`` ``(N, 3, 3)`` looking from ``positions`` at ``target``.

    Columns are the sensor axes in ``W``: ``x`` = unit boresight towards ``target``,
    ``y = up × x`` (left), ``z = x × y`` (as close to ``up`` as possible). Where the boresight
    is within 1e-6 rad of ``±up`` the world axis least aligned with the boresight is used as
    ``up`` instead **[interpretation]**.

    Raises
    ------
    InputError
        If a position coincides with the target (boresight undefined).
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    tgt = np.full(3, float(target)) if np.ndim(target) == 0 else _vec3(target, "target")
    u = _unit(_vec3(up, "up"), "up")
    d = tgt[None, :] - p
    dist = np.linalg.norm(d, axis=1)
    if np.any(dist < 1e-9):
        k = int(np.argmin(dist))
        raise InputError(f"look_at: position {k} coincides with the target; boresight undefined")
    x = d / dist[:, None]
    ups = np.broadcast_to(u, x.shape).copy()
    y = np.cross(ups, x)
    ny = np.linalg.norm(y, axis=1)
    bad = ny < 1e-6
    if np.any(bad):
        alt = np.eye(3)[np.argmin(np.abs(x[bad]), axis=1)]
        ups[bad] = alt
        y[bad] = np.cross(alt, x[bad])
        ny[bad] = np.linalg.norm(y[bad], axis=1)
    y /= ny[:, None]
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=2)


def pointing_poses(
    positions: np.ndarray,
    *,
    target: ArrayLike3 | float = (0.0, 0.0, 0.0),
    up: ArrayLike3 = (0.0, 0.0, 1.0),
    jitter_deg: float | ArrayLike3 = 0.0,
    jitter_kind: str = "white",
    seed: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Sensor poses ``T_W_sensor`` ``(N, 4, 4)``: :func:`look_at` plus seeded attitude jitter.

    Jitter models Paper 1's "minor tumbling" of the hand-moved real sensor and a chaser's
    attitude control: each frame's attitude is perturbed in the sensor frame,
    ``R = R_look · exp([δ_k]×)``. ``jitter_kind="white"``: ``δ_k ~ N(0, diag(σ²))``
    independent between frames **[interpretation: the papers give no tumbling model]**;
    ``"random-walk"``: ``δ_k = δ_{k-1} + w_k``, ``w_k ~ N(0, diag(σ²))`` (``δ_0 = w_0``).
    ``σ = jitter_deg`` (degrees; one value or one per sensor axis x, y, z).
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    R = look_at(p, target, up)
    sigma = np.asarray(jitter_deg, dtype=np.float64).ravel()
    if sigma.size not in (1, 3) or not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
        raise InputError(f"jitter_deg must be one or three values >= 0, got {jitter_deg!r}")
    sigma = np.broadcast_to(sigma, (3,))
    if jitter_kind not in ("white", "random-walk"):
        raise InputError(f"jitter_kind must be 'white' or 'random-walk', got {jitter_kind!r}")
    if np.any(sigma > 0):
        rng = np.random.default_rng(seed)
        delta = rng.normal(0.0, 1.0, size=(len(p), 3)) * np.deg2rad(sigma)
        if jitter_kind == "random-walk":
            delta = np.cumsum(delta, axis=0)
        R = R @ rotvec_to_matrix(delta)
    T = np.zeros((len(p), 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return T
