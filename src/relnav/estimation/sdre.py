"""Paper 1's adaptive SDRE filter over correspondences (eq. 26; ALGORITHMS §D.2, §D.4).

Paper 1 prints only the discrete algebraic Riccati equation (DARE) with ``A = Q = σ_w I``,
``B = M I``; no update law. Coherent reading (**[interpretation]** §D.4): with ``R = σ_v² I`` all
matrices are multiples of the identity, so the stabilising DARE solution is ``X = ξ I`` with the
closed-form scalar (``a = q = σ_w``, ``b = M_u``, ``r = σ_v²``)::

    b² ξ² − (q b² − r (1 − a²)) ξ − q r = 0,   ξ = (c + sqrt(c² + 4 b² q r)) / (2 b²),
    c = q b² − r (1 − a²)

(:func:`sdre_xi`; equals ``scipy.linalg.solve_discrete_are`` on the 12×12 matrices). The scalar
DARE gain ``g_u = (BᵀXB + R)⁻¹ BᵀXA = b ξ a / (b² ξ + r)`` is used as the step size of a
normalised-LMS update, per correspondence ``u`` in ascending descriptor distance::

    x = x + g_u · H_u⁺ (ψ_u − H_u x),   H_u⁺ = H_uᵀ / (‖a_u‖² + 1)

"State-dependent" enters through the adaptive factor ``M_u`` of that match: as printed
(``m_role="input"``) through ``b = M_u``; by default (``m_role="noise"``, **[interpretation]**)
through the measurement noise ``r = M_u σ_v²`` with ``b = 1``, as the common setting's
``V ~ N(0, M σ_v² J)`` of §D.1 — the printed ``B = M I`` gives the best matches (``M_u → 0``) a
vanishing gain. Sweeps are repeated until the state settles and each sweep's output is the mean
of its iterates (``average``); see :class:`~relnav.estimation._recursive.RecursiveEstimator`.

With Paper 1's ``σ_w = 5e-3`` the gain is tiny (``g ≈ σ_w²/(1 + …)`` ≈ 2.5e-5 for ``M ≈ 1``), so
the estimate never leaves the identity; ``sigma_w_sdre`` is therefore a separate option
**[interpretation]**: default ``0.5`` (a usable gain ≈ 0.19 for ``M = 1``) for the coherent
filter, Paper 1's ``5e-3`` with ``paper_literal=True`` or when set explicitly.

``paper_literal=True`` solves the DARE **as printed** (without ``+Q``): its non-negative
solution is ``ξ = max(0, r(a² − 1)/b²)`` = 0 for ``σ_w < 1``, so the gain is 0 and the state stays
at the initialisation; ``H = M·H_u`` (eq. 10) and ``M = 10·Σ d`` by default.

The filter's own output is ``T_source_target``; the single inversion to ``T_target_source`` is in
:mod:`relnav.estimation._recursive`. No state covariance: ``covariance="residual"`` by default.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.estimation._recursive import (
    RecursiveEstimator,
    _check_positive,
    _RunOutput,
    nlms_options,
    run_nlms,
)
from relnav.estimation.base import register_estimator

__all__ = ["SDREEstimator", "sdre_gain", "sdre_xi"]


def sdre_xi(
    a: float | np.ndarray,
    b: float | np.ndarray,
    q: float | np.ndarray,
    r: float | np.ndarray,
    *,
    include_q: bool = True,
) -> np.ndarray:
    """Scalar solution ``ξ`` of the DARE ``a²ξ − ξ − a²b²ξ²/(b²ξ + r) + q = 0``.

    Parameters
    ----------
    a, b, q, r : float or array
        Scalars of ``A = aI``, ``B = bI``, ``Q = qI``, ``R = rI`` (broadcast). ``b ≠ 0``, ``r > 0``.
    include_q : bool
        False: the equation as printed in Paper 1 (eq. 26, no ``+Q``), whose non-negative
        solution is ``max(0, r(a² − 1)/b²)``.

    Returns
    -------
    ndarray
        ``ξ ≥ 0`` (the stabilising solution when ``include_q``).
    """
    a, b, q, r = (np.asarray(v, dtype=np.float64) for v in (a, b, q, r))
    b2 = b * b
    if not include_q:
        return np.maximum(0.0, r * (a * a - 1.0) / b2)
    c = q * b2 - r * (1.0 - a * a)
    # positive root, written to avoid cancellation when c < 0
    disc = np.sqrt(c * c + 4.0 * b2 * q * r)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = np.where(c >= 0, (c + disc) / (2.0 * b2), (2.0 * q * r) / (disc - c))
    return xi


def sdre_gain(xi: np.ndarray, a: float, b: np.ndarray, r: float) -> np.ndarray:
    """Scalar DARE gain ``(BᵀXB + R)⁻¹ BᵀXA = b ξ a / (b² ξ + r)``."""
    return b * xi * a / (b * b * xi + r)


@register_estimator("sdre", "Paper 1 adaptive SDRE (Riccati-gain NLMS) filter (§D.4)")
class SDREEstimator(RecursiveEstimator):
    """Adaptive SDRE filter of Paper 1 (coherent §D.4 by default).

    Parameters
    ----------
    sigma_w_sdre : float, optional
        ``A = Q = σ_w I`` of the DARE. Default 0.5 (coherent) or Paper 1's 5e-3 (literal).
    sigma_v : float
        ``R = σ_v² I`` (default 1).
    m_role : {"noise", "input"}, optional
        Where the adaptive factor enters the DARE. ``"input"`` (eq. 26 as printed, default with
        ``paper_literal=True``): ``B = M_u I``, ``R = σ_v² I``. ``"noise"`` (coherent default,
        **[interpretation]**): ``B = I``, ``R = M_u σ_v² I``, the common setting's measurement
        noise ``V ~ N(0, M σ_v² J)`` (§D.1). With ``B = M_u I`` the gain ``g_u`` is not monotonic
        in ``M_u``: it peaks near ``M_u ≈ 1`` and tends to 0 as ``M_u → 0`` (``g ≈ 0.003`` at
        ``M_u = 0.01``, 0.19 at 1, 0.01 at 50), so the best matches are the ones ignored — the
        opposite of eq. 11's purpose; with ``R = M_u σ_v²`` it decreases with ``M_u``.
    average : bool, optional
        Output the mean of each sweep's iterates (default True; False with
        ``paper_literal=True``); see :class:`~relnav.estimation.alphabeta.AlphaBetaEstimator`.
    **kwargs
        Common options of :class:`~relnav.estimation._recursive.RecursiveEstimator`
        (``covariance`` default ``"residual"``).
    """

    name = "sdre"

    def __init__(
        self,
        *,
        sigma_w_sdre: float | None = None,
        sigma_v: float = 1.0,
        average: bool | None = None,
        normalise: Literal["set", "sample"] | None = None,
        m_role: Literal["noise", "input"] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        if m_role is None:
            m_role = "input" if self.paper_literal else "noise"
        if m_role not in ("noise", "input"):
            raise ConfigError(f"sdre: m_role must be 'noise' or 'input', got {m_role!r}")
        self.m_role = m_role
        self.average, self.normalise = nlms_options(
            self.name, self.paper_literal, average, normalise
        )
        if sigma_w_sdre is None:
            sigma_w_sdre = 5e-3 if self.paper_literal else 0.5
        self.sigma_w_sdre = _check_positive("sigma_w_sdre", sigma_w_sdre)
        self.sigma_v = _check_positive("sigma_v", sigma_v)

    def _options(self) -> dict[str, Any]:
        return {
            "sigma_w_sdre": self.sigma_w_sdre,
            "sigma_v": self.sigma_v,
            "average": self.average,
            "normalise": self.normalise,
            "m_role": self.m_role,
        }

    def gains(self, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-match ``(ξ_u, g_u)`` for adaptive factors ``m`` (``b = M_u``)."""
        a = q = self.sigma_w_sdre
        if self.m_role == "input":
            b, r = m, self.sigma_v**2
        else:
            b, r = np.ones_like(m), m * self.sigma_v**2
        xi = sdre_xi(a, b, q, r, include_q=not self.paper_literal)
        return xi, sdre_gain(xi, a, b, r)

    def _run(self, x0: np.ndarray, a: np.ndarray, b: np.ndarray, m: np.ndarray) -> _RunOutput:
        x = x0.copy()
        xi, g = self.gains(m)
        hs = m if self.paper_literal else np.ones_like(m)
        passes, step = run_nlms(
            x,
            np.zeros(12),
            a,
            b,
            g,
            np.zeros_like(g),
            hs,
            1.0,
            self.n_passes,
            self.tol,
            self.average,
            self.normalise,
        )
        info = {"gain_mean": float(g.mean()), "xi_mean": float(xi.mean())}
        return _RunOutput(x=x, P=None, passes=passes, last_sweep_step=step, info=info)
