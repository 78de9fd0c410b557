"""Far approaches whose first scans are too sparse to register: ``startup.premap_range`` and
``startup.map_min_points``.

    python benchmarks/nav/nav_premap.py --out bench/nav --perturb 6

Before its map starts (scans of fewer than ``solver.min_points`` points) the navigator without
``startup.premap_range`` (``-O startup.premap_range=false``) keeps its initial pose; with it (the
default since session 28) it places the sensor from each sparse scan's centroid (its range along
the first sighting's line of sight, or its whole bearing with the chaser's attitude input) and
starts its motion model at the positions' rate
(:meth:`relnav.navigation.navigator.Navigator._follow_range`). ``startup.map_min_points=N``
defers the map until a scan has N points, the sparser ones placed that way.

This script runs relnav without the pre-map range, with the defaults and with
``startup.map_min_points=N`` (``--map-min-points``, 12), with and without the chaser's measured
attitude (``attitude=1``), under the first ``--perturb`` neutral perturbations of
``nav_weak_directions.py``, on the stress group's voyager-approach (the only sequence of the
suite's groups with such frames; both options were built on it), on three approaches made after
the pre-map range was built (:data:`HELD_OUT`) and on five made with the map's deferral
(:data:`FRESH`). It prints per sequence and configuration the median APE (causal, m) with its
range, the median RPE_t (m), the median wrong steps and the median wrong steps not flagged. The
sequences are simulated once into ``OUT/premap/<name>``.
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

FRESH: dict[str, dict[str, Any]] = {
    "comet-rbar": {
        "target": {"path": "../shared/data/targets/comet67p.ply", "scale_to": 10.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 28, "cols": 28, "range_sigma": 0.02}}],
        "seed": 81,
        "dt": 10.0,
        "trajectory": {"kind": "rbar", "params": {"start": -100.0, "stop": -18.0}},
    },
    "envisat-vbar": {
        "target": {"name": "envisat", "scale_to": 10.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 30, "cols": 30, "range_sigma": 0.02}}],
        "seed": 82,
        "dt": 10.0,
        "trajectory": {"kind": "vbar", "params": {"start": -120.0, "stop": -20.0}},
    },
    "iridium-rbar": {
        "target": {"name": "iridium", "scale_to": 6.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 40, "cols": 40, "range_sigma": 0.02}}],
        "seed": 83,
        "dt": 10.0,
        "trajectory": {"kind": "rbar", "params": {"start": -90.0, "stop": -12.0}},
    },
    "asteroid-vbar": {
        "target": {"name": "asteroid", "scale_to": 8.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 24, "cols": 24, "range_sigma": 0.03}}],
        "seed": 84,
        "dt": 10.0,
        "trajectory": {"kind": "vbar", "params": {"start": -100.0, "stop": -15.0}},
    },
    "comet-helical": {
        "target": {"path": "../shared/data/targets/comet67p.ply", "scale_to": 8.0},
        "sensors": [{**_FLASH, "overrides": {"rows": 30, "cols": 30, "range_sigma": 0.02}}],
        "seed": 85,
        "dt": 15.0,
        "trajectory": {
            "kind": "helical-approach",
            "params": {
                "radius_start": 90.0,
                "radius_end": 20.0,
                "height_start": 8.0,
                "height_end": 2.0,
                "turns": 0.25,
            },
        },
    },
}
"""Approaches made in session 28, when ``startup.map_min_points`` was built, and run once for
it (a clean hold-out): the first 34, 83, 61, 50 and 27 frames have fewer than 6 points
(envisat-vbar and iridium-rbar see nothing over their first 41 and 21 frames)."""

CONFIGS: dict[str, dict[str, str]] = {
    "startup.premap_range=false": {"startup.premap_range": "false"},
    "defaults": {},
}
"""The navigator's configurations compared (``--map-min-points`` adds one)."""


def simulate_scenarios(out: Path, scenarios: dict[str, dict[str, Any]]) -> dict[str, Path]:
    """Simulate (once) every scenario of ``scenarios`` (120 frames, the chaser's measured
    attitude written at 0.01°) into ``out/<name>``; their folders by name."""
    from relnav.sim.scenario import simulate

    folders = {}
    for name, sc in scenarios.items():
        d = out / name
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


def cell(folder: Path, options: dict[str, str], perturb: int) -> str:
    """relnav on ``folder`` with ``options`` under the first ``perturb`` perturbations: median
    APE [range], median RPE_t, median wrong steps, median wrong steps not flagged."""
    runs = [run_method(folder, "relnav", **{**pert, **options}) for pert in PERTURBATIONS[:perturb]]
    ape = np.array([r["ape"] for r in runs])
    rpe = np.median([r["rpe_t"] for r in runs])
    wrong = np.median([r["wrong"] for r in runs])
    missed = np.median([r["wrong"] - r["wrong_flagged"] for r in runs])
    return (
        f"{np.median(ape):.2f} [{ape.min():.2f}–{ape.max():.2f}], {rpe:.3f}, {wrong:g}, {missed:g}"
    )


def print_table(folders: dict[str, Path], configs: dict[str, dict[str, str]], perturb: int) -> None:
    """Print one row per sequence and attitude input (without, with), one :func:`cell` per
    configuration of relnav's options."""
    print(
        f"{perturb} runs per cell: median APE m [min–max], median RPE_t m, median wrong "
        "steps, median wrong steps not flagged\n"
    )
    print(f"| sequence | attitude input | {' | '.join(configs)} |")
    print("|---" * (2 + len(configs)) + "|")
    for name, folder in folders.items():
        for aided in (False, True):
            cells = [cell(folder, {**o, "attitude": str(aided)}, perturb) for o in configs.values()]
            print(f"| {name} | {'yes' if aided else 'no'} | {' | '.join(cells)} |", flush=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--perturb", type=int, default=6, help="runs per cell (1 = unperturbed)")
    p.add_argument(
        "--map-min-points",
        type=int,
        default=12,
        help="a third configuration with startup.map_min_points=N (0: none)",
    )
    a = p.parse_args(argv)
    warnings.simplefilter("ignore", FutureWarning)  # the perturbations' flat option names
    if not 1 <= a.perturb <= len(PERTURBATIONS):
        p.error(f"--perturb must be 1..{len(PERTURBATIONS)}")
    configs = dict(CONFIGS)
    if a.map_min_points > 0:
        configs[f"startup.map_min_points={a.map_min_points}"] = {
            "startup.map_min_points": str(a.map_min_points)
        }
    folders = {
        **simulate_suite(a.out, ["voyager-approach"]),
        **simulate_scenarios(a.out / "premap", {**HELD_OUT, **FRESH}),
    }
    print_table(folders, configs, a.perturb)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
