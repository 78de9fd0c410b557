"""Far approaches whose first scans are too sparse to register: ``startup.premap_range``.

    python benchmarks/nav/nav_premap.py --out bench/nav --perturb 6

Before its map starts (scans of fewer than ``solver.min_points`` points) the navigator without
the option (``-O startup.premap_range=false``) keeps its initial pose; with it (the default since
session 28) it places the sensor from each sparse scan's
centroid (its range along the first sighting's line of sight, or its whole bearing with the
chaser's attitude input) and starts its motion model at the positions' rate
(:meth:`relnav.navigation.navigator.Navigator._follow_range`). This script runs relnav with and
without it, with and without the chaser's measured attitude (``attitude=1``), under the first
``--perturb`` neutral perturbations of ``nav_weak_directions.py``, on the stress group's
voyager-approach (the only sequence of the suite's groups with such frames; the option was built
on it) and on three approaches made after it was built (:data:`HELD_OUT`: two straight ones and a
helical one, other targets and sensors). It prints per sequence and configuration the median APE
(causal, m) with its range, the median RPE (m) and the median wrong steps. The sequences are
simulated once into ``OUT/premap/<name>``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from nav_weak_directions import PERTURBATIONS

from relnav.bench.nav_suite import resolve_target, run_method, simulate_suite

_FLASH = {"preset": "goldeneye", "name": "flash"}
HELD_OUT: dict[str, dict[str, Any]] = {
    "aura-rbar": {
        "target": {"path": "../shared/data/targets/aura.ply", "scale_to": 8.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 36, "cols": 36, "range_sigma": 0.02}}],
        "seed": 71,
        "dt": 10.0,
        "trajectory": {"kind": "rbar", "params": {"start": -95.0, "stop": -15.0}},
    },
    "eros-vbar": {
        "target": {"path": "../shared/data/targets/eros.ply", "scale_to": 12.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 22, "cols": 22, "range_sigma": 0.03}}],
        "seed": 72,
        "dt": 10.0,
        "trajectory": {"kind": "vbar", "params": {"start": -110.0, "stop": -20.0}},
    },
    "orion-helical": {
        "target": {"path": "../shared/data/targets/orion.ply", "scale_to": 6.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 32, "cols": 32, "range_sigma": 0.02}}],
        "seed": 73,
        "dt": 15.0,
        "trajectory": {
            "kind": "helical-approach",
            "params": {
                "radius_start": 80.0,
                "radius_end": 15.0,
                "height_start": 10.0,
                "height_end": 2.0,
                "turns": 0.4,
            },
        },
    },
}
"""Approaches made after ``startup.premap_range`` was built (4–5 points per scan at the start:
the first 44, 30 and 13 frames), 120 frames each, with the chaser's measured attitude (0.01°)."""


def simulate_held_out(out: Path) -> dict[str, Path]:
    """Simulate (once) every :data:`HELD_OUT` approach into ``out/premap/<name>``."""
    from relnav.sim.scenario import simulate

    folders = {}
    for name, sc in HELD_OUT.items():
        d = out / "premap" / name
        if not (d / "scenario.yaml").exists():
            full = {
                **sc,
                "name": name,
                "frames": 120,
                "format": "npy",
                "pointing": {"attitude_sigma_deg": 0.01},
                "target": resolve_target(sc["target"]),
            }
            simulate(full, d, overwrite=True)
        folders[name] = d
    return folders


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--perturb", type=int, default=6, help="runs per cell (1 = unperturbed)")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore", FutureWarning)  # the perturbations' flat option names
    if not 1 <= a.perturb <= len(PERTURBATIONS):
        p.error(f"--perturb must be 1..{len(PERTURBATIONS)}")
    folders = {**simulate_suite(a.out, ["voyager-approach"]), **simulate_held_out(a.out)}
    print(
        f"{a.perturb} runs per cell: median APE m [min–max], median RPE_t m, median wrong steps\n"
    )
    print(
        "| sequence | attitude input | startup.premap_range=false | startup.premap_range=true "
        "(default) |\n|---|---|---|---|"
    )
    for name, folder in folders.items():
        for aided in (False, True):
            cells = []
            for premap in (False, True):
                runs = [
                    run_method(
                        folder,
                        "relnav",
                        **{**pert, "attitude": str(aided), "startup.premap_range": str(premap)},
                    )
                    for pert in PERTURBATIONS[: a.perturb]
                ]
                ape = np.array([r["ape"] for r in runs])
                rpe = np.median([r["rpe_t"] for r in runs])
                wrong = np.median([r["wrong"] for r in runs])
                cells.append(
                    f"{np.median(ape):.2f} [{ape.min():.2f}–{ape.max():.2f}], {rpe:.3f}, {wrong:g}"
                )
            print(f"| {name} | {'yes' if aided else 'no'} | {cells[0]} | {cells[1]} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
