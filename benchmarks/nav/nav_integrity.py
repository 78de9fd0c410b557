"""Integrity monitoring of relnav's navigator on the navigation suite: are its step covariances
honest, and can a protection level separate wrong steps from right ones?

    python benchmarks/nav/nav_integrity.py --out bench/nav            # the suite's flash sequences
    python benchmarks/nav/nav_integrity.py --out bench/nav --holdout  # the held-out ones

Runs ``relnav`` with ``integrity.alert_limit_t=0.5``, ``integrity.alert_limit_r_deg=5`` (the suite's
definition of a wrong step) and prints per sequence: the mean and median NEES of the online steps
against their step covariances (6 dof: 6 is consistent), the wrong steps of the evaluated (smoothed)
trajectory and how many steps the protection level flagged among the wrong and the right ones. The
ground truth is used for scoring only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from relnav.bench.nav_suite import holdout, judge_steps, simulate_suite, suite


def main(argv: list[str] | None = None) -> int:
    from relnav.geometry.lie import log_se3
    from relnav.geometry.se3 import invert
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--holdout", action="store_true")
    p.add_argument("--limit-t", type=float, default=0.5, help="alert limit, m")
    p.add_argument("--limit-r", type=float, default=5.0, help="alert limit, deg")
    a = p.parse_args(argv)
    names = list(holdout() if a.holdout else suite())
    folders = simulate_suite(a.out, names)

    total = np.zeros(4, dtype=int)
    print("sequence              step NEES mean/median  wrong  flagged (wrong, right)")
    for name, folder in folders.items():
        seq = ScanSequence(folder)
        run = run_sequence(seq, "relnav", alert_limit_t=a.limit_t, alert_limit_r_deg=a.limit_r)
        online = np.stack([s.pose for s in run.steps])
        gt = seq.gt_poses
        nees = []
        for k in range(1, len(online)):
            info = run.steps[k].result.info if run.steps[k].result is not None else {}
            if "step_covariance" not in info:
                continue
            e = log_se3(invert(invert(online[k - 1]) @ online[k]) @ (invert(gt[k - 1]) @ gt[k]))
            nees.append(float(e @ np.linalg.solve(info["step_covariance"], e)))
        _, _, wrong, flagged = judge_steps(run, gt)
        w, fw, r, fr = (
            int(wrong.sum()),
            int((wrong & flagged).sum()),
            int((~wrong).sum()),
            int((~wrong & flagged).sum()),
        )
        total += [w, fw, r, fr]
        print(
            f"{name:22s} {np.mean(nees):6.1f} / {np.median(nees):5.1f}        {w:4d}   "
            f"{fw + fr:4d} ({fw:3d}, {fr:4d})"
        )
    print(
        f"total: wrong steps flagged {total[1]}/{total[0]}, right steps flagged "
        f"{total[3]}/{total[2]} ({100 * total[3] / max(total[2], 1):.0f} %)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
