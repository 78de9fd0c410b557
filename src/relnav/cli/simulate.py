"""``relnav simulate``: a paper preset or a scenario YAML → a sequence folder."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from relnav.cli._common import console, parse_options, progress_bar
from relnav.errors import ConfigError


def build_scenario(
    source: str,
    *,
    frames: int | None = None,
    max_frames: int | None = None,
    seed: int | None = None,
    target_mesh: Path | None = None,
    scale_to: float | None = None,
    params: dict[str, str] | None = None,
) -> Any:
    """The :class:`Scenario` for a preset name or a YAML path, with the CLI's overrides.

    Preset options (``distance``, ``axis`` …) go to :func:`get_preset`; dotted keys
    (``trajectory.params.loops=3``) override the scenario's fields.
    """
    from relnav.sim.presets import available_presets, get_preset, preset_options
    from relnav.sim.scenario import apply_overrides, load_scenario

    params = dict(params or {})
    dotted = {k: v for k, v in params.items() if "." in k}
    plain = {k: v for k, v in params.items() if "." not in k}
    is_preset = (
        source.lower().replace("_", "-") in available_presets() and not Path(source).is_file()
    )
    if is_preset:
        allowed = preset_options(source)
        bad = sorted(set(plain) - set(allowed))
        if bad:
            raise ConfigError(
                f"preset {source!r}: unknown --param {', '.join(bad)}; preset options: "
                f"{', '.join(allowed) or '(none)'}; scenario fields use dotted keys "
                "(e.g. trajectory.params.loops=3)"
            )
        from relnav.sim.scenario import parse_value

        opts = {k: parse_value(v) for k, v in plain.items()}
        kwargs: dict[str, Any] = {}
        if scale_to is not None:
            kwargs["scale_to"] = scale_to
        sc = get_preset(
            source,
            frames=frames,
            max_frames=max_frames,
            seed=seed,
            target_mesh=None if target_mesh is None else str(target_mesh),
            **kwargs,
            **opts,
        )
        data = sc.model_dump(mode="json")
    else:
        p = Path(source)
        if not p.suffix and not p.exists():
            raise ConfigError(
                f"{source!r} is neither a preset ({', '.join(available_presets())}) "
                "nor a scenario file"
            )
        from relnav.config import load_yaml

        data = load_yaml(p)
        if not data:
            raise ConfigError(f"{p}: empty scenario file (no keys)")
        if plain:
            raise ConfigError(
                f"--param {', '.join(sorted(plain))}: use dotted scenario keys for a YAML "
                "scenario (e.g. trajectory.params.loops=3, sensors.0.overrides.range_sigma=0)"
            )
        if frames is not None:
            data["frames"] = frames
        if max_frames is not None:
            data["max_frames"] = max_frames
        if seed is not None:
            data["seed"] = seed
        if target_mesh is not None or scale_to is not None:
            tgt = dict(data.get("target") or {})
            if target_mesh is not None:
                tgt.pop("name", None)
                tgt["path"] = str(target_mesh)
            if scale_to is not None:
                tgt["scale_to"] = scale_to
            data["target"] = tgt
    if dotted:
        data = apply_overrides(data, dotted)
    return load_scenario(data, label=f"preset {source!r}" if is_preset else source)


def simulate(
    source: str = typer.Argument(
        ..., help="Preset name (relnav config list) or scenario YAML file."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output sequence folder."),
    frames: int | None = typer.Option(
        None, "--frames", "-n", min=1, help="Number of frames along the whole path."
    ),
    max_frames: int | None = typer.Option(
        None,
        "--max-frames",
        min=1,
        help="Simulate only the first N frames (keeps the scenario's per-frame motion).",
    ),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Scenario seed."),
    target_mesh: Path | None = typer.Option(
        None, "--target-mesh", help="Mesh file replacing the scenario's target."
    ),
    scale_to: float | None = typer.Option(
        None, "--scale-to", help="Rescale the target's longest side to this length, m."
    ),
    param: list[str] | None = typer.Option(
        None,
        "--param",
        "-p",
        help="key=value: a preset option (distance=2.4, axis=y) or a dotted scenario key "
        "(trajectory.params.loops=3, sensors.0.overrides.range_sigma=0). Repeatable.",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace scans already in the output folder."
    ),
) -> None:
    """Simulate a sensor around a target and write a sequence folder.

    Presets: real-fb, real-curved, sim-eoi, sim-helical, sim-voyager, sim-orion, sim-bennu
    (Paper 1); li-rotating (Paper 2: Kinect + LIDAR, options distance and axis); dense-flash
    (option resolution), dense-kinect, dense-hdl64 (dense sensors for the scale benchmark).

    Examples: [bold]relnav simulate sim-voyager --out seq[/];
    [bold]relnav simulate li-rotating --out li --param distance=2.4 --param axis=y[/];
    [bold]relnav simulate configs/scenario_cw_tumbling.yaml --out cw --frames 20[/]
    """
    from rich.table import Table

    from relnav.sim.scenario import simulate as run

    sc = build_scenario(
        source,
        frames=frames,
        max_frames=max_frames,
        seed=seed,
        target_mesh=target_mesh,
        scale_to=scale_to,
        params=parse_options(param, flag="--param", nested=False),
    )
    n_sim = sc.frames if sc.max_frames is None else min(sc.frames, sc.max_frames)
    with progress_bar() as bar:
        task = bar.add_task(f"simulate {sc.name}", total=n_sim)
        summary = run(
            sc,
            out,
            overwrite=overwrite,
            progress=lambda done, total: bar.update(task, completed=done),
        )
    table = Table(title=f"{sc.name}: {n_sim} frames, seed {sc.seed} → {out}")
    for col, just in (
        ("sensor", "left"),
        ("folder", "left"),
        ("frames", "right"),
        ("mean pts", "right"),
        ("min pts", "right"),
        ("max pts", "right"),
        ("path m", "right"),
        ("empty frames", "right"),
    ):
        table.add_column(col, justify=just)  # type: ignore[arg-type]
    for s in summary.sensors:
        table.add_row(
            s.name,
            s.folder,
            str(s.frames),
            f"{s.mean_points:.1f}",
            str(s.min_points),
            str(s.max_points),
            f"{_target_frame_path(out, s.folder, s.path_length_m):.2f}",
            str(s.empty_frames),
        )
    console.print(table)
    console.print("path m: the sensor's path relative to the target (the ground truth written)")
    t = summary.timings
    console.print(
        f"time {t.get('total', 0.0):.2f} s (scan {t.get('scan', 0.0):.2f} s, "
        f"write {t.get('write', 0.0):.2f} s, setup {t.get('setup', 0.0):.2f} s)"
    )


def _target_frame_path(out: Path, folder: str, fallback: float) -> float:
    """Length of the sensor's path relative to the target (the written ground truth), metres.

    A rotating target seen by a static sensor (``li-rotating``) has a zero world-frame path but
    a real path in the target frame, which is what odometry estimates and T_error divides by.
    """
    import numpy as np

    from relnav.io.sequences import ScanSequence

    sensor = None if folder == "scans" else folder[len("scans_") :]
    try:
        gt = ScanSequence(out, sensor=sensor).gt_poses
    except Exception:  # the summary must not fail on an unreadable file
        return fallback
    if gt is None or len(gt) < 2:
        return fallback
    return float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())


def register(app: typer.Typer) -> None:
    """Register ``relnav simulate`` on ``app``."""
    app.command("simulate")(simulate)
