"""Paper 2 per-frame observations (:class:`~relnav.filtering.tracker.Observation`): the
:class:`Observer` protocol and its implementations (scans → observed pose of the target in the
sensor frame), and simulated observations for tests and benchmarks.

:class:`RegistrationObserver` chains frame-to-frame registrations on one sensor;
:class:`ContourObserver` is Paper 2's chain (cross-source registration, plane clustering,
contour model). Frames as in :mod:`relnav.fusion.tracker`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from relnav.errors import ConfigError, InputError
from relnav.filtering.dynamics import ClohessyWiltshire
from relnav.filtering.pose_filter import quat_delta
from relnav.filtering.track_result import TrackTruth
from relnav.filtering.tracker import Observation
from relnav.geometry.dualquat import qmul
from relnav.geometry.rotations import project_to_so3, quat_to_matrix
from relnav.geometry.se3 import invert

if TYPE_CHECKING:
    from relnav.fusion.observer_noise import ObserverNoise

__all__ = [
    "ContourObserver",
    "Observer",
    "RegistrationObserver",
    "simulate_observations",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# simulated observations (tests, benchmarks, demos)
# --------------------------------------------------------------------------------------------


def simulate_observations(
    n_steps: int = 100,
    dt: float = 4.5,
    *,
    omega_deg_s: Sequence[float] = (0.0, 0.0, 5.0),
    position0: Sequence[float] = (3.0, 0.0, 0.0),
    velocity0: Sequence[float] = (0.0, 0.0, 0.0),
    quat0: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
    n_mean_motion: float = 0.0,
    lvlh_axes: str | np.ndarray | None = None,
    sigma_position: float = 0.01,
    sigma_attitude_deg: float = 1.0,
    missing: Sequence[int] = (),
    offset: Sequence[float] = (0.0, 0.0, 0.0),
    merge_sources: np.ndarray | None = None,
    seed: int | np.random.Generator | None = 0,
) -> tuple[np.ndarray, list[Observation | None], TrackTruth]:
    """Observations of a target spinning at a constant body rate, with CW relative translation.

    Truth: ``q_{k+1} = q_k ⊗ q_Δ(ω dt)``, ``(d, ḋ)`` by the exact CW transition; observations
    ``D = d + N(0, σ_p² I)``, ``Q = q ⊗ exp(N(0, σ_θ² I))`` (body-frame noise).

    Parameters
    ----------
    n_steps, dt : int, float
        Number of steps and period (s). Defaults: 100 frames at 4.5 s (22.5° per frame at 5°/s,
        Paper 2's semi-physical run).
    omega_deg_s : (3,)
        Body rate, deg/s (Paper 2: ``(0, 0, 5)``).
    position0, velocity0, quat0 : array_like
        Initial relative state (sensor frame).
    n_mean_motion, lvlh_axes : float, str
        CW dynamics of the truth.
    sigma_position, sigma_attitude_deg : float
        Measurement noise 1σ (m, deg).
    missing : sequence of int
        Steps without an observation (``None``).
    offset : (3,) array_like
        Body-frame offset (m) of the observed reference point from the rotation centre: the
        observed position is ``d + R c`` (it circles the spin axis). Truth is the point of
        the spin axis nearest the reference point, ``d + R c_∥`` with ``c_∥`` the component
        of ``c`` along ``ω`` (the component the observations can resolve).
    merge_sources : (K, K) array_like, optional
        An observer that builds a model and inherits its merge errors (the contour model,
        ``TwistorUKF(merge_slots=…)``): ``W[k, j]`` (``j < k``, rows summing to 1) is the share
        of frame ``k``'s matches on the part of the model frame ``j`` contributed. The error of
        observation ``k`` in body axes, a right perturbation ``[e_p (m), e_θ (rad)]`` of the
        pose (``D = p + R e_p``, ``Q = q ⊗ exp(e_θ)``), is then ``e_k = Σ_j W_kj e_j + v_k``
        with ``v_k`` the noise above drawn in body axes, and ``e_0 = 0`` (frame 0 is the
        anchor). Every observation carries ``frame = k``, ``sources`` (row ``k``; ``{}`` for
        frame 0) and ``R`` (the covariance of ``v_k``, position block in sensor axes); no
        ``missing`` steps.
    seed : int or Generator
        Noise seed.

    Returns
    -------
    times : (K,) ndarray
    observations : list of Observation or None
    truth : TrackTruth
    """
    if int(n_steps) < 1 or not dt > 0:
        raise InputError(f"need n_steps >= 1 and dt > 0, got {n_steps}, {dt}")
    if merge_sources is not None:
        if len(missing):
            raise InputError("missing steps are not simulated with merge_sources")
        return _simulate_merged(
            n_steps, dt, omega_deg_s, position0, velocity0, quat0, n_mean_motion, lvlh_axes,
            sigma_position, sigma_attitude_deg, offset, np.asarray(merge_sources, float), seed,
        )  # fmt: skip
    rng = np.random.default_rng(seed)
    K = int(n_steps)
    w = np.radians(np.asarray(omega_deg_s, dtype=np.float64).reshape(3))
    cw = ClohessyWiltshire(n_mean_motion, lvlh_axes=lvlh_axes)
    q = np.asarray(quat0, dtype=np.float64).reshape(4)
    q = q / np.linalg.norm(q)
    d = np.asarray(position0, dtype=np.float64).reshape(3)
    v = np.asarray(velocity0, dtype=np.float64).reshape(3)
    times = np.arange(K) * float(dt)
    P = np.zeros((K, 3))
    V = np.zeros((K, 3))
    Qs = np.zeros((K, 4))
    qd = quat_delta(w, dt)
    for k in range(K):
        P[k], V[k], Qs[k] = d, v, (q if q[3] >= 0 else -q)
        q = qmul(q, qd)
        q = q / np.linalg.norm(q)
        d, v = cw.propagate(d, v, dt)
    noise_p = rng.normal(size=(K, 3)) * sigma_position
    noise_q = Rotation.from_rotvec(rng.normal(size=(K, 3)) * math.radians(sigma_attitude_deg))
    zq = qmul(Qs, noise_q.as_quat())
    c = np.asarray(offset, dtype=np.float64).reshape(3)
    Rk = quat_to_matrix(Qs)
    ref = P + Rk @ c
    nw = float(np.linalg.norm(w))
    if nw > 0.0 and np.any(c != 0.0):
        u = w / nw
        P = P + Rk @ (u * float(u @ c))  # constant: R_k u = R_0 u for a body-fixed rate
    miss = {int(i) for i in missing}
    obs: list[Observation | None] = [
        None if k in miss else Observation(ref[k] + noise_p[k], zq[k]) for k in range(K)
    ]
    truth = TrackTruth(P, V, Qs, np.tile(w, (K, 1)))
    return times, obs, truth


def _simulate_merged(
    n_steps: int,
    dt: float,
    omega_deg_s: Sequence[float],
    position0: Sequence[float],
    velocity0: Sequence[float],
    quat0: Sequence[float],
    n_mean_motion: float,
    lvlh_axes: str | np.ndarray | None,
    sigma_position: float,
    sigma_attitude_deg: float,
    offset: Sequence[float],
    W: np.ndarray,
    seed: int | np.random.Generator | None,
) -> tuple[np.ndarray, list[Observation | None], TrackTruth]:
    """:func:`simulate_observations` with ``merge_sources`` (see there)."""
    K = int(n_steps)
    if W.shape != (K, K) or not np.all(np.isfinite(W)) or np.any(np.triu(W) != 0.0):
        raise InputError(f"merge_sources must be a finite strictly lower-triangular ({K}, {K})")
    rng = np.random.default_rng(seed)
    times, exact, truth = simulate_observations(
        K, dt, omega_deg_s=omega_deg_s, position0=position0, velocity0=velocity0, quat0=quat0,
        n_mean_motion=n_mean_motion, lvlh_axes=lvlh_axes, sigma_position=0.0,
        sigma_attitude_deg=0.0, offset=offset, seed=None,
    )  # fmt: skip
    sig = np.r_[[sigma_position] * 3, [math.radians(sigma_attitude_deg)] * 3]
    e = np.zeros((K, 6))
    for k in range(1, K):
        e[k] = W[k] @ e + rng.normal(size=6) * sig
    obs: list[Observation | None] = []
    for k, o in enumerate(exact):
        assert o is not None
        Rk = quat_to_matrix(o.quat_xyzw)
        q = qmul(o.quat_xyzw, quat_delta(e[k, 3:], 1.0))
        cov = np.diag(sig**2)
        cov[0:3, 0:3] = Rk @ cov[0:3, 0:3] @ Rk.T
        sources = {int(j): float(W[k, j]) for j in np.flatnonzero(W[k] > 0.0)}
        obs.append(Observation(o.position + Rk @ e[k, :3], q, R=cov, frame=k, sources=sources))
    return times, obs, truth


# --------------------------------------------------------------------------------------------
# observers (scans → observations)
# --------------------------------------------------------------------------------------------


class Observer(Protocol):
    """Turns the scans of one frame into an :class:`Observation`.

    ``observe(k, scans, prior)``: ``scans`` maps sensor names (``""`` = primary camera) to
    ``(N, 3)`` points in that sensor's frame; ``prior`` is the predicted ``T_s_b`` or ``None``.
    Return ``None`` (or raise :class:`relnav.errors.RelnavError`) when no usable observation
    can be made — the tracker then predicts through and flags the step.
    """

    name: str

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None: ...


def _subsample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    if n <= 0 or len(points) <= n:
        return points
    return points[np.sort(rng.choice(len(points), n, replace=False))]


class RegistrationObserver:
    """Observations from a frame-to-frame registration chain on one sensor's scans.

    **[interpretation]** Stand-in for Paper 2's contour-model observation when
    :mod:`relnav.fusion.reconstruction` is not used: the body frame ``b`` is the sensor frame
    at the first observed frame, with its origin at that scan's centroid ``c₀``
    (``T_s_b(0) = [I, c₀]``). Each later scan (source) is registered onto the previous good
    scan (target), initialized from the filter's prediction, and
    ``T_s_b(k) = T_{prev←k}⁻¹ T_s_b(prev)``. A registration whose status is not ``ok`` gives no
    observation. Quality = registration fitness.

    Parameters
    ----------
    method : str
        Registration method string (:func:`relnav.registration.get_registration`).
    sensor : str
        Which scan to use (``""`` = primary).
    max_points : int
        Random subsample per scan (seeded), 0 = all points.
    seed : int
        Subsampling seed.
    **options
        Passed to the registration factory.
    """

    def __init__(
        self,
        method: str = "icp-point",
        *,
        sensor: str = "",
        max_points: int = 4000,
        seed: int = 0,
        **options: Any,
    ) -> None:
        from relnav.registration import get_registration

        self.method = method
        self.reg = get_registration(method, **options)
        self.sensor = sensor
        self.max_points = int(max_points)
        self.rng = np.random.default_rng(seed)
        self.name = f"registration:{method}"
        self.n_failed = 0
        self._prev_pts: np.ndarray | None = None
        self._prev_T: np.ndarray | None = None

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None:
        pts = scans.get(self.sensor)
        if pts is None or len(pts) < 10:
            raise InputError(f"frame {k}: too few points from sensor {self.sensor or 'primary'}")
        pts = _subsample(np.asarray(pts, dtype=np.float64), self.max_points, self.rng)
        if self._prev_pts is None or self._prev_T is None:
            T = np.eye(4)
            T[:3, 3] = pts.mean(axis=0)
            self._prev_pts, self._prev_T = pts, T
            return Observation(T[:3, 3], np.array([0.0, 0.0, 0.0, 1.0]), 1.0)
        init = None if prior is None else self._prev_T @ invert(prior)
        res = self.reg.register(pts, self._prev_pts, init=init)
        if not res.ok:
            self.n_failed += 1
            raise InputError(f"frame {k}: registration {res.status}: {res.message}")
        T = invert(res.T_target_source) @ self._prev_T
        T[:3, :3] = project_to_so3(T[:3, :3])
        self._prev_pts, self._prev_T = pts, T
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        return Observation(T[:3, 3].copy(), q, float(res.fitness))

    @property
    def stats(self) -> dict[str, Any]:
        """Counters for the result metadata."""
        return {"registration_failed": self.n_failed}


class ContourObserver:
    """Paper 2's chain: CGA cross-source registration (LIDAR → camera), plane clustering and the
    contour model's per-frame observation (:func:`relnav.fusion.cross_source.
    cross_source_register`, :func:`relnav.fusion.clustering.cluster_and_project`,
    :class:`relnav.fusion.reconstruction.ContourModel`).

    The body frame is the contour model's ``B`` (axes of the camera frame at the first observed
    frame, origin at that frame's fused centroid) — the same convention as
    :class:`RegistrationObserver`. The filter's prediction is passed to the model as the
    registration start (``T_model_frame = T_M_B · T_s_b⁻¹`` with ``T_M_B = [I, b]``). Frames
    whose cross-source registration fails are tracked on the camera cloud alone
    (``fallback_camera_only=True``) or give no observation; a model rejection (quality 0) gives
    no observation. Needs the camera scan in every frame.

    Parameters
    ----------
    lidar : str
        Second-sensor name.
    m : int
        Samples of the CGA registration (paper 2: 15).
    seed : int
        Seed of the registration and the model (frame ``k`` uses ``seed + k``).
    fallback_camera_only : bool
        See above.
    cluster_options, model_options : dict, optional
        Passed to ``cluster_and_project`` and ``ContourModel``.
    noise : ObserverNoise or "reported"
        The covariance and drift each observation carries. An
        :class:`relnav.fusion.observer_noise.ObserverNoise` (default: ``CONTOUR_LI_ROTATING``,
        calibrated by Monte Carlo on Paper 2's simulation) gives every observation its white
        error and, after the first, its drift. ``"reported"``: the contour model's jackknife
        covariance of the registration, and as drift the previous observation's (5-10x too
        small: docs/results/paper2/table.md).
    """

    def __init__(
        self,
        *,
        lidar: str = "lidar",
        m: int = 15,
        seed: int = 0,
        fallback_camera_only: bool = True,
        cluster_options: dict[str, Any] | None = None,
        model_options: dict[str, Any] | None = None,
        noise: ObserverNoise | Literal["reported"] | None = None,
    ) -> None:
        from relnav.fusion.clustering import cluster_and_project
        from relnav.fusion.cross_source import cross_source_register
        from relnav.fusion.reconstruction import ContourModel

        self._register = cross_source_register
        self._cluster = cluster_and_project
        self.model = ContourModel(seed=seed, **(model_options or {}))
        self.cluster_options = dict(cluster_options or {})
        self.lidar = lidar
        self.m = int(m)
        self.seed = int(seed)
        self.fallback_camera_only = bool(fallback_camera_only)
        self.name = "contour"
        from relnav.fusion.observer_noise import CONTOUR_LI_ROTATING, ObserverNoise

        if noise is None:
            noise = CONTOUR_LI_ROTATING
        if not (isinstance(noise, ObserverNoise) or noise == "reported"):
            raise ConfigError(f"noise must be an ObserverNoise or 'reported', got {noise!r}")
        self.noise = noise
        self.n_fusion_failed = 0
        self._last_R: np.ndarray | None = None
        self._frame_of: dict[int, int] = {}  # model history index -> observer frame id k

    @property
    def stats(self) -> dict[str, Any]:
        """Counters for the result metadata."""
        hist = self.model.history
        return {
            "fusion_failed": self.n_fusion_failed,
            "model_rejected": sum(not h.get("accepted", True) for h in hist),
            "model_points": int(self.model.points.shape[0]),
        }

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None:
        from relnav.geometry.se3 import transform_points

        cam = scans.get("")
        lid = scans.get(self.lidar)
        if cam is None or len(cam) == 0:
            raise InputError(f"frame {k}: no camera points")
        cloud = cam
        why = ""
        if lid is None or len(lid) == 0:
            why = f"no {self.lidar} scan"
        else:
            res = self._register(cam, lid, m=self.m, seed=self.seed + k)
            if res.ok:
                lid_c = transform_points(res.T_target_source, lid)
                cloud = self._cluster(cam, lid_c, **self.cluster_options).fused_points
            else:
                why = f"cross-source registration {res.status}: {res.message}"
        if why:
            self.n_fusion_failed += 1
            if not self.fallback_camera_only:
                raise InputError(f"frame {k}: {why}")
            log.info("frame %d: %s; using the camera cloud alone", k, why)
        init = None
        b = self.model.body_origin
        if prior is not None and b is not None:
            T_M_B = np.eye(4)
            T_M_B[:3, 3] = b
            init = T_M_B @ invert(prior)
        self._frame_of[len(self.model.history)] = k
        position, quat, quality = self.model.observe(cloud, init=init)
        if quality <= 0.0:
            reason = self.model.history[-1].get("reason", "rejected") if self.model.history else ""
            raise InputError(f"frame {k}: contour model: {reason}")
        if self.noise == "reported":
            R = self.model.last_covariance  # None → the filter's fixed noise
            # [interpretation] the frame merged last carries its pose error into the model,
            # which the following registrations inherit: that is the observer's drift since then
            drift, self._last_R = self._last_R, R
        else:
            R = self.noise.white
            drift = None if self.model.n_frames == 1 else self.noise.drift
        # the sequential model records which merged frames the registration matched
        # (first frame: the anchor, no sources; multiview: not recorded)
        src = self.model.last_sources
        if self.model.multiview:
            sources = None
        elif self.model.n_frames == 1:
            sources = {}
        else:
            sources = {self._frame_of[j]: w for j, w in (src or {}).items()}
        return Observation(
            np.asarray(position),
            np.asarray(quat),
            float(quality),
            R=R,
            drift=drift,
            frame=None if self.model.multiview else k,
            sources=sources,
        )


def _default_observer(
    second: str | None, seed: int, noise: ObserverNoise | Literal["reported"] | None = None
) -> Observer:
    if second is not None:
        try:
            return ContourObserver(lidar=second, seed=seed, noise=noise)
        except (ImportError, TypeError) as e:  # I1's modules absent or a different API
            log.info("contour-model observer unavailable (%s); using the registration chain", e)
    return RegistrationObserver(seed=seed)
