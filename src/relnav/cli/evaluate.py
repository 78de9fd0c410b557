"""``relnav evaluate``: accuracy of an estimated trajectory against the ground truth (TUM files)."""

from __future__ import annotations

import json
import math
from enum import StrEnum
from pathlib import Path

import typer

from relnav.cli._common import console
from relnav.errors import InputError


class Align(StrEnum):
    """Alignment of the estimate onto the ground truth."""

    none = "none"
    first = "first"
    se3 = "se3"


class RotError(StrEnum):
    """Definition of ``e_R_avg`` / ``e_R_max``."""

    geodesic = "geodesic"
    euler_mean_diff = "euler_mean_diff"


def _read(path: Path, what: str) -> tuple:  # type: ignore[type-arg]
    """Read a TUM file; every failure becomes an :class:`InputError` naming the file."""
    from relnav.errors import RelnavError
    from relnav.io.trajectories import read_tum

    if not path.is_file():
        raise InputError(f"{path}: no such {what} trajectory file")
    try:
        return read_tum(path)
    except RelnavError:
        raise
    except (OSError, ValueError, IndexError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read TUM trajectory: {e}") from None


def _fmt(key: str, value: float | str) -> str:
    if isinstance(value, str):
        return value
    if math.isnan(value):
        return "—"
    if key.startswith("n_") or key == "rpe_delta":
        return f"{int(value)}"
    return f"{value:.6g}"


def evaluate(
    est: Path = typer.Argument(..., help="Estimated trajectory (TUM: t x y z qx qy qz qw)."),
    gt: Path = typer.Argument(..., help="Ground-truth trajectory (TUM)."),
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
        help="none: compare as is; first: make the first poses coincide; se3: Umeyama fit.",
    ),
    delta: int = typer.Option(1, "--delta", min=1, help="RPE frame offset, in frames."),
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
) -> None:
    """Compare an estimated trajectory with the ground truth (Paper 1 metrics, APE, RPE).

    Poses are associated by timestamp (nearest, one-to-one, within --max-diff).

    Angles are reported in degrees, lengths in metres.

    Example: [bold]relnav evaluate run/poses.tum seq/gt_T_target_sensor.tum --json m.json[/]
    """
    from rich.table import Table

    from relnav import __version__
    from relnav.eval.metrics import METRIC_KEYS, evaluate_trajectories, metric_units

    t_est, P_est = _read(est, "estimated")
    t_gt, P_gt = _read(gt, "ground-truth")
    res = evaluate_trajectories(
        t_est,
        P_est,
        t_gt,
        P_gt,
        max_diff=max_diff,
        offset=offset,
        align=align.value,
        delta=delta,
        rpe_all_pairs=all_pairs,
        rotation_error=rotation_error.value,
    )
    units = metric_units()
    units.update(n_est="", n_gt="", n_matched="", max_diff="s", offset="s", align="")
    table = Table(title=f"{est.name} vs {gt.name}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key in (*METRIC_KEYS, "n_matched", "n_est", "n_gt", "align"):
        table.add_row(key, _fmt(key, res[key]), units.get(key, ""))
    console.print(table)
    console.print(
        f"matched {int(res['n_matched'])} of {int(res['n_est'])} estimated poses "
        f"({int(res['n_gt'])} ground-truth poses, max_diff={max_diff:g} s, align={align.value})",
        highlight=False,
    )

    if json_path is not None:
        doc: dict[str, object] = {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in res.items()
        }
        doc.update(
            est_file=str(est),
            gt_file=str(gt),
            delta=delta,
            rpe_all_pairs=all_pairs,
            rotation_error=rotation_error.value,
            units={k: units.get(k, "") for k in res},
            relnav_version=__version__,
        )
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
        console.print(f"wrote {json_path}", highlight=False)

    if plot_dir is not None:
        from relnav.eval.metrics import match_trajectories
        from relnav.eval.plots import plot_errors, plot_trajectories

        m = match_trajectories(
            t_est, P_est, t_gt, P_gt, max_diff=max_diff, offset=offset, align=align.value
        )
        name = est.stem
        p1 = plot_trajectories(
            plot_dir / "trajectories.png",
            P_gt,
            {name: m.T_align @ P_est},
            title=f"{est.name} vs {gt.name} (align={align.value})",
        )
        p2 = plot_errors(plot_dir / "errors.png", m.gt_poses, {name: m.est_poses}, times=m.times)
        console.print(f"wrote {p1} and {p2}", highlight=False)


def register(app: typer.Typer) -> None:
    """Register ``relnav evaluate``."""
    app.command("evaluate")(evaluate)
