"""Calibrate the contour observer's noise model on Paper 2's simulation (issue 15).

    python benchmarks/paper2/paper2_calibrate.py --work WORK --seeds 20:60 --check 0:20 [--per-axis]
        [--fit consistency|likelihood] [--recording src|cal] [--rate given|unknown|both]
        [--save noise.json]

Loads (or simulates and records, as ``paper2_experiment.py --work WORK`` does) the contour
observer's output on the ``li-rotating`` run of each calibration seed, then chooses the noise
model (:func:`relnav.fusion.observer_noise.calibrate_observer_noise`) with the filter the
default ``relnav track`` uses with that observer (centre offset, observer bias in body axes,
Student-t update; ω₀ = (0, 0, 5)°/s as Paper 2). Prints the model (the values of
``CONTOUR_LI_ROTATING``) and the mean NIS / NEES with their 95 % bands on the calibration seeds
and on the ``--check`` seeds (held out), for each recording loop calibrated on (``--rate``:
Paper 2's initial rate, ``relnav track`` without ``--omega0``, or both).

The contour model's registration starts from the filter's prediction, so the observations
depend on the noise model the filter ran with: ``--recording cal`` (default) uses those recorded
by the main variant with the loop's current model (``CONTOUR_LI_ROTATING`` with the rate given,
``CONTOUR_LI_ROTATING_RATE_UNKNOWN`` without; tag ``cal-<hash>``), ``src`` those
recorded by the former main variant (jackknife covariance; ``obsNNN_16f_3m_src.npz``). The
calibration is a fixed point: calibrate, record with the new model, calibrate again.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import paper2_experiment as pe

from relnav.fusion.observer_noise import (
    CalibrationRun,
    calibrate_observer_noise,
    evaluate_observer_noise,
)


def runs_of(seeds: range, work: Path, recording: str, rate: str = "given") -> list[CalibrationRun]:
    """Calibration runs (observations without covariance, truth by the experiment's alignment)
    of the recording loop with the rate ``given`` or ``unknown`` (then tracked as that loop:
    ``omega0=None, init="rate"``)."""
    tag = "src" if recording == "src" else None  # None: the loop's calibrated model
    options = None if rate == "given" else {"omega0": None, "init": "rate"}
    out = []
    for seed in seeds:
        rec = pe.recorded_seed(seed, work, rate_given=rate == "given", recording=tag)
        T = rec["T_s_target"]
        out.append(
            CalibrationRun(
                rec["time"],
                pe.recorded_observations(rec, "fixed"),
                truth=lambda res, T=T: pe._truth_for(res, T),
                options=options,
            )
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument(
        "--seeds", type=pe.seed_span, default=range(20, 60), help="calibration seeds a:b"
    )
    ap.add_argument("--check", type=pe.seed_span, default=range(0, 20), help="held-out seeds a:b")
    ap.add_argument("--fit", choices=("consistency", "likelihood"), default="consistency")
    ap.add_argument("--per-axis", action="store_true", help="12 values instead of 4")
    ap.add_argument("--recording", choices=("src", "cal"), default="cal")
    ap.add_argument(
        "--rate",
        choices=("given", "unknown", "both"),
        default="given",
        help="the recording loops calibrated on: Paper 2's initial rate, `relnav track` without "
        "--omega0 (paper2_experiment.py --rate unknown), or both",
    )
    ap.add_argument("--save", type=Path, default=None, help="write the model as JSON")
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    options = {"filter": "ukf", "omega0": pe.OMEGA0, **pe.CALIBRATED_OPTIONS}
    loops = ("given", "unknown") if args.rate == "both" else (args.rate,)
    cal = {r: runs_of(args.seeds, args.work, args.recording, r) for r in loops}
    t0 = time.perf_counter()
    model, report = calibrate_observer_noise(
        [run for runs in cal.values() for run in runs],
        options,
        fit=args.fit,
        per_axis=args.per_axis,
    )
    seeds = f"{args.seeds.start}-{args.seeds.stop - 1}"
    seconds = time.perf_counter() - t0
    print(
        f"calibrated on seeds {seeds}, rate {args.rate} ({report['evaluations']} evaluations, "
        f"{seconds:.0f} s):"
    )
    d = model.to_dict()
    mm = lambda key: np.round(1e3 * np.asarray(d[key]), 3)  # noqa: E731
    deg = lambda key: np.round(np.degrees(d[key]), 4)  # noqa: E731
    print(f"  white: position {mm('position_m')} mm, attitude {deg('attitude_rad')} deg")
    drift = f"position {mm('drift_position_m')} mm, attitude {deg('drift_attitude_rad')} deg"
    print(f"  drift: {drift}")
    print("  exact values (m, rad):", d)
    if args.save:
        model.save(args.save)
    print("\n| seeds | rate | mean NIS [95 % band] | mean NEES [95 % band] | blocks p/v/att/ω |")
    print("|---|---|---|---|---|")
    for label in (args.seeds, args.check):
        for r in loops:
            runs = cal[r] if label is args.seeds else runs_of(label, args.work, args.recording, r)
            c = evaluate_observer_noise(model, runs, options)
            lo6, hi6 = pe._band(6, c["nis_n"])
            lo12, hi12 = pe._band(12, c["nees_n"])
            print(
                f"| {label.start}-{label.stop - 1} | {r} "
                f"| {c['nis']:.2f} [{lo6:.2f}, {hi6:.2f}] | {c['nees']:.2f} [{lo12:.2f}, "
                f"{hi12:.2f}] | {' / '.join(f'{x:.2f}' for x in c['blocks'])} |"
            )


if __name__ == "__main__":
    main()
