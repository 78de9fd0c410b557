"""Is the navigator's step covariance honest? The mean step NEES per sequence (6 = consistent).

For every accepted step (``ok`` or ``flagged``) of relnav's causal run, the error of the step
(twist of ``S_true⁻¹ S_est``, body frame of the new pose) weighed by the step's own covariance
(``info["step_covariance"]``, what the flags use). The ground truth scores; the navigator never
sees it. Sequences as simulated by ``benchmarks/nav/nav_suite.py`` into ``OUT/sequences``.

    python benchmarks/nav/nav_step_nees.py --out bench/nav --only eros-ellipse-64,envisat-jitter1
    python benchmarks/nav/nav_step_nees.py --out bench/nav --only envisat-jitter1 \
        -O map.patch_point=mean
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from relnav.bench.nav_suite import MISSION, simulate_suite
from relnav.geometry.lie import log_se3
from relnav.geometry.se3 import invert
from relnav.io.sequences import ScanSequence
from relnav.pipeline import run_sequence


def step_nees(seq: ScanSequence, **options: object) -> np.ndarray:
    """The step NEES of every accepted step of relnav's causal run on ``seq``."""
    run = run_sequence(seq, "relnav", **{**MISSION, **options})
    gt, est = seq.gt_poses, run.online_poses
    out = []
    for k in range(1, len(gt)):
        s = run.steps[k]
        C = s.result.info.get("step_covariance") if s.result is not None else None
        if s.status not in ("ok", "flagged") or C is None:
            continue
        e = log_se3(invert(invert(gt[k - 1]) @ gt[k]) @ (invert(est[k - 1]) @ est[k]))
        out.append(float(e @ np.linalg.solve(C, e)))
    return np.asarray(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--only", required=True, help="comma-separated sequence names")
    p.add_argument("-O", dest="options", action="append", default=[], help="relnav key=value")
    a = p.parse_args(argv)
    names = [n for n in a.only.split(",") if n]
    options = dict(o.split("=", 1) for o in a.options)
    for name, folder in simulate_suite(a.out, names).items():
        q = step_nees(ScanSequence(folder), **options)
        print(f"{name:24s} step NEES mean {np.mean(q):8.1f} median {np.median(q):7.1f} n {len(q)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
