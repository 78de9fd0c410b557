"""Tumbling targets entered at random phases: how often each method keeps the track.

    python benchmarks/nav/nav_phases.py --out bench/nav     # envisat and aura, 20 phases
    python benchmarks/nav/nav_phases.py --out bench/nav --phases 20 \
        --methods relnav-tumbling,relnav,kiss-icp,small-gicp             # the default methods
    python benchmarks/nav/nav_phases.py --out bench/nav --state          # + the relative state
    python benchmarks/nav/nav_phases.py --out bench/nav --only voyager-tumble-64   # another one
    python benchmarks/nav/nav_phases.py --out bench/nav --methods relnav-tumbling \
        -O startup.window=0

The navigation suite's tumbling sequences (``benchmarks/nav/nav_suite.py``) each start their tumble
at one attitude, so one run says little about where the sensor may meet the target. Here each
sequence is simulated again ``--phases`` times, run ``i`` entering the same motion
``attitude.phase_s`` seconds later (uniform over one turn of the initial rate, drawn from seed
3000 + i) with noise seed 1000 + i; target, station and sensor are the sequence's
(cached in ``OUT/sequences/NAME-phaseI``). Every method runs on the same runs; the report
gives, per method, the APE (no alignment) over the runs (median, 90th percentile, max), the runs
whose APE exceeds ``--lost`` m (default 5: a tenth of the 50 m station), the steps wrong by more
than 0.5 m or 5° and the share of them flagged, and the share of right steps flagged (the
suite's definitions, ``nav_suite.run_method``); for the navigator, the wrong steps it did not
flag against their own step covariance (10–90 % of their error and 1σ, their median exceedance
probability), what ``flag_probability`` 0.1 instead of 0.5 would flag, and how many runs over
``--lost`` m (and under it) its revisit test found inconsistent
(:mod:`relnav.navigation.revisit_check`).

``-O key=value`` passes an option to the navigator's methods (``relnav``, ``relnav-tumbling``;
the peers run as they are). ``--state`` also runs the relative state (``relnav-tumbling`` with
``-S preset=hold-point``, :func:`relnav.navigation.state.relative_state`) on every run and
prints the Monte Carlo report of ``benchmarks/nav/nav_state.py``: the runs differ in the geometry
the navigator sees, not only in noise, so their errors are independent samples of the ones the
filter's covariance describes (with noise seeds alone, ``nav_state.py --seeds``, part of the
error is common to every run).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.nav_suite import holdout, run_method, suite, tumbling_holdout

SEQUENCES = ["envisat-tumble-64", "aura-tumble-64"]
METHODS = ["relnav-tumbling", "relnav", "kiss-icp", "small-gicp"]


def turn_period_s(attitude: dict[str, Any]) -> float:
    """Seconds of one turn at the sequence's initial rate (spin: ``rate_deg_s``; tumble: the
    norm of ``omega0_deg_s``)."""
    if attitude["kind"] == "spin":
        rate = abs(float(attitude["rate_deg_s"]))
    else:
        rate = float(np.linalg.norm(attitude["omega0_deg_s"]))
    if rate <= 0:
        raise ValueError("a target that does not turn has no phase")
    return 360.0 / rate


def simulate_phases(out: Path, name: str, phases: int) -> list[Path]:
    """Simulate ``name`` entered at ``phases`` random phases (cached); returns the folders."""
    from relnav.sim.scenario import simulate

    base = {**suite(), **holdout(), **tumbling_holdout()}[name]
    period = turn_period_s(base["attitude"])
    folders = []
    for i in range(phases):
        d = out / "sequences" / f"{name}-phase{i}"
        if not (d / "scenario.yaml").exists():
            phase = float(np.random.default_rng(3000 + i).uniform(0.0, period))
            cfg = {**base, "attitude": {**base["attitude"], "phase_s": phase}}
            simulate({**cfg, "name": f"{name}-phase{i}", "seed": 1000 + i}, d, overwrite=True)
        folders.append(d)
    return folders


def run(folder: Path, method: str, options: dict[str, str]) -> dict[str, Any]:
    """``nav_suite.run_method`` with a method preset (``relnav-tumbling``) resolved; the
    navigator's methods get ``options`` (``-O``)."""
    from relnav.pipeline import resolve_method

    resolved, opts, _ = resolve_method(method, options if method.startswith("relnav") else {})
    return run_method(folder, resolved, per_step=True, **opts)


def report_missed(rs: list[dict[str, Any]]) -> None:
    """The navigator's wrong steps it did not flag against their own step covariance, and
    what ``flag_probability`` 0.1 (instead of 0.5) would flag."""
    st = {k: np.concatenate([r["steps"][k] for r in rs]) for k in rs[0]["steps"]}
    missed = st["wrong"] & ~st["flagged"]
    if not missed.any() or not np.isfinite(st["sigma_t"][missed]).any():
        return
    e10, e90 = np.percentile(st["error_t"][missed], [10, 90])
    s10, s90 = np.nanpercentile(st["sigma_t"][missed], [10, 90])
    at_01 = st["flagged"] | (np.nan_to_num(st["exceed"]) > 0.1)
    right = ~st["wrong"]
    print(
        f"    missed wrong steps (10-90 %): error {e10:.2f}-{e90:.2f} m, own 1-sigma "
        f"{s10:.2f}-{s90:.2f} m, median exceedance {np.nanmedian(st['exceed'][missed]):.3f}; "
        f"flag_probability 0.1 would flag {int(np.sum(at_01 & st['wrong']))} of "
        f"{int(st['wrong'].sum())} wrong, {np.mean(at_01[right]):.1%} of right"
    )


def report(name: str, results: dict[str, list[dict[str, Any]]], lost: float) -> None:
    """One line per method over the runs of one sequence."""
    print(f"{name}: {len(next(iter(results.values())))} phases")
    for method, rs in results.items():
        ape = np.array([r["ape"] for r in rs])
        wrong = sum(r["wrong"] for r in rs)
        steps = sum(r["n_steps"] for r in rs)
        wf = sum(r["wrong_flagged"] for r in rs)
        rf = sum(r["right_flagged"] for r in rs)
        print(
            f"  {method:16s} APE m median {np.median(ape):6.2f}  p90 {np.percentile(ape, 90):6.2f}"
            f"  max {ape.max():6.2f}; runs over {lost:g} m: {int(np.sum(ape > lost))} of "
            f"{len(ape)}; wrong steps {wrong} of {steps}, flagged {wf} "
            f"({wf / max(wrong, 1):.0%}); right steps flagged {rf} "
            f"({rf / max(steps - wrong, 1):.1%})"
        )
        if method.startswith("relnav"):
            lost_runs = ape > lost
            alarmed = np.array([r["revisit_alarm"] > 0 for r in rs])
            print(
                "    revisit alarm (the map found inconsistent): "
                f"{int(np.sum(alarmed & lost_runs))} of the {int(lost_runs.sum())} runs "
                f"over {lost:g} m, "
                f"{int(np.sum(alarmed & ~lost_runs))} of the {int((~lost_runs).sum())} others; "
                f"{sum(r['revisit_alarm'] for r in rs)} steps flagged by it"
            )
        report_missed(rs)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--phases", type=int, default=20)
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--only", default="", help="comma-separated tumbling sequences")
    p.add_argument("--lost", type=float, default=5.0, help="APE (m) of a run counted as lost")
    p.add_argument("--state", action="store_true", help="the relative state's Monte Carlo")
    p.add_argument(
        "-O", dest="options", action="append", default=[], help="navigator option key=value"
    )
    a = p.parse_args(argv)
    if a.phases < 1 or not math.isfinite(a.lost):
        p.error("--phases must be at least 1 and --lost finite")
    names = [n for n in a.only.split(",") if n] or SEQUENCES
    opts = dict(kv.split("=", 1) for kv in a.options)
    for name in names:
        folders = simulate_phases(a.out, name, a.phases)
        methods = [m for m in a.methods.split(",") if m]
        report(name, {m: [run(f, m, opts) for f in folders] for m in methods}, a.lost)
        if a.state:
            from nav_state import report_monte_carlo, track

            from relnav.pipeline import resolve_method

            _, options, _ = resolve_method("relnav-tumbling", opts)
            state = {"preset": "hold-point"}
            results = [track(f, options, state=state) for f in folders]
            report_monte_carlo(name, results, runs="phases (and noise seeds)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
