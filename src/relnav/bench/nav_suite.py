"""The navigation suite: its sequence groups, read from ``configs/``, and the code the navigation
benchmarks share (simulate once, run a method, judge its steps, tables).

The suite is defined once, in YAML: the grids ``configs/nav-suite.yaml`` (the suite's flash
sequences and paper 1's five presets), ``nav-holdout.yaml``, ``nav-stress.yaml`` and
``nav-tumbling-holdout.yaml`` list each group's sequences, and ``configs/nav/<name>.yaml`` is each
sequence's scenario (for :func:`relnav.sim.simulate`). Every sequence is a flash LIDAR (24×24 to
128×128 pixels, 45° field of view, 2–5 cm range noise) at 12–80 m from a target, on paths a GNC
engineer would fly. Mesh targets (``../shared/data/targets``: Eros, Aura, Orion, Voyager, 67P)
fall back to their procedural stand-ins (:data:`MESH_FALLBACK`) when the mesh is absent.

``configs/`` is looked up in ``$RELNAV_CONFIGS``, then beside the source tree (an editable
install: ``src/relnav`` → ``configs``), then in the working directory; the mesh paths of the
scenario files are relative to that folder's parent (the repository root). The command-line
part is ``benchmarks/nav/nav_suite.py``.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import time
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from relnav.errors import ConfigError

__all__ = [
    "ATTITUDE_SIGMA",
    "DEFAULT_METHODS",
    "EVIDENCE",
    "GROUPS",
    "JITTER_DEG",
    "LEO_PERIOD_S",
    "MESH_FALLBACK",
    "MISSION",
    "PAPER_PRESETS",
    "PEERS",
    "TARGETS",
    "THREADED_PEERS",
    "WARM_UP_FRAMES",
    "WRONG_STEP",
    "add_sequence_arguments",
    "attitude_input",
    "configs_dir",
    "group",
    "holdout",
    "jitter_holdout",
    "judge_steps",
    "manoeuvre",
    "markdown_table",
    "paper",
    "relnav_ratios",
    "resolve_target",
    "run_method",
    "scorecard",
    "scorecard_table",
    "selected_names",
    "sequence_names",
    "simulate_suite",
    "step_errors",
    "stress",
    "stress_table",
    "suite",
    "tumbling_holdout",
    "warm_up",
]

log = logging.getLogger(__name__)

LEO_PERIOD_S = 5553.6
MISSION: dict[str, Any] = {"orbit.mean_motion": 2 * math.pi / LEO_PERIOD_S}
"""relnav's mission input on every sequence (suite and held out): the target's orbit, one low
Earth orbit of ``LEO_PERIOD_S`` (``-O orbit.mean_motion=0`` runs without it). Not a tuning; the
grids give ``relnav`` the same value."""

PEERS = [
    "kiss-icp",
    "small-gicp",
    "o3d-icp-plane",
    "o3d-fpfh-ransac",
    "kiss-matcher",
    "kiss-matcher-icp",
]
DEFAULT_METHODS = ["relnav", *PEERS, "icp-plane"]
THREADED_PEERS = ("kiss-icp", "small-gicp")
"""The peers whose adapters take ``num_threads`` (threads within a frame; 1 by default)."""
WARM_UP_FRAMES = 12
WRONG_STEP = (0.5, 5.0)
"""A step is wrong beyond these errors: translation (m), rotation (deg)."""

EVIDENCE = (
    "step_sigma_t",
    "step_sigma_r_deg",
    "exceed_probability",
    "chi2_motion",
    "robust_rms_sigma",
    "variance_factor",
    "overlap",
    "degeneracy",
    "iterations",
    "gate",
    "sigma_t",
    "sigma_r_deg",
    "jitter_sigma_deg",
    "same_rays",
    "repeat_fraction",
    "map_voxels",
)
"""The navigator's per-step diagnostics that need no ground truth (``result.info`` keys), which
``run_method(per_step=True)`` returns under ``["steps"]["evidence"]`` for the flag studies, with
the registration's ``fitness``."""

GROUPS = (
    "suite",
    "holdout",
    "stress",
    "tumbling-holdout",
    "jitter-holdout",
    "manoeuvre",
    "jitter-check",
    "jitter-learning",
    "jitter-choice",
)
"""The sequence groups, one grid ``configs/nav-<group>.yaml`` each."""

JITTER_DEG = (0.25, 0.5, 1.0, 2.0)
"""The stress group's white attitude jitter levels (degrees per axis per frame)."""

ATTITUDE_SIGMA = 0.01
"""1σ per axis (degrees) of the chaser's measured attitude written beside the stress group's
sequences (``chaser_attitude.tum``: a star tracker's order of magnitude)."""

PAPER_PRESETS = ("sim-eoi", "sim-helical", "sim-voyager", "sim-orion", "sim-bennu")
"""Paper 1's five HPR presets, run by the suite's grid (first 60 frames, with paper 1's data
generation and with ``-resample``)."""

MESH_FALLBACK = {
    "eros": "asteroid",
    "aura": "envisat",
    "orion": "capsule",
    "voyager": "voyager",
    "comet67p": "asteroid",
}
"""The procedural target that replaces a shared mesh (by file stem) when it is absent; same
``scale_to``."""


def configs_dir() -> Path:
    """The repository's ``configs/`` folder (see the module docstring for the search order).

    Raises
    ------
    ConfigError
        When no folder holding ``nav-suite.yaml`` is found.
    """
    candidates = []
    if os.environ.get("RELNAV_CONFIGS"):
        candidates.append(Path(os.environ["RELNAV_CONFIGS"]))
    candidates.append(Path(__file__).resolve().parents[3] / "configs")
    candidates.append(Path.cwd() / "configs")
    for c in candidates:
        if (c / "nav-suite.yaml").is_file():
            return c
    raise ConfigError(
        "the navigation suite's configs/ folder (with nav-suite.yaml) was not found in "
        f"{', '.join(str(c) for c in candidates)}: run from a source checkout of relnav or set "
        "RELNAV_CONFIGS to that folder"
    )


def resolve_target(target: dict[str, Any], root: Path | None = None) -> dict[str, Any]:
    """A scenario's target with its mesh path made absolute (relative to ``root``, default the
    repository's root), or its procedural stand-in (:data:`MESH_FALLBACK`) when the mesh is
    absent."""
    root = configs_dir().parent if root is None else root
    if "path" not in target:
        return target
    path = Path(target["path"])
    path = path if path.is_absolute() else (root / path).resolve()
    if path.exists():
        return {**target, "path": str(path)}
    fallback = MESH_FALLBACK.get(path.stem)
    if fallback is None:
        raise ConfigError(f"mesh {path} not found and no procedural stand-in for {path.stem!r}")
    rest = {k: v for k, v in target.items() if k != "path"}
    return {**rest, "name": fallback}


def _grid(name: str) -> Any:
    path = configs_dir() / f"nav-{name}.yaml"
    if not path.is_file():
        raise ConfigError(f"no navigation group {name!r}: {path} does not exist")
    return _load_grid(str(path))


@cache
def _load_grid(path: str) -> Any:
    from relnav.bench.grid import load_grid

    return load_grid(Path(path))


def group(name: str) -> dict[str, dict[str, Any]]:
    """The scenarios (dicts for :func:`relnav.sim.simulate`) of one group of :data:`GROUPS`, by
    sequence name, in the grid's order; paper 1's presets are left out (:func:`paper`).

    Raises
    ------
    ConfigError
        Unknown group, missing or invalid file, a scenario named unlike its file.
    """
    from pydantic import ValidationError

    from relnav.config import load_yaml
    from relnav.sim.scenario import Scenario

    if name not in GROUPS:
        raise ConfigError(f"unknown navigation group {name!r}; choose one of {', '.join(GROUPS)}")
    grid = _grid(name)
    root = configs_dir().parent
    out: dict[str, dict[str, Any]] = {}
    for entry in grid.scenarios:
        if entry.kind != "scenario":
            continue
        sc = load_yaml(configs_dir() / str(entry.scenario))
        if sc.get("name") != entry.label:
            raise ConfigError(f"{entry.scenario}: name {sc.get('name')!r} is not {entry.label!r}")
        sc["target"] = resolve_target(sc.get("target", {}), root)
        try:  # a bad file fails here, with the field named
            Scenario.model_validate(sc)
        except ValidationError as e:
            raise ConfigError(f"{entry.scenario}: {e}") from e
        out[entry.label] = sc
    return out


def suite() -> dict[str, dict[str, Any]]:
    """The suite's flash sequences by name (``configs/nav-suite.yaml``)."""
    return group("suite")


def holdout() -> dict[str, dict[str, Any]]:
    """Sequences never used to choose parameters (``configs/nav-holdout.yaml``)."""
    return group("holdout")


def stress() -> dict[str, dict[str, Any]]:
    """Motion the constant-velocity prior does not predict and scans with few points
    (``configs/nav-stress.yaml``)."""
    return group("stress")


def tumbling_holdout() -> dict[str, dict[str, Any]]:
    """Tumbling sequences made after a configuration was frozen, to check it once
    (``configs/nav-tumbling-holdout.yaml``; ``nav_state.py --fresh``)."""
    return group("tumbling-holdout")


def jitter_holdout() -> dict[str, dict[str, Any]]:
    """Attitude jitter on targets the stress group's jitter levels were not measured on, made
    after the navigator's parameters were frozen (``configs/nav-jitter-holdout.yaml``)."""
    return group("jitter-holdout")


def manoeuvre() -> dict[str, dict[str, Any]]:
    """Impulsive burns on Clohessy–Wiltshire relative orbits, and a free drift as their
    control: translation the constant-velocity prior does not predict, made after the
    navigator's parameters were frozen (``configs/nav-manoeuvre.yaml``)."""
    return group("manoeuvre")


def jitter_check() -> dict[str, dict[str, Any]]:
    """Attitude jitter made after session 30 chose the screened extra starts, to check that
    choice once (``configs/nav-jitter-check.yaml``)."""
    return group("jitter-check")


def paper(max_frames: int | None = None) -> dict[str, dict[str, Any]]:
    """Paper 1's presets of the suite's grid, by label, each its first ``max_frames`` frames
    (default: the grid's): with paper 1's data generation (one model cloud) and with fresh
    surface samples per scan (``-resample``: what a real sensor does)."""
    from relnav.sim.presets import get_preset

    out: dict[str, dict[str, Any]] = {}
    for entry in _grid("suite").scenarios:
        if entry.kind != "preset":
            continue
        n = max_frames if max_frames is not None else entry.max_frames
        sc = get_preset(str(entry.preset), max_frames=n, **entry.options).model_dump(mode="json")
        out[entry.label] = {**sc, "name": entry.label}
    # each preset beside its -resample twin (the grid lists the twins after the five presets)
    order = sorted(out, key=lambda k: (k.removesuffix("-resample"), k.endswith("-resample")))
    first = {k.removesuffix("-resample"): i for i, k in enumerate(out)}
    order.sort(key=lambda k: first[k.removesuffix("-resample")])
    return {k: out[k] for k in order}


def sequence_names(
    held_out: bool = False,
    only: str = "",
    stressed: bool = False,
    jittered: bool = False,
    manoeuvred: bool = False,
    named: str = "",
) -> list[str]:
    """The suite's sequences with the paper presets, or the held-out ones, or the stress group
    (:func:`stress`), or the jitter hold-out (:func:`jitter_holdout`), or the manoeuvres
    (:func:`manoeuvre`), or the group ``named`` (one of :data:`GROUPS`, before the others);
    ``only``: keep the names containing one of its comma-separated substrings."""
    pool = (
        group(named)
        if named
        else manoeuvre()
        if manoeuvred
        else jitter_holdout()
        if jittered
        else stress()
        if stressed
        else holdout()
        if held_out
        else {**suite(), **paper()}
    )
    return [n for n in pool if not only or any(s in n for s in only.split(","))]


def add_sequence_arguments(p: argparse.ArgumentParser) -> None:
    """The navigation benchmarks' common arguments: ``--out`` (where the sequences are
    simulated), ``--only`` and ``--holdout`` (:func:`sequence_names`) and ``-O`` (relnav's
    options, ``key=value``, repeatable; ``dest="options"``)."""
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--only", default="", help="comma-separated substrings of sequence names")
    p.add_argument(
        "--holdout", action="store_true", help="the held-out sequences instead of the suite"
    )
    p.add_argument(
        "--stress",
        action="store_true",
        help="the stress group (attitude jitter, sparse scans, far start-up) instead",
    )
    p.add_argument(
        "--jitter-holdout",
        action="store_true",
        help="attitude jitter on targets the stress group does not have, made after the "
        "parameters were frozen",
    )
    p.add_argument(
        "--manoeuvre",
        action="store_true",
        help="impulsive burns on relative orbits (and a free drift), made after the parameters "
        "were frozen",
    )
    p.add_argument(
        "--group",
        default="",
        help=f"any group by name, instead ({', '.join(GROUPS)}; 'suite' without paper 1's presets)",
    )
    p.add_argument(
        "-O", dest="options", action="append", default=[], help="relnav option key=value"
    )


def selected_names(args: argparse.Namespace) -> list[str]:
    """The sequences that the arguments of :func:`add_sequence_arguments` select (the suite by
    default; ``--holdout``, ``--stress``, ``--jitter-holdout``, ``--manoeuvre`` or ``--group``;
    ``--only``)."""
    return sequence_names(
        args.holdout, args.only, args.stress, args.jitter_holdout, args.manoeuvre, args.group
    )


def simulate_suite(out: Path, names: list[str]) -> dict[str, Path]:
    """Simulate (once) every named sequence of any group into ``out/sequences``; returns their
    folders (``out/sequences/<name>``)."""
    from relnav.sim.scenario import simulate

    folders = {}
    every = {**paper()}
    for g in GROUPS:
        every.update(group(g))
    for name in names:
        d = out / "sequences" / name
        if not (d / "scenario.yaml").exists():
            summ = simulate(every[name], d, overwrite=True)
            s0 = summ.sensors[0]
            log.info(
                "simulated %s: %d frames, %.0f pts/scan (%d-%d)",
                name,
                s0.frames,
                s0.mean_points,
                s0.min_points,
                s0.max_points,
            )
        folders[name] = d
    return folders


def step_errors(est: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-step translation (m) and rotation (deg) error of consecutive relative poses."""
    from relnav.geometry.rotations import rotation_angle
    from relnav.geometry.se3 import invert

    dt, dr = [], []
    for k in range(1, len(est)):
        e = invert(invert(gt[k - 1]) @ gt[k]) @ (invert(est[k - 1]) @ est[k])
        dt.append(np.linalg.norm(e[:3, 3]))
        dr.append(math.degrees(rotation_angle(e[:3, :3])))
    return np.asarray(dt), np.asarray(dr)


def judge_steps(run: Any, gt: np.ndarray) -> tuple[np.ndarray, ...]:
    """The suite's verdict on a run's steps 1 … K − 1: translation (m) and rotation (deg)
    errors (:func:`step_errors`) of the causal poses (the ones each step's flag was given
    with), wrong (beyond 0.5 m or 5°) and flagged (not ``ok``)."""
    et, er = step_errors(np.asarray(run.online_poses), np.asarray(gt))
    wrong = (et > WRONG_STEP[0]) | (er > WRONG_STEP[1])
    flagged = np.array([s.status not in ("ok", "first") for s in run.steps[1:]], dtype=bool)
    return et, er, wrong, flagged


def warm_up(seq_dir: Path, methods: list[str], relnav_options: dict[str, str]) -> None:
    """Run every method once, untimed, on the first frames of ``seq_dir`` (past the navigator's
    multi-view window), so that one-off costs (numba's compiled-code cache, a library's first
    import) are not charged to the first sequence's whole-run time."""
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(seq_dir)
    for method in methods:
        opts = {**MISSION, **relnav_options} if method == "relnav" else {}
        try:
            run_sequence(seq, method, max_frames=WARM_UP_FRAMES, **opts)
        except Exception:  # reported when the method runs for real
            pass


def attitude_input(seq_dir: Path) -> Any:
    """The sequence's measured chaser attitude (``chaser_attitude.tum``) with the σ it was
    simulated with, for relnav's ``attitude`` input (``-O attitude=1``)."""
    from relnav.config import load_yaml
    from relnav.navigation.attitude_input import AttitudeInput

    sigma = load_yaml(seq_dir / "scenario.yaml")["pointing"]["attitude_sigma_deg"]
    return AttitudeInput.from_tum(seq_dir / "chaser_attitude.tum", float(sigma))


def _fitness(step: Any) -> float:
    """A step's registration fitness (inlier fraction of the scan), NaN without a result."""
    return float(step.result.fitness) if step.result is not None else math.nan


def run_method(
    seq_dir: Path, method: str, per_step: bool = False, **options: Any
) -> dict[str, Any]:
    """Run one method on one sequence; APE/RPE (no alignment) of the causal trajectory (what a
    real-time loop has: every peer's), wrong and flagged steps, ms (``relnav`` with the
    :data:`MISSION` input unless ``options`` override it); a smoother's trajectory's APE/RPE
    under ``"smoothed"``; ``per_step`` adds the steps' arrays under ``"steps"`` (with the
    :data:`EVIDENCE` of each step under ``"evidence"``)."""
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(seq_dir)
    if method == "relnav":
        options = {**MISSION, **options}
        if str(options.pop("attitude", "")).lower() in ("1", "true", "yes"):
            options["attitude"] = attitude_input(seq_dir)
    t0 = time.perf_counter()
    run = run_sequence(seq, method, **options)
    wall = time.perf_counter() - t0
    m = evaluate_trajectories(run.timestamps, run.online_poses, seq.timestamps, seq.gt_poses)
    et, er, wrong, flagged = judge_steps(run, seq.gt_poses)
    out = {
        "ape": m["ape_trans_rmse"],
        "ape_r": m["ape_rot_rmse_deg"],
        "rpe_t": m["rpe_trans_rmse"],
        "rpe_r": m["rpe_rot_rmse_deg"],
        "n_steps": len(et),
        "wrong": int(wrong.sum()),
        "flagged": int(flagged.sum()),
        "wrong_flagged": int((wrong & flagged).sum()),
        "right_flagged": int((~wrong & flagged).sum()),
        "ms": run.median_time_ms,
        "wall_s": wall,
        # steps the navigator's revisit test flagged (the map found inconsistent)
        "revisit_alarm": sum(
            bool(s.result is not None and s.result.info.get("revisit_alarm")) for s in run.steps
        ),
    }
    if run.causal_poses is not None:  # the smoother's look-ahead trajectory, as what it is
        ms = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, seq.gt_poses)
        out["smoothed"] = {
            "ape": ms["ape_trans_rmse"],
            "ape_r": ms["ape_rot_rmse_deg"],
            "rpe_t": ms["rpe_trans_rmse"],
            "rpe_r": ms["rpe_rot_rmse_deg"],
        }
    if per_step:  # arrays (not JSON): each step's error, flag, own 1σ (m) and exceedance
        info = [s.result.info if s.result is not None else {} for s in run.steps[1:]]
        sigma = run.step_sigma if run.step_sigma is not None else np.full((len(et) + 1, 2), np.nan)
        out["steps"] = {
            "wrong": wrong,
            "flagged": flagged,
            "error_t": et,
            "error_r": er,
            "sigma_t": sigma[1:, 0],
            "sigma_r": sigma[1:, 1],
            "exceed": np.array([i.get("exceed_probability", np.nan) for i in info], dtype=float),
            "evidence": {
                k: np.array([float(i.get(k, np.nan)) for i in info], dtype=float) for k in EVIDENCE
            }
            | {"fitness": np.array([_fitness(s) for s in run.steps[1:]], dtype=float)},
        }
    return out


TARGETS: dict[str, float] = {
    "ratio": 0.7,
    "wrong_flagged": 0.9,
    "right_flagged": 0.05,
    "time": 1.5,
}
"""The navigator's targets on every sequence (:func:`scorecard`): APE, RPE_t and RPE_r at most
``ratio`` × the best peer's (each metric's best, every peer causal), at least ``wrong_flagged``
of its wrong steps flagged and at most ``right_flagged`` of its right steps, median time per frame
at most ``time`` × KISS-ICP's in the same run."""


def relnav_ratios(res: dict[str, Any]) -> dict[str, Any] | None:
    """relnav's result on one sequence over the peers' (``res``: method → :func:`run_method`'s
    dict): ``ape``, ``rpe_t``, ``rpe_r`` over each metric's best peer (those best values as
    ``best_ape``, ``best_rpe_t``, ``best_rpe_r``), ``time`` and ``run_time`` (median per frame and
    whole run over KISS-ICP's), ``best`` (the peer with the best APE); ``None`` without relnav or
    a peer."""
    r = res.get("relnav", {})
    peers = {m: res[m] for m in PEERS if m in res and "error" not in res[m]}
    if "ape" not in r or not peers:
        return None
    kiss = peers.get("kiss-icp", {})
    best = {m: min(p[m] for p in peers.values()) for m in ("ape", "rpe_t", "rpe_r")}
    out: dict[str, Any] = {m: r[m] / best[m] for m in best}
    out.update({f"best_{m}": v for m, v in best.items()})
    out["time"] = r["ms"] / kiss.get("ms", math.nan)
    out["run_time"] = r["wall_s"] / kiss.get("wall_s", math.nan)
    out["best"] = min(peers, key=lambda m: peers[m]["ape"])
    return out


def markdown_table(results: dict[str, dict[str, Any]]) -> str:
    """The README's table: relnav (causal; its smoothed APE beside, as what it is) beside the
    best peer per sequence (every peer is causal), with the ratios."""
    head = (
        "| sequence | relnav APE m | RPE m / ° | wrong steps (flagged) | smoothed APE m | ms | "
        "best peer APE m (which) | best peer RPE m / ° | relnav ÷ best: APE, RPE_t, RPE_r | "
        "÷ KISS-ICP time: median, run |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    rows = []
    for seq, res in results.items():
        q = relnav_ratios(res)
        if q is None:
            continue
        r, best = res["relnav"], q["best"]
        sm = r.get("smoothed", {}).get("ape", float("nan"))
        rows.append(
            f"| {seq} | {r['ape']:.2f} | {r['rpe_t']:.3f} / {r['rpe_r']:.2f} | "
            f"{r['wrong']}/{r['n_steps']} ({r['wrong_flagged']}) | {sm:.2f} | {r['ms']:.1f} | "
            f"{res[best]['ape']:.2f} ({best}) | "
            f"{q['best_rpe_t']:.3f} / {q['best_rpe_r']:.2f} | {q['ape']:.2f}, "
            f"{q['rpe_t']:.2f}, {q['rpe_r']:.2f} | {q['time']:.2f}, {q['run_time']:.2f} |"
        )
    return head + "\n".join(rows)


def scorecard(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """relnav against :data:`TARGETS` on each sequence of ``results`` (``nav_suite.py --json``).

    Returns
    -------
    list of dict
        Per sequence: ``sequence``, the ratios of :func:`relnav_ratios`, ``wrong`` and
        ``right`` (step counts), ``wrong_flagged`` and ``right_flagged`` (fractions; NaN when
        there is no such step) and ``misses``, the targets it misses (a list of names among
        ``ape``, ``rpe_t``, ``rpe_r``, ``wrong_flagged``, ``right_flagged``, ``time``).
    """
    rows = []
    for seq, res in results.items():
        q = relnav_ratios(res)
        if q is None:
            continue
        r = res["relnav"]
        wrong, right = int(r["wrong"]), int(r["n_steps"]) - int(r["wrong"])
        row = {"sequence": seq, **q, "wrong": wrong, "right": right}
        row["wrong_flagged"] = r["wrong_flagged"] / wrong if wrong else math.nan
        row["right_flagged"] = r["right_flagged"] / right if right else math.nan
        misses = [m for m in ("ape", "rpe_t", "rpe_r") if not q[m] <= TARGETS["ratio"]]
        if wrong and not row["wrong_flagged"] >= TARGETS["wrong_flagged"]:
            misses.append("wrong_flagged")
        if right and not row["right_flagged"] <= TARGETS["right_flagged"]:
            misses.append("right_flagged")
        if not q["time"] <= TARGETS["time"]:
            misses.append("time")
        row["misses"] = misses
        rows.append(row)
    return rows


def scorecard_table(results: dict[str, dict[str, Any]]) -> str:
    """:func:`scorecard` as a markdown table, each missed target in bold."""

    def cell(row: dict[str, Any], key: str, text: str) -> str:
        return f"**{text}**" if key in row["misses"] else text

    lines = [
        "| sequence | ÷ best peer: APE | RPE_t | RPE_r | wrong steps flagged | right steps "
        "flagged | ÷ KISS-ICP time | misses |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in scorecard(results):
        wf = f"{row['wrong_flagged']:.0%} of {row['wrong']}" if row["wrong"] else "no wrong step"
        rf = f"{row['right_flagged']:.1%} of {row['right']}" if row["right"] else "no right step"
        cells = [cell(row, m, f"{row[m]:.2f}") for m in ("ape", "rpe_t", "rpe_r")]
        cells += [cell(row, "wrong_flagged", wf), cell(row, "right_flagged", rf)]
        cells += [cell(row, "time", f"{row['time']:.2f}"), ", ".join(row["misses"]) or "none"]
        lines.append(f"| {row['sequence']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def stress_table(plain: dict[str, Any], aided: dict[str, Any]) -> str:
    """The stress group's table: relnav without and with the chaser attitude input beside the
    best peer, causal (``plain``: ``--stress --json``; ``aided``: ``--stress --methods relnav -O
    attitude=1 --json``)."""

    def cell(r: dict[str, Any]) -> str:
        return (
            f"{r['ape']:.2f} | {r['rpe_t']:.3f} / {r['rpe_r']:.2f} | {r['wrong']}/{r['n_steps']} "
            f"({r['wrong_flagged']} flagged; right flagged {r['right_flagged']})"
        )

    rows = [
        "| sequence | relnav APE m | RPE m / ° | wrong steps | relnav + attitude APE m | "
        "RPE m / ° | wrong steps | best peer APE m (which) | best peer RPE m / ° |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for seq, res in plain.items():
        q = relnav_ratios(res)
        if q is None:
            continue
        own, att = res["relnav"], aided.get(seq, {}).get("relnav", {})
        a = cell(att) if "ape" in att else "– | – | –"
        rows.append(
            f"| {seq} | {cell(own)} | {a} | {q['best_ape']:.2f} ({q['best']}) | "
            f"{q['best_rpe_t']:.3f} / {q['best_rpe_r']:.2f} |"
        )
    return "\n".join(rows)
