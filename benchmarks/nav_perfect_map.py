"""Can one scan fix its pose against a perfect map? relnav's registration on a truth-built map.

    python benchmarks/nav_perfect_map.py --out bench/nav
    python benchmarks/nav_perfect_map.py --out bench/nav --only capsule-ellipse-128 --frames 20

For each sequence (simulated once into ``OUT/sequences`` by ``benchmarks/nav_suite.py``'s
definitions), a navigator map is built from the first ``--frames`` scans placed at their TRUE
poses. Each of the next ``--probe`` scans is then registered onto it with the navigator's own
solver (:meth:`relnav.navigation.navigator.Navigator._solve`) under a weak prior (1σ 1 m and 2°,
centred on the start), from two starts, and inserted at its true pose afterwards (the map stays
perfect):

* ``true``: the scan's true pose — how far the registration itself moves away from the truth;
* ``previous``: the previous frame's true pose (no motion) — how much of the step it recovers.

Printed per start: the median and maximum pose error after the registration (m, degrees), and
the median 1σ of the sensor's position in the answer from the solver's information
(``(H / σ̂² + Λ)⁻¹`` with the lever arm, largest axis) with the ratio of the median error to it
(≈ 1 for an honest covariance). The ground truth builds the map and scores; this is a diagnostic of
the registration, not a navigation result.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from nav_suite import simulate_suite
from relnav.geometry import invert, rotation_angle
from relnav.geometry.rotations import hat
from relnav.io.sequences import ScanSequence
from relnav.navigation.gicp import left_information
from relnav.navigation.navigator import Navigator, _rms_radius

DEFAULT = [
    "capsule-ellipse-128",
    "sim-orion-resample",
    "sim-orion",
    "sim-voyager-resample",
    "orion-inclined-64",
    "eros-ellipse-64",
    "voyager-ellipse-128",
    "asteroid-helical-128",
]
PRIOR_T, PRIOR_R_DEG = 1.0, 2.0  # weak prior of the probes (1σ)


def _finite(points: np.ndarray) -> np.ndarray:
    return points[np.all(np.isfinite(points), axis=1)]


def probe(
    seq_dir: Path, frames: int, n_probe: int, options: dict[str, str] | None = None
) -> dict[str, np.ndarray]:
    """Errors ``(n, 2)`` (m, deg) and 1σ ``(n,)`` (m) per start; the true steps ``(n,)`` (m).
    ``options``: the navigator's (``-O key=value``)."""
    seq = ScanSequence(seq_dir)
    gt = seq.gt_poses
    nav = Navigator(initial_pose=gt[0], bootstrap_frames=0, **(options or {}))
    nav.register_frame(seq[0])
    assert nav.map is not None
    for k in range(1, frames + 1):
        P = _finite(seq[k].points)
        nav.map.insert(P @ gt[k][:3, :3].T + gt[k][:3, 3], k)
    out: dict[str, list] = {"true": [], "previous": [], "sigma_true": [], "sigma_previous": []}
    steps = []
    S_prior = np.diag([PRIOR_T**2] * 3 + [math.radians(PRIOR_R_DEG) ** 2] * 3)
    for j in range(frames + 1, min(frames + 1 + n_probe, len(seq))):
        P = _finite(seq[j].points)
        rng = float(np.median(np.linalg.norm(P, axis=1)))
        radius = max(_rms_radius(P), nav.spacing0)
        for start, T0 in (("true", gt[j]), ("previous", gt[j - 1])):
            Lam = left_information(T0, S_prior)
            fit = nav._solve(P, T0, Lam, 3.0 * PRIOR_T, rng, radius)
            E = invert(gt[j]) @ fit["T"]
            out[start].append((np.linalg.norm(E[:3, 3]), math.degrees(rotation_angle(E[:3, :3]))))
            # covariance of the sensor's position: a left twist [ρ, φ] of T_target_sensor moves
            # it by ρ + φ × t (target frame)
            C = np.linalg.inv(fit["H"] / fit["var_factor"] + Lam)
            J = np.hstack([np.eye(3), -hat(fit["T"][:3, 3])])
            out[f"sigma_{start}"].append(math.sqrt(float(np.linalg.eigvalsh(J @ C @ J.T)[-1])))
        steps.append(float(np.linalg.norm((invert(gt[j - 1]) @ gt[j])[:3, 3])))
        nav.map.insert(P @ gt[j][:3, :3].T + gt[j][:3, 3], j)
    return {k: np.asarray(v) for k, v in out.items()} | {"step": np.asarray(steps)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of OUT/sequences")
    ap.add_argument("--only", nargs="*", default=DEFAULT, help="sequence names")
    ap.add_argument("--frames", type=int, default=20, help="scans in the truth-built map")
    ap.add_argument("--probe", type=int, default=30, help="scans registered onto it")
    ap.add_argument("-O", dest="options", action="append", default=[], help="relnav key=value")
    args = ap.parse_args()
    opts = dict(o.split("=", 1) for o in args.options)
    folders = simulate_suite(args.out, args.only)
    print(
        "| sequence | true step m | start | error median m / deg | error max m | "
        "solver 1σ m | error / 1σ |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.only:
        r = probe(folders[name], args.frames, args.probe, opts)
        for start in ("true", "previous"):
            e, s = r[start], r[f"sigma_{start}"]
            print(
                f"| {name} | {np.median(r['step']):.2f} | {start} | {np.median(e[:, 0]):.2f} / "
                f"{np.median(e[:, 1]):.2f} | {e[:, 0].max():.2f} | {np.median(s):.3f} | "
                f"{np.median(e[:, 0]) / np.median(s):.1f} |"
            )


if __name__ == "__main__":
    main()
