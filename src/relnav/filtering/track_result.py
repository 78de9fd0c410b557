"""Paper 2 tracking output: :class:`TrackResult` (estimate, covariance, per-step status) and
:class:`TrackTruth`, with errors, NIS/NEES consistency, summaries and the per-step CSV.

Frames and angle conventions as in :mod:`relnav.fusion.tracker`: Euler angles are extrinsic
``xyz`` of ``R_s_b``, unwrapped over time; attitude errors are the body-axis rotation vector of
``R_gtᵀ R_est``.
"""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from relnav.geometry.dualquat import qmul

__all__ = ["STATE_BLOCKS", "TrackResult", "TrackTruth"]

log = logging.getLogger(__name__)

STATE_BLOCKS = ("position", "velocity", "attitude", "omega")
"""The 3-dim blocks of the state error, in the order of :meth:`TrackResult.nees_blocks` and
:meth:`TrackResult.nees_conditional`'s columns."""


_QCONJ = np.array([-1.0, -1.0, -1.0, 1.0])


def _euler_unwrapped(quats: np.ndarray) -> np.ndarray:
    """Extrinsic xyz Euler angles ``(K, 3)`` rad of quaternions ``(K, 4)``, unwrapped in time
    (rows with NaN stay NaN)."""
    out = np.full((len(quats), 3), np.nan)
    ok = np.all(np.isfinite(quats), axis=1)
    if np.any(ok):
        e = Rotation.from_quat(quats[ok]).as_euler("xyz")
        out[ok] = np.unwrap(e, axis=0)
    return out


def _body_rates(times: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """Body rates ``(K, 3)`` rad/s by finite differences of attitudes (forward; last backward)."""
    K = len(times)
    w = np.full((K, 3), np.nan)
    if K < 2:
        return w
    dq = qmul(quats[:-1] * _QCONJ, quats[1:])
    dq = np.where(dq[:, 3:4] < 0, -dq, dq)
    dt = np.diff(times)
    with np.errstate(divide="ignore", invalid="ignore"):
        rates = Rotation.from_quat(dq).as_rotvec() / dt[:, None]
    w[:-1] = rates
    w[-1] = rates[-1]
    return w


def _velocities(times: np.ndarray, pos: np.ndarray) -> np.ndarray:
    if len(times) < 2:
        return np.zeros_like(pos)
    return np.gradient(pos, times, axis=0)


@dataclass
class TrackTruth:
    """Ground truth on the tracker's time steps (same frames as the estimate).

    Attributes
    ----------
    position (K, 3) m, velocity (K, 3) m/s, quat (K, 4) xyzw, omega (K, 3) rad/s (body).
    """

    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    omega: np.ndarray

    @property
    def euler(self) -> np.ndarray:
        """Extrinsic xyz Euler angles ``(K, 3)``, rad, unwrapped."""
        return _euler_unwrapped(self.quat)

    @classmethod
    def from_poses(cls, times: np.ndarray, T_s_b: np.ndarray) -> TrackTruth:
        """Truth from poses ``T_sensor_body`` ``(K, 4, 4)``; velocity and body rates by finite
        differences."""
        times = np.asarray(times, dtype=np.float64)
        quats = Rotation.from_matrix(T_s_b[:, :3, :3]).as_quat()
        quats = np.where(quats[:, 3:4] < 0, -quats, quats)
        pos = T_s_b[:, :3, 3].copy()
        return cls(pos, _velocities(times, pos), quats, _body_rates(times, quats))


@dataclass
class TrackResult:
    """Per-step output of :class:`Tracker`.

    Attributes
    ----------
    time : (K,) float64
        Step times, s.
    position, velocity : (K, 3)
        m and m/s, sensor frame (NaN before initialization).
    quat : (K, 4)
        Attitude ``R_sensor_body`` (xyzw).
    omega : (K, 3)
        Body rates, rad/s.
    covariance : (K, 12, 12)
        Covariance of ``[δd, δv, δθ, δω]`` after each step.
    status : list[str]
        ``"init"``, ``"update"``, ``"predict"`` (no observation), ``"waiting"`` (before the
        first observation) or ``"flagged: <reason>"`` (observation rejected or bad time step;
        the filter predicted through).
    nis : (K,)
        Normalized innovation squared of accepted/gated updates (NaN otherwise).
    observed : (K, 7)
        Observed position and quaternion (NaN where none).
    filter : str
        ``"ukf"`` or ``"ekf"``.
    settings : dict
        Filter configuration.
    truth : TrackTruth, optional
        Ground truth on the same steps.
    meta : dict
        Free-form metadata (sequence folder, observer, seed, alignment...).
    noise_scale : (K,), optional
        Measurement-covariance scale ``λ`` used per step (``Tracker(noise_scale=...)``).
    log_likelihood : (K,), optional
        Gaussian log-likelihood of each update's innovation (NaN without one): the evidence a
        bank of filters is weighed by (:func:`relnav.filtering.multiple_model.mix_tracks`).
    model_probability : (K, M), optional
        For a mixed track, each member's probability per step (labels in
        ``meta["models"]``).
    """

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    omega: np.ndarray
    covariance: np.ndarray
    status: list[str]
    nis: np.ndarray
    observed: np.ndarray
    filter: str
    settings: dict[str, Any] = field(default_factory=dict)
    truth: TrackTruth | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    noise_scale: np.ndarray | None = None
    log_likelihood: np.ndarray | None = None
    model_probability: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.time)

    @property
    def euler(self) -> np.ndarray:
        """Extrinsic xyz Euler angles (roll, pitch, yaw) ``(K, 3)``, rad, unwrapped."""
        return _euler_unwrapped(self.quat)

    def sigma(self) -> dict[str, np.ndarray]:
        """1σ per step: ``position`` (m), ``velocity`` (m/s), ``attitude`` (rad, body axes),
        ``omega`` (rad/s), each ``(K, 3)``."""
        d = np.sqrt(np.clip(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0, None))
        return {
            "position": d[:, 0:3],
            "velocity": d[:, 3:6],
            "attitude": d[:, 6:9],
            "omega": d[:, 9:12],
        }

    @property
    def updated(self) -> np.ndarray:
        """``(K,)`` bool: the steps with an accepted update (the NIS samples)."""
        return np.array([s == "update" for s in self.status], dtype=bool)

    @property
    def estimated(self) -> np.ndarray:
        """``(K,)`` bool: the steps with an estimate after the initializing one (the NEES
        samples)."""
        return np.array([s not in ("init", "waiting") for s in self.status], dtype=bool)

    @property
    def n_flagged(self) -> int:
        """Steps whose observation was rejected (``flagged: ...``)."""
        return sum(s.startswith("flagged") for s in self.status)

    @property
    def n_predicted(self) -> int:
        """Steps without a usable observation (predicted through, flagged or not)."""
        return sum(s == "predict" or s.startswith("flagged") for s in self.status)

    def errors(self) -> dict[str, np.ndarray]:
        """Estimate minus truth per step: ``position`` (m), ``velocity`` (m/s), ``attitude``
        (rad, body rotation vector of ``R_gtᵀ R_est``), ``euler`` (rad, wrapped difference),
        ``omega`` (rad/s, body axes: each rate in its own body frame), ``omega_sensor``
        (rad/s, ``R_est ω_est − R_gt ω_gt``: the rate vectors in the sensor's axes); each
        ``(K, 3)``.

        **[interpretation]** ``omega_sensor`` compares the rate as a vector in one frame. The
        body axes of an uncooperative target are the estimator's own (a navigator's map), so
        a constant attitude error ``ε`` of them, already in ``attitude``, puts ``ω × ε`` into
        the body-axis rate error a second time; in the sensor's axes it cancels. At a hold
        point (a sensor holding an inertial attitude) it is the inertial rate's error.

        Raises
        ------
        EstimationError
            No ground truth.
        """
        from relnav.errors import EstimationError

        if self.truth is None:
            raise EstimationError("this track has no ground truth")
        t = self.truth
        att = np.full((len(self), 3), np.nan)
        ok = np.all(np.isfinite(self.quat), axis=1)
        if np.any(ok):
            dq = qmul(t.quat[ok] * _QCONJ, self.quat[ok])
            dq = np.where(dq[:, 3:4] < 0, -dq, dq)
            att[ok] = Rotation.from_quat(dq).as_rotvec()
        de = self.euler - t.euler
        de = (de + np.pi) % (2.0 * np.pi) - np.pi
        w_sensor = np.full((len(self), 3), np.nan)
        both = ok & np.all(np.isfinite(t.quat), axis=1)
        if np.any(both):
            w_sensor[both] = Rotation.from_quat(self.quat[both]).apply(
                self.omega[both]
            ) - Rotation.from_quat(t.quat[both]).apply(t.omega[both])
        return {
            "position": self.position - t.position,
            "velocity": self.velocity - t.velocity,
            "attitude": att,
            "euler": de,
            "omega": self.omega - t.omega,
            "omega_sensor": w_sensor,
        }

    def _state_errors(self) -> np.ndarray:
        """``(K, 12)`` errors ``[position, velocity, attitude, ω]`` (:meth:`errors`), the order
        of the covariance's physical block."""
        e = self.errors()
        return np.concatenate([e["position"], e["velocity"], e["attitude"], e["omega"]], axis=1)

    def _estimated_steps(self, err: np.ndarray) -> list[int]:
        """The steps whose error and covariance are finite."""
        return [
            k
            for k in range(len(self))
            if np.all(np.isfinite(err[k])) and np.all(np.isfinite(self.covariance[k]))
        ]

    def nees(self) -> np.ndarray:
        """NEES per step over the 12 physical components (NaN without an estimate)."""
        err = self._state_errors()
        out = np.full(len(self), np.nan)
        for k in self._estimated_steps(err):
            out[k] = float(err[k] @ np.linalg.solve(self.covariance[k], err[k]))
        return out

    def nees_blocks(self) -> np.ndarray:
        """NEES per step of the four 3-dim blocks (position, velocity, attitude, ω), each
        against its own covariance block, ``(K, 4)`` (NaN without an estimate)."""
        err = self._state_errors()
        out = np.full((len(self), 4), np.nan)
        for k in self._estimated_steps(err):
            for b in range(4):
                s = slice(3 * b, 3 * b + 3)
                out[k, b] = err[k, s] @ np.linalg.solve(self.covariance[k][s, s], err[k, s])
        return out

    def nees_conditional(self) -> np.ndarray:
        """NEES per step of each 3-dim block given the other nine components, ``(K, 4)``
        (position, velocity, attitude, ω; NaN without an estimate).

        The block's error less its regression on the others' errors,
        ``e_b − C_bo C_oo⁻¹ e_o``, against the conditional covariance
        ``C_bb − C_bo C_oo⁻¹ C_ob``; 3 for a consistent filter, like :meth:`nees_blocks`.
        **[interpretation]** A filter can have every block's own NEES at or under 3 and still
        be over-confident along a combination of blocks (a correlation stronger than the
        errors'): this shows which block's coupling to the rest is too tight. The 12-dim NEES
        is a block's NEES given the rest plus the rest's own (9-dim) NEES.
        """
        err = self._state_errors()
        out = np.full((len(self), 4), np.nan)
        idx = np.arange(12)
        blocks = [(idx[3 * b : 3 * b + 3], np.r_[idx[: 3 * b], idx[3 * b + 3 :]]) for b in range(4)]
        for k in self._estimated_steps(err):
            C = self.covariance[k]
            for b, (i, o) in enumerate(blocks):
                G = np.linalg.solve(C[np.ix_(o, o)], C[np.ix_(o, i)]).T  # C_bo C_oo⁻¹
                Cc = C[np.ix_(i, i)] - G @ C[np.ix_(o, i)]
                ec = err[k, i] - G @ err[k, o]
                out[k, b] = ec @ np.linalg.solve(0.5 * (Cc + Cc.T), ec)
        return out

    def innovation_alarm(
        self, window: int = 5, probability: float = 0.999, dof: int = 6
    ) -> np.ndarray:
        """``(K,)`` bool: steps where the mean NIS of the last ``window`` innovations (accepted
        or gated observations, this step included) exceeds the ``probability`` quantile of the
        mean of that many ``χ²_dof`` values, with at least half the window observed.

        **[interpretation]** A causal windowed innovation test (fault detection as in GNSS
        integrity monitoring): a run of observations that the filter's dynamics cannot follow,
        such as a navigator's map sliding at a hold point, where one step alone is within its
        gate (``benchmarks/nav/nav_phases.py``). ``window`` 5 and ``probability`` 0.999 were chosen
        on envisat-tumble-64's and aura-tumble-64's random phases
        (``docs/results/nav/state_hold_point.md``).
        """
        if window < 1 or not 0.0 < probability < 1.0:
            raise ValueError("window must be at least 1 and probability in (0, 1)")
        nis = np.asarray(self.nis, dtype=np.float64)
        seen = np.isfinite(nis)
        total = np.convolve(np.where(seen, nis, 0.0), np.ones(window))[: len(nis)]
        count = np.convolve(seen.astype(np.float64), np.ones(window))[: len(nis)]
        limit = chi2.ppf(probability, dof * window) / window
        enough = count >= max(window // 2, 1)
        return enough & (total > limit * np.maximum(count, 1.0))

    def consistency(self, probability: float = 0.95) -> dict[str, Any]:
        """Mean NIS over the updates and mean NEES over the estimated steps (after the
        initializing one), each with the two-sided ``probability`` band of the mean of that
        many independent χ² values (``χ²_{m·n}/n``; m = 6 for NIS, 12 for NEES).

        Returns
        -------
        dict
            ``{"nis": {"mean", "n", "dof", "band"}, "nees": {...} or None}``.
        """
        a = (1.0 - probability) / 2.0

        def block(x: np.ndarray, dof: int) -> dict[str, Any] | None:
            x = x[np.isfinite(x)]
            if x.size == 0:
                return None
            n = int(x.size)
            band = [float(chi2.ppf(a, dof * n) / n), float(chi2.ppf(1.0 - a, dof * n) / n)]
            return {"mean": float(x.mean()), "n": n, "dof": dof, "band": band}

        out: dict[str, Any] = {
            "nis": block(np.where(self.updated, self.nis, np.nan), 6),
            "nees": None,
        }
        if self.truth is not None:
            out["nees"] = block(np.where(self.estimated, self.nees(), np.nan), 12)
        return out

    def summary(self, skip: int | float = 0.2) -> dict[str, dict[str, list[float]]]:
        """RMS and max absolute error per axis after convergence.

        Parameters
        ----------
        skip : int or float
            Steps to ignore at the start (an int) or a fraction of the steps (a float < 1).

        Returns
        -------
        dict
            ``{quantity: {"rms": [x, y, z], "max": [x, y, z]}}`` with ``position`` (m),
            ``velocity`` (m/s), ``attitude`` and ``euler`` (deg), ``omega`` and
            ``omega_sensor`` (deg/s).
        """
        n0 = round(skip * len(self)) if isinstance(skip, float) and skip < 1 else int(skip)
        out: dict[str, dict[str, list[float]]] = {}
        for key, e in self.errors().items():
            e = e[n0:]
            e = e[np.all(np.isfinite(e), axis=1)]
            if key in ("attitude", "euler", "omega", "omega_sensor"):
                e = np.degrees(e)
            if len(e) == 0:
                out[key] = {"rms": [math.nan] * 3, "max": [math.nan] * 3}
                continue
            out[key] = {
                "rms": np.sqrt(np.mean(e**2, axis=0)).tolist(),
                "max": np.max(np.abs(e), axis=0).tolist(),
            }
        return out

    def to_csv(self, path: str | Path) -> Path:
        """Write one row per step: estimate, 1σ, observation, and truth/errors when present.

        Angles in degrees (Euler angles extrinsic xyz), rates in deg/s, lengths in metres; a
        mixed track adds each member's probability (``p_model<i>``, members in
        ``meta["models"]``); the last column is :meth:`innovation_alarm` (0/1).
        """
        path = Path(path)
        sig = self.sigma()
        eul = np.degrees(self.euler)
        cols: dict[str, np.ndarray] = {}
        xyz = ("x", "y", "z")

        def put(prefix: str, arr: np.ndarray, names: Sequence[str] = xyz) -> None:
            for i, n in enumerate(names):
                cols[f"{prefix}{n}"] = arr[:, i]

        put("p", self.position)
        put("v", self.velocity)
        put("", eul, ("roll", "pitch", "yaw"))
        put("w", np.degrees(self.omega))
        put("q", self.quat, ("x", "y", "z", "w"))
        put("sigma_p", sig["position"])
        put("sigma_v", sig["velocity"])
        put("sigma_att_", np.degrees(sig["attitude"]))
        put("sigma_w", np.degrees(sig["omega"]))
        put("obs_p", self.observed[:, :3])
        put("obs_q", self.observed[:, 3:], ("x", "y", "z", "w"))
        if self.truth is not None:
            t = self.truth
            put("true_p", t.position)
            put("true_v", t.velocity)
            put("true_", np.degrees(t.euler), ("roll", "pitch", "yaw"))
            put("true_w", np.degrees(t.omega))
            e = self.errors()
            put("err_p", e["position"])
            put("err_v", e["velocity"])
            put("err_att_", np.degrees(e["attitude"]))
            put("err_w", np.degrees(e["omega"]))
            put("err_ws", np.degrees(e["omega_sensor"]))
            cols["nees"] = self.nees()
        if self.noise_scale is not None:
            cols["noise_scale"] = np.asarray(self.noise_scale, dtype=np.float64)
        if self.log_likelihood is not None:
            cols["log_likelihood"] = np.asarray(self.log_likelihood, dtype=np.float64)
        if self.model_probability is not None:
            for i in range(self.model_probability.shape[1]):
                cols[f"p_model{i}"] = self.model_probability[:, i]
        cols["innovation_alarm"] = self.innovation_alarm().astype(np.float64)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time", "status", "nis", *cols])
            for k in range(len(self)):
                w.writerow(
                    [repr(float(self.time[k])), self.status[k], f"{self.nis[k]:.6g}"]
                    + [f"{cols[c][k]:.9g}" for c in cols]
                )
        return path
