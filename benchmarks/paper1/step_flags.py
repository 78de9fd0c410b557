"""How honest are the step flags of the pairwise methods? (issue 11, item 9)

For each sequence and method, runs the odometry twice on the same frames — ``step_check=off``
and the mode under test (``auto`` by default) — and prints, per run:

* ``wrong``: steps whose applied step is off the ground truth by more than 0.5 m or 5° (the
  ground truth is used for this evaluation only, never by the checks);
* ``recall``: share of the wrong steps that are not ``ok`` (flagged, degenerate or failed);
* ``gross``: the same for the steps wrong by more than twice that (1 m or 10°), with their count;
* ``false``: share of the right steps that are not ``ok``;
* ``ms off`` / ``ms on``: median wall-clock time per frame of the two runs (they run one after
  the other, so on a shared machine their ratio also measures the load);
* ``check``: median time of the checks per frame inside the checked run (``timings["check"]``:
  the referee's scan preparation, the referee and the backward registration) and ``ratio``,
  the checked run's median frame time over its median frame time without the checks (the
  cost measured under one load).

Tuned on: sim-bennu and the flash sequence comet-ellipse-64. The others are held out.

Run (from the repository root, ``../shared`` beside it)::

    python benchmarks/paper1/step_flags.py --data /tmp/flags --frames 150 \\
        --methods icp-point icp-plane sicp-point paper1 extended

Sequences missing under ``--data`` are simulated first (``relnav simulate``, seed 0).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from relnav.geometry import invert, rotation_angle
from relnav.io.sequences import ScanSequence
from relnav.pipeline import resolve_method, run_sequence

TARGETS = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "targets"
SEQUENCES: dict[str, list[str]] = {
    # tuning sequences
    "bennu": ["sim-bennu", "--max-frames", "200"],
    "comet-ellipse-64": ["configs/nav/comet-ellipse-64.yaml"],
    # held out
    "eros-ellipse-64": ["configs/nav/eros-ellipse-64.yaml"],
    "aura-tumble-64": ["configs/nav/aura-tumble-64.yaml"],
    "orion": ["sim-orion", "--max-frames", "200"],
    "voyager": ["sim-voyager", "--max-frames", "200"],
    "bennu-eros": ["sim-bennu", "--max-frames", "200", "--target-mesh", str(TARGETS / "eros.ply")],
    "orion-aura": ["sim-orion", "--max-frames", "200", "--target-mesh", str(TARGETS / "aura.ply")],
}
TUNED = ("bennu", "comet-ellipse-64")
WRONG_M, WRONG_DEG = 0.5, 5.0


def _ensure(data: Path, name: str) -> Path:
    out = data / name
    if not (out / "scans").exists():
        cmd = ["relnav", "simulate", *SEQUENCES[name], "--out", str(out)]
        subprocess.run(cmd, check=True, capture_output=True)
    return out


def _wrong(seq: ScanSequence, steps: list, factor: float = 1.0) -> np.ndarray:
    """Steps (from the second frame) off the ground truth by > factor × (0.5 m or 5°)."""
    gt = seq.gt_poses
    w = np.zeros(len(steps), dtype=bool)
    for k in range(1, len(steps)):
        D = invert(invert(gt[k - 1]) @ gt[k]) @ steps[k].step
        w[k] = (
            np.degrees(rotation_angle(D[:3, :3])) > factor * WRONG_DEG
            or float(np.linalg.norm(D[:3, 3])) > factor * WRONG_M
        )
    return w[1:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of the sequences")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--methods", nargs="+", default=["icp-point", "icp-plane", "paper1"])
    ap.add_argument("--sequences", nargs="+", default=list(SEQUENCES))
    ap.add_argument("--mode", default="auto", help="step_check mode under test")
    a = ap.parse_args()
    a.data.mkdir(parents=True, exist_ok=True)
    head = (
        f"{'sequence':18s} {'method':11s} {'wrong':>9s} {'recall':>7s} {'gross':>11s} "
        f"{'false':>6s} {'rec.off':>7s} {'ms off':>7s} {'ms on':>7s} {'check':>6s} {'ratio':>6s}"
        "  statuses"
    )
    print(f"step_check={a.mode}, {a.frames} frames; wrong = >{WRONG_M} m or >{WRONG_DEG}°")
    print(head)
    for name in a.sequences:
        seq = ScanSequence(_ensure(a.data, name))
        for method in a.methods:
            m, opts, _ = resolve_method(method, {})
            runs = {}
            for mode in ("off", a.mode):
                runs[mode] = run_sequence(seq, m, max_frames=a.frames, step_check=mode, **opts)
            on, off = runs[a.mode], runs["off"]
            wrong = _wrong(seq, on.steps)
            flag = np.array([s.status != "ok" for s in on.steps[1:]])
            flag_off = np.array([s.status != "ok" for s in off.steps[1:]])
            wrong_off = _wrong(seq, off.steps)
            rec = 100.0 * (flag & wrong).sum() / max(wrong.sum(), 1)
            gross = _wrong(seq, on.steps, 2.0)
            rec_g = 100.0 * (flag & gross).sum() / max(gross.sum(), 1)
            fal = 100.0 * (flag & ~wrong).sum() / max((~wrong).sum(), 1)
            rec_off = 100.0 * (flag_off & wrong_off).sum() / max(wrong_off.sum(), 1)
            st = Counter(s.status for s in on.steps[1:])
            frame = np.array([s.time_s for s in on.steps[1:]])
            check = np.array([s.result.timings.get("check", 0.0) for s in on.steps[1:]])
            t_off = 1000.0 * float(np.median([s.time_s for s in off.steps[1:]]))
            ratio = float(np.median(frame) / max(np.median(frame - check), 1e-12))
            tag = "*" if name in TUNED else " "
            print(
                f"{name + tag:18s} {method:11s} {wrong.sum():4d}/{len(wrong):<4d} "
                f"{rec:6.1f}% {rec_g:5.1f}%/{gross.sum():<4d} {fal:5.1f}% {rec_off:6.1f}% "
                f"{t_off:7.2f} {1000.0 * np.median(frame):7.2f} {1000.0 * np.median(check):6.2f} "
                f"{ratio:5.2f}x  " + ", ".join(f"{k} {v}" for k, v in sorted(st.items())),
                flush=True,
            )
    print("* tuning sequence", file=sys.stderr)


if __name__ == "__main__":
    main()
