"""Can any scale of the contour observer's covariance make paper 2's tracker consistent? (issue 15)

On the recorded observations of ``benchmarks/paper2/paper2_experiment.py`` (run it first with the
same
``--work``), the main variant (UKF, centre offset, observer bias) is re-run with the observer's
covariance ``R`` scaled by ``a`` and the bias drift (the previous observation's covariance)
scaled by ``b``, the bias in sensor or in body axes. Printed per setting: the pooled mean NIS
(innovations are white when the filter is consistent, so the band of their pooled mean is the
right test) and mean NEES with their bands, and the fraction of time steps whose seed-averaged
NEES lies in the band of a mean of that many runs (the Monte Carlo test: a filter's errors are
correlated from step to step, so the pooled NEES band is too narrow).

    python benchmarks/paper2/paper2_noise_sweep.py --work WORK --seeds 20 [--first-seed 0]

Truth as in the experiment (the rotation centre for a centre-offset filter).
"""

from __future__ import annotations

import argparse
import itertools
import sys
import warnings
from pathlib import Path

import numpy as np
from paper2_experiment import OMEGA0, _band, _pack, _truth_for, recorded_observations

from relnav.filtering.tracker import Tracker


def consistency(
    recs: list[dict[str, np.ndarray]], a: float, b: float, bias_frame: str
) -> dict[str, float]:
    """Mean NIS, mean NEES and the fraction of steps whose seed-averaged NEES is in its band."""
    nis, nees = [], []
    for rec in recs:
        obs = recorded_observations(rec, "reported", a, b)
        res = Tracker(
            "ukf", omega0=OMEGA0, centre_offset=True, observer_bias=True, bias_frame=bias_frame
        ).run(rec["time"], obs)
        res.truth = _truth_for(res, rec["T_s_target"])
        p = _pack(res)
        nis.append(p["nis"])
        nees.append(p["nees"])
    N = np.asarray(nees)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        per_step = np.nanmean(N, axis=0)
    per_step = per_step[np.isfinite(per_step)]
    lo, hi = _band(12, len(recs))
    return {
        "nis": float(np.nanmean(nis)),
        "nees": float(np.nanmean(N)),
        "steps_in_band": float(np.mean((per_step >= lo) & (per_step <= hi))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="paper2_experiment.py's --work")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--distance", type=float, default=3.0)
    ap.add_argument("--r-scales", default="1,3,9,25")
    ap.add_argument("--drift-scales", default="1,3,9,25,64")
    args = ap.parse_args()
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    files = [args.work / f"obs{s:03d}_{args.frames}f_{args.distance:g}m.npz" for s in seeds]
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        sys.exit(f"no recorded observations {missing[:3]}…: run paper2_experiment.py first")
    recs = [dict(np.load(f)) for f in files]
    n_upd = sum(int(np.isfinite(r["obs"][:, 0]).sum()) - 1 for r in recs)
    print(f"{len(recs)} seeds; pooled NIS band {_band(6, n_upd)[0]:.2f}–{_band(6, n_upd)[1]:.2f}")
    print(f"per-step NEES band (mean of {len(recs)} runs) {_band(12, len(recs))}")
    print("| bias axes | R × a | drift × b | mean NIS | mean NEES | NEES steps in band |")
    print("|---|---|---|---|---|---|")
    a_s = [float(x) for x in args.r_scales.split(",")]
    b_s = [float(x) for x in args.drift_scales.split(",")]
    for frame, a, b in itertools.product(("sensor", "body"), a_s, b_s):
        c = consistency(recs, a, b, frame)
        print(
            f"| {frame} | {a:g} | {b:g} | {c['nis']:.2f} | {c['nees']:.2f} | "
            f"{100 * c['steps_in_band']:.0f} % |",
            flush=True,
        )


if __name__ == "__main__":
    main()
