"""Re-anchoring the start-up (``startup.reanchor_frame``): the first scan on the later map.

**[interpretation, measured]** On a sparse flash scan the first steps are registered onto a map of
one to a few scans, and such a registration is wrong by degrees even when started at the true pose:
on the navigator's own solver, a voyager-tumble-64 scan registered onto a map of 1, 2, 4 and 11
scans placed at their *true* poses ends 4.7°, 4.0°, 0.7° and 0.6° from the truth (iridium-tumble-64:
10.2°, 10.2°, 6.1°, 0.6°; ``benchmarks/archive/nav_perfect_map.py``). Consecutive sparse scans also
agree best when their sample positions coincide, which favours a slower motion: the joint cost of
the first ten frames is *lower* at an under-rotated constant-velocity solution than at the true
poses (voyager-tumble-64: 134 against 291). Tracking therefore turns the whole map by the start-up's
error, 5–15° on the tumbling sequences, and keeps it: the map is self-consistent in a turned target
frame (a gauge error), which no later registration sees.

Once ``startup.reanchor_frame`` frames are tracked, the map of the frames from
``startup.reanchor_skip`` on (dense, away from the first scan's sample positions) is where the first
scan is registered again, from its pose under the first frame's weak prior. Its answer ``T₀'``
measures the turn: the whole window but the first frame (the anchor) is turned by ``C = T₀ T₀'⁻¹``
in the target frame, frames ``1 … reanchor_skip − 1`` by a growing share ``k / reanchor_skip`` of it
**[interpretation]**: the start-up's error grew over them (the start-up window then rebuilds the map
and restarts the
filter and the smoother, as after the multi-view refinement:
:class:`relnav.navigation.startup.StartupWindow`). The relative state turns every earlier frame by
the whole of ``C`` (``StateRecord.gauge_turn``). The correction is refused (each test against χ²₆ at
``startup.reanchor_gate``) when it is inconsistent with the start-up steps' covariance (frames 1 …
``startup.reanchor_skip``, in the target frame) plus the registration's own, or when the first scan
does not fit the later map significantly better at the corrected pose than where the start-up put it
(the robust mean square's gain times the pairs, against what six free parameters take from noise): a
target whose surface slides along itself lets the single scan slide too.

Not a default: it helps where the start-up error is large and can hurt where it is already
small (one sparse scan's registration, about 0.5°, is then the larger error); see the
``relnav-tumbling`` method preset and ``docs/navigator.md``, "Re-anchoring the start-up".
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from relnav.geometry.lie import exp_se3, log_se3
from relnav.geometry.se3 import adjoint, invert
from relnav.navigation.gicp import solve_scan_to_map
from relnav.navigation.solver import rms_radius

if TYPE_CHECKING:
    from relnav.navigation.solver import MapSolver
    from relnav.navigation.startup.multiview import WindowFrame

__all__ = ["reanchor", "start_up_covariance"]

log = logging.getLogger(__name__)


def start_up_covariance(poses: list[np.ndarray], step_covs: list[np.ndarray | None]) -> np.ndarray:
    """Covariance ``(6, 6)`` of a left twist (target frame) accumulated by the steps that led to
    ``poses``: ``Σ Ad(T_k) C_k Ad(T_k)ᵀ`` over the steps with a covariance ``C_k`` (body frame of
    ``T_k``, the pose they reached)."""
    C = np.zeros((6, 6))
    for T, Ck in zip(poses, step_covs, strict=True):
        if Ck is not None:
            Ad = adjoint(T)
            C += Ad @ np.asarray(Ck) @ Ad.T
    return 0.5 * (C + C.T)


def reanchor(
    frames: list[WindowFrame], solver: MapSolver
) -> tuple[dict, tuple[np.ndarray, list[np.ndarray], float] | None]:
    """Re-register the window's first scan onto the map of its later frames and turn the window
    by the correction (see the module doc).

    Returns the outcome's record (``"kind": "reanchor"``, why when refused) and, when accepted,
    the turn ``G`` (4, 4) of the target frame applied to the frames after the first
    ``startup.reanchor_skip`` (the earlier ones take a share of it; the poses of ``frames`` are
    turned
    in place), the poses before the turn and its angle (deg); None when refused."""
    c = solver.config
    assert solver.map is not None
    used = [f for f in frames if f.ok]
    record: dict = {"kind": "reanchor", "frames": len(frames), "accepted": False}
    first = used[0] if used else None
    late = [
        f
        for f in used[1:]
        if first is not None and f.frame - first.frame >= c.startup.reanchor_skip
    ]
    if first is None or len(late) < 2 or not len(first.P):
        return record | {"reason": "too few frames in the map"}, None
    m = solver.new_map()
    for f in late:
        m.insert(f.Pm @ f.pose[:3, :3].T + f.pose[:3, 3], f.frame)
    st = solver.first_sigma[0]
    fit = solver.solve(
        first.P,
        first.pose,
        solver.weak_prior(first.pose),
        3.0 * st,
        first.rng,
        max(rms_radius(first.P), solver.spacing0),
        primary=False,
        voxel_map=m,
    )
    if not (fit["usable"] and np.all(np.isfinite(fit["T"]))):
        return record | {"reason": "registration unusable"}, None
    xi = log_se3(fit["T"] @ invert(first.pose))  # left twist, target frame
    # the first scan where the start-up put it, on the same map and kernel
    at = solve_scan_to_map(
        first.P,
        m,
        np.ascontiguousarray(first.pose),
        np.ascontiguousarray(first.pose),
        np.zeros((6, 6)),
        3.0 * st,
        float(c.solver.kernel),
        0,
        0.0,
        0.0,
        c0=float(c.solver.kernel),
    )
    rms_before = at.rms
    early = [f for f in used[1:] if f.frame - first.frame <= c.startup.reanchor_skip]
    C_chain = start_up_covariance([f.pose for f in early], [f.step_cov for f in early])
    H = np.asarray(fit["H"]) / fit["var_factor"]
    try:
        chi2 = float(xi @ np.linalg.solve(C_chain + np.linalg.inv(H), xi))
    except np.linalg.LinAlgError:
        chi2 = float("inf")
    # likelihood ratio of the two placements: the fit's gain over what six free parameters
    # take from noise alone (≈ χ²₆)
    gain = fit["n_pairs"] * (rms_before**2 - fit["rms"] ** 2) / max(fit["rms"] ** 2, 1e-12)
    record |= {
        "chi2": chi2,
        "gain_chi2": gain,
        "rms": fit["rms"],
        "rms_before": rms_before,
        "overlap": fit["overlap"],
    }
    if not chi2 <= c.startup.reanchor_gate:
        log.debug("re-anchoring refused: χ² %.1f > %.1f", chi2, c.startup.reanchor_gate)
        return record | {"reason": "inconsistent with the start-up"}, None
    if not gain > c.startup.reanchor_gate:
        log.debug("re-anchoring refused: fit gain χ² %.1f <= %.1f", gain, c.startup.reanchor_gate)
        return record | {"reason": "no better fit"}, None
    g = log_se3(first.pose @ invert(fit["T"]))
    before = [f.pose.copy() for f in frames]
    for f in frames:
        if f is not first:
            share = min(1.0, (f.frame - first.frame) / c.startup.reanchor_skip)
            f.pose = exp_se3(share * g) @ f.pose
    angle = math.degrees(float(np.linalg.norm(xi[3:])))
    log.debug("re-anchored the start-up: %.2f° (χ² %.1f)", angle, chi2)
    return record, (exp_se3(g), before, angle)
