"""Paper 1 odometry grid: every descriptor × estimator on simulated presets, metrics table.

Simulates each preset once (procedural targets, the first ``--frames`` frames at the preset's
own rate, seed ``--seed``), runs ``feature:<descriptor>+<grouper>+<estimator>`` for every
combination, and prints one row per run (and writes ``--csv``). Not a test: it takes minutes.

Example::

    python benchmarks/paper1_odometry_grid.py --presets sim-voyager sim-orion sim-bennu \\
        --frames 60 --csv grid.csv
"""

from __future__ import annotations

import argparse
import csv
import itertools
import tempfile
import time
from pathlib import Path

from relnav.eval.metrics import evaluate_trajectories
from relnav.io.sequences import ScanSequence
from relnav.odometry import run_sequence
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate

DESCRIPTORS = ["hods", "hod", "shot", "fpfh", "rops", "trisi", "spin"]
ESTIMATORS = ["alphabeta", "kalman", "hinf", "sdre", "svd"]
KEYS = [
    "e_T_avg",
    "e_T_max",
    "drift",
    "T_error_pct",
    "e_R_avg",
    "e_R_max",
    "e_RT",
    "rpe_trans_rmse",
    "rpe_rot_rmse_deg",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["sim-voyager", "sim-orion", "sim-bennu"])
    ap.add_argument("--descriptors", nargs="+", default=DESCRIPTORS)
    ap.add_argument("--estimators", nargs="+", default=ESTIMATORS)
    ap.add_argument("--grouper", default="gcc")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--option", action="append", default=[], help="method option key=value")
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args()
    from relnav.cli._common import parse_options

    options = parse_options(args.option)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for preset in args.presets:
            seq_dir = Path(tmp) / preset
            simulate(get_preset(preset, max_frames=args.frames, seed=args.seed), seq_dir)
            seq = ScanSequence(seq_dir)
            for d, e in itertools.product(args.descriptors, args.estimators):
                method = f"feature:{d}+{args.grouper}+{e}"
                t0 = time.perf_counter()
                run = run_sequence(seq, method, **options)
                m = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, seq.gt_poses)
                row = {
                    "preset": preset,
                    "descriptor": d,
                    "estimator": e,
                    "flagged": run.n_flagged,
                    "time_ms": round(run.mean_time_ms, 2),
                }
                row.update({k: round(float(m[k]), 4) for k in KEYS})
                rows.append(row)
                print(
                    " ".join(f"{k}={v}" for k, v in row.items()),
                    f"(wall {time.perf_counter() - t0:.1f} s)",
                    flush=True,
                )
    if args.csv and rows:
        with args.csv.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
