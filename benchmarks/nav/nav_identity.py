"""Did a refactor change what the navigator computes? Snapshot a tree's runs, compare two snapshots.

``snapshot`` runs relnav (with the suite's mission input) on every sequence of the suite, the
held-out and the stress groups (simulated once into ``OUT/sequences``), relnav with the attitude
input on two stress sequences, and two paper-1 presets (``paper1``, ``extended``: 40 frames of
sim-voyager) and ``relnav-tumbling``, and keeps per run: the poses (smoothed and causal), every
step's status, 1σ, exceedance probability and fitness, the metrics against the ground truth and
the navigator's final report. ``compare`` says which runs differ in which field (bit for bit;
times left out) and by how much their positions moved. Issue 43's refactor was checked this way
(41 runs identical); session 29's compiled bookkeeping moved 39 of them by at most 3.2e-8 m
causal (4.8e-6 m smoothed), every step's status the same.

    python benchmarks/nav/nav_identity.py snapshot --out bench/nav --to before   # old tree
    python benchmarks/nav/nav_identity.py snapshot --out bench/nav --to after    # new tree
    python benchmarks/nav/nav_identity.py compare before after

``-O key=value`` (repeatable) adds a navigator option to every run of relnav and its presets: an
option that must not change the answers (``solver.threads``) is checked against a snapshot
without it. Run the first line in a worktree of the old commit (``git worktree add``;
``PYTHONPATH`` its ``src``) so that both snapshots see the same sequences.
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.nav_suite import MISSION, attitude_input, sequence_names, simulate_suite
from relnav.eval.metrics import evaluate_trajectories
from relnav.io.sequences import ScanSequence

PRESETS = [("paper1", "sim-voyager", 40), ("extended", "sim-voyager", 40)]
"""Paper presets run on the first frames of a sequence (name, sequence, frames)."""
TUMBLING = [("relnav-tumbling", "envisat-tumble-64", None)]
ATTITUDE = ["envisat-jitter1", "voyager-sparse30"]
"""Stress sequences run again with the measured chaser attitude as input."""
STEP_KEYS = ["step_sigma_t", "step_sigma_r_deg", "exceed_probability"]


def _jobs() -> list[tuple[str, str, str, int | None, bool]]:
    """``(tag, sequence, method or preset, frames, attitude)`` of every run of a snapshot."""
    names = sequence_names() + sequence_names(held_out=True) + sequence_names(stressed=True)
    jobs = [(n, n, "relnav", None, False) for n in names]
    jobs += [(f"{n}+attitude", n, "relnav", None, True) for n in ATTITUDE]
    jobs += [(f"{m}__{s}", s, m, f, False) for m, s, f in PRESETS + TUMBLING]
    return jobs


def _strip_times(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _strip_times(v) for k, v in value.items() if "time" not in k}
    if isinstance(value, list):
        return [_strip_times(v) for v in value]
    return value


def snapshot(out: Path, to: Path, extra: dict[str, str] | None = None) -> None:
    """Run every job once and keep its results in ``to/<tag>.npz`` (skips those present);
    ``extra``: navigator options added to the runs of relnav and its presets."""
    from relnav.pipeline import resolve_method, run_sequence

    to.mkdir(parents=True, exist_ok=True)
    jobs = _jobs()
    folders = simulate_suite(out, sorted({s for _, s, _, _, _ in jobs}))
    for tag, name, method, frames, aided in jobs:
        target = to / f"{tag}.npz"
        if target.exists():
            continue
        seq = ScanSequence(folders[name])
        options: dict[str, Any] = dict(MISSION) if method == "relnav" else {}
        if aided:
            options["attitude"] = attitude_input(folders[name])
        name_or_method, options, _ = resolve_method(method, options)
        if method.startswith("relnav"):
            options.update(extra or {})
        run = run_sequence(seq, name_or_method, max_frames=frames, **options)
        n = len(run.poses)
        metrics = evaluate_trajectories(
            run.timestamps, run.poses, seq.timestamps[:n], seq.gt_poses[:n]
        )
        steps = {
            k: np.array(
                [
                    float(s.result.info.get(k, np.nan)) if s.result is not None else np.nan
                    for s in run.steps
                ]
            )
            for k in STEP_KEYS
        }
        np.savez(
            target,
            poses=run.poses,
            causal=run.online_poses,
            status=np.array([s.status for s in run.steps]),
            fitness=np.array(
                [s.result.fitness if s.result is not None else np.nan for s in run.steps]
            ),
            metrics=json.dumps(
                _strip_times({k: v for k, v in metrics.items() if isinstance(v, int | float)})
            ),
            final=json.dumps(_strip_times(run.options.get("finalize", {})), default=str),
            **steps,
        )
        print(f"{tag:40s} APE {metrics['ape_trans_rmse']:.6g} m", flush=True)


def _same(u: np.ndarray, v: np.ndarray) -> bool:
    """Bit for bit (NaN equal to NaN in float arrays)."""
    if u.shape != v.shape or u.dtype.kind != v.dtype.kind:
        return False
    return bool(np.array_equal(u, v, equal_nan=u.dtype.kind == "f"))


def compare(a: Path, b: Path) -> int:
    """Print the runs whose fields differ between two snapshots; returns how many."""
    bad = 0
    files = sorted(a.glob("*.npz"))
    for f in files:
        g = b / f.name
        if not g.exists():
            print(f"{f.stem}: missing in {b}")
            bad += 1
            continue
        x, y = np.load(f), np.load(g)
        diff = [k for k in x.files if not _same(x[k], y[k])]
        if diff:
            moved = [
                f"{k} by {np.abs(x[k][:, :3, 3] - y[k][:, :3, 3]).max():.1e} m"
                for k in ("poses", "causal")
                if k in diff and x[k].shape == y[k].shape
            ]
            print(
                f"{f.stem}: {', '.join(diff)} differ" + (f" ({', '.join(moved)})" if moved else "")
            )
            bad += 1
    print(f"{len(files)} runs compared, {bad} differ")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("snapshot", help="run every job and keep its results")
    s.add_argument("--out", type=Path, default=Path("bench/nav"), help="sequences' folder")
    s.add_argument("--to", type=Path, required=True, help="snapshot folder")
    s.add_argument("-O", dest="options", action="append", default=[], help="key=value")
    c = sub.add_parser("compare", help="compare two snapshots")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args(argv)
    warnings.simplefilter("ignore", FutureWarning)  # an old tree's flat option names
    if args.command == "snapshot":
        snapshot(args.out, args.to, dict(o.split("=", 1) for o in args.options))
        return 0
    return 1 if compare(args.a, args.b) else 0


if __name__ == "__main__":
    raise SystemExit(main())
