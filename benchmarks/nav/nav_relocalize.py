"""Kidnapped navigator: relnav's relocalisation on the navigation suite's sequences.

Blocks of frames are removed from a suite sequence at a few seeded places and the remaining
frames are re-timed one frame period apart, so the navigator's constant-velocity prediction
jumps over the gap: after the gap the target is far from the prediction (a kidnap). The
navigator runs on the same kidnapped frames with relocalisation on and off; the unmodified
sequence is also run with it on and off, to check that it never triggers there.

    python benchmarks/nav/nav_relocalize.py --out /work/nav \\
        --only eros-ellipse-64,aura-ellipse-64,envisat-tumble-64,orion-inclined-64

Per sequence it prints: kidnaps; recovered (the online pose back within 0.5 m and 5° of the
unkidnapped run's online pose at that frame, i.e. of the map's own frame, which may have
drifted from the truth) and after how many frames; relocalisations accepted and how many were
wrong (> 0.5 m or > 5° from the truth, and from the unkidnapped run's pose); APE (no
alignment, the finalised trajectory) with and without relocalisation; ms per relocalisation
attempt; and whether the unmodified sequence gives the same poses with the feature on.
Sequences are simulated once into ``OUT/sequences`` by ``benchmarks/nav/nav_suite.py``'s code.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.nav_suite import simulate_suite

WRONG_T, WRONG_R = 0.5, 5.0


def pose_error(T: np.ndarray, G: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (deg) error of ``T`` against ``G``."""
    from relnav.geometry.rotations import rotation_angle

    e = np.linalg.inv(G) @ T
    return float(np.linalg.norm(e[:3, 3])), math.degrees(rotation_angle(e[:3, :3]))


def kidnap_plan(n: int, kidnaps: int, gap: int, rng: np.random.Generator) -> list[int]:
    """Start frames of ``kidnaps`` removed blocks of ``gap`` frames in ``[0.3 n, 0.9 n)``,
    at least ``gap + 15`` frames apart (seeded)."""
    lo, hi = int(0.3 * n), int(0.9 * n) - gap
    for _ in range(1000):
        s = np.sort(rng.integers(lo, hi, kidnaps))
        if kidnaps < 2 or np.all(np.diff(s) >= gap + 15):
            return [int(x) for x in s]
    raise RuntimeError("could not place the kidnaps: sequence too short")


def run(
    seq: Any, frames: list[int], dt: float, **options: Any
) -> tuple[np.ndarray, np.ndarray, list[Any], float]:
    """Navigator over ``frames`` of ``seq``, re-timed ``dt`` apart: (online poses, finalised
    poses, steps, wall seconds)."""
    from relnav.navigation import Navigator
    from relnav.scan import Scan

    gt = seq.gt_poses
    nav = Navigator(initial_pose=gt[frames[0]], **options)
    t0 = float(seq.timestamps[frames[0]])
    steps = []
    w = time.perf_counter()
    for i, k in enumerate(frames):
        steps.append(nav.register_frame(Scan(points=seq[k].points, time=t0 + i * dt)))
    wall = time.perf_counter() - w
    online = np.stack([s.pose for s in steps])
    return online, nav.finalize(), steps, wall


def _wrong(err: tuple[float, float]) -> bool:
    return err[0] > WRONG_T or err[1] > WRONG_R


def ape(poses: np.ndarray, gt: np.ndarray) -> float:
    """Translation RMSE (m) without alignment."""
    d = np.linalg.norm(poses[:, :3, 3] - gt[:, :3, 3], axis=1)
    return float(np.sqrt(np.mean(d**2)))


def evaluate(
    seq: Any, name: str, kidnaps: int, gap: int, seed: int, recover_within: int, opts: dict
) -> dict[str, Any]:
    """Every figure of one sequence (see the module doc)."""
    gt_all = seq.gt_poses
    n = len(seq)
    dt = float(np.median(np.diff(seq.timestamps)))
    rng = np.random.default_rng([seed, n])
    starts = kidnap_plan(n, kidnaps, gap, rng)
    removed = {k for s in starts for k in range(s, s + gap)}
    frames = [k for k in range(n) if k not in removed]
    after = [frames.index(s + gap) for s in starts]  # first kept frame after each gap
    gt = gt_all[frames]
    out: dict[str, Any] = {"frames": len(frames), "kidnaps": starts, "gap": gap}

    # unmodified sequence: on vs off
    full = list(range(n))
    on_full = run(seq, full, dt, **opts)
    off_full = run(seq, full, dt, **opts, relocalise=False)
    attempts = [i for i, s in enumerate(on_full[2]) if "relocalise" in _timings(s)]
    out["unmodified_identical"] = bool(np.array_equal(on_full[1], off_full[1]))
    out["unmodified_attempts"] = attempts
    out["unmodified_ape"] = ape(off_full[1], gt_all)
    ref_online = on_full[0][frames]  # the unkidnapped run's online poses at the kept frames

    for label, o in (("on", dict(opts)), ("off", {**opts, "relocalise": False})):
        online, final, steps, wall = run(seq, frames, dt, **o)
        err = [pose_error(online[i], gt[i]) for i in range(len(frames))]
        bad_gt = np.array([_wrong(e) for e in err])
        bad = np.array([_wrong(pose_error(online[i], ref_online[i])) for i in range(len(frames))])
        rec = []
        for i in after:
            j = next((j for j in range(i, len(frames)) if not bad[j]), None)
            rec.append(None if j is None or j - i > recover_within else j - i)
        reloc = [i for i, s in enumerate(steps) if s.result and s.result.info.get("relocalised")]
        wrong_gt = [i for i in reloc if bad_gt[i]]
        wrong_map = [i for i in reloc if _wrong(pose_error(online[i], ref_online[i]))]
        t_att = [_timings(s)["relocalise"] for s in steps if "relocalise" in _timings(s)]
        flagged = sum(s.status not in ("ok", "first") for s in steps)
        out[label] = {
            "ape": ape(final, gt),
            "ape_online": ape(online, gt),
            "recovered_after": rec,
            "relocalisations": reloc,
            "wrong_vs_truth": wrong_gt,
            "bad_frames_vs_truth": int(bad_gt.sum()),
            "wrong_vs_unkidnapped": wrong_map,
            "attempts": len(t_att),
            "ms_per_attempt": 1000 * float(np.median(t_att)) if t_att else float("nan"),
            "ms_per_attempt_max": 1000 * float(np.max(t_att)) if t_att else float("nan"),
            "flagged": int(flagged),
            "bad_frames": int(bad.sum()),
            "ms_per_frame": 1000 * wall / len(frames),
        }
    return out


def probe(seq: Any, start: float, every: int, back: int, opts: dict) -> dict[str, Any]:
    """The relocaliser alone: the navigator tracks the first ``start`` × the frames, then each
    ``every``-th later scan is located on that map from a prediction ``back`` frames old (the
    navigator's pose then); a located pose is right when within 0.5 m and 5° of the full
    run's online pose at that frame (the map's frame)."""
    from relnav.navigation import Navigator

    n = len(seq)
    n0 = int(start * n)
    full, _, _, _ = run(seq, list(range(n)), 1.0, **opts)
    nav = Navigator(initial_pose=seq.gt_poses[0], **opts)
    for k in range(n0):
        nav.register_frame(seq[k])
    assert nav.relocalizer is not None
    right = wrong = refused = 0
    why: dict[str, int] = {}
    times = []
    for k in range(n0 + back, n, every):
        t = time.perf_counter()
        fit, reason = nav.relocalizer.locate(seq[k].points, full[k - back], frame=nav.n_frames)
        times.append(time.perf_counter() - t)
        if fit is None:
            refused += 1
            key = reason.split(":")[0].split(" (")[0]
            key = "none verified" if key.startswith("none of") else key
            why[key] = why.get(key, 0) + 1
        elif _wrong(pose_error(fit["T"], full[k])):
            wrong += 1
        else:
            right += 1
    return {
        "probes": right + wrong + refused,
        "right": right,
        "wrong": wrong,
        "refused": refused,
        "refused_why": why,
        "ms": 1000 * float(np.median(times)) if times else float("nan"),
    }


def _timings(step: Any) -> dict[str, float]:
    return step.result.timings if step.result is not None else {}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument(
        "--only",
        default="eros-ellipse-64,aura-ellipse-64,envisat-tumble-64,orion-inclined-64",
        help="comma-separated sequence names of the navigation suite",
    )
    p.add_argument("--kidnaps", type=int, default=3, help="removed blocks per sequence")
    p.add_argument("--gap", type=int, default=10, help="frames per removed block")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--recover-within", type=int, default=10, help="frames after a gap to count a recovery"
    )
    p.add_argument("-O", dest="options", action="append", default=[], help="relnav key=value")
    p.add_argument("--json", type=Path, default=None)
    p.add_argument(
        "--unmodified",
        action="store_true",
        help="only check that the unmodified sequences give the same poses with the feature on",
    )
    p.add_argument(
        "--probe",
        action="store_true",
        help="the relocaliser alone: locate later scans on the map of the first 60%% of frames",
    )
    a = p.parse_args(argv)
    from relnav.io.sequences import ScanSequence

    opts: dict[str, Any] = {}
    for o in a.options:
        k, v = o.split("=", 1)
        try:
            opts[k] = float(v) if "." in v or "e" in v else int(v)
        except ValueError:
            opts[k] = v
    from relnav.navigation.relocalize import max_clique

    max_clique(np.ones((3, 3), bool))  # compile (or load) the numba kernels before timing
    names = [s for s in a.only.split(",") if s]
    folders = simulate_suite(a.out, names)
    results = {}
    if a.unmodified:
        for name in names:
            seq = ScanSequence(folders[name])
            n = len(seq)
            dt = float(np.median(np.diff(seq.timestamps)))
            on = run(seq, list(range(n)), dt, **opts)
            off = run(seq, list(range(n)), dt, **opts, relocalise=False)
            att = [i for i, s in enumerate(on[2]) if "relocalise" in _timings(s)]
            flips = [
                i
                for i, (x, y) in enumerate(zip(on[2], off[2], strict=True))
                if x.status != y.status
            ]
            same = bool(np.array_equal(on[1], off[1]))
            results[name] = {"identical": same, "attempts": att, "status_changed": flips}
            print(
                f"{name}: {n} frames, identical {same}, relocalisation attempts at {att}, "
                f"status changed at {flips}, APE on {ape(on[1], seq.gt_poses):.3f} m, off "
                f"{ape(off[1], seq.gt_poses):.3f} m",
                flush=True,
            )
        if a.json:
            a.json.write_text(json.dumps(results, indent=2))
        return 0
    if a.probe:
        for name in names:
            r = probe(ScanSequence(folders[name]), 0.6, 3, a.gap, opts)
            results[name] = r
            print(
                f"{name}: {r['probes']} scans located from a prediction {a.gap} frames old: "
                f"right {r['right']}, wrong {r['wrong']}, refused {r['refused']} "
                f"{r['refused_why']}, {r['ms']:.0f} ms each",
                flush=True,
            )
        if a.json:
            a.json.write_text(json.dumps(results, indent=2))
        return 0
    for name in names:
        r = evaluate(
            ScanSequence(folders[name]), name, a.kidnaps, a.gap, a.seed, a.recover_within, opts
        )
        results[name] = r
        print(
            f"{name}: {r['frames']} frames, kidnaps at {r['kidnaps']} (gap {r['gap']}); "
            f"unmodified: identical with relocalisation {r['unmodified_identical']}, "
            f"attempts {r['unmodified_attempts']}, APE {r['unmodified_ape']:.2f} m",
            flush=True,
        )
        for label in ("on", "off"):
            q = r[label]
            print(
                f"  reloc {label:3s}: APE {q['ape']:7.2f} m (online {q['ape_online']:7.2f})  "
                f"recovered after {q['recovered_after']} frames  relocalisations "
                f"{len(q['relocalisations'])} (wrong vs truth {len(q['wrong_vs_truth'])}, vs "
                f"unkidnapped run {len(q['wrong_vs_unkidnapped'])})  attempts {q['attempts']} "
                f"{q['ms_per_attempt']:.0f} ms (max {q['ms_per_attempt_max']:.0f})  flagged "
                f"{q['flagged']}  frames off > 0.5 m/5°: from the unkidnapped run "
                f"{q['bad_frames']}, "
                f"from the truth {q['bad_frames_vs_truth']}  "
                f"{q['ms_per_frame']:.1f} ms/frame",
                flush=True,
            )
    if a.json:
        a.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
