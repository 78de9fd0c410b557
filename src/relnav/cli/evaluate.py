"""``relnav evaluate``: accuracy of an estimated trajectory against the ground truth (TUM/KITTI)."""

from __future__ import annotations

import json
import math
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import typer
from rich.markup import escape

from relnav.cli._common import console
from relnav.errors import InputError
from relnav.pipeline.outputs import json_safe


class Align(StrEnum):
    """Alignment of the estimate onto the ground truth."""

    none = "none"
    first = "first"
    se3 = "se3"
    sim3 = "sim3"


class RotError(StrEnum):
    """Definition of ``e_R_avg`` / ``e_R_max``."""

    geodesic = "geodesic"
    euler_mean_diff = "euler_mean_diff"


class DeltaUnit(StrEnum):
    """Unit of the RPE delta (evo ``--delta_unit``)."""

    frames = "frames"
    m = "m"
    deg = "deg"
    rad = "rad"


PAPER1_TABLE_KEYS = (
    "n_frames",
    "path_length",
    "duration_s",
    "drift",
    "T_error_pct",
    "e_T_avg",
    "e_T_max",
    "e_x_avg",
    "e_y_avg",
    "e_z_avg",
    "e_x_max",
    "e_y_max",
    "e_z_max",
    "e_R_avg",
    "e_R_max",
    "e_R_euler_avg",
    "e_R_euler_peak",
    "e_RT",
    "e_RT_trans",
    "e_RT_rot",
)
"""Paper 1's metrics in ``relnav evaluate``'s first table (evo's follow in a second one)."""

# Keys only odometry knows (processing time, flags): kept when evaluate rewrites metrics.json.
_ODOMETRY_KEYS = ("time_ms", "time_ms_mean", "flagged_frames", "method", "preset")


def read_poses(path: Path, what: str) -> tuple:  # type: ignore[type-arg]
    """Read a TUM or KITTI file; every failure becomes an :class:`InputError` naming the file."""
    from relnav.errors import RelnavError
    from relnav.io.trajectories import read_trajectory

    if not path.is_file():
        raise InputError(f"{path}: no such {what} trajectory file")
    try:
        return read_trajectory(path)
    except RelnavError:
        raise
    except (OSError, ValueError, IndexError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read trajectory: {e}") from None


def timed_pair(est: Path, gt: Path) -> tuple:  # type: ignore[type-arg]
    """Read both trajectories; give KITTI files without ``times.txt`` usable timestamps.

    **[interpretation]** A KITTI file carries no times: when one side has times and the other
    has the same number of poses, the other borrows them (pose ``k`` ↔ pose ``k``); when
    neither has times both use the frame index.
    """
    t_est, P_est, f_est = read_poses(est, "estimated")
    t_gt, P_gt, f_gt = read_poses(gt, "ground-truth")
    if t_est is None or t_gt is None:
        if t_est is None and t_gt is None:
            t_est = np.arange(len(P_est), dtype=float)
            t_gt = np.arange(len(P_gt), dtype=float)
        else:
            have, need, other = (t_gt, P_est, est) if t_est is None else (t_est, P_gt, gt)
            if len(have) != len(need):
                raise InputError(
                    f"{other}: KITTI poses have no times ({len(need)} poses vs {len(have)}); "
                    "put a times.txt (one time per pose) next to it"
                )
            if t_est is None:
                t_est = have.copy()
            else:
                t_gt = have.copy()
    return t_est, P_est, f_est, t_gt, P_gt, f_gt


def _fmt(key: str, value: float | str | None) -> str:
    if isinstance(value, str):
        return value
    if value is None or math.isnan(value):
        return "—"
    if key.startswith("n_"):
        return f"{int(value)}"
    return f"{value:.6g}"


def evo_table(res: dict, title: str) -> Any:  # type: ignore[type-arg]
    """evo-style statistics table: one row per statistic, one column per APE/RPE error.

    The JSON key of a cell is ``<column>_<row>``, e.g. ``rpe_rot_median``.
    """
    from rich.table import Table

    from relnav.eval.metrics import STAT_NAMES

    t = Table(title=title)
    t.add_column("stat")
    cols = (("ape_trans", "m"), ("ape_rot", "deg"), ("rpe_trans", "m"), ("rpe_rot", "deg"))
    for rel, unit in cols:
        t.add_column(f"{rel} {unit}", justify="right")
    for stat in STAT_NAMES:
        vals = [res.get(f"{rel}_{stat}") for rel, _ in cols]
        t.add_row(stat, *("—" if v is None or math.isnan(v) else f"{v:.6g}" for v in vals))
    return t


FRAME_GAIN = 5.0
"""The estimate and the ground truth are taken to be in frames that differ by a constant
transform when aligning their first poses (``--align first``) or an SE(3) fit (``--align
se3``) divides the unaligned APE translation RMSE by at least this factor."""

FLIP_DEG = 150.0
"""A rotation error beyond this angle counts as "near 180°" for :func:`frame_hints`."""


def _trans_rmse(m: Any) -> float:
    """APE translation RMSE of matched (aligned) trajectories, m."""
    d = m.est_poses[:, :3, 3] - m.gt_poses[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def _rot_errors_deg(m: Any) -> np.ndarray:
    """Geodesic angle between matched estimated and ground-truth rotations, degrees (K,)."""
    from relnav.geometry.rotations import angle_between_rotations

    ang = angle_between_rotations(m.gt_poses[:, :3, :3], m.est_poses[:, :3, :3])
    return np.degrees(np.atleast_1d(ang))


def frame_hints(
    t_est: np.ndarray,
    P_est: np.ndarray,
    t_gt: np.ndarray,
    P_gt: np.ndarray,
    *,
    max_diff: float = 0.01,
    offset: float = 0.0,
    align: str = "none",
) -> list[str]:
    """One-line warnings about the frames of an evaluation, empty when nothing looks wrong.

    - Without alignment: the estimate and ground truth differ by a constant transform (a run
      that did not start from the ground truth's first pose, another world frame) when
      ``--align first`` or ``se3`` cuts the APE translation RMSE by :data:`FRAME_GAIN` or more.
    - Most rotation errors near 180° (beyond :data:`FLIP_DEG`) and no alignment explaining
      them: rotations transposed, or TUM quaternions written w-first (TUM is
      ``qx qy qz qw``).

    Parameters
    ----------
    t_est, t_gt : (N,), (M,) float
        Timestamps, s.
    P_est, P_gt : (N, 4, 4), (M, 4, 4) float
        Poses (target ← sensor, or any world ← body), m.
    max_diff, offset : float
        Association as in ``relnav evaluate``, s.
    align : str
        The alignment the evaluation used.
    """
    from relnav.errors import RelnavError
    from relnav.eval.metrics import match_trajectories

    def matched(how: str) -> Any:
        return match_trajectories(
            t_est, P_est, t_gt, P_gt, max_diff=max_diff, offset=offset, align=how
        )

    try:
        used = matched(align)
    except RelnavError:
        return []
    hints: list[str] = []
    if align == "none" and len(used.times) >= 3:
        e0 = _trans_rmse(used)
        gains = {}
        for how in ("first", "se3"):
            try:
                gains[how] = _trans_rmse(matched(how))
            except RelnavError:  # e.g. a degenerate (collinear) path for the SE(3) fit
                continue
        best = min(gains, key=gains.__getitem__) if gains else None
        if best is not None and e0 > 1e-9 and gains[best] * FRAME_GAIN <= e0:
            hints.append(
                "the estimate and the ground truth look like the same path in frames that "
                f"differ by a constant transform (APE translation RMSE {e0:.4g} m as is, "
                f"{gains[best]:.4g} m with --align {best}): did the run start from another "
                f"pose than the ground truth's first (e.g. initial_pose=identity)? Pass "
                f"--align {best} (or first/se3/sim3) to compare the paths"
            )
            return hints
    ang = _rot_errors_deg(used)
    if ang.size and np.mean(ang > FLIP_DEG) > 0.5:
        hints.append(
            f"{np.mean(ang > FLIP_DEG):.0%} of the rotation errors are near 180° (beyond "
            f"{FLIP_DEG:g}°, median {np.median(ang):.1f}°): rotations transposed, or TUM "
            "quaternions written w-first? (TUM lines are 'time x y z qx qy qz qw')"
        )
    return hints


def evaluate(
    est: Path | None = typer.Argument(None, help="Estimated trajectory (TUM or KITTI poses)."),
    gt: Path | None = typer.Argument(None, help="Ground-truth trajectory (TUM or KITTI poses)."),
    json_path: Path | None = typer.Option(
        None, "--json", help="Write every metric to this JSON file."
    ),
    max_diff: float = typer.Option(
        0.01, "--max-diff", min=0.0, help="Largest timestamp difference for association, seconds."
    ),
    offset: float = typer.Option(
        0.0, "--offset", help="Constant added to the estimate's timestamps, seconds."
    ),
    align: Align = typer.Option(
        Align.none,
        "--align",
        help="none: compare as is; first: make the first poses coincide; se3: Umeyama fit; "
        "sim3: Umeyama fit with scale (evo --align --correct_scale).",
    ),
    delta: float = typer.Option(1.0, "--delta", min=0.0, help="RPE pair distance (--delta-unit)."),
    delta_unit: DeltaUnit = typer.Option(
        DeltaUnit.frames, "--delta-unit", help="Unit of --delta: frames, m (path), deg, rad."
    ),
    all_pairs: bool = typer.Option(
        False, "--all-pairs", help="RPE over every pair (i, i+delta), not evo's default."
    ),
    rotation_error: RotError = typer.Option(
        RotError.geodesic,
        "--rotation-error",
        help="Definition of e_R_avg/e_R_max (euler_mean_diff = Paper 1's signed legacy form).",
    ),
    plot_dir: Path | None = typer.Option(
        None, "--plot-dir", help="Write trajectories.png and errors.png into this folder."
    ),
    list_metrics: bool = typer.Option(
        False, "--metrics", help="Print what every metric key means (unit, origin) and stop."
    ),
) -> None:
    """Compare an estimated trajectory with the ground truth (Paper 1 metrics, evo APE/RPE).

    Poses are associated by timestamp (nearest, one-to-one, within --max-diff). TUM and KITTI
    files are told apart by their numbers per line; KITTI times come from a times.txt next to
    the file (else the other file's times, pose by pose).

    Angles are reported in degrees, lengths in metres. Paper 1's metrics keep the paper's
    names (e_T_avg is its e^T_avg, an RMSE); evo's carry evo's statistic names
    (ape_trans_rmse, rpe_rot_median, ...). [bold]relnav evaluate --metrics[/] lists them.

    Example: [bold]relnav evaluate run/estimate.tum seq/gt_T_target_sensor.tum --json m.json[/]
    """
    from rich.table import Table

    from relnav import __version__
    from relnav.eval.metrics import METRIC_DOCS, evaluate_trajectories, metric_units

    if list_metrics:
        t = Table(title="metric keys (JSON and tables)")
        for col in ("key", "unit", "origin", "definition"):
            t.add_column(col)
        for k, (unit, origin, definition) in METRIC_DOCS.items():
            t.add_row(k, unit, origin, definition)
        console.print(t)
        return
    if est is None or gt is None:
        raise InputError("give the estimated and the ground-truth trajectory files (EST GT)")
    if delta_unit == DeltaUnit.frames and delta != int(delta):
        raise InputError(f"--delta {delta:g}: an RPE delta in frames must be an integer")
    if delta <= 0:
        raise InputError("--delta must be > 0")
    t_est, P_est, f_est, t_gt, P_gt, f_gt = timed_pair(est, gt)
    d = int(delta) if delta_unit == DeltaUnit.frames else float(delta)
    res = evaluate_trajectories(
        t_est,
        P_est,
        t_gt,
        P_gt,
        max_diff=max_diff,
        offset=offset,
        align=align.value,
        delta=d,
        delta_unit=delta_unit.value,  # type: ignore[arg-type]
        rpe_all_pairs=all_pairs,
        rotation_error=rotation_error.value,
    )
    units = metric_units()
    units.update(n_est="", n_gt="", n_matched="", max_diff="s", offset="s", align="")
    table = Table(title=f"{est.name} vs {gt.name}: paper 1 metrics")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key in PAPER1_TABLE_KEYS:
        table.add_row(key, _fmt(key, res[key]), units.get(key, ""))
    console.print(table)
    console.print(
        evo_table(res, f"evo APE / RPE (RPE delta {d:g} {delta_unit.value}, align={align.value})")
    )
    scale = f", scale {res['align_scale']:.6g}" if align == Align.sim3 else ""
    console.print(
        f"matched {int(res['n_matched'])} of {int(res['n_est'])} estimated poses "
        f"({int(res['n_gt'])} ground-truth poses, max_diff={max_diff:g} s, "
        f"align={align.value}{scale})",
        highlight=False,
    )
    hints = frame_hints(
        t_est, P_est, t_gt, P_gt, max_diff=max_diff, offset=offset, align=align.value
    )
    euler, geo = res.get("e_R_euler_peak"), res.get("e_R_max")
    if euler is not None and geo is not None and abs(euler) > 10.0 * geo + 1.0:
        console.print(
            f"  note: e_R_euler_peak {euler:.3g}° against a geodesic e_R_max of {geo:.3g}°: "
            "paper 1's legacy form differences Euler angles one by one, which jump near ±180° "
            "and gimbal lock; e_R_max is the rotation error",
            highlight=False,
        )
    for hint in hints:
        console.print(f"[yellow]warning:[/] {escape(hint)}", highlight=False)

    if json_path is not None:
        doc: dict[str, object] = json_safe(res)
        doc.update(
            est_file=str(est),
            gt_file=str(gt),
            est_format=f_est,
            gt_format=f_gt,
            delta=d,
            rpe_all_pairs=all_pairs,
            rotation_error=rotation_error.value,
            units={k: units.get(k, "") for k in res},
            relnav_version=__version__,
            warnings=hints,
        )
        kept = []
        if json_path.is_file():
            try:
                old = json.loads(json_path.read_text())
            except (OSError, ValueError):
                old = {}
            for k in _ODOMETRY_KEYS:
                if isinstance(old, dict) and old.get(k) is not None and doc.get(k) is None:
                    doc[k] = old[k]
                    kept.append(k)
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
        note = f" (kept {', '.join(kept)} from the existing file)" if kept else ""
        console.print(f"wrote {json_path}{note}", highlight=False)

    if plot_dir is not None:
        from relnav.eval.metrics import apply_alignment, match_trajectories
        from relnav.eval.plots import plot_errors, plot_trajectories

        m = match_trajectories(
            t_est, P_est, t_gt, P_gt, max_diff=max_diff, offset=offset, align=align.value
        )
        name = est.stem
        p1 = plot_trajectories(
            plot_dir / "trajectories.png",
            P_gt,
            {name: apply_alignment(m.T_align, P_est)},
            title=f"{est.name} vs {gt.name} (align={align.value})",
        )
        p2 = plot_errors(plot_dir / "errors.png", m.gt_poses, {name: m.est_poses}, times=m.times)
        console.print(f"wrote {p1} and {p2}", highlight=False)


def register(app: typer.Typer) -> None:
    """Register ``relnav evaluate``."""
    app.command("evaluate")(evaluate)
