"""Constant-velocity SE(3) filter: the navigator's motion model and velocity estimate.

State: the pose ``T`` (``T_target_sensor``) and the body-frame twist rate ``v = [ν (m/s),
ω (rad/s)]``; error state ``[δp, δv]`` (12) with ``T_true = T exp(δp)`` (right, body-frame
perturbation) and covariance ``P`` (12×12).

* **Predict** over ``Δt``: ``T ← T exp(v Δt)``, ``P ← F P Fᵀ + Q`` with
  ``F = [[Ad(exp(−v Δt)), Δt I], [0, I]]`` and a white-acceleration ``Q`` on the velocity.
* **Adapt**: ``Q`` is scaled by the running normalised innovation (:meth:`adapt`).
* **Update** with the registered pose ``T*`` and the registration's own information ``H`` (left
  perturbation in the target frame, converted to the body frame with the adjoint): the pose
  prior used inside the registration is this filter's ``P_pp``, so ``T*`` already is the
  posterior mean of the pose; the velocity follows by Gaussian conditioning,
  ``v ← v + P_vp P_pp⁻¹ log(T_pred⁻¹ T*)``, and ``P ← P − P_{:,p} G P_{p,:}`` with
  ``G = H (P_pp H + I)⁻¹`` (well defined when ``H`` is singular: a direction the scan did not
  see leaves both the pose and the velocity to the model).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from relnav.geometry.eigen import block, inverse, matmul, matmul_t, matmul_tn, symmetrize
from relnav.geometry.lie import adjoint_nb, exp_se3, exp_se3_nb, invert_nb, log_se3, log_se3_nb
from relnav.geometry.se3 import invert

__all__ = ["ConstantVelocityFilter"]

_NO_CLONE = np.zeros((12, 6))


@njit(cache=True)
def _predict_nb(
    pose: np.ndarray,
    velocity: np.ndarray,
    P: np.ndarray,
    dt: float,
    sa2: np.ndarray,
    jitter_var: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    """:meth:`ConstantVelocityFilter.predict`'s arithmetic: the predicted pose, its state
    covariance (12×12, symmetrised, attitude jitter added), ``F``, ``F P[:, :6]`` and the
    model's mean rotation variance before the jitter."""
    step = exp_se3_nb(velocity * dt)
    A = adjoint_nb(invert_nb(step))
    F = np.eye(12)
    for i in range(6):
        for j in range(6):
            F[i, j] = A[i, j]
        F[i, 6 + i] = dt
    FP = matmul(F, P)
    Pn = matmul_t(FP, F)
    for i in range(6):
        Pn[6 + i, 6 + i] += sa2[i]
        Pn[i, i] += sa2[i] * dt * dt / 3.0
    model_rr = (Pn[3, 3] + Pn[4, 4] + Pn[5, 5]) / 3.0
    for i in range(3, 6):
        Pn[i, i] += jitter_var
    return matmul(pose, step), symmetrize(Pn), F, block(FP, 0, 12, 0, 6), model_rr


@njit(cache=True)
def _step_covariance_nb(
    pose_prev: np.ndarray, T_new: np.ndarray, P_new: np.ndarray, P_clone: np.ndarray, C: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    """Covariance (6×6) of the step ``T_prev⁻¹ T_new`` (see
    :meth:`ConstantVelocityFilter._set_step_covariance`)."""
    A = adjoint_nb(invert_nb(matmul(invert_nb(pose_prev), T_new)))
    X = matmul_t(block(C, 0, 6, 0, 6), A)
    S = matmul_t(matmul(A, P_clone), A)
    for i in range(6):
        for j in range(6):
            S[i, j] += P_new[i, j] - X[i, j] - X[j, i]
    return symmetrize(S)


@njit(cache=True)
def _update_nb(
    T_pred: np.ndarray,
    P: np.ndarray,
    T_star: np.ndarray,
    H_left: np.ndarray,
    T0: np.ndarray,
    jitter: bool,
    velocity: np.ndarray,
    pose_prev: np.ndarray,
    P_clone: np.ndarray,
    C: np.ndarray,
    clone: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    """:meth:`ConstantVelocityFilter.update`'s arithmetic: the new velocity, the state
    covariance, the step's covariance (zeros without ``clone``), the rotation innovation
    against ``T0`` and the scan's mean rotation variance (both for the jitter, when
    ``jitter``; ``inf`` for a singular ``H``). A singular ``P_pp`` leaves the velocity and the
    covariance to the model, a singular ``P_pp H + I`` the covariance."""
    Ad = adjoint_nb(T_star)
    H = matmul(matmul_tn(Ad, H_left), Ad)
    Ppp = block(P, 0, 6, 0, 6)
    y = log_se3_nb(matmul(invert_nb(T_pred), T_star))
    scan_rr = np.inf
    y_r = np.zeros(3)
    if jitter:
        Hi, ok = inverse(H)
        if ok:
            scan_rr = (Hi[3, 3] + Hi[4, 4] + Hi[5, 5]) / 3.0
        y_r = log_se3_nb(matmul(invert_nb(T0), T_star))[3:]
    v = velocity.copy()
    G = np.zeros((6, 6))
    Pi, ok = inverse(Ppp)
    if ok:
        K = matmul(block(P, 6, 12, 0, 6), Pi)
        for i in range(6):
            for j in range(6):
                v[i] += K[i, j] * y[j]
        M = matmul(Ppp, H)
        for i in range(6):
            M[i, i] += 1.0
        Mi, ok = inverse(M)
        if ok:
            G = matmul(H, Mi)
    Pc = block(P, 0, 12, 0, 6)
    PcG = matmul(Pc, G)
    P_post = P - matmul(PcG, block(P, 0, 6, 0, 12))
    S = np.zeros((6, 6))
    if clone:
        C_post = C - matmul(PcG, block(C, 0, 6, 0, 6))
        S = _step_covariance_nb(pose_prev, T_star, P_post, P_clone, C_post)
    return v, symmetrize(P_post), S, y_r, scan_rr


class ConstantVelocityFilter:
    """Error-state Kalman filter of pose and body-frame velocity (see the module doc).

    Parameters
    ----------
    pose : (4, 4) float64
        Initial ``T_target_sensor``.
    t0 : float
        Its time, s.
    sigma_v0 : (6,) float64
        1σ of the unknown initial velocity, ``[m/s ×3, rad/s ×3]``.
    sigma_acc : (6,) float64
        White-acceleration 1σ: change of the velocity per step, ``[m/s ×3, rad/s ×3]``.
    jitter_max : float
        Largest learned attitude-jitter variance, rad² per axis per step (:meth:`adapt_jitter`;
        learning is off until ``jitter_rate`` is set above 0).
    jitter_scan_margin : float
        How many times the scan's own rotation variance a correction must exceed to count as
        jitter.
    """

    def __init__(
        self,
        pose: np.ndarray,
        t0: float,
        sigma_v0: np.ndarray,
        sigma_acc: np.ndarray,
        jitter_max: float = 0.0,
        jitter_scan_margin: float = 9.0,
    ) -> None:
        self.pose = np.array(pose, dtype=np.float64)
        self.t = float(t0)
        self.velocity = np.zeros(6)
        self.P = np.zeros((12, 12))
        self.P[:6, :6] = np.eye(6) * 1e-12
        self.P[6:, 6:] = np.diag(np.asarray(sigma_v0, dtype=float) ** 2)
        self.sigma_acc = np.asarray(sigma_acc, dtype=float)
        self._pred: tuple[np.ndarray, np.ndarray, float] | None = None
        self.q_scale = 1.0
        self.nis_ema: float | None = None
        self.lag = 0
        self._hist: list[dict[str, np.ndarray]] = []
        self.smoothed: list[np.ndarray] = []
        self._F: np.ndarray | None = None
        self._clone: tuple[np.ndarray, np.ndarray] | None = None
        self._raw_pred: tuple[np.ndarray, np.ndarray] | None = None
        self.jitter_var = 0.0
        self.jitter_rate = 0.0
        self.jitter_max = float(jitter_max)
        self.jitter_scan_margin = float(jitter_scan_margin)
        self._model_rr = 0.0
        self.step_covariance: np.ndarray | None = None

    def adapt(self, chi2: float, dof: int = 6, rate: float = 0.1, max_scale: float = 100.0) -> None:
        """Scale the process noise by the recent normalised innovation (``χ²/dof``, EMA).

        **[interpretation]** covariance matching: an over-confident model (corrections larger
        than it predicts) gets a larger ``Q``, never below the nominal one.
        """
        r = float(chi2) / dof
        self.nis_ema = r if self.nis_ema is None else (1 - rate) * self.nis_ema + rate * r
        self.q_scale = float(np.clip(self.nis_ema, 1.0, max_scale))

    def adapt_jitter(self, innovation_r: np.ndarray, scan_rr: float = 0.0) -> None:
        """Learn the white attitude noise of the pose (rad² per axis per step) from the
        rotation part of an innovation (body frame, rad).

        **[interpretation]** A chaser's attitude jitters (limit cycles, thruster firings):
        white rotation noise of the pose that the constant-velocity model would otherwise
        read as changes of the rotation rate. Its variance is the EMA (rate
        ``jitter_rate``) of the innovation's per-axis square in excess of the model's own
        predicted rotation variance and ``jitter_scan_margin`` times the scan's own
        (``scan_rr``, rad² per axis: a registration's information under-states its error, so
        only corrections far beyond it are taken for jitter), at most ``jitter_max``; it is
        added to the predicted pose's rotation block only, so the velocity does not absorb
        it. Off at ``jitter_rate = 0``; the navigator turns it on from the map's
        ``prior.jitter_after_frames``-th frame (**[interpretation]**, 3 since session 31, 10
        before: the first corrections are also the velocity being learned, which a symmetric
        target's first frames can take for jitter; docs/navigator.md, session 31).
        """
        if self.jitter_rate <= 0:
            return
        y = np.asarray(innovation_r, dtype=float)
        floor = self._model_rr + self.jitter_scan_margin * max(scan_rr, 0.0)
        excess = max(float(y @ y) / 3.0 - floor, 0.0)
        a = self.jitter_rate
        self.jitter_var = min((1 - a) * self.jitter_var + a * excess, self.jitter_max)

    def predict(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Predicted pose and its body-frame covariance ``P_pp`` (6×6) at time ``t``."""
        dt = float(t) - self.t
        if not np.isfinite(dt) or dt <= 0:
            dt = 1e-9
        sa2 = self.q_scale * self.sigma_acc**2
        T_pred, P, F, C, self._model_rr = _predict_nb(
            self.pose, self.velocity, self.P, dt, sa2, float(self.jitter_var)
        )
        # stochastic clone of the previous pose error: its covariance and its cross-covariance
        # with the predicted state, for the covariance of the step (see step_covariance)
        self._clone = (self.P[:6, :6].copy(), C)
        self._v_pred = self.velocity.copy()
        self._pred = (T_pred, P, float(t))
        self._raw_pred = None
        self._F = F
        return T_pred.copy(), P[:6, :6].copy()

    def observe_rotation(
        self, R_meas: np.ndarray, noise: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Update the prediction with a measurement ``R_meas`` (3×3) of the predicted pose's
        rotation, noise covariance ``noise`` (3×3, rad², body frame): an EKF update of the whole
        error state (``y = log(R_predᵀ R_meas)`` observes ``δp``'s rotation part). Returns the
        updated ``(T_pred, P_pp)``. The smoother keeps the model's own prediction (its
        backward pass needs only the filtered states and the model's predictions)."""
        from relnav.geometry.rotations import matrix_to_rotvec

        assert self._pred is not None, "predict() first"
        T_pred, P, t = self._pred
        y = np.asarray(matrix_to_rotvec(T_pred[:3, :3].T @ R_meas), dtype=float).reshape(3)
        S = P[3:6, 3:6] + np.asarray(noise, dtype=float)
        try:
            K = np.linalg.solve(S, P[3:6, :]).T  # (12, 3) = P Hᵀ S⁻¹
        except np.linalg.LinAlgError:
            return T_pred.copy(), P[:6, :6].copy()
        dx = K @ y
        T_new = T_pred @ exp_se3(dx[:6])
        P_new = P - K @ P[3:6, :]
        self.velocity = self.velocity + dx[6:]
        if self._clone is not None:  # the previous pose's cross-covariance with the state
            Pc, C = self._clone
            self._clone = (Pc, C - K @ C[3:6, :])
        self._raw_pred = self._raw_pred or (T_pred, P)
        self._pred = (T_new, 0.5 * (P_new + P_new.T), t)
        return T_new.copy(), self._pred[1][:6, :6].copy()

    def reset(
        self,
        pose: np.ndarray | None = None,
        velocity: np.ndarray | None = None,
        *,
        velocity_covariance: np.ndarray | None = None,
        widen: np.ndarray | None = None,
        widen_velocity: np.ndarray | None = None,
        smooth_lag: int | None = None,
    ) -> None:
        """Set the filter's state from evidence outside its own updates (the start-up window's
        correction, a relocalisation, the second pass over the first frames), in this order:

        Parameters
        ----------
        pose : (4, 4) float64, optional
            The new pose ``T_target_sensor``.
        velocity : (6,) float64, optional
            The new body velocity ``[m/s ×3, rad/s ×3]``.
        velocity_covariance : (6, 6) float64, optional
            The new velocity covariance (per second²).
        widen, widen_velocity : (6,) float64, optional
            1σ added to the predicted pose and velocity (:meth:`widen`; after :meth:`predict`).
        smooth_lag : int, optional
            Restart the fixed-lag smoother from here with this lag (:meth:`start_smoothing`).
        """
        if pose is not None:
            self.pose = np.array(pose, dtype=np.float64)
        if velocity is not None:
            self.velocity = np.array(velocity, dtype=np.float64)
        if velocity_covariance is not None:
            self.P[6:, 6:] = velocity_covariance
        if widen is not None:
            self.widen(widen, sigma_velocity=widen_velocity)
        if smooth_lag is not None:
            self.start_smoothing(smooth_lag)

    def per_second(self, dt: float) -> None:
        """Turn the velocity's covariance and the white acceleration set up per frame period
        into per second, with the first frame period ``dt`` (s)."""
        self.P[6:, 6:] /= dt**2
        self.sigma_acc = self.sigma_acc / dt

    def widen(self, sigma_pose: np.ndarray, sigma_velocity: np.ndarray | None = None) -> None:
        """Add ``sigma_pose²`` (body frame, 6) to the predicted pose covariance, and
        ``sigma_velocity²`` (6, per second; default ``sigma_pose`` per frame period) to the
        velocity's: the model was found wrong, trust the next scans."""
        assert self._pred is not None, "predict() first"
        T_pred, P, t = self._pred
        dt = max(t - self.t, 1e-9)
        P = P.copy()
        P[:6, :6] += np.diag(np.asarray(sigma_pose, dtype=float) ** 2)
        sv = np.asarray(sigma_pose, dtype=float) / dt if sigma_velocity is None else sigma_velocity
        P[6:, 6:] += np.diag(np.asarray(sv, dtype=float) ** 2)
        self._pred = (T_pred, P, t)

    def update(self, T_star: np.ndarray, H_left: np.ndarray) -> None:
        """Accept the registered pose ``T*`` with the scan's information ``H`` (left, target)."""
        assert self._pred is not None, "predict() first"
        T_pred, P, t = self._pred
        T_star = np.ascontiguousarray(T_star, dtype=np.float64)
        T0 = self._raw_pred[0] if self._raw_pred else T_pred
        # the previous pose's estimate is not revised here (no smoothing): its error keeps the
        # clone's covariance Pc; only its correlation with the new state changes
        Pc, C = self._clone if self._clone is not None else (_NO_CLONE[:6], _NO_CLONE)
        self.velocity, self.P, S, y_r, scan_rr = _update_nb(
            T_pred,
            P,
            T_star,
            np.ascontiguousarray(H_left, dtype=np.float64),
            T0,
            self.jitter_rate > 0,
            self.velocity,
            self.pose,
            Pc,
            C,
            self._clone is not None,
        )
        if self._clone is not None:
            self.step_covariance = S
        if self.jitter_rate > 0:
            self.adapt_jitter(y_r, scan_rr)
        self.pose = T_star.copy()
        self.t = t
        self._record(*(self._raw_pred or (T_pred, P)))
        self._pred = None

    def skip(self) -> None:
        """No usable measurement: keep the prediction (pose and grown covariance)."""
        assert self._pred is not None, "predict() first"
        T_pred, P, t = self._pred
        if self._clone is not None:
            self._set_step_covariance(T_pred, P, *self._clone)
        self.pose, self.P, self.t = T_pred, P, t
        self._record(*(self._raw_pred or (T_pred, P)))
        self._pred = None

    def _set_step_covariance(
        self, T_new: np.ndarray, P_new: np.ndarray, P_clone: np.ndarray, C: np.ndarray
    ) -> None:
        """Covariance of the step ``S = T_prev⁻¹ T_new`` (body frame of ``T_new``, 6×6).

        With right perturbations ``T = T̂ exp(δ)``, the step's error is
        ``e = δ_new − Ad(S⁻¹) δ_prev``; ``C`` is ``Cov(state_new, δ_prev)`` (12×6).
        """
        self.step_covariance = _step_covariance_nb(
            self.pose, np.ascontiguousarray(T_new), P_new, P_clone, np.ascontiguousarray(C)
        )

    # ------------------------------------------------------------------ fixed-lag smoothing
    def start_smoothing(self, lag: int) -> None:
        """Smooth every frame with at least ``lag`` later frames (Rauch–Tung–Striebel on the
        error state, run over windows of ``2·lag`` frames every ``lag`` frames) from the current
        frame on (a restart forgets what was smoothed before); ``lag=0`` turns smoothing off."""
        self.lag = int(lag)
        self.smoothed = []
        self._hist = [{"T": self.pose.copy(), "v": self.velocity.copy(), "P": self.P.copy()}]

    def _record(self, T_pred: np.ndarray, P_pred: np.ndarray) -> None:
        if self.lag <= 0:
            return
        self._hist.append(
            {
                "T": self.pose.copy(),
                "v": self.velocity.copy(),
                "P": self.P.copy(),
                "T_pred": T_pred,
                "v_pred": self._v_pred,
                "P_pred": P_pred,
                "F": self._F,
            }
        )
        if len(self._hist) > 2 * self.lag + 1:  # emit the oldest lag frames (amortised cost)
            self.smoothed.extend(self._smooth_window()[: self.lag])
            del self._hist[: self.lag]

    def _smooth_window(self) -> list[np.ndarray]:
        """RTS backward pass over the window; smoothed poses, oldest first."""
        h = self._hist
        Ts, vs, Ps = h[-1]["T"], h[-1]["v"], h[-1]["P"]
        out = [Ts]
        for k in range(len(h) - 2, -1, -1):
            nxt = h[k + 1]
            try:
                C = h[k]["P"] @ nxt["F"].T @ np.linalg.inv(nxt["P_pred"])
            except np.linalg.LinAlgError:
                C = np.zeros((12, 12))
            d = np.concatenate([log_se3(invert(nxt["T_pred"]) @ Ts), vs - nxt["v_pred"]])
            corr = C @ d
            Ts = h[k]["T"] @ exp_se3(corr[:6])
            vs = h[k]["v"] + corr[6:]
            Ps = h[k]["P"] + C @ (Ps - nxt["P_pred"]) @ C.T
            out.append(Ts)
        return out[::-1]

    def finish_smoothing(self) -> list[np.ndarray]:
        """Smoothed poses of every frame still in the window; returns all smoothed poses."""
        if self.lag > 0 and self._hist:
            self.smoothed.extend(self._smooth_window())
            self._hist = []
        return self.smoothed
