"""The navigation suite: sparse flash-LIDAR sequences for relnav's own navigator and its peers.

Every sequence is made with relnav's simulator: a flash LIDAR (64×64 or 128×128 pixels, 45° field
of view, 2 cm range noise) at 35–65 m from a target, on paths that a GNC engineer would fly:
2.5 loops of an ellipse, a helical approach, an inspection ellipse inclined to a symmetric target's
axis, and a hold point beside a target tumbling about a tilted axis. Targets: the meshes of
``../shared/data/targets`` (Eros, Aura, Orion, Voyager, 67P) when present, relnav's procedural ones
otherwise (and always for the procedural entries). The sequences are defined in YAML
(``configs/nav-suite.yaml``, ``nav-holdout.yaml``, ``nav-stress.yaml`` and the scenarios
``configs/nav/*.yaml``), read by :mod:`relnav.bench.nav_suite`, which holds the code the
navigation benchmarks share; this script is its command line.

    python benchmarks/nav/nav_suite.py --out bench/nav                  # all sequences, all methods
    python benchmarks/nav/nav_suite.py --out bench/nav --only eros --methods relnav,kiss-icp
    python benchmarks/nav/nav_suite.py --out bench/nav --methods relnav,kiss-icp \
        --onto docs/results/nav/suite_causal.json --json docs/results/nav/suite_causal.json

The script simulates each sequence once (cached in ``OUT/sequences``), runs every method once
untimed on the first sequence's first frames (so that one-off loading is not charged to that
sequence's whole-run time), runs every method on the same frames, and prints APE, RPE,
wrong-step counts (> 0.5 m or > 5°), flagged steps and ms per frame, then each method's ratio to
the best peer. ``--json`` writes everything. ``relnav`` is given the target's orbit (its mean
motion, :data:`relnav.bench.nav_suite.MISSION`: every sequence is flown about a target in the
same low Earth orbit), as a mission would give it; ``-O orbit.mean_motion=0`` runs it without.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

from relnav.bench.nav_suite import (
    DEFAULT_METHODS,
    THREADED_PEERS,
    add_sequence_arguments,
    markdown_table,
    relnav_ratios,
    run_method,
    scorecard_table,
    selected_names,
    simulate_suite,
    stress_table,
    warm_up,
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS))
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="threads within a frame for every method that has them (relnav's solver.threads, "
        "KISS-ICP's and small_gicp's num_threads); default 1 (DESIGN §7)",
    )
    p.add_argument("--json", type=Path, default=None)
    p.add_argument(
        "--stress-table",
        nargs=2,
        type=Path,
        metavar=("PLAIN_JSON", "ATTITUDE_JSON"),
        help="print the stress group's table from two --json files and exit",
    )
    p.add_argument(
        "--scorecard",
        nargs="+",
        type=Path,
        metavar="JSON",
        help="print relnav against its targets (TARGETS) on each sequence of --json files and exit",
    )
    p.add_argument(
        "--onto",
        type=Path,
        default=None,
        metavar="JSON",
        help="merge the runs into this --json file's results (the methods run replace their "
        "entries, the other methods' are kept: relnav and KISS-ICP timed together beside an "
        "all-peer run); --json then writes the merged results",
    )
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if a.scorecard:
        for f in a.scorecard:
            print(f"{f}:\n\n{scorecard_table(json.loads(f.read_text()))}\n")
        return 0
    if a.stress_table:
        plain, aided = (json.loads(f.read_text()) for f in a.stress_table)
        print(stress_table(plain, aided))
        return 0
    names = selected_names(a)
    folders = simulate_suite(a.out, names)
    methods = [m for m in a.methods.split(",") if m]
    relnav_options = dict(o.split("=", 1) for o in a.options)
    peer_options: dict[str, Any] = {}
    if a.threads != 1:  # like with like: every method with threads gets as many
        relnav_options.setdefault("solver.threads", str(a.threads))
        peer_options = {m: {"num_threads": a.threads} for m in THREADED_PEERS}
    if names:
        warm_up(folders[names[0]], methods, relnav_options)
    results: dict[str, dict[str, Any]] = {}
    for name in names:
        results[name] = {}
        for method in methods:
            try:
                # strings: the navigator converts them to its options' types (bool, int, ...)
                opts = relnav_options if method == "relnav" else peer_options.get(method, {})
                r = run_method(folders[name], method, **opts)
            except Exception as e:  # a missing extra, say: report and go on
                r = {"error": f"{type(e).__name__}: {e}"}
            results[name][method] = r
            if "error" in r:
                print(f"{name:22s} {method:16s} ERROR {r['error']}")
                continue
            print(
                f"{name:22s} {method:16s} APE {r['ape']:7.3f} m  RPE {r['rpe_t']:6.3f} m "
                f"{r['rpe_r']:6.3f}°  wrong {r['wrong']:3d}/{r['n_steps']}  flagged "
                f"{r['flagged']:3d} (wrong {r['wrong_flagged']:3d}, right "
                f"{r['right_flagged']:3d})  {r['ms']:6.2f} ms",
                flush=True,
            )
        q = relnav_ratios(results[name])
        if q is not None:
            print(
                f"{name:22s} relnav / best peer: APE {q['ape']:.2f}  RPE_t {q['rpe_t']:.2f}  "
                f"RPE_r {q['rpe_r']:.2f}  time / kiss-icp {q['time']:.2f} "
                f"(whole run {q['run_time']:.2f})",
                flush=True,
            )
    if a.onto:
        merged: dict[str, dict[str, Any]] = json.loads(a.onto.read_text())
        for name, runs in results.items():
            merged.setdefault(name, {}).update(runs)
        results = {name: merged[name] for name in merged}
    if a.json:
        a.json.write_text(json.dumps(results, indent=2))
    print()
    print(markdown_table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
