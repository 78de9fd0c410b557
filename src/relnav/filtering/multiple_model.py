"""A bank of filters weighed by the likelihood of their innovations.

Multiple-model adaptive estimation (Magill 1965; Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation*, §11.6): the same observations run through ``M``
filters that differ in one modelling choice (say, how fast the target's rate may change); after
each update every member's probability is multiplied by the Gaussian likelihood of its
innovation, ``N(ν; 0, S)``, and the output is the probability-weighted mixture. No truth is
involved: the data say which model explains them.

**[interpretation]** An observation the most probable member rejects (its χ² gate) is an
outlier, not evidence: its step leaves the probabilities as they were. Scored like any other,
one wrong scan would hand the bank to its loosest member, which then follows the outlier
(measured on envisat-tumble-64, ``docs/results/nav/state_hold_point.md``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from relnav.errors import InputError
from relnav.filtering.track_result import TrackResult

__all__ = ["mix_tracks", "model_probabilities"]

log = logging.getLogger(__name__)


def model_probabilities(
    log_likelihood: np.ndarray, floor: float = 1e-3, rejected: np.ndarray | None = None
) -> np.ndarray:
    """Each member's probability after each step, from the log-likelihoods of its updates.

    Parameters
    ----------
    log_likelihood : (K, M) float64
        Log-likelihood of each member's innovation per step (NaN where it had no update).
    floor : float
        Lower bound of a member's probability (then renormalized), so that a member can take
        over again when the target's behaviour changes (0 = pure Bayes, which locks in).
    rejected : (K, M) bool, optional
        Where a member rejected the step's observation (gated it). A step rejected by the
        member most probable before it carries no evidence: the probabilities stay.

    Returns
    -------
    (K, M) float64
        Rows sum to 1; equal weights until the first step with evidence. A member without
        an update where another had one is scored like the worst member of that step.
    """
    L = np.asarray(log_likelihood, dtype=np.float64)
    if L.ndim != 2 or L.shape[1] < 1:
        raise InputError(f"log-likelihoods must be (K, M), got {L.shape}")
    if not 0.0 <= floor < 1.0 / L.shape[1]:
        raise InputError(f"floor must be in [0, 1/M), got {floor!r}")
    K, M = L.shape
    if rejected is not None and np.shape(rejected) != (K, M):
        raise InputError(f"rejected must be {(K, M)}, got {np.shape(rejected)}")
    out = np.empty((K, M))
    logp = np.full(M, -np.log(M))
    for k in range(K):
        row = L[k]
        outlier = rejected is not None and bool(rejected[k, int(np.argmax(logp))])
        if np.any(np.isfinite(row)) and not outlier:
            logp = logp + np.where(np.isfinite(row), row, np.nanmin(row))
            logp -= logp.max()
            p = np.exp(logp)
            p /= p.sum()
            if floor > 0.0:
                p = np.maximum(p, floor)
                p /= p.sum()
            logp = np.log(p)
        out[k] = np.exp(logp)
    return out


def mix_tracks(
    tracks: Sequence[TrackResult], labels: Sequence[str] | None = None, floor: float = 1e-3
) -> TrackResult:
    """Probability-weighted mixture of tracks of the same observations.

    Parameters
    ----------
    tracks : sequence of TrackResult
        The bank's members, same time steps, each with ``log_likelihood``.
    labels : sequence of str, optional
        One name per member (``meta["models"]`` of the result).
    floor : float
        See :func:`model_probabilities`.

    An observation the most probable member rejected (status ``flagged: …``) is no evidence
    (:func:`model_probabilities` ``rejected``).

    Returns
    -------
    TrackResult
        Per step the mixture's mean (attitude: the members' rotations averaged in the tangent
        space of the most probable one) and covariance ``Σ pᵢ (Pᵢ + dᵢ dᵢᵀ)`` (``dᵢ`` the
        member's offset from the mean), the most probable member's status, NIS and settings,
        ``model_probability`` ``(K, M)`` and as ``log_likelihood`` the mixture's predictive
        likelihood ``log Σ pᵢ(k−1) exp(ℓᵢ(k))``.
    """
    if not tracks:
        raise InputError("no tracks to mix")
    K, M = len(tracks[0]), len(tracks)
    if any(len(t) != K for t in tracks):
        raise InputError("tracks to mix must have the same steps")
    if any(t.log_likelihood is None for t in tracks):
        raise InputError("tracks to mix need their log-likelihoods (Tracker.run records them)")
    names = list(labels) if labels is not None else [f"model {i}" for i in range(M)]
    if len(names) != M:
        raise InputError(f"{len(names)} labels for {M} tracks")
    L = np.column_stack([np.asarray(t.log_likelihood, dtype=np.float64) for t in tracks])
    rejected = np.array([[s.startswith("flagged") for s in t.status] for t in tracks]).T
    P = model_probabilities(L, floor, rejected)
    best = np.argmax(P, axis=1)
    first = tracks[0]
    pos, vel = np.full((K, 3), np.nan), np.full((K, 3), np.nan)
    om, quat = np.full((K, 3), np.nan), np.full((K, 4), np.nan)
    cov = np.full((K, 12, 12), np.nan)
    # the most probable member's status and NIS (no mixture of those)
    status = [tracks[b].status[k] for k, b in enumerate(best)]
    nis = np.array([tracks[b].nis[k] for k, b in enumerate(best)], dtype=np.float64)
    for k in range(K):
        live = [i for i in range(M) if np.all(np.isfinite(tracks[i].quat[k]))]
        if not live:
            continue
        w = P[k, live] / P[k, live].sum()
        ref = Rotation.from_quat(tracks[best[k]].quat[k])
        rot = Rotation.from_quat(np.stack([tracks[i].quat[k] for i in live]))
        mean_att = ref * Rotation.from_rotvec(w @ (ref.inv() * rot).as_rotvec())
        X = np.stack(
            [
                np.r_[tracks[i].position[k], tracks[i].velocity[k], np.zeros(3), tracks[i].omega[k]]
                for i in live
            ]
        )
        X[:, 6:9] = (mean_att.inv() * rot).as_rotvec()
        mean = w @ X
        mean[6:9] = 0.0
        D = X - mean
        C = np.einsum("i,ijk->jk", w, np.stack([tracks[i].covariance[k] for i in live]))
        cov[k] = C + np.einsum("i,ij,ik->jk", w, D, D)
        pos[k], vel[k], om[k] = mean[0:3], mean[3:6], mean[9:12]
        quat[k] = mean_att.as_quat()
    prior = np.vstack([np.full(M, 1.0 / M), P[:-1]])
    with np.errstate(invalid="ignore", divide="ignore"):
        top = np.nanmax(L, axis=1, initial=-np.inf)
        mixed = top + np.log(np.nansum(prior * np.exp(L - top[:, None]), axis=1))
    mixed[~np.any(np.isfinite(L), axis=1)] = np.nan
    last = tracks[int(best[-1])]
    return TrackResult(
        time=first.time,
        position=pos,
        velocity=vel,
        quat=quat,
        omega=om,
        covariance=cov,
        status=status,
        nis=nis,
        observed=first.observed,
        filter=first.filter,
        settings={**last.settings, "bank": names, "floor": float(floor)},
        truth=first.truth,
        meta={**first.meta, "models": names},
        log_likelihood=mixed,
        model_probability=P,
    )
