"""Paper 1's feature pipeline with RoPS on its two frames: local mesh (default) vs points.

Two parts (``--part``, default both), on the same simulated sequences (``relnav simulate PRESET
--max-frames N``, seed 0, simulated once into ``--work``):

* ``pipeline`` — for each estimator (``svd``, ``kalman``), runs ``relnav odometry SEQ --method
  feature:rops+gcc+EST -O descriptor_options.lrf=LRF`` for ``LRF ∈ {local_mesh, points}`` and
  prints Paper 1's translation error (``T_error_pct``), evo's RPE (translation RMSE, m; rotation
  RMSE, °), the median describe time and frame time (ms; frames after the first two, from
  ``diagnostics.csv``) and the flagged frames;
* ``cpu`` — describes every point of the first ``--cpu-frames`` scans (the feature pipeline's
  default keypoints) with radius ``20·Tr`` (RoPS's registered factor) and prints the median
  **process CPU time** per frame (numba single-threaded; CPU time because the machine may be
  shared, which inflates wall-clock times), the frame-computation share and the ratio
  local_mesh / points. Compilation is excluded (one warm-up call). (This part was
  ``bench_rops_lrf.py`` before issue 43.)

Run: ``nice -n 10 python benchmarks/paper1/rops_lrf.py [--presets sim-voyager sim-bennu
sim-helical] [--frames 60] [--work /tmp/rops_lrf] [--part pipeline|cpu|both]``
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from relnav.features.rops import rops
from relnav.geometry import mean_resolution
from relnav.geometry.lrf import rops_lrf_csr, support_csr
from relnav.io.pointclouds import read_points

LRFS = ("local_mesh", "points")
ESTIMATORS = ("svd", "kalman")


def relnav(*args: str) -> None:
    """Run the relnav CLI (same interpreter), quiet; raise on failure."""
    cmd = [sys.executable, "-m", "relnav.cli.main", *args]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed:\n{res.stdout[-2000:]}{res.stderr[-2000:]}")


def cpu_ms(fn) -> float:
    """Process CPU time of ``fn()``, ms."""
    t = time.process_time()
    fn()
    return 1e3 * (time.process_time() - t)


def cpu_table(seqs: list[Path], frames: int) -> None:
    """The ``cpu`` part: RoPS's CPU time per frame with each frame, as a Markdown table."""
    warm = np.random.default_rng(0).random((50, 3))
    for lrf in ("points", "local_mesh"):
        rops(warm, np.arange(5), radius=0.5, lrf=lrf)
    print("| sequence | points/frame | RoPS points (ms) | RoPS local_mesh (ms) | ratio "
          "| of which frame: points / local_mesh (ms) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for seq in seqs:
        scans = sorted((seq / "scans").glob("*"))[:frames]
        res: dict[str, list[float]] = {"points": [], "local_mesh": []}
        frame: dict[str, list[float]] = {"points": [], "local_mesh": []}
        sizes = []
        for f in scans:
            P = read_points(f)
            kp = np.arange(len(P))
            r = 20.0 * mean_resolution(P)
            sizes.append(len(P))
            flat, off = support_csr(P, kp, r)
            for lrf in res:
                res[lrf].append(cpu_ms(lambda: rops(P, kp, radius=r, lrf=lrf)))  # noqa: B023
                frame[lrf].append(
                    cpu_ms(lambda: rops_lrf_csr(P, kp, flat, off, r, None, 1e-10, lrf))  # noqa: B023
                )
        a = np.median(res["points"])
        b = np.median(res["local_mesh"])
        print(
            f"| {seq.name} | {np.median(sizes):.0f} | {a:.1f} | {b:.1f} | {b / a:.2f} "
            f"| {np.median(frame['points']):.1f} / {np.median(frame['local_mesh']):.1f} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["sim-voyager", "sim-bennu", "sim-helical"])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--cpu-frames", type=int, default=10, help="scans timed by the cpu part")
    ap.add_argument("--work", type=Path, default=Path("/tmp/rops_lrf"))
    ap.add_argument("--part", choices=("pipeline", "cpu", "both"), default="both")
    args = ap.parse_args()
    rows = []
    seqs = []
    for preset in args.presets:
        seq = args.work / "seq" / preset
        seqs.append(seq)
        if not (seq / "scans").is_dir():
            relnav("simulate", preset, "--max-frames", str(args.frames), "--out", str(seq))
    if args.part in ("cpu", "both"):
        cpu_table(seqs, args.cpu_frames)
    if args.part == "cpu":
        return
    for preset, seq in zip(args.presets, seqs, strict=True):
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
