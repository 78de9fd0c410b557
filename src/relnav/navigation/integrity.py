"""A step's integrity, the navigator's ``flagged`` label
(:meth:`relnav.navigation.navigator.Navigator._judge_integrity`): the probability that its error
exceeds an alert limit under its covariance, and the evidence that the motion model and the scan
disagree, which that covariance (theirs) cannot show."""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from relnav.geometry.eigen import block, matmul_t, sym_eigvals
from relnav.odometry.step_check import step_difference
from relnav.registration.result import RegistrationResult

if TYPE_CHECKING:
    from relnav.navigation.options import NavigatorConfig

__all__ = ["ambiguity", "disagreement", "exceedance_probability", "step_sigmas"]


@functools.cache
def _unit_normals(n: int = 4096) -> np.ndarray:
    """Fixed standard-normal draws ``(n, 6)`` (seed 0): deterministic probabilities."""
    return np.random.default_rng(0).standard_normal((n, 6))


@njit(cache=True)
def _exceed_count(
    Zt: np.ndarray, B: np.ndarray, limit_t2: float, limit_r2: float, n: int
) -> int:  # pragma: no cover - numba
    """How many of the first ``n`` draws ``e = B z`` (``z`` the columns of ``Zt``, (6, ≥ n))
    have ``|e[:3]|² > limit_t2`` or ``|e[3:]|² > limit_r2``."""
    s_t, s_r = np.zeros(n), np.zeros(n)
    for r in range(6):  # two loops, not one on an alias of either: numba vectorises these
        b0, b1, b2, b3, b4, b5 = B[r, 0], B[r, 1], B[r, 2], B[r, 3], B[r, 4], B[r, 5]
        z0, z1, z2, z3, z4, z5 = Zt[0], Zt[1], Zt[2], Zt[3], Zt[4], Zt[5]
        if r < 3:
            for i in range(n):
                v = b0 * z0[i] + b1 * z1[i] + b2 * z2[i] + b3 * z3[i] + b4 * z4[i] + b5 * z5[i]
                s_t[i] += v * v
        else:
            for i in range(n):
                v = b0 * z0[i] + b1 * z1[i] + b2 * z2[i] + b3 * z3[i] + b4 * z4[i] + b5 * z5[i]
                s_r[i] += v * v
    count = 0
    for i in range(n):
        if s_t[i] > limit_t2 or s_r[i] > limit_r2:
            count += 1
    return count


@njit(cache=True)
def _draws_that_can_exceed(
    B: np.ndarray, z2_desc: np.ndarray, limit_t2: float, limit_r2: float
) -> int:  # pragma: no cover - numba
    """How many of the draws, sorted by squared norm ``z2_desc`` (descending), could exceed a
    limit: ``|B_ρ z|² ≤ λ_max(B_ρ B_ρᵀ) |z|²`` (and the same for ``φ``), so a draw whose
    ``|z|²`` keeps both bounds within the limits (by a relative margin of 1e-9, far above
    rounding) cannot, nor can any shorter one."""
    lam = np.empty(2)
    for blk in range(2):
        Bb = block(B, 3 * blk, 3 * blk + 3, 0, 6)
        lam[blk] = max(sym_eigvals(matmul_t(Bb, Bb))[2], 0.0) * (1.0 + 1e-9)
    thr = np.inf  # draws with |z|² > thr may exceed a limit
    if lam[0] > 0.0:
        thr = min(thr, limit_t2 / lam[0])
    if lam[1] > 0.0:
        thr = min(thr, limit_r2 / lam[1])
    n = 0
    while n < z2_desc.shape[0] and z2_desc[n] > thr:
        n += 1
    return n


@functools.cache
def _draws_by_norm() -> tuple[np.ndarray, np.ndarray]:
    """:func:`_unit_normals` ordered by squared norm, longest first: the draws by axis
    ``(6, n)`` C-contiguous and their squared norms ``(n,)``."""
    z = _unit_normals()
    z2 = np.einsum("ij,ij->i", z, z)
    order = np.argsort(-z2, kind="stable")
    return np.ascontiguousarray(z[order].T), np.ascontiguousarray(z2[order])


def exceedance_probability(C: np.ndarray, limit_t: float, limit_r: float) -> float:
    """Probability that a step error ``e ~ N(0, C)`` exceeds ``limit_t`` in translation or
    ``limit_r`` in rotation.

    Parameters
    ----------
    C : (6, 6) float64
        Covariance of the step's error twist ``[ρ, φ]`` (m, rad), e.g. the filter's
        ``step_covariance`` (body frame).
    limit_t : float
        Translation limit on ``|ρ|`` (m).
    limit_r : float
        Rotation limit on ``|φ|`` (rad).

    Returns
    -------
    float
        ``P(|ρ| > limit_t or |φ| > limit_r)`` in [0, 1], estimated from 4096 fixed draws
        (standard error at most 0.008); 1 for a non-finite ``C``.

    Notes
    -----
    The two norms are correlated through ``C``'s off-diagonal block, so the joint event is
    counted on draws of the whole twist (no closed form for a union of two generalised χ²).
    A draw's error is ``e = B z`` with ``B = U √w`` (``C = U diag(w) Uᵀ``), so
    ``|e_ρ|² ≤ λ_max(B_ρ B_ρᵀ) |z|²`` (the same for ``φ``): only the draws long enough to pass
    a limit by that bound are counted (:func:`_draws_that_can_exceed`; the others cannot), the
    same count as over all of them, and none (the result 0) when no draw is long enough.
    """
    C = np.ascontiguousarray(C, dtype=np.float64)
    if not np.all(np.isfinite(C)):
        return 1.0
    # LAPACK's eigenvectors (their order and signs pair each fixed draw with a direction)
    w, U = np.linalg.eigh(0.5 * (C + C.T))
    B = np.ascontiguousarray(U * np.sqrt(np.maximum(w, 0.0)))
    Zt, z2 = _draws_by_norm()
    n = _draws_that_can_exceed(B, z2, limit_t**2, limit_r**2)
    if n == 0:
        return 0.0
    return _exceed_count(Zt, B, limit_t**2, limit_r**2, n) / Zt.shape[1]


@njit(cache=True)
def _largest_block_variances(C: np.ndarray) -> tuple[float, float]:  # pragma: no cover - numba
    """Largest eigenvalue of the translation and of the rotation block of ``C`` (6×6)."""
    return sym_eigvals(block(C, 0, 3, 0, 3))[2], sym_eigvals(block(C, 3, 6, 3, 6))[2]


def step_sigmas(C: np.ndarray) -> tuple[float, float]:
    """A step's 1σ along its worst translation axis (m) and its worst rotation axis (rad),
    from its covariance ``C`` (6×6, twist ``[ρ, φ]``); NaN when ``C`` is not finite."""
    C = np.ascontiguousarray(C, dtype=np.float64)
    if not np.all(np.isfinite(C)):
        return float("nan"), float("nan")
    v_t, v_r = _largest_block_variances(C)
    return math.sqrt(max(v_t, 0.0)), math.sqrt(max(v_r, 0.0))


def ambiguity(
    best: dict[str, Any], answers: list[dict[str, Any]], c: NavigatorConfig
) -> dict[str, float]:
    """The other registration answer (of the extra starts under jitter) that fits the scan
    almost as well as the chosen one and lies farthest from it beyond the flag limits.

    **[interpretation]** Solution separation: when two starts end at answers whose robust RMS
    differ by at most ``integrity.ambiguity_rms`` (a ratio) and whose sensor poses are farther
    apart than ``integrity.flag_limit_t`` or ``integrity.flag_limit_r_deg``, the scan does not
    tell which one is right at the flag limits, whatever the chosen answer's covariance says.

    Parameters
    ----------
    best : dict
        The chosen answer (``"T"`` (4, 4) target-from-sensor, ``"rms"``, ``"usable"``).
    answers : list of dict
        Every answer, the chosen one included.
    c : NavigatorConfig
        The navigator's options (``integrity``: the ratio and the flag limits).

    Returns
    -------
    dict
        ``{"ambiguity_t": m, "ambiguity_r_deg": deg, "ambiguity_rms_ratio": ratio}`` of that
        answer, or ``{}`` when there is none.
    """
    ig = c.integrity
    out: dict[str, float] = {}
    far = 0.0
    for a in answers:
        if a is best or not a["usable"] or not a["rms"] <= ig.ambiguity_rms * best["rms"]:
            continue
        angle, d_t = step_difference(best["T"], a["T"])
        d_r = math.degrees(angle)
        excess = max(d_t / ig.flag_limit_t, d_r / ig.flag_limit_r_deg)
        if excess > 1.0 and excess > far:
            far = excess
            out = {
                "ambiguity_t": d_t,
                "ambiguity_r_deg": d_r,
                "ambiguity_rms_ratio": float(a["rms"] / best["rms"]),
            }
    return out


def disagreement(result: RegistrationResult, c: NavigatorConfig) -> str:
    """Why an accepted step's motion model and scan disagree beyond what its covariance can
    say (another answer as good beyond the flag limits: :func:`ambiguity`,
    ``integrity.flag_recovered``, ``integrity.flag_chi2``, ``integrity.flag_min_fitness``), or
    ``""``."""
    info, ig = result.info, c.integrity
    chi2 = float(info.get("chi2_motion", 0.0))
    if "ambiguity_t" in info:
        return (
            f"ambiguous: another start fits the scan within "
            f"{info['ambiguity_rms_ratio'] - 1.0:.1%} of the RMS {info['ambiguity_t']:.2f} m / "
            f"{info['ambiguity_r_deg']:.1f}° away"
        )
    if ig.flag_recovered and info.get("recovered"):
        return "the motion model's prior was rejected: registered again under the weak prior"
    if ig.flag_chi2 > 0 and chi2 > ig.flag_chi2:
        return f"correction inconsistent with the motion model (χ² {chi2:.1f} > {ig.flag_chi2:g})"
    if ig.flag_min_fitness > 0 and result.fitness < ig.flag_min_fitness:
        return f"{result.fitness:.0%} of the scan fits the map (< {ig.flag_min_fitness:.0%})"
    return ""
