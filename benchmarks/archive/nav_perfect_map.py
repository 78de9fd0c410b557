"""Can one scan fix its pose against a perfect map? relnav's registration on a truth-built map.

    python benchmarks/archive/nav_perfect_map.py --out bench/nav
    python benchmarks/archive/nav_perfect_map.py --out bench/nav --only capsule-ellipse-128 \
        --frames 20
    python benchmarks/archive/nav_perfect_map.py --out bench/nav --prior 100 90   # the scan alone

For each sequence (simulated once into ``OUT/sequences`` by ``benchmarks/nav/nav_suite.py``'s
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
(≈ 1 for an honest covariance). Then, per sequence, whether the scan's own cost can tell the two
answers apart: of the probes whose two answers are more than 0.5 m apart, how many end with the
answer farther from the truth fitting at least as well (robust RMS of the residuals, in units of
the noise model, no prior). ``--prior T R`` sets the prior's 1σ (m, degrees; ``--prior 100 90``:
the scan alone). The ground truth builds the map and scores; this is a diagnostic of the
registration, not a navigation result.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from relnav.bench.nav_suite import simulate_suite
from relnav.geometry import invert, rotation_angle
from relnav.geometry.rotations import hat
from relnav.io.sequences import ScanSequence
from relnav.navigation.gicp import left_information
from relnav.navigation.navigator import Navigator
from relnav.navigation.solver import rms_radius

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
STARTS = ("true", "previous")
PRIOR_T, PRIOR_R_DEG = 1.0, 2.0  # weak prior of the probes (1σ, default of --prior)
APART_M = 0.5  # two answers farther apart than this are different answers (the flag limit)


def _finite(points: np.ndarray) -> np.ndarray:
    return points[np.all(np.isfinite(points), axis=1)]


def probe(
    seq_dir: Path,
    frames: int,
    n_probe: int,
    options: dict[str, str] | None = None,
    prior: tuple[float, float] = (PRIOR_T, PRIOR_R_DEG),
) -> dict[str, np.ndarray]:
    """Errors ``(n, 2)`` (m, deg), 1σ ``(n,)`` (m), robust RMS ``(n,)`` (noise σ) and answers
    ``(n, 3)`` (sensor position, target frame, m) per start; the true steps ``(n,)`` (m).
    ``options``: the navigator's (``-O key=value``); ``prior``: 1σ of the probes' prior (m,
    degrees)."""
    seq = ScanSequence(seq_dir)
    gt = seq.gt_poses
    nav = Navigator(initial_pose=gt[0], **{"startup.bootstrap_frames": 0, **(options or {})})
    nav.register_frame(seq[0])
    assert nav.map is not None
    for k in range(1, frames + 1):
        P = _finite(seq[k].points)
        nav.map.insert(P @ gt[k][:3, :3].T + gt[k][:3, 3], k)
    out: dict[str, list] = {
        f"{key}{start}": [] for key in ("", "sigma_", "rms_", "at_") for start in STARTS
    }
    steps = []
    S_prior = np.diag([prior[0] ** 2] * 3 + [math.radians(prior[1]) ** 2] * 3)
    for j in range(frames + 1, min(frames + 1 + n_probe, len(seq))):
        P = _finite(seq[j].points)
        rng = float(np.median(np.linalg.norm(P, axis=1)))
        radius = max(rms_radius(P), nav.spacing0)
        for start, T0 in zip(STARTS, (gt[j], gt[j - 1]), strict=True):
            Lam = left_information(T0, S_prior)
            fit = nav.solver.solve(P, T0, Lam, 3.0 * prior[0], rng, radius)
            E = invert(gt[j]) @ fit["T"]
            out[start].append((np.linalg.norm(E[:3, 3]), math.degrees(rotation_angle(E[:3, :3]))))
            out[f"rms_{start}"].append(fit["rms"])
            out[f"at_{start}"].append(fit["T"][:3, 3])
            # covariance of the sensor's position: a left twist [ρ, φ] of T_target_sensor moves
            # it by ρ + φ × t (target frame)
            C = np.linalg.inv(fit["H"] / fit["var_factor"] + Lam)
            J = np.hstack([np.eye(3), -hat(fit["T"][:3, 3])])
            out[f"sigma_{start}"].append(math.sqrt(float(np.linalg.eigvalsh(J @ C @ J.T)[-1])))
        steps.append(float(np.linalg.norm((invert(gt[j - 1]) @ gt[j])[:3, 3])))
        nav.map.insert(P @ gt[j][:3, :3].T + gt[j][:3, 3], j)
    return {k: np.asarray(v) for k, v in out.items()} | {"step": np.asarray(steps)}


def indistinct(r: dict[str, np.ndarray]) -> tuple[int, int]:
    """Probes whose two answers are more than :data:`APART_M` apart, and how many of them end
    with the answer farther from the truth fitting at least as well (robust RMS)."""
    apart = np.linalg.norm(r["at_true"] - r["at_previous"], axis=1) > APART_M
    far_is_prev = r["previous"][:, 0] >= r["true"][:, 0]
    rms_far = np.where(far_is_prev, r["rms_previous"], r["rms_true"])
    rms_near = np.where(far_is_prev, r["rms_true"], r["rms_previous"])
    return int(apart.sum()), int((apart & (rms_far <= rms_near)).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of OUT/sequences")
    ap.add_argument("--only", nargs="*", default=DEFAULT, help="sequence names")
    ap.add_argument("--frames", type=int, default=20, help="scans in the truth-built map")
    ap.add_argument("--probe", type=int, default=30, help="scans registered onto it")
    ap.add_argument("-O", dest="options", action="append", default=[], help="relnav key=value")
    ap.add_argument(
        "--prior",
        nargs=2,
        type=float,
        default=(PRIOR_T, PRIOR_R_DEG),
        metavar=("T_M", "R_DEG"),
        help="1σ of the probes' prior, m and degrees",
    )
    args = ap.parse_args()
    opts = dict(o.split("=", 1) for o in args.options)
    folders = simulate_suite(args.out, args.only)
    print(
        "| sequence | true step m | start | error median m / deg | error max m | "
        "solver 1σ m | error / 1σ | robust RMS σ |"
    )
    print("|---|---|---|---|---|---|---|---|")
    apart = {}
    for name in args.only:
        r = probe(folders[name], args.frames, args.probe, opts, tuple(args.prior))
        for start in STARTS:
            e, s = r[start], r[f"sigma_{start}"]
            print(
                f"| {name} | {np.median(r['step']):.2f} | {start} | {np.median(e[:, 0]):.2f} / "
                f"{np.median(e[:, 1]):.2f} | {e[:, 0].max():.2f} | {np.median(s):.3f} | "
                f"{np.median(e[:, 0]) / np.median(s):.1f} | {np.median(r[f'rms_{start}']):.3f} |"
            )
        apart[name] = indistinct(r)
    print(
        f"\nprobes whose two answers are more than {APART_M} m apart / of them, the answer "
        "farther from the truth fits at least as well (robust RMS):"
    )
    for name, (n_apart, n_same) in apart.items():
        print(f"  {name}: {n_apart} / {n_same}")


if __name__ == "__main__":
    main()
