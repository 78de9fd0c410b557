"""Starts for registering a scan again when the motion model's rotation is uncertain.

**[interpretation]** Under the chaser's attitude jitter (learned by
:meth:`~relnav.navigation.motion.ConstantVelocityFilter.adapt_jitter`) the scan's cost can have
other minima within the jitter's reach of the prediction, and the solver, started at the
prediction, stops in the nearest. The navigator registers the scan again from the prediction
turned by ``±k σ_j`` about each sensor axis (``k = 1 … jitter_starts``, ``σ_j`` the learned
jitter's 1σ per axis) and keeps the answer of lowest objective (``prior.jitter_choice``: the
robust cost at its pairs plus its χ² against the prior, what the solver minimises; lowest robust
RMS, the scan's fit alone, before session 31). Measured on
the stress group (causal, ``nav_suite.py --stress``): envisat-jitter1 wrong steps 50 → 10,
envisat-jitter2 97 → 55, envisat-jitter0.5 5 → 0; ``k = 1.5`` alone or ``2.5`` alone did worse
(15 and 28 wrong on envisat-jitter1; measured with the lowest robust RMS kept).

**[interpretation]** The lowest objective rather than the lowest RMS (session 31): along a
nearly flat direction of the scan's cost (a near-symmetric target) the answers' RMS differ by
little, and the RMS alone let the track walk along it from frame to frame; the objective lets
the prior decide there (docs/navigator.md, session 31).

**[interpretation]** The starts are screened by default (``prior.jitter_screen``,
:meth:`relnav.navigation.solver.MapSolver.solve_starts`): each is registered on every third scan
point, and only the two that fit those points best are registered on the whole scan; this halves
a jittered frame's time with wrong steps fewer or within the perturbations' spread
(docs/navigator.md, session 30).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from relnav.geometry.lie import exp_se3

__all__ = ["kept_answer", "rotated_starts"]


def rotated_starts(T_pred: np.ndarray, sigma_rad: float, multiples: int) -> list[np.ndarray]:
    """``T_pred · exp([0, ±k σ eᵢ])`` for ``k = 1 … multiples`` and the three sensor axes
    ``eᵢ`` (body frame): ``6 · multiples`` poses ``(4, 4)``."""
    starts = []
    for k in range(1, int(multiples) + 1):
        for axis in range(3):
            for sign in (-1.0, 1.0):
                w = np.zeros(6)
                w[3 + axis] = sign * k * float(sigma_rad)
                starts.append(T_pred @ exp_se3(w))
    return starts


def kept_answer(answers: list[dict[str, Any]], choice: str = "objective") -> dict[str, Any]:
    """The answer kept among the prediction's (first, kept unless another beats it) and the
    extra starts': the usable one of lowest ``"objective"`` (robust cost plus χ² against the
    prior) or, with ``choice="rms"``, of lowest robust RMS; ties keep the earlier answer."""
    key = "rms" if choice == "rms" else "objective"
    fit = answers[0]
    for alt in answers[1:]:
        if alt["usable"] and alt[key] < fit[key]:
            fit = alt
    return fit
