"""The full relative state on tumbling-target sequences: angular-rate accuracy and consistency.

    python benchmarks/nav/nav_state.py --out bench/nav   # envisat-tumble-64, aura-tumble-64
    python benchmarks/nav/nav_state.py --out bench/nav --seeds 20   # Monte Carlo over noise seeds
    python benchmarks/nav/nav_state.py --out bench/nav --compare suite   # both process noises
    python benchmarks/nav/nav_state.py --out bench/nav --seeds 20 -S drift=map  # an option
    python benchmarks/nav/nav_state.py --out bench/nav --seeds 20 --method relnav-tumbling \
        -S preset=hold-point                                        # the tumbling presets

Runs ``relnav`` (given the suite's mission input, the target's orbit ``nav_suite.MISSION``;
``-O orbit.mean_motion=0`` runs without it) on the navigation suite's tumbling sequences
(simulated once into ``OUT/sequences`` by ``benchmarks/nav/nav_suite.py``'s definitions), feeds its
poses to paper 2's twistor UKF (:func:`relnav.navigation.state.relative_state`) and prints, after
the first 30 % of the frames (convergence): the angular-rate error (median, 95th percentile,
max, deg/s; in body axes and, as vectors, in the sensor's axes: ``TrackResult.errors``
``omega_sensor``), the attitude/position/velocity RMS errors, and the mean NEES of the full 12-dim
state and of its rates (velocity + angular rate) beside their 95 % bands.

With ``--seeds N`` each sequence is simulated again with N noise seeds (1000 … 1000 + N − 1;
same target, path and sensor) and the NEES is tested as a Monte Carlo test should be: per time
step, the NEES averaged over the N runs against the 95 % band of such an average (the fraction
of steps inside it), and the pooled mean NEES of each 3-dim block (position, velocity,
attitude, angular rate; 3 when consistent), the share of each block's mean squared error that
is common to every run (the per-step mean over the runs: the runs share the geometry, so the
per-step band's independence does not hold for that part; ``benchmarks/nav/nav_phases.py --state``
varies the geometry too) and the wrong steps flagged by the navigator and by its state's
innovation alarm. One run's time average is not a fair test: its errors are correlated from
step to step (the navigator's map drift), so its band is too narrow.

``--compare suite`` (or ``holdout``) runs ``relnav`` once on every sequence of the suite (with the
paper presets) or of the held-out set and prints, as a markdown table, the relative state's errors
after the first 30 % of the frames with ``relative_state(process_noise="poses")`` → ``"physics"``:
RMS of the position, velocity and attitude error vectors, the angular-rate error's median and
max, and the mean 12-dim NEES (a time average of one run: indicative, no band). With ``-S``
options it compares the default relative state with the one given those options instead.

``--fit`` (with ``--seeds N``) first chooses the relative state's noise scales
(``drift_scale``, ``drift_rotation_scale``, ``measurement_scale``) by the likelihood of the
innovations on the SUITE sequence envisat-tumble-64's N runs, without ground truth
(:func:`relnav.navigation.state.noise_fit.fit_noise_scales`, ~4 min for 20 runs), prints them and
then reports both sequences with them (aura-tumble-64 is held out: only checked).

``--fresh`` (with ``--seeds N``) runs the Monte Carlo on the tumbling sequences made after a
configuration was frozen (``nav_suite.tumbling_holdout``: voyager, iridium, orion, eros, capsule,
comet and probe, ``-tumble-64``) instead.

``--error-structure`` (with ``--seeds N``) prints what the navigator's online pose error is
made of on both sequences, from the truth (``T_b_m``: the map's frame in the target's): the
per-run offset (mean over the frames after the first 30; RMS per target axis), the wander
around it (RMS, autocorrelation at lags 1, 5 and 20 frames), how the offset lies in the
eigen-axes of the start-up steps' summed rotation covariance (10 frames;
:func:`relnav.navigation.state.map_offset_rotation` keeps the largest: mean squared offset
over variance per axis, 1 = calibrated) and what the random-walk bias would give it by the
last frame (summed step covariances).

``-S key=value`` passes an option to :func:`relnav.navigation.state.relative_state` (numbers
are read as floats, ``none`` as None), e.g. ``-S drift=map``, ``-S robust_dof=5``,
``-S initial_bias=10`` (the start-up frames' drift as the map's initial offset) or
``-S angular_acceleration=none`` (the torque-free bound alone instead of the adaptive bank);
``-S preset=hold-point`` (:data:`relnav.navigation.state.STATE_PRESETS`, the other options win
over the preset's), ``-S torque_free_shares=1,0.1,0.01``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from relnav.bench.nav_suite import (
    MISSION,
    holdout,
    judge_steps,
    sequence_names,
    suite,
    tumbling_holdout,
)
from relnav.filtering.track_result import STATE_BLOCKS

TUMBLING = ["envisat-tumble-64", "aura-tumble-64"]


def rate_nees(res, k0: int) -> np.ndarray:
    """NEES of ``[velocity, angular rate]`` (6 dof) per step from ``k0``."""
    e = res.errors()
    err = np.concatenate([e["velocity"], e["omega"]], axis=1)
    idx = [3, 4, 5, 9, 10, 11]
    out = []
    for k in range(k0, len(err)):
        if np.all(np.isfinite(err[k])):
            C = res.covariance[k][np.ix_(idx, idx)]
            out.append(float(err[k] @ np.linalg.solve(C, err[k])))
    return np.asarray(out)


def simulate_seeds(out: Path, name: str, seeds: int) -> list[Path]:
    """Simulate ``name`` with noise seeds 1000 … (cached in ``out/sequences/NAME-mcS``)."""
    from relnav.sim.scenario import simulate

    every = {**suite(), **holdout(), **tumbling_holdout()}
    folders = []
    for s in range(seeds):
        d = out / "sequences" / f"{name}-mc{s}"
        if not (d / "scenario.yaml").exists():
            simulate({**every[name], "name": f"{name}-mc{s}", "seed": 1000 + s}, d, overwrite=True)
        folders.append(d)
    return folders


def track(
    folder: Path,
    options: dict[str, str] | None = None,
    process_noises=("physics",),
    state: dict | None = None,
    variants: list[dict] | None = None,
):
    """``relnav`` (with ``options``, strings as on the command line) on one sequence and the
    relative state from its poses, one per ``process_noises`` (a list) or the first alone;
    ``state``: options of ``relative_state``; ``variants``: instead of ``process_noises``, one
    relative state per dict of ``relative_state`` options."""
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.navigation.state import relative_state, state_options
    from relnav.pipeline import run_sequence

    seq = ScanSequence(folder)
    run = run_sequence(seq, "relnav", **{**MISSION, **(options or {})})
    if variants is None:
        variants = [{**(state or {}), "process_noise": p} for p in process_noises]
    out = [relative_state(run, gt_poses=seq.gt_poses, **state_options(v)) for v in variants]
    m = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, seq.gt_poses)
    _, _, wrong, flagged = judge_steps(run, seq.gt_poses)
    for r in out:  # the navigator's own trajectory error and steps, for the reports
        r.meta["navigator_ape"] = (m["ape_trans_rmse"], m["ape_rot_rmse_deg"])
        r.meta["step_wrong"], r.meta["step_flagged"] = wrong, flagged  # steps 1 … K − 1
    return out if len(out) > 1 else out[0]


def state_errors(res) -> tuple[float, ...]:
    """RMS position (m), velocity (mm/s), attitude (deg) error vectors, rate error median and
    max (deg/s) and mean 12-dim NEES, after the first 30 % of the frames."""
    k0 = round(0.3 * len(res))
    e = {k: v[k0:] for k, v in res.errors().items()}

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.nanmean(np.sum(x**2, axis=1))))

    w = np.degrees(np.linalg.norm(e["omega"], axis=1))
    return (
        rms(e["position"]),
        1e3 * rms(e["velocity"]),
        np.degrees(rms(e["attitude"])),
        float(np.nanmedian(w)),
        float(np.nanmax(w)),
        float(np.nanmean(res.nees()[k0:])),
    )


def report_compare(out: Path, which: str, opts: dict[str, str], state: dict) -> None:
    from relnav.bench.nav_suite import simulate_suite

    pair = [{"process_noise": "poses"}, {"process_noise": "physics"}]
    if state:
        pair = [{}, dict(state)]

    print("| sequence | position m | velocity mm/s | attitude ° | rate median / max °/s | NEES |")
    print("|---|---|---|---|---|---|")
    for name, folder in simulate_suite(out, sequence_names(which == "holdout")).items():
        a, b = (state_errors(r) for r in track(folder, opts, variants=pair))
        print(
            f"| {name} | {a[0]:.3f} → {b[0]:.3f} | {a[1]:.2f} → {b[1]:.2f} | {a[2]:.2f} → "
            f"{b[2]:.2f} | {a[3]:.3f} / {a[4]:.3f} → {b[3]:.3f} / {b[4]:.3f} | {a[5]:.1f} → "
            f"{b[5]:.1f} |",
            flush=True,
        )


def report_single(name: str, res) -> None:
    from relnav.navigation.state import nees_band

    k0 = round(0.3 * len(res))
    s = res.summary(skip=0.3)
    full = res.nees()[k0:]
    full = full[np.isfinite(full)]
    rates = rate_nees(res, k0)
    rate_true = np.degrees(np.median(np.linalg.norm(res.truth.omega, axis=1)))
    print(f"{name}: true rate {rate_true:.2f} deg/s; after {k0} of {len(res)} frames:")
    err = res.errors()
    for key, label in (("omega", "body axes"), ("omega_sensor", "sensor axes")):
        w = np.degrees(np.linalg.norm(err[key][k0:], axis=1))
        print(
            f"  angular-rate error deg/s, {label}: median {np.median(w):.3f}  p95 "
            f"{np.percentile(w, 95):.3f}  max {w.max():.3f}"
        )
    fmt = " / ".join
    print(
        "  RMS errors: attitude "
        + fmt(f"{x:.2f}" for x in s["attitude"]["rms"])
        + " deg, position "
        + fmt(f"{x:.2f}" for x in s["position"]["rms"])
        + " m, velocity "
        + fmt(f"{x:.3f}" for x in s["velocity"]["rms"])
        + " m/s"
    )
    lo, hi = nees_band(len(full))
    lo6, hi6 = nees_band(len(rates), dof=6)
    print(f"  mean NEES, 12-dim state: {full.mean():.1f} (95 % band {lo:.1f}-{hi:.1f})")
    print(f"  mean NEES, rates (6-dim): {rates.mean():.2f} (95 % band {lo6:.2f}-{hi6:.2f})")


def report_monte_carlo(name: str, results: list, runs: str = "noise seeds") -> None:
    from relnav.navigation.state import nees_band

    n = len(results)
    k0 = round(0.3 * len(results[0]))
    # (n, K, 5): the four 3-dim blocks and the whole 12-dim state, from step k0
    B = np.stack([np.column_stack([r.nees_blocks(), r.nees()])[k0:] for r in results])
    errs = [r.errors() for r in results]
    w, w_sensor = (
        np.concatenate([np.degrees(np.linalg.norm(e[key][k0:], axis=1)) for e in errs])
        for key in ("omega", "omega_sensor")
    )
    per_step = np.nanmean(B[:, :, 4], axis=0)  # averaged over the runs
    lo, hi = nees_band(n)  # band of the average of n runs at one step (12 dof)
    inside = float(np.mean((per_step >= lo) & (per_step <= hi)))
    pooled = np.nanmean(B, axis=(0, 1))
    print(f"{name}: {n} {runs}, steps {k0}-{len(results[0]) - 1}")
    ape = np.array([r.meta.get("navigator_ape", (np.nan, np.nan)) for r in results])
    print(
        f"  navigator APE (all frames) m: median {np.median(ape[:, 0]):.2f}  mean "
        f"{np.mean(ape[:, 0]):.2f}  max {np.max(ape[:, 0]):.2f}; rotation deg: median "
        f"{np.median(ape[:, 1]):.2f}  max {np.max(ape[:, 1]):.2f}; runs over 5 m: "
        f"{int(np.sum(ape[:, 0] > 5.0))} of {n}"
    )
    for label, x in (("body axes", w), ("sensor axes", w_sensor)):
        print(
            f"  angular-rate error deg/s, {label} (all runs): median {np.median(x):.3f}  p95 "
            f"{np.percentile(x, 95):.3f}  max {x.max():.3f}; over 0.1 deg/s on "
            f"{int(np.sum(x > 0.1))} of {x.size} steps"
        )
    print(
        f"  12-dim NEES averaged over the runs: median over steps {np.median(per_step):.1f}, "
        f"{inside:.0%} of steps inside the 95 % band {lo:.1f}-{hi:.1f}"
    )
    print(
        "  pooled mean NEES per 3-dim block (3 = consistent): "
        + ", ".join(f"{b} {x:.2f}" for b, x in zip(STATE_BLOCKS, pooled[:4], strict=True))
        + f"; 12-dim {pooled[4]:.1f}"
    )
    given = np.nanmean(np.concatenate([r.nees_conditional()[k0:] for r in results]), axis=0)
    print(
        "  pooled mean NEES per block given the other nine components (3 = consistent; above: "
        "the block is coupled to the rest more tightly than its errors are): "
        + ", ".join(f"{b} {x:.2f}" for b, x in zip(STATE_BLOCKS, given, strict=True))
    )
    report_tracked(B, ape[:, 0], w.reshape(n, -1))
    report_inertia(results)
    E = np.stack([np.concatenate([e[b][k0:] for b in STATE_BLOCKS], axis=1) for e in errs])
    common = E.mean(axis=0)  # the part of each step's error shared by every run
    shares = [
        np.nanmean(np.sum(common[:, 3 * b : 3 * b + 3] ** 2, axis=1))
        / np.nanmean(np.sum(E[:, :, 3 * b : 3 * b + 3] ** 2, axis=2))
        for b in range(4)
    ]
    print(
        "  share of the mean squared error common to every run: "
        + ", ".join(f"{b} {x:.0%}" for b, x in zip(STATE_BLOCKS, shares, strict=True))
    )
    report_alarms(results)


def report_tracked(B: np.ndarray, ape: np.ndarray, rate_deg_s: np.ndarray) -> None:
    """A diagnostic, the runs chosen by the truth: the pooled NEES ``B`` ``(n, K, 5)`` of the
    runs whose navigator APE is under 2 m, and the body-rate error (°/s, ``(n, K)``) of those
    under 1 m."""
    if np.all(ape < 2.0):
        return
    for limit in (2.0, 1.0):
        sel = ape < limit
        if not np.any(sel):
            continue
        pooled = np.nanmean(B[sel], axis=(0, 1))
        r = rate_deg_s[sel]
        print(
            f"  runs under {limit:g} m APE ({int(sel.sum())}, chosen by the truth): pooled "
            f"NEES {pooled[4]:.1f} (blocks "
            + " / ".join(f"{x:.2f}" for x in pooled[:4])
            + f"); worst rate error {np.nanmax(r):.3f} deg/s, over 0.1 on "
            f"{int(np.sum(r > 0.1))} of {r.size} steps"
        )


def report_inertia(results: list) -> None:
    """How many runs identified a tumbling target's inertia (``rigid_body``) and which fit's
    second pass they kept (:func:`relnav.navigation.state.rigid_body.rigid_body_pass`)."""
    found = sum(bool(r.meta.get("inertia_identified")) for r in results)
    if found:
        kept = [r.meta.get("inertia_source") for r in results]
        print(
            f"  inertia identified on {found} of {len(results)} runs; second pass kept with the "
            f"attitudes' fit on {kept.count('attitudes')}, the rates' on {kept.count('rates')}"
        )


def report_alarms(results: list) -> None:
    """Wrong steps (0.5 m or 5°) flagged by the navigator, and by the navigator or the state's
    innovation alarm (``TrackResult.innovation_alarm``), over every run and step."""
    wrong, nav, both, frames = [], [], [], []
    for r in results:
        w, f = r.meta["step_wrong"], r.meta["step_flagged"]
        alarm = r.innovation_alarm()
        wrong.append(w)
        nav.append(f)
        both.append(f | alarm[1 : len(w) + 1])
        frames.append(int(alarm.sum()))
    w, f, b = (np.concatenate(x) for x in (wrong, nav, both))
    ape = np.array([r.meta["navigator_ape"][0] for r in results])
    frames = np.array(frames)
    for label, sel in (("under 0.5 m", ape < 0.5), ("over 5 m", ape > 5.0)):
        if np.any(sel):
            print(
                f"  alarm frames per run, runs {label} APE ({int(sel.sum())}): "
                f"{frames[sel].min()}-{frames[sel].max()}"
            )
    for label, x in (("navigator", f), ("navigator or the state's innovation alarm", b)):
        print(
            f"  flagged by the {label}: {int(np.sum(x & w))} of {int(w.sum())} wrong steps, "
            f"{int(np.sum(x & ~w))} of {int(np.sum(~w))} right ones ({np.mean(x[~w]):.1%})"
        )


def main(argv: list[str] | None = None) -> int:
    from relnav.bench.nav_suite import simulate_suite

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--seeds", type=int, default=1, help="Monte Carlo runs per sequence")
    p.add_argument(
        "-O", dest="options", action="append", default=[], help="relnav option key=value"
    )
    p.add_argument(
        "--method",
        default="relnav",
        help="the navigator or one of its method presets (relnav-tumbling); -O options win",
    )
    p.add_argument(
        "--compare",
        choices=["suite", "holdout"],
        help="process noise 'poses' → 'physics' on every sequence (one run each)",
    )
    p.add_argument(
        "-S", dest="state", action="append", default=[], help="relative_state option key=value"
    )
    p.add_argument(
        "--fit",
        action="store_true",
        help="noise scales by the innovations' likelihood on envisat-tumble-64 (with --seeds)",
    )
    p.add_argument(
        "--fresh",
        action="store_true",
        help="the tumbling sequences made after the hold-point preset was frozen (with --seeds)",
    )
    p.add_argument(
        "--error-structure",
        action="store_true",
        help="the navigator's pose error: offset, wander, start-up axes (with --seeds)",
    )
    a = p.parse_args(argv)
    from relnav.pipeline import resolve_method

    method, opts, _ = resolve_method(a.method, dict(kv.split("=", 1) for kv in a.options))
    if method != "relnav":
        p.error(f"--method {a.method}: not the navigator ({method})")
    state = {k: _value(v) for k, v in (kv.split("=", 1) for kv in a.state)}
    if a.compare:
        report_compare(a.out, a.compare, opts, state)
        return 0
    if a.seeds <= 1:
        for name, folder in simulate_suite(a.out, TUMBLING).items():
            report_single(name, track(folder, opts, state=state))
        return 0
    if a.error_structure:
        for name in TUMBLING:
            report_error_structure(name, simulate_seeds(a.out, name, a.seeds), opts)
        return 0
    if a.fit:
        state = {**state, **fit_scales(a.out, TUMBLING[0], a.seeds, opts, state)}
    for name in list(tumbling_holdout()) if a.fresh else TUMBLING:
        folders = simulate_seeds(a.out, name, a.seeds)
        report_monte_carlo(name, [track(f, opts, state=state) for f in folders])
    return 0


def report_error_structure(name: str, folders: list[Path], opts: dict[str, str]) -> None:
    """The navigator's pose error on ``name``'s runs: offset, wander, start-up axes."""
    from relnav.geometry.lie import log_se3
    from relnav.geometry.se3 import invert
    from relnav.io.sequences import ScanSequence
    from relnav.navigation.options import in_map
    from relnav.navigation.state import StateRecord, drift_covariance
    from relnav.pipeline import run_sequence

    offsets, wander, axes, walk = [], [], [], []
    for folder in folders:
        seq = ScanSequence(folder)
        run = run_sequence(seq, "relnav", **{**MISSION, **opts})
        steps = [StateRecord.from_step(st) for st in run.steps]
        # the map's frame in the target's: [ρ (m), φ (rad)], target axes
        E = np.array(
            [
                log_se3(G @ invert(st.pose)) if in_map(st) else np.full(6, np.nan)
                for G, st in zip(seq.gt_poses, steps, strict=False)
            ]
        )
        off = np.nanmean(E[30:], axis=0)
        offsets.append(off)
        wander.append(E[30:] - off)
        Q = [drift_covariance(st.step_covariance, st.pose) for st in steps[1:]
             if in_map(st) and st.step_covariance is not None]  # fmt: skip
        w, V = np.linalg.eigh(sum(q[3:, 3:] for q in Q[:10]))
        axes.append((V.T @ off[3:]) ** 2 / w)
        walk.append(np.sqrt([np.trace(sum(Q)[:3, :3]), np.trace(sum(Q)[3:, 3:])]))
    O = np.array(offsets)
    W = np.concatenate(wander)

    def norm_rms(X: np.ndarray, sl: slice) -> float:
        return float(np.sqrt(np.nanmean(np.sum(X[:, sl] ** 2, axis=1))))

    t, r = slice(0, 3), slice(3, 6)
    print(f"{name}: {len(folders)} noise seeds, the map's frame in the target's (frames 30+)")
    print(
        f"  offset per run, RMS: {norm_rms(O, t):.3f} m (per axis "
        + " / ".join(f"{x:.3f}" for x in np.sqrt(np.mean(O[:, t] ** 2, axis=0)))
        + f"), {np.degrees(norm_rms(O, r)):.2f}° (per axis "
        + " / ".join(f"{np.degrees(x):.2f}" for x in np.sqrt(np.mean(O[:, r] ** 2, axis=0)))
        + ")"
    )
    print(f"  wander around it, RMS: {norm_rms(W, t):.3f} m, {np.degrees(norm_rms(W, r)):.2f}°")
    for lag in (1, 5, 20):
        rho = []
        for w in wander:
            x, y = w[:-lag], w[lag:]
            ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
            rho.append(np.sum(x[ok] * y[ok], axis=0) / np.sum(x[ok] ** 2, axis=0))
        m = np.mean(rho, axis=0)
        print(
            f"  wander autocorrelation at lag {lag:2d}: translation "
            + " / ".join(f"{x:.2f}" for x in m[:3])
            + ", rotation "
            + " / ".join(f"{x:.2f}" for x in m[3:])
        )
    print(
        "  rotation offset in the start-up's (10 steps) covariance axes, mean offset² / "
        "variance, smallest → largest axis: "
        + " / ".join(f"{x:.2f}" for x in np.mean(axes, axis=0))
    )
    walk_m = np.mean(walk, axis=0)
    print(
        f"  a random walk of every step's covariance by the last frame: {walk_m[0]:.2f} m, "
        f"{np.degrees(walk_m[1]):.2f}°"
    )


def fit_scales(out: Path, name: str, seeds: int, opts: dict[str, str], state: dict) -> dict:
    """Noise scales of maximum innovation likelihood on ``name``'s noise seeds (no truth)."""
    from relnav.io.sequences import ScanSequence
    from relnav.navigation.state import StateRecord
    from relnav.navigation.state.noise_fit import NOISE_SCALES, fit_noise_scales
    from relnav.pipeline import run_sequence

    held = {k: v for k, v in state.items() if k not in NOISE_SCALES}
    start = [float(state.get(k, 1.0)) for k in NOISE_SCALES]
    runs = []
    for folder in simulate_seeds(out, name, seeds):
        run = run_sequence(ScanSequence(folder), "relnav", **{**MISSION, **opts})
        # the compact records the relative state needs, not the whole run
        steps = [StateRecord.from_step(s) for s in run.steps]
        runs.append(SimpleNamespace(steps=steps, timestamps=run.timestamps, method=run.method))
    fit = fit_noise_scales(runs, start=start, **held)
    print(
        f"{name}: noise scales of maximum likelihood ({fit['evaluations']} evaluations, summed "
        f"log-likelihood {fit['start_log_likelihood']:.0f} → {fit['log_likelihood']:.0f}): "
        + ", ".join(f"{k}={v:.3g}" for k, v in fit["scales"].items()),
        flush=True,
    )
    return fit["scales"]


def _value(text: str) -> float | tuple[float, ...] | str | None:
    """A ``-S`` value: ``None`` for "none", a float when it reads as one, a tuple of floats for
    comma-separated numbers (``torque_free_shares=1,0.1,0.01``), else the string."""
    if text.lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        pass
    try:
        return tuple(float(x) for x in text.split(",")) if "," in text else text
    except ValueError:
        return text


if __name__ == "__main__":
    raise SystemExit(main())
