"""Judging a pairwise odometry step without ground truth (:class:`StepChecker`).

A pairwise registration that converges reports good residuals whether it is right or wrong:
measured on the simulated presets, icp-point's wrong steps have the same fitness, inlier RMSE and
covariance as its right ones. Two checks that *are* informative re-examine the answer instead:

* **referee** — point-to-plane ICP (:class:`relnav.registration.icp.ICP`, variant ``plane``)
  started at the method's step ``T``. A step at a minimum of the point-to-plane cost stays put;
  a step stopped short (point-to-point ICP creeping on sparse scans), or a wrong global match
  (feature pipelines), moves. It costs one point-to-plane ICP (the scan's normals are computed
  once and reused as the next step's target).
* **forward–backward** — the method registers the previous scan onto the current one, started
  at ``T⁻¹``; the loop ``T @ T_back`` of a well-determined step is the identity. It costs one
  more registration of the method (prepared per-scan data reused).

A step whose referee moves it by more than ``referee_factor`` × the step tolerance, whose
referee fails from it, or whose loop exceeds ``loop_factor`` × the tolerance, is ``flagged``.
[interpretation] ``flagged`` keeps the method's step in the pose chain (the motion prior is no
better informed than the registration) but marks it as not trusted; only ``degenerate`` and
``failed`` steps keep the motion prior. The tolerance (0.5 m, 5° by default) is the accuracy a
step must have to count as right, the same figures the navigation suite uses to count wrong steps.

Factors were chosen on sim-bennu and the flash sequence comet-ellipse-64 and frozen
(``benchmarks/paper1/step_flags.py`` measures recall and false flags on other sequences).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import invert
from relnav.registration.base import PreparedRegistration, Registration
from relnav.registration.result import RegistrationResult

__all__ = [
    "CHECKED_FAMILIES",
    "REFEREE_MAX_ITER",
    "STEP_CHECK_MODES",
    "StepCheckMode",
    "StepChecker",
    "make_referee",
    "prepare_referee",
    "resolve_step_check",
    "step_difference",
]

log = logging.getLogger(__name__)

StepCheckMode = Literal["auto", "off", "referee", "backward", "full"]
STEP_CHECK_MODES: tuple[str, ...] = ("auto", "off", "referee", "backward", "full")
"""``off``: no check; ``referee``: point-to-plane referee only; ``backward``: forward–backward
only; ``full``: both. ``auto``: both for point-to-point ICP; the referee for Sparse ICP
point-to-point (its backward run doubles a slow method and flagged no more on the tuning
sequences) and for feature pipelines (their second registration doubles the time per frame);
forward–backward for point-to-plane ICP and for feature pipelines refined by ICP (preset
``extended``), where a point-to-plane referee would repeat the method; ``off`` for other
methods."""

REFEREE_MAX_ITER = 30
"""Iterations of the point-to-plane referee (at most)."""

CHECKED_FAMILIES: dict[str, str] = {
    "icp-point": "full",
    "icp-x84": "full",
    "sicp-point": "referee",
    "icp-plane": "backward",
    "sicp-plane": "backward",
    "feature": "referee",
}
"""Method family → the checks ``auto`` runs. Other methods (stateful adapters such as
KISS-ICP, relnav's navigator with its own checks, user objects) are not re-run."""


def resolve_step_check(mode: Any, method: Any, options: dict[str, Any] | None = None) -> str:
    """The checks to run (``off``, ``referee`` or ``full``) for ``mode`` and a method.

    Parameters
    ----------
    mode : str or bool
        One of :data:`STEP_CHECK_MODES` (``True``/``False`` mean ``auto``/``off``).
    method : str or Registration
        The method string, or a registration object (``auto`` is ``off`` for objects: they
        may be stateful, and a second call would disturb them).
    options : dict, optional
        The method's options: a feature pipeline refined by ICP (``refine``) is checked
        forward–backward (a point-to-plane referee would repeat its refinement).

    Raises
    ------
    ConfigError
        Unknown mode.
    """
    if isinstance(mode, bool):
        mode = "auto" if mode else "off"
    m = str(mode).strip().lower()
    if m in ("on", "true", "yes"):
        m = "auto"
    elif m in ("false", "no", "none"):
        m = "off"
    if m not in STEP_CHECK_MODES:
        raise ConfigError(f"step_check must be one of {', '.join(STEP_CHECK_MODES)}, got {mode!r}")
    if m != "auto":
        return m
    if not isinstance(method, str):
        return "off"
    family = method.strip().lower().partition(":")[0]
    if family == "feature" and (options or {}).get("refine"):
        return "backward"
    return CHECKED_FAMILIES.get(family, "off")


@dataclass
class _Referee:
    """Per-scan data of the referee (a point-to-plane prepared cloud) and its cost (s)."""

    cloud: Any
    time_s: float = 0.0


class StepChecker:
    """Re-examine an ``ok`` pairwise step; flag it when the checks disagree with it.

    Parameters
    ----------
    registration : Registration
        The odometry's method (re-run backwards by the forward–backward check).
    mode : {"referee", "backward", "full"}
        Checks to run (see :data:`STEP_CHECK_MODES`).
    tolerance_m, tolerance_deg : float
        Accuracy a step must have to be trusted: translation (m) and rotation (degrees).
    referee_factor : float
        Flag when the referee moves the step by more than this × the tolerance.
    loop_factor : float
        Flag when the forward–backward loop exceeds this × the tolerance.
    """

    def __init__(
        self,
        registration: Registration,
        mode: Literal["referee", "backward", "full"] = "full",
        *,
        tolerance_m: float = 0.5,
        tolerance_deg: float = 5.0,
        referee_factor: float = 1.0,
        loop_factor: float = 0.7,
    ) -> None:
        if mode not in ("referee", "backward", "full"):
            raise ConfigError(
                f"StepChecker mode must be 'referee', 'backward' or 'full', got {mode!r}"
            )
        for nm, v in (
            ("step_tolerance_m", tolerance_m),
            ("step_tolerance_deg", tolerance_deg),
            ("referee_factor", referee_factor),
            ("loop_factor", loop_factor),
        ):
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{nm} must be a positive number, got {v!r}")
        self.registration = registration
        self.mode = mode
        self.tolerance_m = float(tolerance_m)
        self.tolerance_rad = math.radians(float(tolerance_deg))
        self.referee_factor = float(referee_factor)
        self.loop_factor = float(loop_factor)
        self.referee = make_referee()
        self.uses_referee = mode in ("referee", "full")
        self.uses_backward = mode in ("backward", "full")

    def prepare(self, points: np.ndarray) -> _Referee | None:
        """The referee's per-scan data (normals, KD-tree), or None if the scan is unusable
        or the referee is not used."""
        if not self.uses_referee:
            return None
        return prepare_referee(self.referee, points)

    def judge(
        self,
        result: RegistrationResult,
        *,
        source: np.ndarray,
        target: np.ndarray,
        source_prepared: Any = None,
        target_prepared: Any = None,
        source_referee: _Referee | None = None,
        target_referee: _Referee | None = None,
        referee_result: RegistrationResult | None = None,
    ) -> None:
        """Check an ``ok`` result (in place): status ``flagged`` with the reason in
        ``message``; the figures go to ``result.info["step_check"]`` and the time (this call
        and the current scan's :meth:`prepare`) to ``result.timings["check"]`` (s).

        ``source`` is the current scan, ``target`` the previous one (sensor frames, m);
        ``*_prepared`` are the method's per-scan data (:class:`PreparedRegistration`).
        ``referee_result``: the referee already run from the step on the same two scans (the
        odometry's dense refinement, :mod:`relnav.odometry.odometry`); it is judged instead
        of running the referee again (the referee check then needs no ``*_referee`` data).
        """
        if result.status != "ok":
            return
        t0 = time.perf_counter()
        T = np.asarray(result.T_target_source, dtype=np.float64)
        info: dict[str, Any] = {"mode": self.mode}
        reasons: list[str] = []
        ref: RegistrationResult | None = None
        if self.uses_referee and referee_result is not None:
            ref = referee_result
            info["referee_shared"] = True
        elif source_referee is not None and target_referee is not None:
            ref = self.referee.register_prepared(source_referee.cloud, target_referee.cloud, init=T)
        if ref is not None:
            info["referee_status"] = ref.status
            if ref.status == "ok":
                d_rot, d_t = step_difference(T, ref.T_target_source)
                info["referee_rot_deg"] = math.degrees(d_rot)
                info["referee_t"] = d_t
                f = self.referee_factor
                if d_rot > f * self.tolerance_rad or d_t > f * self.tolerance_m:
                    reasons.append(
                        f"point-to-plane ICP started at the step moves it by "
                        f"{math.degrees(d_rot):.2f}° / {d_t:.3g} m"
                    )
            elif ref.status == "failed":
                reasons.append(f"point-to-plane ICP fails from the step ({ref.message})")
        if self.uses_backward:
            back = self._backward(T, source, target, source_prepared, target_prepared)
            info["backward_status"] = back.status
            if back.status == "ok":
                loop = T @ back.T_target_source
                l_rot = rotation_angle(loop[:3, :3])
                l_t = float(np.linalg.norm(loop[:3, 3]))
                info["loop_rot_deg"] = math.degrees(l_rot)
                info["loop_t"] = l_t
                f = self.loop_factor
                if l_rot > f * self.tolerance_rad or l_t > f * self.tolerance_m:
                    reasons.append(
                        f"forward–backward loop {math.degrees(l_rot):.2f}° / {l_t:.3g} m"
                    )
            else:
                reasons.append(f"backward registration {back.status} ({back.message})")
        dt = time.perf_counter() - t0 + (source_referee.time_s if source_referee else 0.0)
        result.timings["check"] = result.timings.get("check", 0.0) + dt
        info["flagged"] = bool(reasons)
        result.info["step_check"] = info
        if reasons:
            result.status = "flagged"  # type: ignore[assignment]
            result.message = "step not trusted: " + "; ".join(reasons)

    def _backward(
        self,
        T: np.ndarray,
        source: np.ndarray,
        target: np.ndarray,
        source_prepared: Any,
        target_prepared: Any,
    ) -> RegistrationResult:
        """The method registering the previous scan onto the current one, from ``T⁻¹``."""
        reg = self.registration
        try:
            if (
                isinstance(reg, PreparedRegistration)
                and source_prepared is not None
                and target_prepared is not None
            ):
                return reg.register_prepared(target_prepared, source_prepared, init=invert(T))
            return reg.register(target, source, init=invert(T))
        except Exception as e:  # the check must never stop the run
            log.debug("step check: backward registration raised %s", e)
            return RegistrationResult(status="failed", message=f"{type(e).__name__}: {e}")


def make_referee() -> Registration:
    """The referee: point-to-plane ICP (:class:`relnav.registration.icp.ICP`, scale-aware
    thresholds) with at most :data:`REFEREE_MAX_ITER` iterations."""
    from relnav.registration.icp import ICP

    return ICP("plane", max_iter=REFEREE_MAX_ITER)


def prepare_referee(referee: Registration, points: np.ndarray) -> _Referee | None:
    """Per-scan data of a point-to-plane ``referee`` (normals, KD-tree) and its cost, or None
    when the scan is unusable (a bad scan is judged by the method, not here)."""
    t0 = time.perf_counter()
    try:
        cloud = referee.prepare(points)  # type: ignore[attr-defined]
    except Exception as e:
        log.debug("step check: referee preparation failed: %s", e)
        return None
    return _Referee(cloud, time.perf_counter() - t0) if cloud.ok else None


def step_difference(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Rotation angle (rad) of ``A⁻¹ B`` and the distance (m) between the translations."""
    D = invert(A) @ B
    return rotation_angle(D[:3, :3]), float(np.linalg.norm(A[:3, 3] - B[:3, 3]))
