"""Paper 1's adaptive αβ filter over correspondences (eqs. 22–25; ALGORITHMS §D.2, §D.4).

Coherent form (default, **[interpretation]** §D.4), for each correspondence ``u`` in ascending
descriptor distance (``a_u`` from the target ``P_k`` builds ``H_u``, ``ψ_u = b_u`` from the source
``P_{k+1}``)::

    x⁻ = x + Δt v
    e  = ψ_u − H_u x⁻
    r  = H_u⁺ e = H_uᵀ e / (‖a_u‖² + 1)      (minimum-norm state-space residual)
    x  = x⁻ + α_u r
    v  = v + (β_u / Δt) r
    α_u = α₀ / (1 + M_u),  β_u = β₀ / (1 + M_u)     defaults α₀ = 0.5, β₀ = 0, Δt = 1, v₀ = 0

With ``β₀ = 0`` this is an adaptive-gain normalised-LMS; ``α ∈ (0, 2)`` makes every update a
contraction towards the measurement's solution set. By default the sweeps are repeated until
the state settles, in whitened coordinates with one normaliser for the whole set
(``normalise="set"``, :func:`~relnav.estimation._recursive.run_nlms`), and each sweep's output
is the mean of its iterates (``average``): the converged filter is then close to the fit
weighted by ``α_u``. Measured on the same GCC correspondences (fixed model cloud with the
presets' 1 cm noise, first 30 frames of the five HPR presets × six descriptors,
``benchmarks/paper1/paper1_estimators_same_corr.py``): the four converged filters' T_error are
within 2× of each other on 24 of 30 pairs (one sweep: 10 of 30).

``paper_literal=True`` implements the printed eqs. 22–25 verbatim::

    x_k = x_{k−1} + V Δt ;  r = x_{k−1} − x_k ;  x_k = x_k + α r ;  V = V − (β/Δt) x_k
    V₀ = 1 (every component), Δt = 1e-5, α = 1e-6, β = M (eq. 11; by default the printed sum)

As printed the residual never involves a measurement: the output depends only on ``M``, ``α``,
``Δt``, ``V₀`` and the number of correspondences, not on the points. In the scaled variable
``u = V Δt`` one step is the linear map ``[[1, 1−α], [−β, 1 − β(1−α)]]`` (determinant 1), so the
state oscillates without decaying for ``0 < β(1−α) < 4`` and diverges for larger ``β`` (then the
estimate is flagged ``failed``). It is provided for comparison only.

The filter's own output is ``T_source_target``; the single inversion to ``T_target_source`` is in
:mod:`relnav.estimation._recursive`. No state covariance exists: ``covariance="residual"``
(Gauss–Newton from the post-fit residuals) is the default.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numba import njit

from relnav.errors import ConfigError
from relnav.estimation._recursive import (
    RecursiveEstimator,
    _check_positive,
    _RunOutput,
    nlms_options,
    run_nlms,
)
from relnav.estimation.base import register_estimator

__all__ = ["AlphaBetaEstimator"]


@njit(cache=True)
def _alphabeta_printed_kernel(
    x: np.ndarray,
    v: np.ndarray,
    beta: np.ndarray,
    alpha: float,
    dt: float,
    n_passes: int,
    tol: float,
) -> tuple[int, float]:
    """Eqs. 22–25 verbatim, in place on ``x`` (12,) and ``v`` (12,)."""
    n = beta.shape[0]
    xs = np.empty(12)
    step = 0.0
    passes = 0
    for _p in range(n_passes):
        passes += 1
        xs[:] = x
        for u in range(n):
            for k in range(12):
                x_prev = x[k]
                xk = x_prev + v[k] * dt  # (22)
                r = x_prev - xk  # (23)
                xk = xk + alpha * r  # (24)
                v[k] = v[k] - beta[u] / dt * xk  # (25)
                x[k] = xk
        step = 0.0
        for k in range(12):
            step += (x[k] - xs[k]) ** 2
        step = np.sqrt(step)
        if step <= tol:
            break
    return passes, step


@register_estimator("alphabeta", "Paper 1 adaptive alpha-beta filter over correspondences (§D.4)")
class AlphaBetaEstimator(RecursiveEstimator):
    """Adaptive αβ filter of Paper 1 (coherent §D.4 by default).

    Parameters
    ----------
    alpha : float, optional
        Coherent: ``α₀`` (default 0.5, ``α_u = α₀/(1+M_u)``). Literal: ``α`` (default 1e-6).
    beta : float, optional
        Coherent: ``β₀`` (default 0, ``β_u = β₀/(1+M_u)``). Literal: must be None (``β = M``).
    dt : float, optional
        ``Δt``; coherent default 1, literal 1e-5.
    v0 : float, optional
        Initial velocity (every component); coherent default 0, literal 1 (Paper 1 "V_k = 1").
    average : bool, optional
        Coherent filter only: each sweep's output is the mean of its iterates
        **[interpretation]** (default True; False with ``paper_literal=True``). A constant-gain
        filter cycling over inconsistent measurements ends each sweep on a limit cycle pulled
        towards the LAST matches, i.e. the worst ones (ascending descriptor distance); the
        sweep mean is much closer to the fixed point of the whole set.
    **kwargs
        Common options of :class:`~relnav.estimation._recursive.RecursiveEstimator`
        (``covariance`` default ``"residual"``).
    """

    name = "alphabeta"

    def __init__(
        self,
        *,
        alpha: float | None = None,
        beta: float | None = None,
        dt: float | None = None,
        v0: float | None = None,
        average: bool | None = None,
        normalise: Literal["set", "sample"] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self.average, self.normalise = nlms_options(
            self.name, self.paper_literal, average, normalise
        )
        lit = self.paper_literal
        if lit and beta is not None:
            raise ConfigError("alphabeta: with paper_literal=True β = M (eq. 11); leave beta unset")
        self.alpha = _check_positive("alpha", (1e-6 if lit else 0.5) if alpha is None else alpha)
        self.beta = _check_positive("beta", 0.0 if beta is None else beta, allow_zero=True)
        self.dt = _check_positive("dt", (1e-5 if lit else 1.0) if dt is None else dt)
        self.v0 = float((1.0 if lit else 0.0) if v0 is None else v0)
        if not np.isfinite(self.v0):
            raise ConfigError(f"alphabeta: v0 must be finite, got {v0!r}")

    def _options(self) -> dict[str, Any]:
        return {
            "alpha": self.alpha,
            "beta": self.beta,
            "dt": self.dt,
            "v0": self.v0,
            "average": self.average,
            "normalise": self.normalise,
        }

    def _run(self, x0: np.ndarray, a: np.ndarray, b: np.ndarray, m: np.ndarray) -> _RunOutput:
        x = x0.copy()
        v = np.full(12, self.v0)
        if self.paper_literal:
            with np.errstate(over="ignore", invalid="ignore"):
                passes, step = _alphabeta_printed_kernel(
                    x, v, m, self.alpha, self.dt, self.n_passes, self.tol
                )
        else:
            alpha_u = self.alpha / (1.0 + m)
            beta_u = self.beta / (1.0 + m)
            passes, step = run_nlms(
                x,
                v,
                a,
                b,
                alpha_u,
                beta_u,
                np.ones_like(m),
                self.dt,
                self.n_passes,
                self.tol,
                self.average,
                self.normalise,
            )
        return _RunOutput(x=x, P=None, passes=passes, last_sweep_step=step, info={})
