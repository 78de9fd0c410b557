"""The free-relative-orbit test of relnav's navigator on every sequence, with and without it.

    python benchmarks/nav/nav_orbit.py --out bench/nav               # the suite
    python benchmarks/nav/nav_orbit.py --out bench/nav --holdout     # the held-out sequences

Runs ``relnav`` on each sequence with the suite's mission input (the target's orbit,
``nav_suite.MISSION``) and with ``orbit.mean_motion=0``, and prints the orbit test's figures
(:func:`relnav.navigation.orbit.correct_azimuth`): the map's symmetry ratio about its best
axis, the orbit's misfit to the sensor's radius and height about that axis (m, and % of the
sensor's median distance from the axis's centre), the excess (misfit of the orbit fitted to the
whole positions over that misfit), whether the azimuth was taken from the orbit and the largest
turn, then APE and wrong steps (> 0.5 m or 5°) without → with and the test's own time (once
per run, in ``finalize``). The test uses the estimate only; the ground truth scores.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from relnav.bench.nav_suite import (
    MISSION,
    add_sequence_arguments,
    judge_steps,
    selected_names,
    simulate_suite,
)


def _run(folder: Path, options: dict[str, Any]) -> dict[str, Any]:
    import relnav.navigation.navigator as nav
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(folder)
    spent: list[float] = []
    test = nav.correct_azimuth

    def timed(*args: Any, **kwargs: Any) -> Any:  # the test's own cost, once per run
        t0 = time.perf_counter()
        try:
            return test(*args, **kwargs)
        finally:
            spent.append(time.perf_counter() - t0)

    nav.correct_azimuth = timed
    try:
        run = run_sequence(seq, "relnav", **options)
    finally:
        nav.correct_azimuth = test
    m = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, seq.gt_poses)
    return {
        "ape": m["ape_trans_rmse"],
        "wrong": int(judge_steps(run, seq.gt_poses)[2].sum()),
        "orbit": run.options.get("finalize", {}).get("orbit"),
        "ms": 1e3 * sum(spent),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    a = p.parse_args(argv)
    names = selected_names(a)
    folders = simulate_suite(a.out, names)
    extra = dict(o.split("=", 1) for o in a.options)
    print(
        "| sequence | symmetry ratio | misfit m (% of range) | excess | azimuth from the orbit "
        "(largest turn) | APE m without → with | wrong steps without → with | test ms |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in names:
        off = _run(folders[name], {**extra, "orbit.mean_motion": 0.0})
        on = _run(folders[name], {**MISSION, **extra})
        o = on["orbit"] or {}
        ratio, misfit, excess, scale = (
            o.get(k, float("nan")) for k in ("symmetry_ratio", "misfit_m", "excess", "scale_m")
        )
        turn = f"yes ({o['max_correction_deg']:.1f}°)" if o.get("applied") else "no"
        print(
            f"| {name} | {ratio:.4f} | {misfit:.3f} ({100 * misfit / scale:.2f} %) | "
            f"{excess:.1f} | {turn} | {off['ape']:.3f} → {on['ape']:.3f} | "
            f"{off['wrong']} → {on['wrong']} | {on['ms']:.1f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
