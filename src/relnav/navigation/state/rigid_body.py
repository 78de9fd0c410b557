"""The relative state's rigid-body pass: a tumbling target's rate turned by Euler's equations.

A first pass of the relative state (constant-rate model) gives the target's body rates and
attitudes. :func:`rigid_body_pass` identifies the inertia's shape from them
(:func:`~relnav.navigation.state.inertia.fit_inertia` on the rates, then
:func:`~relnav.navigation.state.inertia.refine_inertia` on the attitudes) and runs a second pass
with each identified inertia; the pass whose innovations are the more likely is kept
(``relative_state(rigid_body=True)``; measured in ``docs/results/nav/state_hold_point.md``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from relnav.filtering.track_result import TrackResult
from relnav.navigation.state.inertia import InertiaFit, fit_inertia, refine_inertia

__all__ = ["rigid_body_pass"]

log = logging.getLogger(__name__)


def _second_pass(
    run_pass: Callable[[InertiaFit], TrackResult], fit: InertiaFit
) -> tuple[TrackResult | None, str]:
    """``run_pass(fit)`` and why it is refused ("" when it is not)."""
    try:  # a diverging pass overflows: said once by the caller, not by numpy per sigma point
        with np.errstate(over="ignore", invalid="ignore"):
            second = run_pass(fit)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as e:
        return None, f"{type(e).__name__}: {e}"
    if not (np.all(np.isfinite(second.omega)) and np.all(np.isfinite(second.quat))):
        return None, "non-finite states"
    return second, ""


def _evidence(a: TrackResult, b: TrackResult) -> tuple[float, float]:
    """Summed log-likelihood of two passes' innovations over the steps where both have one."""
    if a.log_likelihood is None or b.log_likelihood is None:
        return float("nan"), float("nan")
    La = np.asarray(a.log_likelihood, dtype=np.float64)
    Lb = np.asarray(b.log_likelihood, dtype=np.float64)
    both = np.isfinite(La) & np.isfinite(Lb)
    return float(La[both].sum()), float(Lb[both].sum())


def rigid_body_pass(
    first: TrackResult,
    run_pass: Callable[[InertiaFit], TrackResult],
    *,
    skip: int,
    refine: bool = True,
) -> tuple[TrackResult, dict[str, Any]]:
    """The relative state of a torque-free tumbling target, from a first pass.

    **[interpretation]** The inertia's shape is fitted to the first pass's rates after its
    first ``skip`` steps (:func:`~relnav.navigation.state.inertia.fit_inertia`); with ``refine`` the
    fit is refined on its attitudes (:func:`~relnav.navigation.state.inertia.refine_inertia`: a
    filter's rates lag, which biases the rate fit on a near-axisymmetric tumble). A second pass
    runs with each fit; of two, the one whose innovations have the larger summed
    log-likelihood (over the steps where both have one) is kept, as a bank of filters weighs
    its members. A spin reveals no inertia, and a pass that diverges is refused: the first pass
    then stands.

    Parameters
    ----------
    first : TrackResult
        The first pass (body rates and attitudes, observed attitudes).
    run_pass : callable
        ``run_pass(fit)`` runs the second pass with the inertia ``fit.inertia`` and the
        angular acceleration ``fit.residual`` (rad/s²) as its process noise.
    skip : int
        First-pass steps left out of the fits (converging).
    refine : bool
        Refine the rate fit on the attitudes and keep the likelier pass.

    Returns
    -------
    TrackResult, dict
        The pass kept and what the choice saw: ``inertia_identified``, ``principal_inertia``,
        ``inertia_residual_rad_s2``, ``inertia_source`` (``"rates"`` or ``"attitudes"``),
        ``inertia_log_likelihood`` (per source, when both ran) and ``inertia_rejected`` (why a
        pass was refused).
    """
    meta: dict[str, Any] = {}
    fit = fit_inertia(first.time[skip:], first.omega[skip:])
    meta["inertia_identified"] = fit is not None
    if fit is None:
        return first, meta
    fits = {"rates": fit}
    if refine:
        sl = slice(skip, None)
        try:
            refined = refine_inertia(
                fit, first.time[sl], first.observed[sl, 3:], first.quat[sl], first.omega[sl]
            )
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as e:
            log.warning("rigid body: inertia not refined (%s: %s)", type(e).__name__, e)
            refined = None
        if refined is not None:
            fits["attitudes"] = refined
    passes: dict[str, TrackResult] = {}
    refused = []
    for source, f in fits.items():
        second, why = _second_pass(run_pass, f)
        if second is None:
            refused.append(f"{source}: {why}")
        else:
            passes[source] = second
    if refused:
        # Euler's equations with a wild fit can diverge
        log.warning("rigid body: second pass refused (%s)", "; ".join(refused))
        meta["inertia_rejected"] = "; ".join(refused)
    if not passes:
        return first, meta
    source = next(iter(passes))
    if len(passes) == 2:
        ll = _evidence(passes["rates"], passes["attitudes"])
        meta["inertia_log_likelihood"] = {"rates": ll[0], "attitudes": ll[1]}
        source = "attitudes" if ll[1] > ll[0] else "rates"
    meta["inertia_source"] = source
    meta["principal_inertia"] = fits[source].principal.tolist()
    meta["inertia_residual_rad_s2"] = fits[source].residual
    return passes[source], meta
