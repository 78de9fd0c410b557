"""Which direction is off on relnav's wrong steps, and how stable are the figures?

    python benchmarks/nav/nav_weak_directions.py --out bench/nav
    python benchmarks/nav/nav_weak_directions.py --out bench/nav -O map.nonplanar_gain=100 \
        --perturb 12

For each sequence (default the two with wrong steps on the suite's flash sequences,
iridium-helical-64 and orion-inclined-64) runs ``relnav`` and, for every wrong step of the
evaluated (smoothed) trajectory (> 0.5 m or 5°), takes the step's error as a body-frame twist
``[ρ, φ]`` with ``φ`` scaled by the scan's RMS radius (its lever arm) and prints the share of its
squared norm along the weakest eigen-direction of the scan's information (same frame and scaling),
the error's rotation axis in the target frame, the step's rotation in the truth and in the
estimate (the rotation part of the left twist ``log(T_k T_{k-1}⁻¹)``, target frame, degrees), and
the online step's NEES against its own step covariance (6 dof). It also prints the median, over
all frames, of the scan's information along that weakest direction divided by the motion prior's
(``> 1``: the scan, not the model, decides that direction). With ``--perturb N`` it then runs
``N`` neutral perturbations of the solver (``kernel``, ``kernel_decay``, ``max_iter``) and prints
their APE and wrong steps with the medians: on sparse scans a single run is one draw. The ground
truth is used for scoring only.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.nav_suite import (
    MISSION,
    WRONG_STEP,
    add_sequence_arguments,
    run_method,
    selected_names,
    simulate_suite,
    step_errors,
)

PERTURBATIONS: list[dict[str, str]] = [
    {},
    {"solver.kernel": "2.9"},
    {"solver.kernel": "3.1"},
    {"solver.kernel_decay": "0.58"},
    {"solver.kernel_decay": "0.62"},
    {"solver.max_iter": "32"},
    {"solver.kernel": "2.95"},
    {"solver.kernel": "3.05"},
    {"solver.kernel_decay": "0.59"},
    {"solver.kernel_decay": "0.61"},
    {"solver.max_iter": "31"},
    {"solver.max_iter": "33"},
]


def _weak_direction_figures(seq_dir: Path, options: dict[str, Any]) -> dict[str, Any]:
    """Per wrong step: share of the error in the weakest direction, rotation axis, NEES."""
    from relnav.geometry.lie import log_se3
    from relnav.geometry.se3 import adjoint, invert
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(seq_dir)
    run = run_sequence(seq, "relnav", **{**MISSION, **options})
    gt, est = seq.gt_poses, run.poses
    online = np.stack([s.pose for s in run.steps])
    et, er = step_errors(est, gt)
    rows, prior_ratio = [], []
    for k in range(1, len(gt)):
        r = run.steps[k].result
        info = {} if r is None else r.info
        H = info.get("information")
        C = info.get("step_covariance")
        if H is None:
            continue
        P = seq[k].points
        P = P[np.all(np.isfinite(P), axis=1)]
        lever = float(np.sqrt(np.mean(np.sum((P - P.mean(0)) ** 2, axis=1))))
        sc = np.array([1.0, 1.0, 1.0, lever, lever, lever])
        Ad = adjoint(r.T_target_source)
        Hb = Ad.T @ H @ Ad
        _, V = np.linalg.eigh(Hb / sc[:, None] / sc[None, :])
        weak = V[:, 0] / sc  # body-frame twist of unit scaled length
        Lam = info.get("prior_information")
        if Lam is not None:
            Lb = Ad.T @ Lam @ Ad
            prior_ratio.append(float(weak @ Hb @ weak) / max(float(weak @ Lb @ weak), 1e-300))
        if not (et[k - 1] > WRONG_STEP[0] or er[k - 1] > WRONG_STEP[1]):
            continue
        e = log_se3(invert(invert(gt[k - 1]) @ gt[k]) @ (invert(est[k - 1]) @ est[k]))
        eo = log_se3(invert(invert(gt[k - 1]) @ gt[k]) @ (invert(online[k - 1]) @ online[k]))
        z = e * sc
        share = float((V[:, 0] @ z) ** 2 / max(z @ z, 1e-300))
        axis = gt[k][:3, :3] @ e[3:]
        nees = float(eo @ np.linalg.solve(C, eo)) if C is not None else float("nan")
        turn = [log_se3(T[k] @ invert(T[k - 1]))[3:] for T in (gt, est)]
        rows.append((k, et[k - 1], er[k - 1], share, axis, nees, *turn))
    return {"rows": rows, "prior_ratio": prior_ratio}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    p.set_defaults(only="iridium-helical-64,orion-inclined-64")
    p.add_argument("--perturb", type=int, default=0, help="neutral perturbations (0 = none)")
    a = p.parse_args(argv)
    names = selected_names(a)
    if not names:
        p.error(f"no sequence matches --only {a.only!r} (--only '' for all)")
    folders = simulate_suite(a.out, names)
    opts = dict(o.split("=", 1) for o in a.options)
    for name in names:
        fig = _weak_direction_figures(folders[name], opts)
        rows = fig["rows"]
        print(f"{name}: {len(rows)} wrong steps")
        for k, t, r, share, axis, nees, turn_true, turn_est in rows:
            ax, tt, te = (
                " ".join(f"{math.degrees(v):+5.2f}" for v in w) for w in (axis, turn_true, turn_est)
            )
            print(
                f"  step {k:3d}: {t:4.2f} m {r:4.2f}°  share in the weakest direction "
                f"{share:4.2f}  rotation error (target frame, °) [{ax}]  step rotation true "
                f"[{tt}] estimated [{te}]  online NEES {nees:5.1f}"
            )
        if rows:
            sh = np.array([r[3] for r in rows])
            print(
                f"  share in the weakest direction: median {np.median(sh):.2f}, min {sh.min():.2f}"
            )
        if fig["prior_ratio"]:
            print(
                "  scan information / motion prior along the weakest direction, median over "
                f"frames: {np.median(fig['prior_ratio']):.2f}"
            )
        if a.perturb > 0:
            apes, wrong = [], []
            for pert in PERTURBATIONS[: a.perturb]:
                res = run_method(folders[name], "relnav", **{**opts, **pert})
                apes.append(res["ape"])
                wrong.append(res["wrong"])
            print(
                f"  {len(apes)} perturbations: APE "
                + " ".join(f"{x:.2f}" for x in apes)
                + f" (median {np.median(apes):.2f} m); wrong "
                + " ".join(str(x) for x in wrong)
                + f" (median {np.median(wrong):.1f})",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
