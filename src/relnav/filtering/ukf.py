"""Twist (Cayley) dual-quaternion unscented Kalman filter (Paper 2 §2.4, Algorithm 1).

What is estimated (ALGORITHMS.md §G.6)
-------------------------------------
The motion of the target relative to the sensor, all in the **sensor frame** ``s`` (x forward,
y left, z up) unless stated:

* ``d`` (m): the target's reference point (centroid) in ``s``; ``ḋ`` (m/s) its velocity;
* ``q`` (xyzw): attitude of the target body frame ``b`` in ``s`` (``R_s_b``), kept together with
  ``d`` as the unit pose dual quaternion ``q̂ = q + ε ½ d ⊗ q`` (``T_s_b``);
* ``ω`` (rad/s): body angular rate in ``b`` (``q̇ = ½ q ⊗ [ω, 0]``), constant between frames.

Translation follows Clohessy–Wiltshire (:mod:`relnav.filtering.dynamics`; ``n = 0`` is a
force-free double integrator), attitude the body rates (eq. 31, right multiplication).

Error state (``L = 15``): ``[δd (3), δḋ (3), B (6), δω (3)]`` with ``B = cayley(q̂⁻¹ ⊗ q̂_true)``
(:mod:`relnav.geometry.dualquat`). ``B_r = tan(φ/4) u`` ≈ ``δθ/4``.

Interpretations (Paper 2 is garbled or silent; each is named here)
-----------------------------------------------------------------
* **[interpretation] pose rebuild**: after propagation the dual part of every sigma point's pose
  is rebuilt from its own ``(q, d)`` (eqs. 35–37 are garbled), so ``d`` is the master copy of the
  translation. The dual half ``B_d`` of the twist is carried in the 15-dim error state as the
  paper specifies but is therefore re-derived from ``δd`` at each prediction (it is redundant
  with ``δd``); only ``B_r`` carries attitude information. :meth:`PoseFilter.nees` and
  :meth:`PoseFilter.physical_covariance` use the 12 non-redundant components.
* **[interpretation] sigma points** (eq. 32): ``λ = α²(L + κ) − L``, ``χ₀ = 0``,
  ``χ_i = ±col_i(sqrt((L + λ) P))`` (Cholesky of the symmetrized ``P``, jitter on failure);
  ``W0_m = λ/(L+λ)``, ``W0_c = W0_m + 1 − α² + β``, ``W_i = 1/(2(L+λ))``. Defaults ``α = 1``,
  ``β = 2``, ``κ = 3 − L`` (Julier's rule; ALGORITHMS.md writes "λ = 3", it is ``L + λ = 3``,
  so ``λ = −12`` and ``W0_m = −4``). ``kappa=0`` gives non-negative weights.
* **[interpretation] mean of poses**: iterative Cayley mean (``|B̄| < 1e-10``, ≤ 10 iterations)
  of the sigma-point poses, weights ``W_m``.
* **[interpretation] measurement**: ``z = [D (3), Q]`` — the observed centroid and attitude
  (eq. 41 combines them into a pose dual quaternion). ``innovation="position+rotation"``
  (default): ``[D − d, B_r(q̂_pred⁻¹ ⊗ Q)]`` (6 numbers). ``innovation="twist"``: the full
  ``B(q̂_pred⁻¹ ⊗ q̂_meas)`` (6 numbers; position enters through the dual half).
* **[interpretation] update sigma points**: ``update_sigma="redraw"`` (default) draws fresh sigma
  points from the predicted mean and covariance (so process noise enters ``P_xz``);
  ``"propagated"`` reuses the predicted sigma points as Algorithm 1 does literally.
* Gain with the weights (Paper 2 Step 5 omits ``W_i``): ``P_xz = Σ W_c δX δZᵀ``,
  ``K = P_xz P_zz⁻¹``; injection ``q̂ ← q̂ ⊗ cayley⁻¹(δB)``, others additive.
  ``covariance_update="standard"`` (``P⁻ − K P_zz Kᵀ``, Step 6) or ``"joseph"`` (with the
  statistical linearization ``H = P_xzᵀ P⁻⁻¹``).
* **[interpretation] noise** (Paper 2 gives none): 1σ per *nominal step* ``dt``; the process
  variance is scaled by ``Δt/dt`` for other steps. Defaults :class:`ProcessNoise`,
  :class:`MeasurementNoise`, :class:`InitialUncertainty` (= ``P₀ = 1e-2 I`` in error
  coordinates).

The noise settings live in :mod:`relnav.filtering.noise`, the base class shared with the EKF in
:mod:`relnav.filtering.pose_filter` (both re-exported here).

References
----------
Li, Zhuang, Peng, Zhao, *Pose estimation of non-cooperative space targets based on cross-source
point cloud fusion*, Remote Sens. 13, 4239 (2021), doi:10.3390/rs13214239.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.filtering.dynamics import TranslationModel
from relnav.filtering.noise import InitialUncertainty, MeasurementNoise, ProcessNoise
from relnav.filtering.pose_filter import (
    PAPER2_RATE_HZ,
    PoseFilter,
    UpdateInfo,
    _sqrt_psd,
    _sym,
    canon_q,
    quat_delta,
)
from relnav.geometry.dualquat import (
    cayley,
    dq_conjugate,
    dq_from_rt,
    dq_multiply,
    qmul,
    quat_cayley,
    quat_cayley_inverse,
    quat_cayley_mean,
)
from relnav.geometry.rotations import quat_to_matrix

__all__ = [
    "InitialUncertainty",
    "MeasurementNoise",
    "PoseFilter",
    "ProcessNoise",
    "TwistorUKF",
    "UpdateInfo",
    "euler_rates",
    "quat_delta",
    "torque_free_acceleration",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# twistor UKF
# --------------------------------------------------------------------------------------------

# merge states (TwistorUKF(merge_slots=…)): variance of an unused slot (m², rad²), numerical
# floor of the otherwise exact measurement of a merged frame, share that counts as a use
_IDLE_VAR = 1e-12
_EXACT_VAR = 1e-12
_USED_SHARE = 0.02


def _correlation_times(value: Any) -> tuple[float, float] | None:
    """``bias_correlation_time`` as ``(τ_p, τ_θ)`` s, or None for a random walk."""
    if value is None:
        return None
    taus = np.broadcast_to(np.asarray(value, dtype=np.float64), (2,))
    if not np.all(taus > 0.0):
        raise ConfigError(f"bias_correlation_time must be > 0 s (or inf), got {value!r}")
    if np.all(np.isinf(taus)):
        return None
    return float(taus[0]), float(taus[1])


Innovation = Literal["position+rotation", "twist"]
CovUpdate = Literal["standard", "joseph"]
UpdateSigma = Literal["redraw", "propagated"]


def _inertia_tensor(value: Any) -> np.ndarray:
    """A (3, 3) symmetric positive definite inertia scaled to ``det = 1``, or ConfigError."""
    try:
        J = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        J = np.full(1, np.nan)
    if J.shape != (3, 3) or not np.all(np.isfinite(J)) or not np.allclose(J, J.T):
        raise ConfigError(f"inertia must be a finite symmetric (3, 3) matrix, got {value!r}")
    lam = np.linalg.eigvalsh(J)
    if not lam.min() > 0.0:
        raise ConfigError(f"inertia must be positive definite, eigenvalues {lam}")
    return J / float(np.prod(lam)) ** (1.0 / 3.0)


def torque_free_acceleration(
    w: np.ndarray, J: np.ndarray, J_inv: np.ndarray | None = None
) -> np.ndarray:
    """Euler's torque-free angular acceleration ``ω̇ = J⁻¹((Jω) × ω)`` ``(n, 3)`` rad/s² of
    body rates ``w`` ``(n, 3)`` rad/s, inertia ``J`` ``(3, 3)`` symmetric (any scale), or one
    inertia per rate ``(n, 3, 3)`` (then ``J_inv``, their inverses, when already known)."""
    J = np.asarray(J, dtype=np.float64)
    if J.ndim == 2:
        return np.linalg.solve(J, np.cross(w @ J, w).T).T
    c = np.cross(np.einsum("nij,nj->ni", J, w), w)
    if J_inv is None:
        return np.linalg.solve(J, c[:, :, None])[:, :, 0]
    return np.einsum("nij,nj->ni", J_inv, c)


def euler_rates(w: np.ndarray, J: np.ndarray, dt: float, max_step: float = 1.0) -> np.ndarray:
    """Body rates ``(n, 3)`` rad/s after ``dt`` s of torque-free motion from ``w`` ``(n, 3)``
    (:func:`torque_free_acceleration`, inertia ``J`` ``(3, 3)`` or ``(n, 3, 3)``; classical
    Runge–Kutta, steps of at most ``max_step`` s)."""
    J = np.asarray(J, dtype=np.float64)
    J_inv = np.linalg.inv(J) if J.ndim == 3 else None  # one inverse for the four stages

    def rate(x: np.ndarray) -> np.ndarray:
        return torque_free_acceleration(x, J, J_inv)

    dt = max(float(dt), 0.0)
    n = max(1, math.ceil(dt / max_step))
    h = dt / n
    x = np.array(w, dtype=np.float64)
    for _ in range(n):
        k1 = rate(x)
        k2 = rate(x + 0.5 * h * k1)
        k3 = rate(x + 0.5 * h * k2)
        k4 = rate(x + h * k3)
        x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


class TwistorUKF(PoseFilter):
    """Twist (Cayley) dual-quaternion UKF with Clohessy–Wiltshire translation (Paper 2).

    Parameters
    ----------
    n_mean_motion : float
        CW mean motion, rad/s (0 = Paper 2 lab set-up, force-free).
    dt : float
        Nominal step, s (default ``1/0.22``, Paper 2 Table 3); the process noise is per step.
    q : ProcessNoise or dict, optional
        Process noise (default :class:`ProcessNoise`).
    r : MeasurementNoise, dict or (6, 6) array_like, optional
        Measurement noise of ``[position (m), attitude (rad)]`` (default
        :class:`MeasurementNoise`).
    alpha, beta, kappa : float
        Sigma-point parameters; ``kappa=None`` → ``3 − L``.
    p0 : InitialUncertainty or dict, optional
        Initial 1σ (default = ``P₀ = 1e-2 I`` in error coordinates).
    position0, velocity0, quat0, omega0 : array_like, optional
        Initial state (default zeros / identity).
    translation_model : {"cw", "euler"}
        Exact CW transition or Paper 2 eq. 38's Euler step.
    lvlh_axes : str or (3, 3), optional
        Sensor → LVLH axes (:func:`relnav.filtering.dynamics.axis_permutation`).
    innovation : {"position+rotation", "twist"}
        Measurement coordinates (module docstring).
    update_sigma : {"redraw", "propagated"}
        Sigma points used by the update.
    covariance_update : {"standard", "joseph"}
    gate_probability : float, optional
        Reject measurements whose NIS exceeds the χ² quantile (default: no gate).
    gate_patience : int, optional
        With a gate: after this many observations in a row refused by it, the filter is taken
        to have diverged, its covariance is widened until the observation fits and the
        observation is used (default: never; a diverged filter then coasts for good).
    centre_offset : bool
        **[interpretation, not in Paper 2]** Estimate the constant body-frame offset ``c``
        (m) from the rotation centre to the observed reference point: the state's ``d`` is
        then the rotation centre (it moves by CW), the measured point is ``d + R_s_b c``
        (error state ``L = 18``, ``δc`` last). An observer whose reference point is the first
        frame's centroid sees it circle the spin axis, which CW + constant-ω dynamics alone
        cannot follow. The component of ``c`` along the spin axis is unobservable; a
        pseudo-measurement ``ω̂ · c = 0`` (1σ ``axis_sigma`` m, applied after each update while
        ``|ω| > 3σ_ω``) picks the point of the axis nearest the reference point.
    axis_sigma : float
        See ``centre_offset`` (m, default 1e-3; ``inf``: no pseudo-measurement, the offset
        along the axis then kept by its prior alone).
    observer_bias : bool
        **[interpretation, not in Paper 2]** Carry the observer's slowly varying error as a
        6-D random-walk bias ``β = [β_p (m), β_θ (rad)]`` (last in the error state): the
        measured point is ``d + R c + β_p`` and the measured attitude ``q ⊗ exp(β_θ)``. ``β``
        starts at zero (the observer's frame is anchored at its first observation) and grows
        by :meth:`add_observer_drift` — for the contour model, the covariance of each frame
        merged into the model, which the next registrations inherit. Without it a drifting
        observer's errors are treated as independent from frame to frame.
    bias_correlation_time : float or (float, float), optional
        **[interpretation, not in Paper 2]** Correlation times ``(τ_p, τ_θ)`` (s; one number
        for both) of a first-order Gauss–Markov observer bias instead of a random walk: over
        a step of ``Δt`` the bias and its covariance's rows and columns are multiplied by
        ``e^(−Δt/τ)``, while :meth:`add_observer_drift` still adds its growth. A stationary
        error of an observer that keeps re-registering against the same model (default None:
        random walk, ``τ = ∞``).
    bias_frame : {"sensor", "body"}
        Axes of the position bias ``β_p`` **[interpretation]**. ``"sensor"`` (default): the
        measured point is ``d + R c + β_p``. ``"body"``: ``d + R (c + β_p)`` — a bias fixed to
        the target, as the contour model's is (a frame merged with a registration error shifts
        the model in its own axes; a quarter turn later that shift is seen along another
        sensor axis). The drift's position block (given in sensor axes) is rotated into body
        axes with the current attitude estimate.
    merge_slots : int
        **[interpretation, not in Paper 2]** Model the error a model-building observer (the
        contour model) inherits through its merges, instead of a random-walk bias (0 = off;
        exclusive with ``observer_bias``). Each merged frame ``j`` wrote its pose error ``m_j``
        into the model as a body-fixed rigid error; a later registration inherits the errors of
        the model parts it matched. With an observation's ``sources`` ``{j: w_kj}``
        (:meth:`set_merge_sources`, shares of its matches per merged frame) its error is
        ``m_k = Σ_j w_kj m_j + v_k`` (``v_k`` ~ the observation's covariance, the one
        registration's own error), and ``m_k`` is kept as a state for later frames: the
        measured point is ``d + R (c + m_p)``, the measured attitude ``q ⊗ exp(m_θ)`` (body
        axes, ``[m_p (m), m_θ (rad)]``). ``merge_slots`` 6-D states are kept (error state
        ``L = 15|18 + 6 · merge_slots``); when they are full the slot matched least recently is
        dropped (its share of later errors is then treated as zero, as the anchor's).
        Observations without ``sources`` are plain updates; with ``sources`` but no frame id
        (not merged) their error is ``Σ_j w_kj m_j`` plus their covariance as measurement
        noise, and no state is kept. ``add_observer_drift`` is then a no-op.
        **[measured]** (docs/results/paper2/merge_states.md) on a simulated observer with that
        error structure (24 steps, 20 seeds) it is consistent (NEES 11.6, NIS 5.6; the
        random-walk bias 6.7 / 3.2, no model 155 / 8.5). On the paper-2 experiment
        (``paper2_experiment.py``, ``merge_slots=16``) the errors fall against the bias variant
        (seeds 0–19: spin-axis attitude RMS 3.17 → 1.53°, position y 31 → 23 mm) but NIS / NEES
        rise (14 / 49.7 → 38.9 / 203; seeds 20–39: 11.3 / 38.5 → 28.8 / 166): the contour
        model's one-registration error ``v_k`` is 4.6–11× its jackknife σ in position (per
        axis), and the bias variant's accumulated drift had covered part of that. Off by
        default.
    inertia : (3, 3) array_like, optional
        **[interpretation, not in Paper 2]** The target's inertia tensor in body axes (any
        scale; symmetric positive definite), when known: the prediction then turns the body
        rate by Euler's torque-free equations, ``ω̇ = J⁻¹ ((J ω) × ω)`` (:func:`euler_rates`),
        and the attitude by the mean of the step's first and last rates; the process noise's
        angular acceleration is what they leave out. Default None: a constant body rate. For
        a sensor holding an inertial attitude (the body rate is then the inertial one).
    robust_dof : float, optional
        **[interpretation, not in Paper 2]** A Student-t measurement with ``robust_dof``
        degrees of freedom instead of a Gaussian (default None: Gaussian): before each update
        the measurement covariance is multiplied by ``s ≥ 1`` (:meth:`_student_scale`), so a
        one-off registration error far outside its covariance moves the state less. Measured
        on envisat-tumble-64 (20 noise seeds, ``relnav.navigation.state.relative_state``,
        after the first 30 % of the frames), dof 5: rate error median/p95/max 0.027/0.069/
        0.172 → 0.028/0.072/0.180 deg/s, 12-dim NEES 5.2 → 5.4, RMS attitude 3.54 → 3.76°;
        with ``drift="map"`` 0.028/0.069/0.172 → 0.028/0.071/0.168, 5.9 → 5.7. No gain: the
        worst rate errors come from views (steps 116–117) whose scans already report a weak
        axis (rotation σ 0.5° about y), so their errors are not outliers of the covariance.

    Examples
    --------
    >>> ukf = TwistorUKF(dt=4.5, omega0=[0, 0, np.radians(5)])
    >>> ukf.predict()
    >>> info = ukf.update([3.0, 0.0, 0.0], [0.0, 0.0, 0.19509, 0.98079])
    >>> ukf.covariance.shape
    (15, 15)
    """

    name = "ukf"
    dim = 15

    def __init__(
        self,
        n_mean_motion: float = 0.0,
        dt: float = 1.0 / PAPER2_RATE_HZ,
        q: ProcessNoise | Mapping[str, float] | None = None,
        r: MeasurementNoise | Mapping[str, float] | np.ndarray | None = None,
        alpha: float = 1.0,
        beta: float = 2.0,
        kappa: float | None = None,
        *,
        p0: InitialUncertainty | Mapping[str, float] | None = None,
        position0: Any = None,
        velocity0: Any = None,
        quat0: Any = None,
        omega0: Any = None,
        translation_model: TranslationModel = "cw",
        lvlh_axes: str | np.ndarray | None = None,
        innovation: Innovation = "position+rotation",
        update_sigma: UpdateSigma = "redraw",
        covariance_update: CovUpdate = "standard",
        gate_probability: float | None = None,
        gate_patience: int | None = None,
        centre_offset: bool = False,
        axis_sigma: float = 1e-3,
        observer_bias: bool = False,
        bias_correlation_time: float | tuple[float, float] | None = None,
        bias_frame: Literal["sensor", "body"] = "sensor",
        merge_slots: int = 0,
        inertia: Any = None,
        robust_dof: float | None = None,
    ) -> None:
        if robust_dof is not None and not (
            math.isfinite(float(robust_dof)) and float(robust_dof) > 0.0
        ):
            raise ConfigError(f"robust_dof must be > 0 or None, got {robust_dof!r}")
        self.robust_dof = None if robust_dof is None else float(robust_dof)
        self.inertia = None if inertia is None else _inertia_tensor(inertia)
        self.centre_offset = bool(centre_offset)
        self.observer_bias = bool(observer_bias)
        self.bias_correlation_time = _correlation_times(bias_correlation_time)
        if bias_frame not in ("sensor", "body"):
            raise ConfigError(f"bias_frame must be 'sensor' or 'body', got {bias_frame!r}")
        self.bias_frame = bias_frame
        self._ib = 18 if self.centre_offset else 15
        if int(merge_slots) != merge_slots or int(merge_slots) < 0:
            raise ConfigError(f"merge_slots must be an integer >= 0, got {merge_slots!r}")
        self.merge_slots = int(merge_slots)
        if self.merge_slots and self.observer_bias:
            raise ConfigError("merge_slots and observer_bias are alternatives; choose one")
        self.dim = self._ib + (6 if self.observer_bias else 0) + 6 * self.merge_slots
        self._b = np.zeros(6)
        self._m = np.zeros((self.merge_slots, 6))
        self._slot_frame: list[int | None] = [None] * self.merge_slots
        self._slot_used = np.zeros(self.merge_slots)
        self._pending: tuple[int | None, dict[int, float]] | None = None
        self._n_merges = 0
        if not float(axis_sigma) > 0.0:
            raise ConfigError(f"axis_sigma must be > 0 m, got {axis_sigma!r}")
        self.axis_sigma = float(axis_sigma)
        self._c = np.zeros(3)
        L = self.dim
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.kappa = float(3 - L if kappa is None else kappa)
        if not (math.isfinite(self.alpha) and self.alpha > 0.0 and math.isfinite(self.beta)):
            raise ConfigError(f"alpha must be > 0 and beta finite, got {alpha!r}, {beta!r}")
        self.lam = self.alpha**2 * (L + self.kappa) - L
        if not (math.isfinite(self.lam) and L + self.lam > 0.0):
            raise ConfigError(
                f"sigma-point spread L + λ = α²(L + κ) must be > 0, got {L + self.lam!r} "
                f"(alpha={alpha}, kappa={kappa})"
            )
        c = L + self.lam
        self.Wm = np.full(2 * L + 1, 0.5 / c)
        self.Wc = self.Wm.copy()
        self.Wm[0] = self.lam / c
        self.Wc[0] = self.lam / c + (1.0 - self.alpha**2 + self.beta)
        if innovation not in ("position+rotation", "twist"):
            raise ConfigError(
                f"innovation must be 'position+rotation' or 'twist', got {innovation!r}"
            )
        if update_sigma not in ("redraw", "propagated"):
            raise ConfigError(
                f"update_sigma must be 'redraw' or 'propagated', got {update_sigma!r}"
            )
        if covariance_update not in ("standard", "joseph"):
            raise ConfigError(
                f"covariance_update must be 'standard' or 'joseph', got {covariance_update!r}"
            )
        self.innovation: Innovation = innovation
        self.update_sigma: UpdateSigma = update_sigma
        self.covariance_update: CovUpdate = covariance_update
        self._prop: dict[str, np.ndarray] | None = None
        self.mean_iterations = 0
        super().__init__(
            n_mean_motion,
            dt,
            q,
            r,
            p0=p0,
            position0=position0,
            velocity0=velocity0,
            quat0=quat0,
            omega0=omega0,
            translation_model=translation_model,
            lvlh_axes=lvlh_axes,
            gate_probability=gate_probability,
            gate_patience=gate_patience,
        )

    # --- coordinates --------------------------------------------------------------------------

    def _on_reset(self) -> None:
        self._prop = None
        self._c = np.zeros(3)
        self._b = np.zeros(6)
        if self.centre_offset:
            self._P[15:18, 15:18] = np.eye(3) * self.p0.offset**2
        if self.observer_bias:
            ib = self._ib
            self._P[ib : ib + 6, ib : ib + 6] = np.diag([1e-8] * 3 + [1e-10] * 3)
        if self.merge_slots:
            self._m = np.zeros((self.merge_slots, 6))
            self._slot_frame = [None] * self.merge_slots
            self._slot_used = np.zeros(self.merge_slots)
            self._pending = None
            self._n_merges = 0
            ib = self._ib
            self._P[ib:, :] = 0.0
            self._P[:, ib:] = 0.0
            self._P[ib:, ib:] = np.eye(self.dim - ib) * _IDLE_VAR

    def set_merge_sources(self, frame: int | None, sources: Mapping[int, float]) -> None:
        """Declare where the next update's observation came from (``merge_slots`` > 0; else
        a no-op).

        Parameters
        ----------
        frame : int or None
            The observer's id of the observation's frame (merged into its model); ``None``:
            not merged (its error is not kept for later frames).
        sources : dict of int to float
            ``{frame id: share}`` of the observation's model matches per earlier merged frame.
            Empty: the anchor frame (defines the body frame, no error).
        """
        if not self.merge_slots:
            return
        self._pending = (
            None if frame is None else int(frame),
            {int(j): float(w) for j, w in sources.items()},
        )

    @property
    def merge_errors(self) -> dict[int, np.ndarray]:
        """Current estimates of the kept merge errors ``{frame id: [m_p (m), m_θ (rad)]}``
        (body axes; empty without ``merge_slots``)."""
        return {f: self._m[i].copy() for i, f in enumerate(self._slot_frame) if f is not None}

    def _slot_rows(self, i: int) -> slice:
        a = self._ib + 6 * i
        return slice(a, a + 6)

    def _open_merge(self, frame: int | None, sources: dict[int, float], R: np.ndarray) -> int:
        """Put ``m_k = Σ_j w_j m_j + v`` (``v`` ~ ``R`` moved to body axes) into a slot and
        return it (state and covariance updated in place)."""
        slot_of = {f: i for i, f in enumerate(self._slot_frame) if f is not None}
        free = [i for i, f in enumerate(self._slot_frame) if f is None]
        if free:
            s = free[0]
        else:  # the slot whose frame was matched least recently
            s = int(np.argmin(self._slot_used))
            log.debug("merge slot of frame %s dropped", self._slot_frame[s])
        A = np.eye(self.dim)
        rows = self._slot_rows(s)
        A[rows, :] = 0.0
        mean = np.zeros(6)
        self._n_merges += 1
        for j, w in sources.items():
            i = slot_of.get(j)
            if i is None or w == 0.0:
                continue  # the anchor, or a frame no longer kept
            A[rows, self._slot_rows(i)] += w * np.eye(6)
            mean += w * self._m[i]
            if w >= _USED_SHARE:
                self._slot_used[i] = self._n_merges
        J = np.eye(6)
        J[0:3, 0:3] = quat_to_matrix(self._q).T
        P = A @ self._P @ A.T
        P[rows, rows] += _sym(J @ R @ J.T)
        self._P = _sym(P)
        self._m[s] = mean
        self._slot_frame[s] = frame
        self._slot_used[s] = self._n_merges
        self._prop = None
        return s

    def add_observer_drift(self, Q: np.ndarray) -> None:
        """Add ``Q`` ``(6, 6)`` (``[m, rad]``) to the observer bias's covariance (no-op without
        ``observer_bias``)."""
        if not self.observer_bias:
            return
        Q = np.asarray(Q, dtype=np.float64)
        if Q.shape != (6, 6) or not np.all(np.isfinite(Q)):
            raise InputError(f"observer drift must be a finite (6, 6) matrix, got {Q.shape}")
        if self.bias_frame == "body":
            J = np.eye(6)
            J[0:3, 0:3] = quat_to_matrix(self._q).T
            Q = J @ Q @ J.T
        ib = self._ib
        self._P[ib : ib + 6, ib : ib + 6] += _sym(Q)
        self._prop = None

    def add_offset_drift(self, Q: np.ndarray) -> None:
        """Add ``Q`` ``(3, 3)`` (m², sensor axes) to the covariance of the body-frame offset ``c``
        (rotated into body axes with the current attitude; no-op without ``centre_offset``): an
        observer whose reference point moves on the target while its model is being built."""
        if not self.centre_offset:
            return
        Q = np.asarray(Q, dtype=np.float64)
        if Q.shape != (3, 3) or not np.all(np.isfinite(Q)):
            raise InputError(f"offset drift must be a finite (3, 3) matrix, got {Q.shape}")
        R_bs = quat_to_matrix(self._q).T
        self._P[15:18, 15:18] += _sym(R_bs @ Q @ R_bs.T)
        self._prop = None

    def _decay_bias(self, P: np.ndarray, dt: float) -> np.ndarray:
        """Gauss–Markov observer bias over ``dt`` s: ``β ← φ β``, rows and columns of ``P``
        by ``φ = e^(−dt/τ)`` (``bias_correlation_time``)."""
        assert self.bias_correlation_time is not None
        tau = np.repeat(np.asarray(self.bias_correlation_time), 3)
        phi = np.exp(-max(float(dt), 0.0) / tau)
        self._b = phi * self._b
        D = np.ones(self.dim)
        D[self._ib : self._ib + 6] = phi
        return D[:, None] * P * D[None, :]

    @property
    def observer_bias_estimate(self) -> np.ndarray:
        """Current observer bias ``[β_p (m), β_θ (rad)]`` ``(6,)`` (zeros without it)."""
        return self._b.copy()

    @property
    def offset(self) -> np.ndarray:
        """Body-frame offset ``c`` from the rotation centre to the reference point ``(3,)``, m
        (zeros without ``centre_offset``)."""
        return self._c.copy()

    @property
    def reference_position(self) -> np.ndarray:
        """Observed reference point ``d + R_s_b c`` in the sensor frame ``(3,)``, m."""
        return self._d + quat_to_matrix(self._q) @ self._c

    def predicted_reference(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean reference point and attitude predicted ``dt`` s ahead (filter unchanged)."""
        d, q = super().predicted_reference(dt)
        return d + quat_to_matrix(q) @ self._c, q

    def _native_from_phys_var(self, phys_var: np.ndarray) -> np.ndarray:
        v = np.zeros(self.dim)
        v[0:6] = phys_var[0:6]
        v[6:9] = phys_var[6:9] / 16.0  # B_r ≈ δθ/4
        v[9:12] = phys_var[0:3] / 16.0  # B_d ≈ R_bsᵀ δd/4 (redundant with δd)
        v[12:15] = phys_var[9:12]
        return np.diag(v)

    def _phys_jacobian(self) -> np.ndarray:
        J = np.zeros((12, self.dim))
        J[0:6, 0:6] = np.eye(6)
        J[6:9, 6:9] = 4.0 * np.eye(3)
        J[9:12, 12:15] = np.eye(3)
        return J

    def _pose_dq(self) -> np.ndarray:
        return dq_from_rt(self._q, self._d)

    def sigma_points(self) -> np.ndarray:
        """Error-state sigma points ``(2L+1, L)`` ``χ`` around the current mean."""
        L = self.dim
        S = _sqrt_psd((L + self.lam) * self._P)
        chi = np.zeros((2 * L + 1, L))
        chi[1 : L + 1] = S.T
        chi[L + 1 :] = -S.T
        return chi

    def _apply_sigma(
        self, chi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Nominal states of error sigma points: ``d, v, q (xyzw), ω`` per point.

        ``q̂ⁱ = q̂ ⊗ cayley⁻¹(Bⁱ)`` (eq. 34); only its rotation is kept, the translation being
        ``dⁱ = d + δdⁱ`` (pose rebuild, module docstring).
        """
        d = self._d + chi[:, 0:3]
        v = self._v + chi[:, 3:6]
        q = canon_q(qmul(self._q, quat_cayley_inverse(chi[:, 6:9])))
        w = self._w + chi[:, 12:15]
        return d, v, q, w

    def _sigma_offset(self, chi: np.ndarray) -> np.ndarray:
        """Offsets ``c`` of error sigma points ``(2L+1, 3)`` (the mean's without an offset)."""
        if not self.centre_offset:
            return np.broadcast_to(self._c, (chi.shape[0], 3))
        return self._c + chi[:, 15:18]

    def _reference(self, d: np.ndarray, q: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Reference points ``d + R(q) c`` ``(n, 3)``."""
        if not self.centre_offset:
            return d
        return d + np.einsum("nij,nj->ni", quat_to_matrix(q), c)

    # --- predict ------------------------------------------------------------------------------

    def _predict(self, dt: float) -> None:
        chi = self.sigma_points()
        d, v, q, w = self._apply_sigma(chi)
        c = self._sigma_offset(chi)
        # propagate: attitude by body rates (right multiplication), translation by CW
        if self.inertia is not None:
            w_end = euler_rates(w, self.inertia, dt)
            q = canon_q(qmul(q, quat_delta(0.5 * (w + w_end), dt)))
            w = w_end
        else:
            q = canon_q(qmul(q, quat_delta(w, dt)))
        s = np.concatenate([d, v], axis=1) @ self.dynamics.stm(dt).T
        d, v = s[:, :3], s[:, 3:]
        d_m = self.Wm @ d
        v_m = self.Wm @ v
        w_m = self.Wm @ w
        # iterative Cayley mean of the poses; its rotation part only involves the rotations
        q_m, it, ok = quat_cayley_mean(q, self.Wm, init=q[0])
        self.mean_iterations = it
        if not ok:
            log.debug("Cayley mean not converged after %d iterations", it)
        dX = np.empty_like(chi)
        dX[:, 0:3] = d - d_m
        dX[:, 3:6] = v - v_m
        dX[:, 6:12] = cayley(dq_multiply(dq_conjugate(dq_from_rt(q_m, d_m)), dq_from_rt(q, d)))
        dX[:, 12:15] = w - w_m
        c_m = self.Wm @ c
        if self.centre_offset:
            dX[:, 15:18] = c - c_m
        if self.observer_bias or self.merge_slots:
            ib = self._ib
            dX[:, ib:] = chi[:, ib:]  # β and the merge errors are constant over the step
        P = (dX * self.Wc[:, None]).T @ dX
        P += self._native_from_phys_var(self._phys_process_var(dt))
        self._d, self._v, self._q, self._w, self._c = d_m, v_m, q_m, w_m, c_m
        if self.observer_bias and self.bias_correlation_time is not None:
            P = self._decay_bias(P, dt)
        self._P = _sym(P)
        self._prop = {"dX": dX, "d": self._reference(d, q, c), "q": q}

    # --- update -------------------------------------------------------------------------------

    def _meas_cov(self, R: np.ndarray) -> np.ndarray:
        """Measurement covariance in the filter's measurement coordinates."""
        if self.innovation == "position+rotation":
            J = np.zeros((6, 6))
            J[0:3, 0:3] = np.eye(3)
            J[3:6, 3:6] = 0.25 * np.eye(3)
            return _sym(J @ R @ J.T)
        # twist [B_r, B_d]: B_r ≈ δθ/4, B_d ≈ R_bs δp / 4 (relative translation in body axes)
        Rbs = quat_to_matrix(self._q).T
        J = np.zeros((6, 6))
        J[0:3, 3:6] = 0.25 * np.eye(3)
        J[3:6, 0:3] = 0.25 * Rbs
        return _sym(J @ R @ J.T)

    def _meas_of(self, d: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Measurement coordinates of poses ``(d, q)`` relative to the predicted pose."""
        if self.innovation == "position+rotation":
            conj = self._q * np.array([-1.0, -1.0, -1.0, 1.0])
            return np.concatenate([d, quat_cayley(qmul(conj, q))], axis=-1)
        return cayley(dq_multiply(dq_conjugate(self._pose_dq()), dq_from_rt(q, d)))

    def _update(self, p: np.ndarray, q_meas: np.ndarray, R: np.ndarray) -> UpdateInfo:
        pending, self._pending = self._pending, None
        if pending is None or not pending[1]:
            return self._update_core(p, q_meas, R, combo=None)
        frame, sources = pending
        if frame is None:  # not merged: inherits the kept errors, v is measurement noise
            slot_of = {f: i for i, f in enumerate(self._slot_frame) if f is not None}
            combo = [(slot_of[j], w) for j, w in sources.items() if j in slot_of and w != 0.0]
            return self._update_core(p, q_meas, R, combo=combo or None)
        saved = (self._P.copy(), self._m.copy(), list(self._slot_frame),
                 self._slot_used.copy(), self._n_merges)  # fmt: skip
        s = self._open_merge(frame, sources, R)
        info = self._update_core(p, q_meas, R, combo=[(s, 1.0)], exact=True)
        if not info.accepted:
            self._P, self._m, self._slot_frame, self._slot_used, self._n_merges = saved
        return info

    def _update_core(
        self,
        p: np.ndarray,
        q_meas: np.ndarray,
        R: np.ndarray,
        *,
        combo: list[tuple[int, float]] | None,
        exact: bool = False,
    ) -> UpdateInfo:
        """One UKF update; ``combo``: the observation's error is ``Σ w · m_slot`` (body axes,
        merge states), ``exact``: that sum already holds the observation's own noise."""
        if (
            self.update_sigma == "propagated"
            and self._prop is not None
            and not self.observer_bias
            and combo is None
        ):
            dX = self._prop["dX"]
            d_i, q_i = self._prop["d"], self._prop["q"]
        else:
            dX = self.sigma_points()
            d_i, _, q_i, _ = self._apply_sigma(dX)
            d_i = self._reference(d_i, q_i, self._sigma_offset(dX))
            if self.observer_bias:
                ib = self._ib
                b = self._b + dX[:, ib : ib + 6]
                if self.bias_frame == "body":
                    d_i = d_i + np.einsum("nij,nj->ni", quat_to_matrix(q_i), b[:, 0:3])
                else:
                    d_i = d_i + b[:, 0:3]
                q_i = canon_q(qmul(q_i, quat_delta(b[:, 3:6], 1.0)))
            if combo is not None:
                g = sum(w * (self._m[i] + dX[:, self._slot_rows(i)]) for i, w in combo)
                d_i = d_i + np.einsum("nij,nj->ni", quat_to_matrix(q_i), g[:, 0:3])
                q_i = canon_q(qmul(q_i, quat_delta(g[:, 3:6], 1.0)))
        Z = self._meas_of(d_i, q_i)
        z_hat = self.Wm @ Z
        dZ = Z - z_hat
        Rz = self._meas_cov(R)
        if exact:
            # the registration's own error v is in the merge state: the measurement is exact
            # up to a numerical floor; Rz is still reported as the observation's covariance
            Pzz = _sym((dZ * self.Wc[:, None]).T @ dZ + _EXACT_VAR * np.eye(Rz.shape[0]))
            return self._finish_update(dX, dZ, z_hat, Pzz, p, q_meas, Rz, Rz_used=None)
        Pzz = _sym((dZ * self.Wc[:, None]).T @ dZ + Rz)
        return self._finish_update(dX, dZ, z_hat, Pzz, p, q_meas, Rz, Rz_used=Rz)

    def _finish_update(
        self,
        dX: np.ndarray,
        dZ: np.ndarray,
        z_hat: np.ndarray,
        Pzz: np.ndarray,
        p: np.ndarray,
        q_meas: np.ndarray,
        Rz: np.ndarray,
        *,
        Rz_used: np.ndarray | None,
    ) -> UpdateInfo:
        """Gain, gate and injection shared by the updates (``Rz_used``: the measurement noise
        inside ``Pzz``, ``None`` when it is carried by a merge state)."""
        Pxz = (dX * self.Wc[:, None]).T @ dZ
        z = self._meas_of(p, q_meas)
        nu = z - z_hat
        nis = float(nu @ np.linalg.solve(Pzz, nu))
        reason = self._gate(nis, nu.size)
        if reason:
            return UpdateInfo(False, nis, nu, reason, Pzz, Rz)
        if self.robust_dof is not None and Rz_used is not None:
            A = Pzz - Rz_used
            Rz_used = self._student_scale(A, Rz_used, nu) * Rz_used
            Pzz = _sym(A + Rz_used)
        K = np.linalg.solve(Pzz, Pxz.T).T
        dx = K @ nu
        P_prior = self._P
        if self.covariance_update == "standard":
            P = P_prior - K @ Pzz @ K.T
        else:
            H = np.linalg.solve(P_prior, Pxz).T
            IKH = np.eye(self.dim) - K @ H
            Rn = Rz_used if Rz_used is not None else _EXACT_VAR * np.eye(Pzz.shape[0])
            P = IKH @ P_prior @ IKH.T + K @ Rn @ K.T
        self._inject(dx)
        self._P = _sym(P)
        self._prop = None
        if self.centre_offset:
            self._axis_constraint()
        return UpdateInfo(True, nis, nu, "", Pzz, Rz if Rz_used is None else Rz_used)

    def _student_scale(self, A: np.ndarray, Rz: np.ndarray, nu: np.ndarray) -> float:
        """Scale ``s ≥ 1`` of the measurement covariance under a Student-t noise (``ν`` dof).

        **[interpretation]** The variational-Bayes fixed point of a Student-t measurement with
        the filter's spread ``A``: ``s = (ν + νᵀ(A + s R)⁻¹ν) / (ν + m)`` (``m`` = 6), clipped at
        1 so that only an innovation larger than the Gaussian expects is down-weighted (a
        registration error much larger than the scan's own covariance: a one-off, not noise).
        """
        dof = float(self.robust_dof)  # type: ignore[arg-type]
        m = nu.size
        s = 1.0
        for _ in range(20):
            nis = float(nu @ np.linalg.solve(A + s * Rz, nu))
            s_new = max(1.0, (dof + nis) / (dof + m))
            if abs(s_new - s) <= 1e-3 * s:
                return s_new
            s = s_new
        return s

    def _widen(self, factor: float) -> None:
        super()._widen(factor)
        self._prop = None  # the update draws its sigma points from the widened covariance

    def _inject(self, dx: np.ndarray) -> None:
        """Add an error-state correction to the nominal state."""
        self._d = self._d + dx[0:3]
        self._v = self._v + dx[3:6]
        # q̂ ← q̂ ⊗ cayley⁻¹(δB); its translation is then rebuilt from the updated d
        self._q = canon_q(qmul(self._q, quat_cayley_inverse(dx[6:9])))
        self._w = self._w + dx[12:15]
        if self.centre_offset:
            self._c = self._c + dx[15:18]
        if self.observer_bias:
            self._b = self._b + dx[self._ib : self._ib + 6]
        if self.merge_slots:
            self._m = self._m + dx[self._ib :].reshape(self.merge_slots, 6)

    def _axis_constraint(self) -> None:
        """Pseudo-measurement ``ω̂ · c = 0`` (class docstring), a linear Kalman update."""
        if not math.isfinite(self.axis_sigma):
            return
        sw = math.sqrt(max(float(np.trace(self._P[12:15, 12:15])) / 3.0, 0.0))
        nw = float(np.linalg.norm(self._w))
        if not nw > 3.0 * sw:
            return
        u = self._w / nw
        H = np.zeros(self.dim)
        H[15:18] = u
        PH = self._P @ H
        S = float(H @ PH) + self.axis_sigma**2
        K = PH / S
        self._inject(K * (0.0 - float(u @ self._c)))
        self._P = _sym(self._P - np.outer(K, K) * S)

    def settings(self) -> dict[str, Any]:
        """Configuration as plain values."""
        out = super().settings()
        out.update(
            alpha=self.alpha,
            beta=self.beta,
            kappa=self.kappa,
            innovation=self.innovation,
            update_sigma=self.update_sigma,
            covariance_update=self.covariance_update,
            centre_offset=self.centre_offset,
            observer_bias=self.observer_bias,
            bias_correlation_time=self.bias_correlation_time,
            bias_frame=self.bias_frame,
            merge_slots=self.merge_slots,
            inertia=None if self.inertia is None else self.inertia.tolist(),
            robust_dof=self.robust_dof,
        )
        return out
