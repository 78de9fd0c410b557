"""Scale benchmark (issue 13): every relnav-native method and the peers from 1k to 300k points.

Scenes (``relnav.sim.presets``, a satellite spinning 2°/s in front of a static sensor, the target
filling most of the field of view):

* a density ladder on ONE scene, ``dense-flash`` (the whole 6 m satellite in view, ~31 % of the
  pixels) with ``resolution`` 57, 98, 180, 311, 622 and 984 pixels per side (≈ 1k, 3k, 10k,
  30k, 120k and 300k points per scan; 256 px is the ``flash256`` preset, ≈ 20k points here);
* the sensor presets at their own density: ``dense-hdl64`` (HDL-64, ≈ 49k points — a target on
  one side fills at most half of a 360° scan) and ``dense-kinect`` (Kinect v1 640×480,
  ≈ 220k points).

Each (method, scene) runs in its own subprocess (``--worker``) through
:func:`relnav.odometry.run_sequence` with the ground truth's first pose, so the peak memory is
that process's high-water resident memory (``VmHWM``: Python, libraries, the scans and the
method; an idle worker that only imports and loads the scans is printed as ``baseline``).
Printed per method and scene: median ms per frame (registered frames, the first excluded:
numba compilation and cache loading), peak MB, RPE (δ = 1 frame, translation RMSE mm and
rotation RMSE deg, evo's definition via :func:`relnav.eval.metrics.compute_metrics`), frames
flagged, and the time as a ratio to KISS-ICP's in the same run. Last, per method, the exponent
``b`` of a least-squares fit ``ms ∝ n^b`` over the ladder scenes above the method's point budget
(relnav-native methods: :data:`relnav.odometry.budget.DEFAULT_POINT_BUDGET`; the navigator: its
``max_points``). With the default 8 frames the median is over 6 timed frames.

Run:  ``nice -n 10 python benchmarks/speed/bench_scale.py [--frames 12] [--methods a,b]
[--scenes x,y]``
(≈ 13 min on a shared 2-core machine with --frames 8). Seeds: scenario seed 0.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

LADDER = [57, 98, 180, 311, 622, 984]
"""``dense-flash`` resolutions of the density ladder (pixels per side)."""

NATIVE = [
    "relnav",
    "feature:hods+gcc+alphabeta",
    "feature:shot+gcc+kalman",
    "feature:fpfh+gcc+svd",
    "clgv:hods",
    "icp-point",
    "icp-plane",
    "icp-x84",
    "sicp-point",
    "sicp-plane",
    "s4pcs",
]
"""relnav-native methods (``cbd``/``cga-sphere`` are paper 2's cross-source methods, not
frame-to-frame odometry, and are not run)."""

PEERS = ["kiss-icp", "small-gicp"]


def scenes() -> list[tuple[str, str, dict]]:
    """(label, preset, preset options) of every scene, ladder first."""
    out = [(f"flash {r}x{r}", "dense-flash", {"resolution": r}) for r in LADDER]
    out += [("HDL-64", "dense-hdl64", {}), ("Kinect 640x480", "dense-kinect", {})]
    return out


# ------------------------------------------------------------------------------------ worker


def peak_rss_mb() -> float:
    """Peak resident memory of THIS process image, MB: ``VmHWM`` of ``/proc/self/status``.

    ``ru_maxrss`` is not used: on Linux it survives ``exec`` and so includes the driver's
    memory at fork time. Falls back to ``ru_maxrss`` where ``/proc`` is absent.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(method: str, folder: str) -> None:
    """Run one method on one simulated sequence; print one JSON line."""
    from relnav.eval.metrics import compute_metrics
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(folder)
    scans = [seq[k] for k in range(len(seq))]  # all in memory, as a sensor stream would be
    gt = np.asarray(seq.gt_poses)
    if method == "baseline":
        print(json.dumps({"peak_mb": peak_rss_mb()}))
        return
    run = run_sequence(scans, method, initial_pose=gt[0])
    steps = run.steps
    times = np.array([s.time_s for s in steps[2:]]) if len(steps) > 2 else np.array([np.nan])
    m = compute_metrics(run.poses, gt)
    used = [s.n_used for s in steps if s.n_used is not None]
    print(
        json.dumps(
            {
                "ms": 1000.0 * float(np.median(times)),
                "peak_mb": peak_rss_mb(),
                "rpe_mm": 1000.0 * float(m["rpe_trans_rmse"]),
                "rpe_deg": float(m["rpe_rot_rmse_deg"]),
                "flagged": int(run.n_flagged),
                "n_points": float(np.mean([s.n_points for s in steps])),
                "n_used": float(np.mean(used)) if used else float("nan"),
            }
        )
    )


# ------------------------------------------------------------------------------------ driver


def run_worker(method: str, folder: Path, timeout: float) -> dict:
    cmd = [sys.executable, __file__, "--worker", method, "--folder", str(folder)]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout {timeout:.0f} s"}
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]
    if p.returncode != 0 or not lines:
        tail = (p.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": f"exit {p.returncode}: {tail[:80]}"}
    out = json.loads(lines[-1])
    out["wall_s"] = time.perf_counter() - t0
    return out


def fit_exponent(n: list[float], ms: list[float]) -> float:
    """Slope of log(ms) against log(n) (least squares); NaN with fewer than 2 points."""
    ok = [(a, b) for a, b in zip(n, ms, strict=True) if np.isfinite(b) and b > 0 and a > 0]
    if len(ok) < 2:
        return float("nan")
    x, y = np.log([a for a, _ in ok]), np.log([b for _, b in ok])
    return float(np.polyfit(x, y, 1)[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--methods", default=",".join(NATIVE + PEERS))
    ap.add_argument("--scenes", default="", help="comma-separated scene labels (default all)")
    ap.add_argument("--timeout", type=float, default=600.0, help="per method and scene, s")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--folder", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        worker(a.worker, a.folder)
        return

    from relnav.navigation.navigator import NavigatorConfig
    from relnav.odometry.budget import DEFAULT_POINT_BUDGET
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    if "kiss-icp" not in methods:
        methods.append("kiss-icp")  # the reference of the ratios
    chosen = [s for s in scenes() if not a.scenes or s[0] in a.scenes.split(",")]
    budget = {m: DEFAULT_POINT_BUDGET for m in NATIVE}
    budget["relnav"] = NavigatorConfig().max_points
    results: dict[tuple[str, str], dict] = {}
    npts: dict[str, float] = {}
    print(
        f"bench_scale: {a.frames} frames per scene, seed 0, point budget {DEFAULT_POINT_BUDGET} "
        f"(navigator max_points {budget['relnav']}), one process per cell, os.nice "
        f"{os.nice(0)}"
    )
    with tempfile.TemporaryDirectory() as td:
        for label, preset, opts in chosen:
            folder = Path(td) / label.replace(" ", "_")
            simulate(get_preset(preset, max_frames=a.frames, **opts), folder)
            base = run_worker("baseline", folder, a.timeout)
            for m in methods:
                r = run_worker(m, folder, a.timeout)
                results[(m, label)] = r
                if "n_points" in r:
                    npts[label] = r["n_points"]
                state = r.get("error") or f"{r['ms']:.1f} ms"
                print(f"  {label:<16s} {m:<28s} {state}", file=sys.stderr, flush=True)
            print(
                f"scene {label}: {npts.get(label, float('nan')):.0f} points/scan, baseline "
                f"process {base.get('peak_mb', float('nan')):.0f} MB",
                flush=True,
            )

    labels = [s[0] for s in chosen]
    print()
    print(
        f"{'scene':<16s} {'points':>7s}  {'method':<28s} {'ms/frame':>9s} {'xKISS':>6s} "
        f"{'peak MB':>8s} {'RPE mm':>8s} {'RPE deg':>8s} {'flagged':>7s}"
    )
    for lab in labels:
        k = results.get(("kiss-icp", lab), {}).get("ms", float("nan"))
        for m in methods:
            r = results.get((m, lab), {})
            head = f"{lab:<16s} {npts.get(lab, float('nan')):>7.0f}  {m:<28s}"
            if "error" in r:
                print(f"{head} {r['error']}")
                continue
            print(
                f"{head} {r['ms']:>9.1f} {r['ms'] / k:>6.2f} {r['peak_mb']:>8.0f} "
                f"{r['rpe_mm']:>8.1f} {r['rpe_deg']:>8.2f} {r['flagged']:>4d}/{a.frames - 1}"
            )
    print()
    print("fitted exponent b of ms ∝ n^b over the ladder scenes above each method's budget")
    ladder = [s[0] for s in scenes()[: len(LADDER)] if s[0] in labels]
    for m in methods:
        b = budget.get(m, 0)
        pts = [(npts[lab], results[(m, lab)].get("ms", np.nan)) for lab in ladder if lab in npts]
        above = [(n, t) for n, t in pts if n > b]
        e = fit_exponent([n for n, _ in above], [t for _, t in above])
        print(f"  {m:<28s} b = {e:5.2f}  ({len(above)} scenes above {b} points)")


if __name__ == "__main__":
    main()
