"""The full relative state on tumbling-target sequences: angular-rate accuracy and consistency.

    python benchmarks/nav_state.py --out bench/nav            # envisat-tumble-64, aura-tumble-64

Runs ``relnav`` on the navigation suite's tumbling sequences (simulated once into
``OUT/sequences`` by ``benchmarks/nav_suite.py``'s definitions), feeds its poses to paper 2's
twistor UKF (:func:`relnav.navigation.state.relative_state`) and prints, after the first 30 % of
the frames (convergence): the angular-rate error (median, 95th percentile, max, deg/s), the
attitude/position/velocity RMS errors, and the mean NEES of the full 12-dim state and of its
rates (velocity + angular rate) beside their 95 % bands.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from nav_suite import simulate_suite

TUMBLING = ["envisat-tumble-64", "aura-tumble-64"]


def rate_nees(res, k0: int) -> np.ndarray:
    """NEES of ``[velocity, angular rate]`` (6 dof) per step from ``k0``."""
    e = res.errors()
    err = np.concatenate([e["velocity"], e["omega"]], axis=1)
    idx = [3, 4, 5, 9, 10, 11]
    out = []
    for k in range(k0, len(err)):
        if np.all(np.isfinite(err[k])):
            C = res.covariance[k][np.ix_(idx, idx)]
            out.append(float(err[k] @ np.linalg.solve(C, err[k])))
    return np.asarray(out)


def main(argv: list[str] | None = None) -> int:
    from relnav.io.sequences import ScanSequence
    from relnav.navigation.state import nees_band, relative_state
    from relnav.odometry import run_sequence

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    a = p.parse_args(argv)
    folders = simulate_suite(a.out, TUMBLING)
    for name, folder in folders.items():
        seq = ScanSequence(folder)
        run = run_sequence(seq, "relnav")
        res = relative_state(run, gt_poses=seq.gt_poses)
        k0 = round(0.3 * len(res))
        w = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
        s = res.summary(skip=0.3)
        full = res.nees()[k0:]
        full = full[np.isfinite(full)]
        rates = rate_nees(res, k0)
        rate_true = np.degrees(np.median(np.linalg.norm(res.truth.omega, axis=1)))
        print(f"{name}: true rate {rate_true:.2f} deg/s; after {k0} of {len(res)} frames:")
        print(
            f"  angular-rate error deg/s: median {np.median(w):.3f}  p95 "
            f"{np.percentile(w, 95):.3f}  max {w.max():.3f}"
        )
        fmt = " / ".join
        print(
            "  RMS errors: attitude "
            + fmt(f"{x:.2f}" for x in s["attitude"]["rms"])
            + " deg, position "
            + fmt(f"{x:.2f}" for x in s["position"]["rms"])
            + " m, velocity "
            + fmt(f"{x:.3f}" for x in s["velocity"]["rms"])
            + " m/s"
        )
        lo, hi = nees_band(len(full))
        lo6, hi6 = nees_band(len(rates), dof=6)
        print(f"  mean NEES, 12-dim state: {full.mean():.1f} (95 % band {lo:.1f}-{hi:.1f})")
        print(f"  mean NEES, rates (6-dim): {rates.mean():.2f} (95 % band {lo6:.2f}-{hi6:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
