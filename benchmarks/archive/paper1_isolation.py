"""Why is paper 1's best T_error not reproduced? One change at a time, per scenario.

Issue 9 asks, for every scenario where our best proposed combination is more than 2× the paper's
best T_error, for an experiment that isolates the cause. This script re-simulates a scenario with
one of our choices changed at a time (scan generation) or runs the pipelines with one parameter
changed (method options, applied to the ``feature:`` pipelines only; competitors keep theirs) and
prints T_error % (endpoint error / ground-truth path length, as the paper) and the number of
steps wrong by more than 0.5 m or 5°.

* ``real-fb``, ``real-curved`` (VLP-16 on the Envisat mock-up): our 0.5° white attitude jitter
  per frame ("minor tumbling of the Source") and σ = 3 cm range noise, both choices of ours;
  for Real-Curved also the beams on the target (the paper: "the vertical cardinality ... is
  fixed to 16 vertices"; our mock-up pose puts 6–9 of the 16 beams on it, so a variant spreads
  the 16 beams over ±7.5°).
* ``sim-orion``, ``sim-bennu`` (HPR scans of one model cloud): the 1 cm range noise we add, and
  GCC's tolerance ε (paper 1: ``2·Tr``; ``Tr`` here is the scan's mean nearest-neighbour
  spacing, so at 150–300 points ε is 0.3–1 m and admits matches one point off).

The ground-truth diagnosis of the same HPR failure (GCC inliers that are a neighbouring point,
not the same model point) is ``benchmarks/paper1/paper1_near_miss_oracle.py``; the ε rows here
show it
without the truth, through the one parameter that admits those inliers.

No parameter is changed in the presets or the methods' defaults by this script; it measures.

Run: ``python benchmarks/archive/paper1_isolation.py --scenario sim-bennu [--out DIR] [--frames N]``
(``--scenario all`` runs the four; about 40 min on 2 cores; every sequence is seeded, so the
tables are reproducible). Results: ``docs/results/paper1-fidelity/isolation.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relnav.eval.metrics import evaluate_trajectories
from relnav.geometry.rotations import rotation_angle
from relnav.io.sequences import ScanSequence
from relnav.pipeline import run_sequence
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate

WRONG_T_M, WRONG_R_DEG = 0.5, 5.0
"""A step is wrong when its error exceeds 0.5 m or 5° (the navigation suite's rule)."""

_BEAMS_16_ON_TARGET = [float(e) for e in np.round(np.linspace(-7.5, 7.5, 16), 3)]


@dataclass(frozen=True)
class Variant:
    """One change: to the simulated scenario (dotted keys) and/or to the feature pipelines."""

    scan_changes: dict[str, Any] = field(default_factory=dict)
    feature_options: dict[str, Any] = field(default_factory=dict)


_VLP16_METHODS = [
    "icp-point",
    "icp-x84",
    "sicp-point",
    "feature:hods+gcc+alphabeta",
    "feature:hod+gcc+hinf",
    "feature:shot+gcc+kalman",
    "feature:rops+gcc+kalman",
    "feature:trisi+gcc+sdre",
    "relnav",
    "kiss-icp",
]
_HPR_METHODS = [
    "icp-point",
    "sicp-point",
    "feature:hods+gcc+alphabeta",
    "feature:hods+gcc+svd",
    "feature:hod+gcc+kalman",
    "feature:shot+gcc+kalman",
    "feature:rops+gcc+sdre",
    "feature:trisi+gcc+sdre",
]
_JITTER, _SIGMA = "pointing.jitter_deg", "sensors.0.overrides.range_sigma"
_HPR_SIGMA = "sensors.0.overrides.noise_sigma"


def _eps(factor: float) -> dict[str, Any]:
    return {"grouper_options": {"epsilon_factor": factor}}


_HPR_VARIANTS = {
    "preset (σ 1 cm, ε = 2·Tr)": Variant(),
    "no noise": Variant({_HPR_SIGMA: 0.0}),
    "ε = 1·Tr": Variant(feature_options=_eps(1.0)),
    "ε = 0.5·Tr": Variant(feature_options=_eps(0.5)),
    "ε = 0.25·Tr": Variant(feature_options=_eps(0.25)),
}
"""Changes tried on the two HPR scenarios (Sim-Orion, Sim-Bennu)."""

SCENARIOS: dict[str, tuple[list[str], dict[str, Variant]]] = {
    "real-fb": (
        _VLP16_METHODS,
        {
            "preset (jitter 0.5°, σ 3 cm)": Variant(),
            "jitter 0.05°": Variant({_JITTER: 0.05}),
            "jitter 0.05°, σ 1 cm": Variant({_JITTER: 0.05, _SIGMA: 0.01}),
            "no jitter, no noise": Variant({_JITTER: 0.0, _SIGMA: 0.0}),
        },
    ),
    "real-curved": (
        _VLP16_METHODS,
        {
            "preset (jitter 0.5°, σ 3 cm)": Variant(),
            "no jitter, no noise": Variant({_JITTER: 0.0, _SIGMA: 0.0}),
            "16 beams on the target": Variant(
                {"sensors.0.overrides.elevations_deg": _BEAMS_16_ON_TARGET}
            ),
            "no jitter, no noise, 16 beams on the target": Variant(
                {
                    _JITTER: 0.0,
                    _SIGMA: 0.0,
                    "sensors.0.overrides.elevations_deg": _BEAMS_16_ON_TARGET,
                }
            ),
        },
    ),
    "sim-orion": (_HPR_METHODS, _HPR_VARIANTS),
    "sim-bennu": (_HPR_METHODS, _HPR_VARIANTS),
}

PAPER_BEST = {
    "real-fb": "HoD/H∞ 2.00, HoD-S/αβ 2.20, Sparse ICP (point) 1.70 %",
    "real-curved": "HoD/αβ 0.41, HoD-S/αβ 2.03, Sparse ICP (point) 1.70 %",
    "sim-orion": "RoPS/SDRE 0.90, HoD-S/αβ 13.91, ICP (plane) 1.46 %",
    "sim-bennu": "SHOT/H∞ 0.15, HoD-S/αβ 0.26, S4PCS 2.88 %",
}


def _scenario(preset: str, changes: dict[str, Any], max_frames: int | None) -> dict:
    sc = get_preset(preset, max_frames=max_frames).model_dump()
    for dotted, value in changes.items():
        node = sc
        *path, last = dotted.split(".")
        for key in path:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[last] = value
    return sc


def wrong_steps(poses: np.ndarray, gt: np.ndarray) -> int:
    """Steps whose relative-pose error exceeds 0.5 m or 5°."""
    n = 0
    for k in range(1, len(poses)):
        step_gt = np.linalg.inv(gt[k - 1]) @ gt[k]
        step = np.linalg.inv(poses[k - 1]) @ poses[k]
        E = np.linalg.inv(step_gt) @ step
        n += bool(
            np.linalg.norm(E[:3, 3]) > WRONG_T_M
            or np.degrees(rotation_angle(E[:3, :3])) > WRONG_R_DEG
        )
    return n


def run_scenario(name: str, root: Path, frames: list[int | None]) -> None:
    """Print one markdown table: variants × lengths (rows), methods (columns)."""
    methods, variants = SCENARIOS[name]
    available = [m for m in methods if m != "kiss-icp" or _has("kiss_icp")]
    print(f"\n### {name}\n")
    print("Cells: T_error % (steps wrong by > 0.5 m or 5°).\n")
    print("| variant | frames | " + " | ".join(available) + " |")
    print("|---|---|" + "---|" * len(available))
    for label, variant in variants.items():
        for n_frames in frames:
            key = json.dumps(variant.scan_changes, sort_keys=True)
            slug = "".join(c if c.isalnum() else "-" for c in key)[:80] or "preset"
            d = root / name / f"{slug}-{n_frames or 'all'}"
            if not (d / "scenario.yaml").exists():
                simulate(_scenario(name, variant.scan_changes, n_frames), d)
            seq = ScanSequence(d)
            gt = np.asarray(seq.gt_poses)
            cells = []
            for m in available:
                opts = variant.feature_options if m.startswith("feature:") else {}
                run = run_sequence(seq, m, keep_steps=False, **opts)
                t = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, gt)
                cells.append(f"{t['T_error_pct']:.2f} ({wrong_steps(np.asarray(run.poses), gt)})")
            print(f"| {label} | {n_frames or len(seq)} | " + " | ".join(cells) + " |", flush=True)
    print(f"\nPaper 1, {name}: {PAPER_BEST[name]}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=[*SCENARIOS, "all"], default="all")
    ap.add_argument("--out", type=Path, default=None, help="keep the sequences here")
    ap.add_argument(
        "--frames",
        type=int,
        action="append",
        default=None,
        help="run length(s); default: the whole run (and 30 frames for real-fb)",
    )
    args = ap.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp())
    names = list(SCENARIOS) if args.scenario == "all" else [args.scenario]
    for name in names:
        frames = args.frames or ([None, 30] if name == "real-fb" else [None])
        run_scenario(name, root, frames)
    return 0


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


if __name__ == "__main__":
    sys.exit(main())
