"""Noise scales of the relative state chosen by the likelihood of its innovations.

System identification without ground truth (:func:`fit_noise_scales`): what a user can run on
their own recorded navigator runs before freezing :func:`relnav.navigation.state.relative_state`'s
settings. Measured on the tumbling sequences: ``docs/results/nav/state_noise_scales.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from relnav.errors import ConfigError
from relnav.navigation.state.relative import check_state_options, relative_state

__all__ = ["NOISE_SCALES", "fit_noise_scales"]

NOISE_SCALES = ("drift_scale", "drift_rotation_scale", "measurement_scale")


def fit_noise_scales(
    runs: Sequence[Any],
    *,
    names: Sequence[str] = NOISE_SCALES,
    start: Sequence[float] | None = None,
    bounds: tuple[float, float] = (1e-3, 1e3),
    max_evaluations: int = 60,
    **options: Any,
) -> dict[str, Any]:
    """Noise scales of :func:`relative_state` that maximise its innovations' likelihood.

    **[interpretation]** System identification without ground truth: the summed Gaussian
    log-likelihood of the filter's innovations (:attr:`TrackResult.log_likelihood`, i.e. the
    log-density of the observations under the noise model) over ``runs`` is maximised with
    respect to the scales ``names`` (options of :func:`relative_state` taking a number > 0),
    by Nelder–Mead on their logarithms (first simplex: the start and each scale divided by 4),
    each kept within ``bounds``. What a user can run on
    their own recorded runs before freezing the settings.

    Parameters
    ----------
    runs : sequence
        Navigator runs (what :func:`relative_state` takes as ``run``; their ``steps`` are used).
    names : sequence of str
        The scales to fit (default :data:`NOISE_SCALES`).
    start : sequence of float, optional
        Initial scales (default 1 each).
    bounds : (float, float)
        Smallest and largest scale.
    max_evaluations : int
        Function evaluations of the search (one :func:`relative_state` per run each).
    **options
        Further options of :func:`relative_state`, held fixed.

    Returns
    -------
    dict
        ``scales`` (name → value), ``log_likelihood`` (summed over the runs, at the scales),
        ``start_log_likelihood`` (at ``start``) and ``evaluations``.
    """
    from scipy.optimize import minimize

    names = list(names)
    first = np.ones(len(names)) if start is None else np.asarray(start, dtype=float)
    if first.shape != (len(names),) or not np.all(np.isfinite(first) & (first > 0.0)):
        raise ConfigError(f"start must hold {len(names)} scales > 0, got {start!r}")
    x0 = np.log(first)
    lo, hi = np.log(float(bounds[0])), np.log(float(bounds[1]))
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ConfigError(f"bounds must be 0 < low < high, got {bounds!r}")
    check_state_options(options)
    cache: dict[tuple[float, ...], float] = {}

    def total(x: np.ndarray) -> float:
        key = tuple(np.round(np.clip(x, lo, hi), 6))
        if key not in cache:
            scales = dict(zip(names, np.exp(key), strict=True))
            ll = 0.0
            for run in runs:
                res = relative_state(run, **options, **scales)
                ll += float(np.nansum(np.asarray(res.log_likelihood, dtype=float)))
            cache[key] = ll
        return cache[key]

    ll0 = total(np.clip(x0, lo, hi))
    # initial simplex: the start and each scale divided by 4 in turn
    x0 = np.clip(x0, lo, hi)
    simplex = np.vstack([x0, x0 - np.log(4.0) * np.eye(len(names))])
    out = minimize(
        lambda x: -total(x),
        x0,
        method="Nelder-Mead",
        options={
            "maxfev": int(max_evaluations),
            "xatol": 0.05,
            "fatol": 1.0,
            "initial_simplex": simplex,
        },
    )
    best = np.clip(out.x, lo, hi)
    return {
        "scales": {n: float(v) for n, v in zip(names, np.exp(best), strict=True)},
        "log_likelihood": total(best),
        "start_log_likelihood": ll0,
        "evaluations": len(cache),
    }
