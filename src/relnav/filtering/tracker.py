"""Run a pose filter over per-frame pose observations: :class:`Observation`, :class:`Tracker`.

:class:`Tracker` runs the twistor UKF (:mod:`relnav.filtering.ukf`) or the quaternion EKF
(:mod:`relnav.filtering.ekf`) over a sequence of per-frame observations (observed position of a
reference point and attitude of the target in the sensor frame). Frames without a usable
observation are **predicted through**: the filter propagates its state and covariance and the
step is flagged. The output is a :class:`~relnav.filtering.track_result.TrackResult`.

Frames: ``s`` = sensor frame, ``b`` = the observer's body frame of the target; the estimate is
``T_s_b`` (position ``d`` of ``b``'s origin in ``s``, attitude ``R_s_b``), velocity ``ḋ`` in
``s``, body rates ``ω`` in ``b``. Where observations come from (paper 2's observers, a
sequence folder, the navigator's poses) is the caller's business: :mod:`relnav.fusion.tracker`
runs paper 2's chain, :mod:`relnav.navigation.state` the navigator's relative state.
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.filtering.dynamics import mean_motion
from relnav.filtering.ekf import QuaternionEKF
from relnav.filtering.pose_filter import PAPER2_RATE_HZ, PoseFilter
from relnav.filtering.track_result import TrackResult, TrackTruth, _body_rates
from relnav.filtering.ukf import TwistorUKF

__all__ = ["FilterName", "Observation", "TrackLog", "Tracker", "make_filter"]

log = logging.getLogger(__name__)

FilterName = Literal["ukf", "ekf"]


@dataclass(frozen=True)
class Observation:
    """One per-frame observation of the target.

    Attributes
    ----------
    position : (3,) ndarray
        Target reference point (centroid) in the sensor frame, m.
    quat_xyzw : (4,) ndarray
        Attitude ``R_sensor_body``.
    quality : float
        Observer's quality score (e.g. registration fitness, 1 = best).
    R : (6, 6) ndarray, optional
        Covariance of ``[δp (m), δθ (rad)]``; default: the filter's.
    drift : (6, 6) ndarray, optional
        Growth of the observer's own slowly varying error since its previous observation
        (same coordinates), for ``TwistorUKF(observer_bias=True)``.
    offset_drift : (3, 3) ndarray, optional
        Growth of the offset of the observer's reference point from the target's origin since
        its previous observation (m², sensor axes), for ``TwistorUKF(centre_offset=True)``
        (:meth:`~relnav.filtering.ukf.TwistorUKF.add_offset_drift`).
    frame : int, optional
        The observer's id of this frame when the frame was merged into its model (the keys of
        later observations' ``sources``); ``None``: not merged.
    sources : dict of int to float, optional
        Where the observation's model matches came from: ``{frame id: share}`` of the earlier
        merged frames (shares sum to 1), for ``TwistorUKF(merge_slots=…)``. Each merged frame
        wrote its pose error into the model, and a registration onto that part of the model
        inherits it. An empty dict marks the anchor frame, which defines the body frame (its
        merge carries no error); ``None``: no such information.
    """

    position: np.ndarray
    quat_xyzw: np.ndarray
    quality: float = 1.0
    R: np.ndarray | None = None
    drift: np.ndarray | None = None
    offset_drift: np.ndarray | None = None
    frame: int | None = None
    sources: dict[int, float] | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=np.float64)
        q = np.asarray(self.quat_xyzw, dtype=np.float64)
        if p.shape != (3,) or q.shape != (4,):
            raise InputError(
                f"observation needs position (3,) and quat_xyzw (4,), got {p.shape}, {q.shape}"
            )
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "quat_xyzw", q)


class TrackLog:
    """Accumulates per-step filter outputs into :class:`TrackResult` arrays."""

    def __init__(self, K: int) -> None:
        self.pos = np.full((K, 3), np.nan)
        self.vel = np.full((K, 3), np.nan)
        self.quat = np.full((K, 4), np.nan)
        self.om = np.full((K, 3), np.nan)
        self.cov = np.full((K, 12, 12), np.nan)
        self.nis = np.full(K, np.nan)
        self.loglik = np.full(K, np.nan)
        self.obs = np.full((K, 7), np.nan)
        self.lam = np.full(K, np.nan)
        self.status: list[str] = []

    def record(
        self, k: int, f: PoseFilter | None, live: bool, status: str, nis: float, o: Any
    ) -> None:
        self.status.append(status)
        self.nis[k] = nis
        if o is not None:
            self.obs[k] = np.r_[o.position, o.quat_xyzw]
        if live and f is not None:
            self.pos[k], self.vel[k], self.quat[k], self.om[k] = (
                f.position,
                f.velocity,
                f.quaternion,
                f.omega,
            )
            self.cov[k] = f.physical_covariance()

    def result(
        self,
        times: np.ndarray,
        name: str,
        settings: dict[str, Any],
        truth: TrackTruth | None,
        meta: dict[str, Any],
    ) -> TrackResult:
        n_flag = sum(s.startswith("flagged") for s in self.status)
        if n_flag:
            log.info("%d of %d steps flagged (predicted through)", n_flag, len(self.status))
        return TrackResult(
            time=times,
            position=self.pos,
            velocity=self.vel,
            quat=self.quat,
            omega=self.om,
            covariance=self.cov,
            status=self.status,
            nis=self.nis,
            observed=self.obs,
            filter=name,
            settings=settings,
            truth=truth,
            meta=meta,
            noise_scale=self.lam,
            log_likelihood=self.loglik,
        )


def make_filter(name: FilterName | str = "ukf", **options: Any) -> PoseFilter:
    """Build ``"ukf"`` (:class:`TwistorUKF`) or ``"ekf"`` (:class:`QuaternionEKF`).

    Raises
    ------
    ConfigError
        Unknown filter or options.
    """
    key = str(name).lower()
    classes: dict[str, type[PoseFilter]] = {"ukf": TwistorUKF, "ekf": QuaternionEKF}
    if key not in classes:
        raise ConfigError(f"unknown filter {name!r}; choose 'ukf' or 'ekf'")
    try:
        return classes[key](**options)
    except TypeError as e:
        raise ConfigError(f"bad option for filter {key!r}: {e}") from None


class Tracker:
    """Run a pose filter over per-frame observations, predicting through missing ones.

    Parameters
    ----------
    filter : {"ukf", "ekf"}
        Twistor UKF (Paper 2) or the quaternion EKF baseline.
    n_mean_motion : float, optional
        CW mean motion, rad/s (default 0, Paper 2's lab set-up).
    orbit_radius_m : float, optional
        Alternative to ``n_mean_motion``: circular-orbit radius (m, from Earth's centre).
    dt : float, optional
        Nominal step for the process noise (default: median step of the run, else 1/0.22 s).
    omega0 : (3,) array_like, optional
        Initial body rate, rad/s (default zero; Paper 2 Table 3 uses ``(0, 0, 5)°/s``).
    velocity0 : (3,) array_like, optional
        Initial velocity, m/s (default zero).
    min_quality : float
        Observations with ``quality`` below this are rejected (flagged).
    init : {"first", "rate", "prior"}
        ``"first"``: initialize position and attitude from the first usable observation (steps
        before it are ``"waiting"``); ``"rate"`` **[interpretation, not in Paper 2]**: as
        ``"first"``, then at the second usable observation the filter starts again from the
        first one with the attitude change between them as its body rate, ``log(q₀⁻¹ q₁)/Δt``
        (the shortest rotation: a target turning less than 180° between them), and takes the
        second as its first update — for a target whose rate is unknown (no ``omega0``): a
        zero initial rate reads the first turns of a reference point circling the spin axis as
        velocity; ``"prior"``: start from the filter's initial state
        (``position0``/``quat0`` in ``filter_options``).
    noise_scale : {"fixed", "innovation"}
        ``"fixed"``: each update uses the observation's covariance (or the filter's ``r``) as
        is. ``"innovation"`` **[interpretation]**: covariance matching on the innovations seen
        so far — before each update the measurement covariance is multiplied by the scalar
        ``λ ≥ 1`` that makes the mean NIS of the updates so far, this one included
        (re-evaluated with ``S_j = H P_j Hᵀ + λ R_j``), equal to the measurement dimension;
        ``λ = 1`` without an innovation. Only the measurements up to the current one
        are used (causal, no ground truth); ``λ`` per step is in
        :attr:`TrackResult.noise_scale`.
    **filter_options
        Passed to the filter (``q``, ``r``, ``p0``, ``alpha``, ``kappa``, ``lvlh_axes``,
        ``translation_model``, ``jacobian``, ``gate_probability`` …).

    Examples
    --------
    >>> from relnav.fusion.observers import simulate_observations
    >>> times, obs, truth = simulate_observations(n_steps=30, seed=0)
    >>> result = Tracker("ukf").run(times, obs, truth=truth)
    >>> result.summary()["attitude"]["rms"]  # doctest: +SKIP
    """

    def __init__(
        self,
        filter: FilterName | str = "ukf",
        *,
        n_mean_motion: float | None = None,
        orbit_radius_m: float | None = None,
        dt: float | None = None,
        omega0: Any = None,
        velocity0: Any = None,
        min_quality: float = 0.0,
        init: Literal["first", "rate", "prior"] = "first",
        noise_scale: Literal["fixed", "innovation"] = "fixed",
        **filter_options: Any,
    ) -> None:
        if n_mean_motion is not None and orbit_radius_m is not None:
            raise ConfigError("give n_mean_motion or orbit_radius_m, not both")
        n = 0.0 if n_mean_motion is None else float(n_mean_motion)
        if orbit_radius_m is not None:
            n = mean_motion(orbit_radius_m)
        if init not in ("first", "rate", "prior"):
            raise ConfigError(f"init must be 'first', 'rate' or 'prior', got {init!r}")
        if init == "rate" and omega0 is not None:
            raise ConfigError("init='rate' estimates the initial rate: give no omega0")
        self.filter_name = str(filter).lower()
        self.n_mean_motion = n
        self.dt = dt
        self.omega0 = None if omega0 is None else np.asarray(omega0, dtype=np.float64)
        self.velocity0 = None if velocity0 is None else np.asarray(velocity0, dtype=np.float64)
        self.min_quality = float(min_quality)
        self.init = init
        if noise_scale not in ("fixed", "innovation"):
            raise ConfigError(f"noise_scale must be 'fixed' or 'innovation', got {noise_scale!r}")
        self.noise_scale = noise_scale
        self.lam = 1.0
        self.log_likelihood = math.nan  # of the last step's update (NaN without one)
        self._innov: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.filter_options = dict(filter_options)
        make_filter(self.filter_name, n_mean_motion=n, **self._opts(1.0))  # validate early
        self.filter: PoseFilter | None = None
        self._t: float | None = None
        self._initialized = False

    def _opts(self, dt: float) -> dict[str, Any]:
        opts = dict(self.filter_options)
        opts.setdefault("dt", dt)
        if self.omega0 is not None:
            opts.setdefault("omega0", self.omega0)
        if self.velocity0 is not None:
            opts.setdefault("velocity0", self.velocity0)
        return opts

    def reset(self, dt: float | None = None) -> None:
        """Build a fresh filter (nominal step ``dt``)."""
        step = self.dt or dt or 1.0 / PAPER2_RATE_HZ
        self.filter = make_filter(
            self.filter_name, n_mean_motion=self.n_mean_motion, **self._opts(step)
        )
        self._t = None
        self._initialized = self.init == "prior"
        self._first: tuple[float, Observation] | None = None  # init="rate": held observation
        self.lam = 1.0
        self._innov = []

    def _match_scale(self) -> float:
        """``λ ≥ 1`` with mean ``νᵀ(A + λR)⁻¹ν`` over the past updates = their dimension."""
        if not self._innov:
            return 1.0
        m = float(np.mean([nu.size for nu, _, _ in self._innov]))

        def mean_nis(lam: float) -> float:
            return float(
                np.mean([nu @ np.linalg.solve(A + lam * R, nu) for nu, A, R in self._innov])
            )

        if mean_nis(1.0) <= m:
            return 1.0
        lo, hi = 0.0, math.log(1e6)
        if mean_nis(math.exp(hi)) > m:
            return math.exp(hi)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if mean_nis(math.exp(mid)) > m:
                lo = mid
            else:
                hi = mid
        return math.exp(hi)

    def _usable(self, obs: Observation | None) -> str:
        """``""`` if ``obs`` can be used, else the reason."""
        if obs is None:
            return "none"
        if not (np.all(np.isfinite(obs.position)) and np.all(np.isfinite(obs.quat_xyzw))):
            return "non-finite observation"
        if float(np.linalg.norm(obs.quat_xyzw)) < 1e-9:
            return "zero quaternion"
        if not math.isfinite(obs.quality) or obs.quality < self.min_quality:
            return f"quality {obs.quality:.3g} below {self.min_quality:.3g}"
        return ""

    def step(self, t: float, obs: Observation | None) -> tuple[str, float]:
        """Advance to time ``t`` (s) and use ``obs`` if any.

        Returns
        -------
        status : str
            See :class:`TrackResult`.
        nis : float
            NIS of the update (NaN if none).
        """
        if self.filter is None:
            self.reset()
        f = self.filter
        assert f is not None
        self.log_likelihood = math.nan  # set again by an update
        t = float(t)
        reason = self._usable(obs)
        if not self._initialized:
            if reason:
                self._t = t if math.isfinite(t) else self._t
                return ("waiting" if reason == "none" else f"flagged: {reason}"), math.nan
            assert obs is not None
            f.initialize(
                obs.position,
                obs.quat_xyzw,
                velocity=self.velocity0,
                omega=self.omega0,
            )
            self._initialized = True
            self._t = t
            self._first = (t, obs) if self.init == "rate" else None
            return "init", math.nan
        if self._first is not None and not reason and math.isfinite(t) and t > self._first[0]:
            # init="rate": start again from the first observation, with the rate the second shows
            assert obs is not None
            t0, o0 = self._first
            f.initialize(
                o0.position,
                o0.quat_xyzw,
                velocity=self.velocity0,
                omega=_body_rates(np.array([t0, t]), np.stack([o0.quat_xyzw, obs.quat_xyzw]))[0],
            )
            self._t, self._first = t0, None
        if not math.isfinite(t) or (self._t is not None and t < self._t):
            return f"flagged: time {t!r} not after {self._t!r}", math.nan
        if self._t is not None:
            f.predict(t - self._t)
        self._t = t
        if reason == "none":
            return "predict", math.nan
        if reason:
            return f"flagged: {reason}", math.nan
        assert obs is not None
        R = obs.R
        if obs.drift is not None and hasattr(f, "add_observer_drift"):
            f.add_observer_drift(obs.drift)
        if obs.offset_drift is not None and hasattr(f, "add_offset_drift"):
            f.add_offset_drift(obs.offset_drift)
        if obs.sources is not None and hasattr(f, "set_merge_sources"):
            f.set_merge_sources(obs.frame, obs.sources)
        if self.noise_scale == "innovation":
            R0 = f.R if R is None else np.asarray(R, dtype=np.float64)
            probe = copy.deepcopy(f).update(obs.position, obs.quat_xyzw, R=R0)
            if probe.meas_cov.size and np.all(np.isfinite(probe.innovation)):
                A = probe.innovation_cov - probe.meas_cov
                self._innov.append((probe.innovation, A, probe.meas_cov))
            self.lam = self._match_scale()
            R = R0 * self.lam
        info = f.update(obs.position, obs.quat_xyzw, R=R)
        self.log_likelihood = info.log_likelihood
        if not info.accepted:
            return f"flagged: {info.message}", info.nis
        return "update", info.nis

    def run(
        self,
        times: Sequence[float] | np.ndarray,
        observations: Sequence[Observation | None],
        *,
        truth: TrackTruth | None = None,
        progress: Callable[[int, int], None] | None = None,
        meta: dict[str, Any] | None = None,
    ) -> TrackResult:
        """Run the filter over a whole sequence (a fresh filter).

        Parameters
        ----------
        times : (K,) array_like
            Step times, s (non-decreasing; a step going back in time is flagged and skipped).
        observations : sequence of Observation or None
            One per step; ``None`` = no observation (predicted through).
        truth : TrackTruth, optional
            Attached to the result.
        progress : callable, optional
            ``progress(done, total)`` after each step.
        meta : dict, optional
            Stored in the result.

        Raises
        ------
        InputError
            ``times`` and ``observations`` differ in length, or ``truth`` does.
        """
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        K = len(t)
        if len(observations) != K:
            raise InputError(f"{len(observations)} observations for {K} time steps")
        if truth is not None and len(truth.position) != K:
            raise InputError(f"ground truth has {len(truth.position)} steps for {K} time steps")
        finite = t[np.isfinite(t)]
        steps = np.diff(finite)
        steps = steps[steps > 0]
        self.reset(float(np.median(steps)) if len(steps) else None)
        rec = TrackLog(K)
        for k in range(K):
            o = observations[k]
            st, ni = self.step(t[k], o)
            rec.record(k, self.filter, self._initialized, st, ni, o)
            rec.lam[k] = self.lam
            rec.loglik[k] = self.log_likelihood
            if progress is not None:
                progress(k + 1, K)
        assert self.filter is not None
        return rec.result(t, self.filter_name, self.filter.settings(), truth, dict(meta or {}))
