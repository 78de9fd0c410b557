"""Quality of paper 1's correspondences (descriptor → NN → GCC) against the ground truth.

Per preset and descriptor, over consecutive scan pairs: the fraction of GCC inliers whose
source point, moved by the TRUE step, lands within ``2·Tr`` of its target point (and within
``0.1·Tr``: the same model point, noiseless fixed cloud), and the
fraction of pairs whose GCC cluster is mostly wrong (< 50 % such inliers). Isolates the front
end from the estimator (a filter cannot fix a wrong cluster). Not a test.

Run: ``python benchmarks/paper1/paper1_correspondence_quality.py --presets sim-voyager sim-orion``
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from paper1_estimators_same_corr import pair_correspondences

from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.se3 import invert, transform_points
from relnav.io.sequences import ScanSequence
from relnav.sim.presets import get_preset, preset_options
from relnav.sim.scenario import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["sim-voyager", "sim-orion", "sim-bennu"])
    ap.add_argument("--descriptors", nargs="+", default=["hods", "hod", "shot", "fpfh"])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--model-cloud", default="fixed")
    a = ap.parse_args()
    print(
        "preset descriptor inliers_within_2Tr_pct inliers_same_point_pct "
        "wrong_cluster_pairs_pct mean_inliers"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for preset in a.presets:
            d = Path(tmp) / preset
            opts = {"model_cloud": a.model_cloud} if "model_cloud" in preset_options(preset) else {}
            simulate(get_preset(preset, max_frames=a.frames, **opts), d)
            seq = ScanSequence(d)
            gt = seq.gt_poses
            for desc in a.descriptors:
                pairs = pair_correspondences(seq, desc, len(seq), 0.0)
                good, same, wrong, n_in = [], [], 0, []
                for k, p in enumerate(pairs):
                    if p is None or len(p[2]) == 0:
                        wrong += 1
                        continue
                    src, tgt, g = p
                    T = invert(gt[k]) @ gt[k + 1]  # source (k+1) -> target (k)
                    tr = mean_resolution(tgt)
                    err = np.linalg.norm(
                        transform_points(T, src[g.src_idx]) - tgt[g.tgt_idx], axis=1
                    )
                    ok = err < 2.0 * tr
                    good.append(ok.mean())
                    same.append((err < 0.1 * tr).mean())
                    wrong += ok.mean() < 0.5
                    n_in.append(len(g))
                print(
                    f"{preset} {desc} {100 * np.mean(good):.1f} {100 * np.mean(same):.1f} "
                    f"{100 * wrong / len(pairs):.1f} "
                    f"{np.mean(n_in):.0f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
