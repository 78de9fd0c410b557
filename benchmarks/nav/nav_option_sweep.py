"""An option of relnav's navigator against its defaults, under neutral solver perturbations.

    python benchmarks/nav/nav_option_sweep.py --out bench/nav -O map.surface=quadric
    python benchmarks/nav/nav_option_sweep.py --out bench/nav -O map.surface=quadric --holdout \
        --perturb 6

On sparse scans one run of a sequence is one draw: neutral changes of the solver (``kernel``
2.9–3.1, ``kernel_decay`` 0.58–0.62, ``max_iter`` 31–33; the list of
``nav_weak_directions.py``) move orion-inclined-64's APE between 4.7 and 15.4 m. This script runs
``relnav`` with its defaults and with the given options (``-O key=value``, repeatable) under the
same ``--perturb`` perturbations (the first is none) on every sequence of the navigation suite
(``--holdout``: the held-out ones) and prints, per sequence, the median APE with its range, the
median wrong steps and the wrong / right steps flagged, then the suite's totals per
perturbation. ``--json`` keeps every run. The ground truth is used for scoring only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from nav_weak_directions import PERTURBATIONS

from relnav.bench.nav_suite import (
    add_sequence_arguments,
    run_method,
    selected_names,
    simulate_suite,
)

KEYS = ("ape", "rpe_t", "rpe_r", "wrong", "wrong_flagged", "right_flagged", "ms", "wall_s")


def sweep(folder: Path, options: dict[str, str], n: int) -> list[dict[str, Any]]:
    """``relnav`` on one sequence under the first ``n`` perturbations (with ``options``)."""
    runs = []
    for pert in PERTURBATIONS[:n]:
        r = run_method(folder, "relnav", **{**options, **pert})
        runs.append({k: r[k] for k in KEYS})
    return runs


def _cell(runs: list[dict[str, Any]]) -> str:
    a = np.array([r["ape"] for r in runs])
    w = np.median([r["wrong"] for r in runs])
    wf = sum(r["wrong_flagged"] for r in runs)
    rf = sum(r["right_flagged"] for r in runs)
    ms = np.median([r["ms"] for r in runs])
    return f"{np.median(a):.3f} [{a.min():.2f}–{a.max():.2f}], {w:g} ({wf}/{rf}), {ms:.2f} ms"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    p.add_argument("--perturb", type=int, default=6, help="runs per sequence (1 = unperturbed)")
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args(argv)
    if not 1 <= a.perturb <= len(PERTURBATIONS):
        p.error(f"--perturb must be 1..{len(PERTURBATIONS)}")
    names = selected_names(a)
    folders = simulate_suite(a.out, names)
    opts = dict(o.split("=", 1) for o in a.options)
    label = " ".join(a.options) or "defaults"
    results: dict[str, dict[str, list[dict[str, Any]]]] = {}
    print(
        f"{a.perturb} runs per sequence; cells: median APE m [min–max], median wrong steps "
        "(wrong/right steps flagged over all runs), median time per frame"
    )
    print(f"| sequence | defaults | {label} |\n|---|---|---|")
    for name in names:
        results[name] = {"defaults": sweep(folders[name], {}, a.perturb)}
        results[name][label] = sweep(folders[name], opts, a.perturb)
        base, other = results[name]["defaults"], results[name][label]
        print(f"| {name} | {_cell(base)} | {_cell(other)} |", flush=True)
    for which in ("defaults", label):
        tot = [
            (
                sum(results[n][which][k]["wrong"] for n in names),
                sum(results[n][which][k]["wrong_flagged"] for n in names),
                sum(results[n][which][k]["right_flagged"] for n in names),
            )
            for k in range(a.perturb)
        ]
        print(
            f"{which}: wrong steps per run "
            + " ".join(str(t[0]) for t in tot)
            + "; wrong flagged "
            + " ".join(str(t[1]) for t in tot)
            + "; right flagged "
            + " ".join(str(t[2]) for t in tot)
        )
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(results, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
