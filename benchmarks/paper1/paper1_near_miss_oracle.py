"""Diagnostic (uses the ground truth, not a method): are near-miss matches the cause?

Chains Kalman steps on the GCC inliers of paper 1's pipeline, once with every inlier and once
keeping only the inliers that are the SAME model point (the true step moves the source point
within 0.1·Tr of its target point; fixed noiseless model cloud). If the error collapses, the
inliers that GCC accepts at up to 2·Tr from the right point are what breaks the estimate.

Run: ``python benchmarks/paper1/paper1_near_miss_oracle.py``
"""

import tempfile
from pathlib import Path

import numpy as np
from paper1_estimators_same_corr import pair_correspondences

from relnav.estimation import get_estimator
from relnav.eval.metrics import evaluate_trajectories
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.se3 import invert, transform_points
from relnav.io.sequences import ScanSequence
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate

tmp = tempfile.mkdtemp()
print("preset descriptor T_error_pct(all inliers, same-point inliers only)")
for preset in ["sim-orion", "sim-bennu", "sim-voyager"]:
    d = Path(tmp) / preset
    simulate(get_preset(preset, max_frames=30), d)
    seq = ScanSequence(d)
    gt = seq.gt_poses
    for desc in ["hods", "shot"]:
        pairs = pair_correspondences(seq, desc, len(seq), 0.0)
        out = {}
        for mode in ["all", "oracle"]:
            est = get_estimator("kalman")
            W = [gt[0]]
            step = np.eye(4)
            for k, p in enumerate(pairs):
                if p is not None and len(p[2]) >= 4:
                    src, tgt, g = p
                    if mode == "oracle":
                        T = invert(gt[k]) @ gt[k + 1]
                        err = np.linalg.norm(
                            transform_points(T, src[g.src_idx]) - tgt[g.tgt_idx], axis=1
                        )
                        g = g.subset(np.flatnonzero(err < 0.1 * mean_resolution(tgt)))
                    e = est.estimate(src, tgt, g)
                    if e.status == "ok":
                        step = e.T_target_source
                W.append(W[-1] @ step)
            m = evaluate_trajectories(seq.timestamps, np.array(W), seq.timestamps, gt)
            out[mode] = float(m["T_error_pct"])
        print(preset, desc, {k: round(v, 3) for k, v in out.items()}, flush=True)
