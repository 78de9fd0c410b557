"""How far could a flag built from the navigator's own evidence go? The ceiling of relnav's flags.

    python benchmarks/nav/nav_flag_ceiling.py --out bench/nav               # every group
    python benchmarks/nav/nav_flag_ceiling.py --out bench/nav --groups stress,jitter-holdout

The navigation suite's target for the flags is, on every sequence, at least 90 % of the wrong
steps (> 0.5 m or 5°) flagged and at most 5 % of the right ones. This script runs ``relnav``
(default options and the mission input, causal) on the chosen groups, records every step's
evidence that needs no ground truth (:data:`relnav.bench.nav_suite.EVIDENCE`: its covariance's
1σ, the exceedance probability, χ² against the motion model, robust RMS, fitness, overlap,
degeneracy, …) and asks how well any rule on that evidence *could* separate wrong steps from
right ones, with the ground truth used to choose the rule (so every figure is an upper bound):

1. **Per sequence, one feature, threshold chosen on that sequence's truth**: the fraction of its
   wrong steps above the threshold that flags 5 % of its right ones (either direction).
2. **One threshold for all sequences** (chosen on the pooled truth), per feature.
3. **All features together**: a logistic regression on the log features, trained on the other
   sequences and tested on each held-out one (leave one sequence out), its threshold at 5 % of
   the training sequences' right steps.

It prints the relnav flags' own counts beside them, then **which wrong steps the flags catch**:
pooled over the sequences, by how far the step is beyond the limits (``max(e_t / 0.5 m,
e_r / 5°)``) and by how far beyond its own 1σ (``max(e_t / σ_t, e_r / σ_r)``, the step's
translation and rotation 1σ that the flags use). Per-step data are cached in
``OUT/flag_ceiling/<sequence>.npz`` (delete them to re-run; a cache without the step errors is
run again).
"""

from __future__ import annotations

import argparse
import itertools
import math
from pathlib import Path

import numpy as np

from relnav.bench.nav_suite import (
    EVIDENCE,
    GROUPS,
    WRONG_STEP,
    group,
    paper,
    run_method,
    simulate_suite,
)

RIGHT_FLAGGED = 0.05
FEATURES = (*EVIDENCE, "fitness")
STEP_ERRORS = ("error_t", "error_r")
SIZE_BINS = (1.0, 1.5, 2.0, 5.0, np.inf)
SIGMA_BINS = (0.0, 2.0, 3.0, 5.0, 10.0, np.inf)


def caught_by_bins(
    data: dict[str, dict[str, np.ndarray]], ratio: str, bins: tuple[float, ...]
) -> list[tuple[float, float, int, int]]:
    """The wrong steps pooled over ``data``, binned by ``ratio`` (``"limits"``: how far beyond
    the limits, ``max(e_t / 0.5 m, e_r / 5°)``; ``"sigma"``: how far beyond the step's own 1σ,
    ``max(e_t / σ_t, e_r / σ_r)``, NaN σ counted as the last bin): per bin ``(low, high, wrong,
    of them flagged)``."""
    x, fl = [], []
    for d in data.values():
        w = d["wrong"].astype(bool)
        if ratio == "limits":
            r = np.maximum(d["error_t"] / WRONG_STEP[0], d["error_r"] / WRONG_STEP[1])
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.maximum(
                    d["error_t"] / d["step_sigma_t"], d["error_r"] / d["step_sigma_r_deg"]
                )
            r = np.where(np.isfinite(r), r, np.inf)
        x.append(r[w])
        fl.append(d["flagged"].astype(bool)[w])
    r, f = np.concatenate(x), np.concatenate(fl)
    out = []
    for lo, hi in itertools.pairwise(bins):
        m = (r > lo) & (r <= hi)
        out.append((lo, hi, int(m.sum()), int((m & f).sum())))
    return out


def collect(out: Path, groups: list[str]) -> dict[str, dict[str, np.ndarray]]:
    """Each sequence's ``wrong``, ``flagged`` and evidence arrays (cached in ``out``)."""
    names: list[str] = []
    for g in groups:
        names += list(group(g)) + (list(paper()) if g == "suite" else [])
    folders = simulate_suite(out, names)
    cache = out / "flag_ceiling"
    cache.mkdir(parents=True, exist_ok=True)
    data = {}
    for name in names:
        f = cache / f"{name}.npz"
        stale = True
        if f.exists():
            with np.load(f) as z:
                stale = not set(STEP_ERRORS) <= set(z.files)
        if stale:
            st = run_method(folders[name], "relnav", per_step=True)["steps"]
            errors = {k: st[k] for k in STEP_ERRORS}
            np.savez(f, wrong=st["wrong"], flagged=st["flagged"], **errors, **st["evidence"])
            print(f"{name:24s} {int(st['wrong'].sum()):3d} wrong of {len(st['wrong'])}", flush=True)
        with np.load(f) as z:
            data[name] = {k: z[k] for k in z.files}
    return data


def caught_at(score: np.ndarray, wrong: np.ndarray, q: float = RIGHT_FLAGGED) -> float:
    """Fraction of the wrong steps whose score exceeds the threshold that flags a fraction ``q``
    of the right ones, the better of flagging high or low values (NaN never flags)."""
    best = 0.0
    for s in (score, -score):
        s = np.where(np.isfinite(s), s, -np.inf)
        right = np.sort(s[~wrong])[::-1]
        k = math.floor(q * len(right))
        th = right[k] if k < len(right) else -np.inf
        best = max(best, float(np.mean(s[wrong] > th)) if wrong.any() else 1.0)
    return best


def _design(d: dict[str, np.ndarray]) -> np.ndarray:
    X = np.stack([d[k] for k in FEATURES], axis=1)
    X = np.where(np.isfinite(X), X, np.nan)
    return np.sign(X) * np.log1p(np.abs(X))


def logistic(X: np.ndarray, y: np.ndarray, ridge: float = 1e-2, iters: int = 50):
    """A ridge logistic regression (Newton's method) on standardised features (NaN → the mean);
    returns the scoring function."""
    mu, sd = np.nanmean(X, axis=0), np.nanstd(X, axis=0) + 1e-9

    def design(A: np.ndarray) -> np.ndarray:
        Z = np.nan_to_num((A - mu) / sd)
        return np.c_[np.ones(len(Z)), Z]

    Z, w = design(X), np.zeros(X.shape[1] + 1)
    for _ in range(iters):
        p = 1.0 / (1.0 + np.exp(-np.clip(Z @ w, -50.0, 50.0)))
        g = Z.T @ (p - y) + ridge * w
        H = (Z * (p * (1 - p))[:, None]).T @ Z + ridge * np.eye(len(w))
        w -= np.linalg.solve(H, g)
    return lambda A: design(A) @ w


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--groups", default=",".join(GROUPS), help=f"of {', '.join(GROUPS)}")
    a = p.parse_args(argv)
    data = collect(a.out, [g for g in a.groups.split(",") if g])

    print(
        f"\nPer sequence: wrong steps; relnav's flags (wrong, right); the best single feature "
        f"with its threshold chosen on the sequence's truth at {RIGHT_FLAGGED:.0%} of right "
        "steps flagged; the logistic regression trained on the other sequences.\n"
    )
    print(
        "| sequence | wrong / steps | relnav flags: wrong, right | best feature (oracle) | "
        "logistic, left out: wrong, right |\n|---|---|---|---|---|"
    )
    totals = dict.fromkeys(("wrong", "right", "fw", "fr", "oracle", "lw", "lr", "mixed", "mw"), 0)
    X_all = {n: _design(d) for n, d in data.items()}
    for name, d in data.items():
        w, fl = d["wrong"].astype(bool), d["flagged"].astype(bool)
        others = [n for n in data if n != name]
        Xtr = np.vstack([X_all[n] for n in others])
        ytr = np.concatenate([data[n]["wrong"].astype(float) for n in others])
        score = logistic(Xtr, ytr)
        s_tr = score(Xtr)
        th = np.percentile(s_tr[ytr == 0], 100 * (1 - RIGHT_FLAGGED))
        s = score(X_all[name]) > th
        per = {k: caught_at(d[k], w) for k in FEATURES}
        best = max(per, key=per.get)
        nw, nr = int(w.sum()), int((~w).sum())
        totals["wrong"] += nw
        totals["right"] += nr
        totals["fw"] += int((w & fl).sum())
        totals["fr"] += int((~w & fl).sum())
        totals["oracle"] += round(per[best] * nw)
        if nw and nr:  # sequences with both kinds of step: the oracle had to choose
            totals["mixed"] += nw
            totals["mw"] += round(per[best] * nw)
        totals["lw"] += int((w & s).sum())
        totals["lr"] += int((~w & s).sum())
        oracle = f"{best} {per[best]:.0%}" if nw and nr else "—"
        print(
            f"| {name} | {nw} / {len(w)} | {int((w & fl).sum())}, {int((~w & fl).sum())} | "
            f"{oracle} | {int((w & s).sum())}, {int((~w & s).sum())} |"
        )
    t = totals
    print(
        f"\nAll sequences: {t['wrong']} wrong and {t['right']} right steps. relnav's flags: "
        f"{t['fw']} wrong ({t['fw'] / t['wrong']:.1%}), {t['fr']} right "
        f"({t['fr'] / t['right']:.1%}). Best single feature per sequence, threshold on its "
        f"truth: {t['oracle']} wrong ({t['oracle'] / t['wrong']:.1%}; a sequence whose steps are "
        f"all wrong counts as caught; on the sequences with both kinds {t['mw']} of "
        f"{t['mixed']}, {t['mw'] / max(t['mixed'], 1):.1%}). Logistic, left out: {t['lw']} wrong "
        f"({t['lw'] / t['wrong']:.1%}), {t['lr']} right ({t['lr'] / t['right']:.1%})."
    )
    print(
        f"\nOne threshold for every sequence (chosen on the pooled truth), wrong steps caught at "
        f"{RIGHT_FLAGGED:.0%} of the right ones flagged:\n"
    )
    w_all = np.concatenate([d["wrong"].astype(bool) for d in data.values()])
    for k in FEATURES:
        v = np.concatenate([d[k] for d in data.values()])
        print(f"- {k}: {caught_at(v, w_all):.1%}")
    for ratio, bins, what in (
        ("limits", SIZE_BINS, "how far beyond the limits: max(e_t / 0.5 m, e_r / 5°)"),
        ("sigma", SIGMA_BINS, "how far beyond its own 1σ: max(e_t / σ_t, e_r / σ_r)"),
    ):
        print(f"\nThe wrong steps by {what}, and relnav's flags on them:\n")
        print("| ratio | wrong steps | flagged |\n|---|---|---|")
        for lo, hi, n, f in caught_by_bins(data, ratio, bins):
            share = f"{f} ({f / n:.0%})" if n else "–"
            print(f"| {lo:g}–{hi:g} | {n} | {share} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
