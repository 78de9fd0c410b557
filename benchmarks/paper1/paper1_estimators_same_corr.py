"""Paper 1's estimators on the SAME correspondences: isolates the filter from the front end.

For each preset and descriptor, every consecutive scan pair is described, matched and grouped
(GCC) once; then every estimator variant (``name`` or ``name:key=value,key=value``) turns the
same grouped correspondences into a step, the steps are chained (a non-``ok`` step repeats the
previous one, as the odometry's constant-velocity prior would) and scored against the ground
truth. Not a test; ``--shift`` adds a constant offset (m) to every scan's x to check the
estimators' invariance to the coordinate origin.

Example::

    python benchmarks/paper1/paper1_estimators_same_corr.py --presets sim-voyager --frames 60 \\
        --descriptors shot hods --variants svd kalman alphabeta hinf sdre
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from relnav.estimation import get_estimator
from relnav.eval.metrics import evaluate_trajectories
from relnav.io.sequences import ScanSequence
from relnav.registration.feature import FeatureRegistration
from relnav.sim.presets import get_preset, preset_options
from relnav.sim.scenario import simulate


def parse_variant(spec: str) -> tuple[str, dict]:
    name, _, rest = spec.partition(":")
    opts: dict = {}
    for kv in filter(None, rest.split(",")):
        k, _, v = kv.partition("=")
        try:
            opts[k] = int(v)
        except ValueError:
            try:
                opts[k] = float(v)
            except ValueError:
                opts[k] = {"true": True, "false": False}.get(v.lower(), v)
    return name, opts


def pair_correspondences(
    seq: ScanSequence,
    descriptor: str,
    n: int,
    shift: float,
    descriptor_options: dict | None = None,
    radius_factor: float | None = None,
):
    reg = FeatureRegistration(
        descriptor,
        "gcc",
        "svd",
        descriptor_options=descriptor_options,
        radius_factor=radius_factor,
    )
    off = np.array([shift, 0.0, 0.0])
    feats = [reg.prepare(np.asarray(seq[k].points) + off) for k in range(n)]
    out = []
    from relnav.matching.nn import match_descriptors

    for k in range(n - 1):
        src, tgt = feats[k + 1], feats[k]
        if src.keypoints.size == 0 or tgt.keypoints.size == 0:
            out.append(None)
            continue
        corr = match_descriptors(
            src.descriptors,
            tgt.descriptors,
            tau=reg.tau,
            src_keypoints=src.keypoints,
            tgt_keypoints=tgt.keypoints,
        )
        grouped = reg.grouper.select(src.points, tgt.points, corr, resolution=src.resolution)
        out.append((src.points, tgt.points, grouped))
    return out


def run_variant(pairs, spec: str, W0: np.ndarray):
    name, opts = parse_variant(spec)
    est = get_estimator(name, **opts)
    W = [W0]
    step = np.eye(4)
    n_bad = 0
    passes = []
    t0 = time.perf_counter()
    for p in pairs:
        if p is None:
            n_bad += 1
        else:
            e = est.estimate(*p)
            if e.status == "ok":
                step = e.T_target_source
                passes.append(e.info.get("passes", 1))
            else:
                n_bad += 1
        W.append(W[-1] @ step)
    ms = 1e3 * (time.perf_counter() - t0) / max(len(pairs), 1)
    return np.asarray(W), n_bad, float(np.mean(passes)) if passes else float("nan"), ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["sim-voyager"])
    ap.add_argument("--descriptors", nargs="+", default=["shot", "hods"])
    ap.add_argument("--variants", nargs="+", default=["svd", "kalman", "hinf", "alphabeta", "sdre"])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model-cloud", default="fixed")
    ap.add_argument("--shift", type=float, default=0.0)
    ap.add_argument(
        "--descriptor-option", action="append", default=[], help="key=value (repeatable)"
    )
    ap.add_argument("--radius-factor", type=float, default=None)
    a = ap.parse_args()
    dopts = parse_variant("x:" + ",".join(a.descriptor_option))[1]
    print("preset descriptor variant T_error_pct e_R_avg_deg flagged mean_passes est_ms")
    with tempfile.TemporaryDirectory() as tmp:
        for preset in a.presets:
            d = Path(tmp) / preset
            opts = {"model_cloud": a.model_cloud} if "model_cloud" in preset_options(preset) else {}
            sc = get_preset(preset, max_frames=a.frames, seed=a.seed, **opts)
            simulate(sc, d)
            seq = ScanSequence(d)
            n = len(seq)
            for desc in a.descriptors:
                pairs = pair_correspondences(seq, desc, n, a.shift, dopts, a.radius_factor)
                for v in a.variants:
                    W, bad, passes, ms = run_variant(pairs, v, seq.gt_poses[0])
                    m = evaluate_trajectories(seq.timestamps[:n], W, seq.timestamps, seq.gt_poses)
                    print(
                        f"{preset} {desc} {v} {float(m['T_error_pct']):.3f} "
                        f"{float(m['e_R_avg']):.3f} {bad} {passes:.1f} {ms:.2f}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
