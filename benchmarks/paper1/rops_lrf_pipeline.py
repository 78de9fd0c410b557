"""Paper 1's feature pipeline with RoPS on its two frames: local mesh (default) vs points.

For each preset (``relnav simulate PRESET --max-frames N``, seed 0, simulated once into
``--work``) and each estimator (``svd``, ``kalman``), runs
``relnav odometry SEQ --method feature:rops+gcc+EST -O descriptor_options.lrf=LRF`` for
``LRF ∈ {local_mesh, points}`` and prints Paper 1's translation error (``T_error_pct``), evo's
RPE (translation RMSE, m; rotation RMSE, °), the median describe time and frame time (ms; frames
after the first two, from ``diagnostics.csv``) and the flagged frames.

Run: ``nice -n 10 python benchmarks/paper1/rops_lrf_pipeline.py [--presets sim-voyager sim-bennu
sim-helical] [--frames 60] [--work /tmp/rops_lrf]``
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

LRFS = ("local_mesh", "points")
ESTIMATORS = ("svd", "kalman")


def relnav(*args: str) -> None:
    """Run the relnav CLI (same interpreter), quiet; raise on failure."""
    cmd = [sys.executable, "-m", "relnav.cli.main", *args]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed:\n{res.stdout[-2000:]}{res.stderr[-2000:]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["sim-voyager", "sim-bennu", "sim-helical"])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--work", type=Path, default=Path("/tmp/rops_lrf"))
    args = ap.parse_args()
    rows = []
    for preset in args.presets:
        seq = args.work / "seq" / preset
        if not (seq / "scans").is_dir():
            relnav("simulate", preset, "--max-frames", str(args.frames), "--out", str(seq))
        for est in ESTIMATORS:
            for lrf in LRFS:
                out = args.work / "runs" / f"{preset}_{est}_{lrf}"
                relnav(
                    "odometry", str(seq), "--method", f"feature:rops+gcc+{est}",
                    "-O", f"descriptor_options.lrf={lrf}", "--out", str(out),
                    "--max-frames", str(args.frames),
                )  # fmt: skip
                m = json.loads((out / "metrics.json").read_text())
                with open(out / "diagnostics.csv") as fh:
                    diag = list(csv.DictReader(fh))[2:]
                t_desc = np.median([float(d["t_describe_ms"]) for d in diag])
                t_frame = np.median([float(d["t_frame_ms"]) for d in diag])
                flagged = sum(d["status"] not in ("ok", "first") for d in diag)
                rows.append(
                    (preset, est, lrf, m["T_error_pct"], m["rpe_trans_rmse"],
                     m["rpe_rot_rmse_deg"], t_desc, t_frame, flagged, int(m["n_frames"]))
                )  # fmt: skip
                print(
                    f"{preset:12s} {est:7s} {lrf:10s} T_err {m['T_error_pct']:7.3f} %  "
                    f"RPE {m['rpe_trans_rmse']:.4f} m {m['rpe_rot_rmse_deg']:.3f}°  "
                    f"describe {t_desc:7.1f} ms  frame {t_frame:7.1f} ms  flagged {flagged}",
                    flush=True,
                )
    print(
        "\n| preset | estimator | RoPS frame | T_error % | RPE trans (m) | RPE rot (°) "
        "| describe ms | frame ms | flagged |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.3f} | {r[4]:.4f} | {r[5]:.3f} | {r[6]:.1f} "
            f"| {r[7]:.1f} | {r[8]}/{r[9]} |"
        )


if __name__ == "__main__":
    main()
