"""The navigation suite: sparse flash-LIDAR sequences for relnav's own navigator and its peers.

Every sequence is made with relnav's simulator: a flash LIDAR (64×64 or 128×128 pixels, 45° field
of view, 2 cm range noise) at 35–65 m from a target, on paths that a GNC engineer would fly:
2.5 loops of an ellipse, a helical approach, an inspection ellipse inclined to a symmetric target's
axis, and a hold point beside a target tumbling about a tilted axis. Targets: the meshes of
``../shared/data/targets`` (Eros, Aura, Orion, Voyager, 67P) when present, relnav's procedural ones
otherwise (and always for the procedural entries).

    python benchmarks/nav_suite.py --out bench/nav                  # all sequences, all methods
    python benchmarks/nav_suite.py --out bench/nav --only eros --methods relnav,kiss-icp

The script simulates each sequence once (cached in ``OUT/sequences``), runs every method once
untimed on the first sequence's first frames (so that one-off loading is not charged to that
sequence's whole-run time), runs every method on the same frames, and prints APE, RPE,
wrong-step counts (> 0.5 m or > 5°), flagged steps and ms per frame, then each method's ratio to
the best peer. ``--json`` writes everything. ``relnav`` is given the target's orbit (its mean
motion, :data:`MISSION`: every sequence is flown about a target in the same low Earth orbit), as
a mission would give it; ``-O orbit_mean_motion=0`` runs it without.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED_TARGETS = REPO.parent / "shared" / "data" / "targets"
LEO_PERIOD_S = 5553.6
MISSION: dict[str, Any] = {"orbit_mean_motion": 2 * math.pi / LEO_PERIOD_S}
"""relnav's mission input on every sequence (suite and held out): the target's orbit, one low
Earth orbit of ``LEO_PERIOD_S`` (``-O orbit_mean_motion=0`` runs without it). Not a tuning."""

PEERS = [
    "kiss-icp",
    "small-gicp",
    "o3d-icp-plane",
    "o3d-fpfh-ransac",
    "kiss-matcher",
    "kiss-matcher-icp",
]
DEFAULT_METHODS = ["relnav", *PEERS, "icp-plane"]
WARM_UP_FRAMES = 12


def _flash(pixels: int) -> dict[str, Any]:
    return {
        "preset": "goldeneye",
        "name": "flash",
        "overrides": {"rows": pixels, "cols": pixels, "range_sigma": 0.02},
    }


def _mesh(name: str, fallback: str, scale_to: float) -> dict[str, Any]:
    path = SHARED_TARGETS / f"{name}.ply"
    if path.exists():
        return {"path": str(path), "scale_to": scale_to}
    return {"name": fallback, "scale_to": scale_to}


def _ellipse(a: float, b: float, loops: float, tilt: float, frames: int) -> dict[str, Any]:
    return {
        "frames": frames,
        "dt": loops * LEO_PERIOD_S / (frames - 1),
        "trajectory": {
            "kind": "elliptic-orbit",
            "params": {"semi_major": a, "semi_minor": b, "loops": loops, "tilt_deg": tilt},
        },
    }


def _inspection(a: float, b: float, tilt: float) -> dict[str, Any]:
    """One inspection ellipse (semi-axes ``a``, ``b`` m, tilted ``tilt`` degrees) per low Earth
    orbit, 200 frames."""
    return {
        "frames": 200,
        "dt": LEO_PERIOD_S / 199,
        "trajectory": {
            "kind": "ellipse-of-inspection",
            "params": {"semi_major": a, "semi_minor": b, "tilt_deg": tilt},
        },
    }


def _helical(r0: float, r1: float, h0: float, h1: float, turns: float) -> dict[str, Any]:
    """A helical approach from radius ``r0`` to ``r1`` (m), height ``h0`` to ``h1`` (m), in 150
    frames 10 s apart."""
    return {
        "frames": 150,
        "dt": 10.0,
        "trajectory": {
            "kind": "helical-approach",
            "params": {
                "radius_start": r0,
                "radius_end": r1,
                "height_start": h0,
                "height_end": h1,
                "turns": turns,
            },
        },
    }


def suite() -> dict[str, dict[str, Any]]:
    """The suite's scenarios by name (dicts for :func:`relnav.sim.simulate`)."""
    s: dict[str, dict[str, Any]] = {}
    s["eros-ellipse-64"] = {
        "target": _mesh("eros", "asteroid", 16.0),
        "sensors": [_flash(64)],
        **_ellipse(60.0, 45.0, 2.5, 20.0, 250),
    }
    s["aura-ellipse-64"] = {
        "target": _mesh("aura", "envisat", 17.0),
        "sensors": [_flash(64)],
        "attitude": {"initial_rpy_deg": (20.0, 10.0, 30.0)},
        **_ellipse(60.0, 42.0, 2.5, 25.0, 250),
    }
    s["iridium-helical-64"] = {
        "target": {"name": "iridium", "scale_to": 10.0},
        "sensors": [_flash(64)],
        **_helical(55.0, 35.0, 30.0, 0.0, 1.0),
    }
    s["orion-inclined-64"] = {
        # the capsule's symmetry axis is y; the inspection ellipse is inclined 35° to it
        "target": _mesh("orion", "capsule", 7.0),
        "sensors": [_flash(64)],
        **_inspection(50.0, 35.0, 35.0),
    }
    s["envisat-tumble-64"] = {
        "target": {"name": "envisat", "scale_to": 16.0},
        "sensors": [_flash(64)],
        "frames": 200,
        "dt": 2.0,
        "trajectory": {"kind": "static", "params": {"position": (-50.0, 0.0, 5.0)}},
        "attitude": {
            "kind": "spin",
            "axis": (0.35, 0.25, 0.90),
            "rate_deg_s": 1.0,
            "initial_rpy_deg": (10.0, 20.0, 0.0),
        },
    }
    s["voyager-ellipse-128"] = {
        "target": _mesh("voyager", "voyager", 12.3),
        "sensors": [_flash(128)],
        **_ellipse(55.0, 40.0, 2.5, 15.0, 250),
    }
    s["asteroid-helical-128"] = {
        "target": {"name": "asteroid", "scale_to": 14.0},
        "sensors": [_flash(128)],
        **_helical(60.0, 40.0, -25.0, 5.0, 1.25),
    }
    return _finish(s)


def _tumble(
    target: dict[str, Any],
    seed: int,
    position: tuple[float, float, float],
    inertia: tuple[float, float, float],
    omega0_deg_s: tuple[float, float, float],
    initial_rpy_deg: tuple[float, float, float],
) -> dict[str, Any]:
    """A 64×64 flash LIDAR holding its station beside a torque-free tumbling target."""
    return {
        "target": target,
        "sensors": [_flash(64)],
        "seed": seed,
        "frames": 200,
        "dt": 2.0,
        "trajectory": {"kind": "static", "params": {"position": position}},
        "attitude": {
            "kind": "tumble",
            "inertia": inertia,
            "omega0_deg_s": omega0_deg_s,
            "initial_rpy_deg": initial_rpy_deg,
        },
    }


def tumbling_holdout() -> dict[str, dict[str, Any]]:
    """Tumbling sequences made after a configuration was frozen, to check it once
    (``nav_state.py --fresh``): voyager and iridium in session 16 after the full state's
    hold-point preset (with ``rigid_body``), orion, eros and capsule in session 17 after the
    ``relnav-tumbling`` method preset, comet and probe (a procedural Voyager) after the
    hold-point preset's ``gate_patience``; not part of the navigator's held-out APE tables."""
    return {
        "voyager-tumble-64": _tumble(
            _mesh("voyager", "voyager", 12.3),
            41,
            (-40.0, 5.0, -6.0),
            (4000.0, 7000.0, 9000.0),
            (0.6, -0.9, 0.5),
            (15.0, 40.0, -20.0),
        ),
        "iridium-tumble-64": _tumble(
            {"name": "iridium", "scale_to": 10.0},
            42,
            (-45.0, -5.0, 3.0),
            (800.0, 2500.0, 2900.0),
            (-0.4, 0.3, 1.4),
            (-25.0, 10.0, 60.0),
        ),
        # made in session 17 after the ``relnav-tumbling`` method preset (curved patches and the
        # start-up's re-anchoring) and the hold-point preset's ``wander_frames`` were frozen
        "orion-tumble-64": _tumble(
            _mesh("orion", "capsule", 8.0),
            43,
            (-38.0, 4.0, 5.0),
            (6000.0, 6200.0, 4000.0),
            (0.8, 0.2, 1.0),
            (40.0, -15.0, 10.0),
        ),
        "eros-tumble-64": _tumble(
            _mesh("eros", "asteroid", 15.0),
            44,
            (-42.0, -6.0, -3.0),
            (300.0, 1200.0, 1300.0),
            (0.5, -0.7, 0.4),
            (-10.0, 25.0, 70.0),
        ),
        "capsule-tumble-64": _tumble(
            {"name": "capsule", "scale_to": 6.0},
            45,
            (-36.0, 3.0, -4.0),
            (2500.0, 2600.0, 1800.0),
            (-0.3, 0.9, -0.6),
            (5.0, -35.0, 20.0),
        ),
        # made in session 17 after the hold-point preset's gate_patience was added (found on
        # eros-tumble-64, which is therefore no longer a clean check of it)
        "comet-tumble-64": _tumble(
            _mesh("comet67p", "asteroid", 14.0),
            46,
            (-44.0, 2.0, 6.0),
            (900.0, 1500.0, 1800.0),
            (0.4, 0.6, -0.8),
            (20.0, 5.0, -45.0),
        ),
        "probe-tumble-64": _tumble(
            {"name": "voyager", "scale_to": 12.0},
            47,
            (-41.0, -4.0, 3.0),
            (3000.0, 5500.0, 7000.0),
            (-0.7, 0.5, 0.6),
            (-30.0, 15.0, 35.0),
        ),
    }


def holdout() -> dict[str, dict[str, Any]]:
    """Sequences never used to choose parameters (checked once the suite's were frozen)."""
    s: dict[str, dict[str, Any]] = {}
    s["comet-ellipse-64"] = {
        "target": _mesh("comet67p", "asteroid", 14.0),
        "sensors": [_flash(64)],
        "seed": 11,
        **_ellipse(58.0, 40.0, 2.5, -30.0, 250),
    }
    s["voyager-helical-64"] = {
        "target": _mesh("voyager", "voyager", 12.3),
        "sensors": [_flash(64)],
        "seed": 12,
        **_helical(58.0, 38.0, 20.0, -10.0, 1.0),
    }
    s["aura-tumble-64"] = _tumble(
        _mesh("aura", "envisat", 16.0),
        13,
        (-45.0, 8.0, -4.0),
        (17000.0, 120000.0, 125000.0),
        (0.3, 0.4, 1.2),
        (30.0, -10.0, 50.0),
    )
    s["capsule-ellipse-128"] = {
        "target": {"name": "capsule", "scale_to": 6.0},
        "sensors": [_flash(128)],
        "seed": 14,
        **_ellipse(45.0, 40.0, 2.5, 50.0, 250),
    }
    # made after the orbit test's thresholds were frozen (session 14), never used to choose them
    s["orion-tilt60-64"] = {
        "target": _mesh("orion", "capsule", 7.0),
        "sensors": [_flash(64)],
        "seed": 31,
        **_inspection(45.0, 32.0, 60.0),
    }
    s["capsule-ellipse-64"] = {
        "target": {"name": "capsule", "scale_to": 6.0},
        "sensors": [_flash(64)],
        "seed": 32,
        **_ellipse(45.0, 40.0, 1.5, 30.0, 150),
    }
    s["orion-ellipse-64"] = {
        "target": _mesh("orion", "capsule", 7.0),
        "sensors": [_flash(64)],
        "seed": 33,
        **_ellipse(55.0, 40.0, 2.0, 15.0, 200),
    }
    s["aura-inclined-64"] = {
        "target": _mesh("aura", "envisat", 16.0),
        "sensors": [_flash(64)],
        "seed": 34,
        **_inspection(50.0, 35.0, 35.0),
    }
    s["asteroid-ellipse-64"] = {
        "target": {"name": "asteroid", "scale_to": 12.0},
        "sensors": [_flash(64)],
        "seed": 35,
        **_ellipse(50.0, 40.0, 2.0, 20.0, 200),
    }
    s["voyager-inclined-64"] = {
        "target": _mesh("voyager", "voyager", 12.3),
        "sensors": [_flash(64)],
        "seed": 36,
        **_inspection(55.0, 40.0, 50.0),
    }
    return _finish(s)


JITTER_DEG = (0.25, 0.5, 1.0, 2.0)
"""The stress group's white attitude jitter levels (degrees per axis per frame)."""


ATTITUDE_SIGMA = 0.01
"""1σ per axis (degrees) of the chaser's measured attitude written beside the stress group's
sequences (``chaser_attitude.tum``: a star tracker's order of magnitude)."""


def _jittered(sc: dict[str, Any], jitter: float, kind: str = "white") -> dict[str, Any]:
    """``sc`` with 5 cm range noise and sensor attitude jitter ``jitter`` degrees per axis."""
    sensor = {**sc["sensors"][0], "overrides": {**sc["sensors"][0]["overrides"]}}
    sensor["overrides"]["range_sigma"] = 0.05
    pointing = {"jitter_deg": jitter, "jitter_kind": kind, "attitude_sigma_deg": ATTITUDE_SIGMA}
    return {**sc, "sensors": [sensor], "pointing": pointing}


def stress() -> dict[str, dict[str, Any]]:
    """Motion the constant-velocity prior does not predict and scans with few points (issue
    "the navigator when motion is not smooth"): sensor attitude jitter 0.25–2° per axis per
    frame (white, and a random walk) with 5 cm range noise on a box-and-panel satellite's
    orbit (procedural Envisat); a ~30-point-per-scan orbit of a 10 m satellite at 40–60 m; a
    straight-line approach from 80 m to 12 m; a start at 40 m with ≤ 15 points per scan closing
    to 15 m. Made after the suite's parameters
    were frozen."""
    s: dict[str, dict[str, Any]] = {}
    base = {
        "target": {"name": "envisat", "scale_to": 16.0},
        "sensors": [_flash(128)],
        "seed": 51,
        **_ellipse(50.0, 38.0, 1.0, 20.0, 120),
    }
    for j in (0.0, *JITTER_DEG):
        s[f"envisat-jitter{j:g}"] = _jittered(base, j)
    s["envisat-walk0.5"] = _jittered(base, 0.5, "random-walk")
    s["voyager-sparse30"] = {
        "pointing": {"attitude_sigma_deg": ATTITUDE_SIGMA},
        "target": _mesh("voyager", "voyager", 10.0),
        "sensors": [_flash(80)],
        "seed": 52,
        **_ellipse(60.0, 40.0, 1.0, 10.0, 100),
    }
    s["voyager-approach"] = {
        "pointing": {"attitude_sigma_deg": ATTITUDE_SIGMA},
        "target": _mesh("voyager", "voyager", 10.0),
        "sensors": [_flash(64)],
        "seed": 54,
        "frames": 120,
        "dt": 10.0,
        "trajectory": {"kind": "vbar", "params": {"start": -80.0, "stop": -12.0}},
    }
    s["aura-farstart"] = {
        "pointing": {"attitude_sigma_deg": ATTITUDE_SIGMA},
        "target": _mesh("aura", "envisat", 10.0),
        "sensors": [_flash(24)],
        "seed": 53,
        "frames": 120,
        "dt": 20.0,
        "trajectory": {
            "kind": "helical-approach",
            "params": {
                "radius_start": 40.0,
                "radius_end": 15.0,
                "height_start": 8.0,
                "height_end": 2.0,
                "turns": 0.5,
            },
        },
    }
    return _finish(s)


PAPER_PRESETS = ("sim-eoi", "sim-helical", "sim-voyager", "sim-orion", "sim-bennu")


def paper(max_frames: int = 60) -> dict[str, dict[str, Any]]:
    """Paper 1's five HPR presets, their first ``max_frames`` frames (as in the grid): with paper
    1's data generation (one model cloud, the same surface points in every scan) and with fresh
    surface samples per scan (``-resample``: what a real sensor does)."""
    from relnav.sim.presets import get_preset

    out: dict[str, dict[str, Any]] = {}
    for name in PAPER_PRESETS:
        sc = get_preset(name, max_frames=max_frames).model_dump(mode="json")
        out[name] = sc
        re = get_preset(name, max_frames=max_frames, model_cloud="resample")
        out[f"{name}-resample"] = {**re.model_dump(mode="json"), "name": f"{name}-resample"}
    return out


def _finish(s: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    for name, sc in s.items():
        sc.setdefault("name", name)
        sc.setdefault("seed", 0)
        sc.setdefault("format", "npy")
    return s


def write_configs(folder: Path) -> list[Path]:
    """Write every scenario (suite and held-out) as a YAML file for ``relnav simulate`` and
    ``relnav benchmark``; mesh paths are relative to the repository root (run from there)."""
    import yaml

    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for group, scenarios in (("suite", suite()), ("holdout", holdout()), ("stress", stress())):
        for name, sc in scenarios.items():
            sc = json.loads(json.dumps(sc))  # tuples -> lists
            path = sc.get("target", {}).get("path")
            if path:
                sc["target"]["path"] = str(Path(path).relative_to(REPO.parent).as_posix())
                sc["target"]["path"] = "../" + sc["target"]["path"]
            p = folder / f"{name}.yaml"
            head = (
                f"# navigation {group} sequence '{name}' (generated by "
                "benchmarks/nav_suite.py --write-configs; mesh paths relative to the "
                "repository root)\n"
            )
            p.write_text(head + yaml.safe_dump(sc, sort_keys=False), encoding="utf-8")
            written.append(p)
    return written


def sequence_names(held_out: bool = False, only: str = "", stressed: bool = False) -> list[str]:
    """The suite's sequences with the paper presets, or the held-out ones, or the stress group
    (:func:`stress`); ``only``: keep the names containing one of its comma-separated
    substrings."""
    pool = stress() if stressed else holdout() if held_out else {**suite(), **paper()}
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
        "-O", dest="options", action="append", default=[], help="relnav option key=value"
    )


def simulate_suite(out: Path, names: list[str]) -> dict[str, Path]:
    """Simulate (once) every named sequence into ``out/sequences``; returns their folders."""
    from relnav.sim.scenario import simulate

    folders = {}
    every = {**suite(), **holdout(), **stress(), **paper()}
    for name in names:
        d = out / "sequences" / name
        if not (d / "scenario.yaml").exists():
            summ = simulate(every[name], d, overwrite=True)
            s0 = summ.sensors[0]
            print(
                f"simulated {name}: {s0.frames} frames, {s0.mean_points:.0f} pts/scan "
                f"({s0.min_points}-{s0.max_points})",
                file=sys.stderr,
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
    wrong = (et > 0.5) | (er > 5.0)
    flagged = np.array([s.status not in ("ok", "first") for s in run.steps[1:]], dtype=bool)
    return et, er, wrong, flagged


def warm_up(seq_dir: Path, methods: list[str], relnav_options: dict[str, str]) -> None:
    """Run every method once, untimed, on the first frames of ``seq_dir`` (past the navigator's
    multi-view window), so that one-off costs (numba's compiled-code cache, a library's first
    import) are not charged to the first sequence's whole-run time."""
    from relnav.io.sequences import ScanSequence
    from relnav.odometry import run_sequence

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


def run_method(
    seq_dir: Path, method: str, per_step: bool = False, **options: Any
) -> dict[str, Any]:
    """Run one method on one sequence; APE/RPE (no alignment) of the causal trajectory (what a
    real-time loop has: every peer's), wrong and flagged steps, ms (``relnav`` with the
    :data:`MISSION` input unless ``options`` override it); a smoother's trajectory's APE/RPE
    under ``"smoothed"``; ``per_step`` adds the steps' arrays under ``"steps"``."""
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.odometry import run_sequence

    seq = ScanSequence(seq_dir)
    if method == "relnav":
        options = {**MISSION, **options}
        if str(options.pop("attitude", "")).lower() in ("1", "true", "yes"):
            options["attitude"] = attitude_input(seq_dir)
    t0 = time.perf_counter()
    run = run_sequence(seq, method, **options)
    wall = time.perf_counter() - t0
    m = evaluate_trajectories(run.timestamps, run.online_poses, seq.timestamps, seq.gt_poses)
    et, _, wrong, flagged = judge_steps(run, seq.gt_poses)
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
        out["steps"] = {
            "wrong": wrong,
            "flagged": flagged,
            "error_t": et,
            "sigma_t": np.array([i.get("step_sigma_t", np.nan) for i in info], dtype=float),
            "exceed": np.array([i.get("exceed_probability", np.nan) for i in info], dtype=float),
        }
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
        r = res.get("relnav", {})
        peers = {m: res[m] for m in PEERS if m in res and "error" not in res[m]}
        if "ape" not in r or not peers:
            continue
        best = min(peers, key=lambda m: peers[m]["ape"])
        bt = min(p["rpe_t"] for p in peers.values())
        br = min(p["rpe_r"] for p in peers.values())
        kiss = peers.get("kiss-icp", {}).get("ms", float("nan"))
        kiss_run = peers.get("kiss-icp", {}).get("wall_s", float("nan"))
        sm = r.get("smoothed", {}).get("ape", float("nan"))
        rows.append(
            f"| {seq} | {r['ape']:.2f} | {r['rpe_t']:.3f} / {r['rpe_r']:.2f} | "
            f"{r['wrong']}/{r['n_steps']} ({r['wrong_flagged']}) | {sm:.2f} | {r['ms']:.1f} | "
            f"{peers[best]['ape']:.2f} ({best}) | "
            f"{bt:.3f} / {br:.2f} | {r['ape'] / peers[best]['ape']:.2f}, {r['rpe_t'] / bt:.2f}, "
            f"{r['rpe_r'] / br:.2f} | {r['ms'] / kiss:.2f}, {r['wall_s'] / kiss_run:.2f} |"
        )
    return head + "\n".join(rows)


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
        peers = {m: res[m] for m in PEERS if m in res and "error" not in res[m]}
        own, att = res.get("relnav", {}), aided.get(seq, {}).get("relnav", {})
        if "ape" not in own or not peers:
            continue
        best = min(peers, key=lambda m: peers[m]["ape"])
        bt = min(p["rpe_t"] for p in peers.values())
        br = min(p["rpe_r"] for p in peers.values())
        a = cell(att) if "ape" in att else "– | – | –"
        rows.append(
            f"| {seq} | {cell(own)} | {a} | {peers[best]['ape']:.2f} ({best}) | "
            f"{bt:.3f} / {br:.2f} |"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS))
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--write-configs", type=Path, default=None, help="write scenario YAMLs")
    p.add_argument(
        "--stress-table",
        nargs=2,
        type=Path,
        metavar=("PLAIN_JSON", "ATTITUDE_JSON"),
        help="print the stress group's table from two --json files and exit",
    )
    a = p.parse_args(argv)
    if a.stress_table:
        plain, aided = (json.loads(f.read_text()) for f in a.stress_table)
        print(stress_table(plain, aided))
        return 0
    if a.write_configs:
        for path in write_configs(a.write_configs):
            print(path)
        return 0
    names = sequence_names(a.holdout, a.only, a.stress)
    folders = simulate_suite(a.out, names)
    methods = [m for m in a.methods.split(",") if m]
    relnav_options = dict(o.split("=", 1) for o in a.options)
    if names:
        warm_up(folders[names[0]], methods, relnav_options)
    results: dict[str, dict[str, Any]] = {}
    for name in names:
        results[name] = {}
        for method in methods:
            try:
                # strings: the navigator converts them to its options' types (bool, int, ...)
                opts = relnav_options if method == "relnav" else {}
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
        peers = {m: r for m, r in results[name].items() if m in PEERS and "error" not in r}
        own = results[name].get("relnav", {})
        if peers and "ape" in own:
            best_ape = min(r["ape"] for r in peers.values())
            best_rpe = min(r["rpe_t"] for r in peers.values())
            best_rpr = min(r["rpe_r"] for r in peers.values())
            kiss = peers.get("kiss-icp", {}).get("ms", float("nan"))
            kiss_run = peers.get("kiss-icp", {}).get("wall_s", float("nan"))
            print(
                f"{name:22s} relnav / best peer: APE {own['ape'] / best_ape:.2f}  "
                f"RPE_t {own['rpe_t'] / best_rpe:.2f}  RPE_r {own['rpe_r'] / best_rpr:.2f}  "
                f"time / kiss-icp {own['ms'] / kiss:.2f} "
                f"(whole run {own['wall_s'] / kiss_run:.2f})",
                flush=True,
            )
    if a.json:
        a.json.write_text(json.dumps(results, indent=2))
    print()
    print(markdown_table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
