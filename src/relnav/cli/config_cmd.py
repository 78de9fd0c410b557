"""``relnav config``: print scenario YAML (default or a preset) and list the presets."""

from __future__ import annotations

from pathlib import Path

import typer

from relnav.cli._common import console

config_app = typer.Typer(
    help="Scenario configuration: dump a YAML that relnav simulate accepts, list presets.",
    no_args_is_help=True,
    rich_markup_mode="rich",
)


@config_app.command("dump")
def dump(
    preset: str | None = typer.Option(
        None, "--preset", help="Dump this preset instead of the default scenario."
    ),
    frames: int | None = typer.Option(None, "--frames", "-n", min=1, help="Number of frames."),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Scenario seed."),
    param: list[str] | None = typer.Option(
        None, "--param", "-p", help="key=value preset option or dotted scenario key."
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file too."),
) -> None:
    """Print a complete scenario YAML (every default filled in).

    Edit it and run it: [bold]relnav config dump --preset sim-orion > my.yaml[/] then
    [bold]relnav simulate my.yaml --out seq[/].
    """
    from relnav.cli._common import parse_options
    from relnav.cli.simulate import build_scenario
    from relnav.sim.scenario import apply_overrides, default_scenario, load_scenario, scenario_yaml

    if preset is None:
        sc = default_scenario()
        updates: dict[str, object] = {}
        if frames is not None:
            updates["frames"] = frames
        if seed is not None:
            updates["seed"] = seed
        params = parse_options(param, flag="--param", nested=False)
        data = apply_overrides(sc.model_dump(mode="json"), {**params, **updates})
        sc = load_scenario(data, check=False)
    else:
        sc = build_scenario(
            preset,
            frames=frames,
            seed=seed,
            params=parse_options(param, flag="--param", nested=False),
        )
    text = scenario_yaml(sc)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    typer.echo(text, nl=False)


def preset_sensor_ranges(name: str) -> str:
    """``"label: sensor preset, R m range"`` of each sensor of scenario preset ``name`` (a
    depth camera's limit is a depth along its boresight), ``"; "``-joined."""
    from relnav.sim.presets import get_preset
    from relnav.sim.sensors import make_sensor

    out = []
    for s in get_preset(name).sensors:
        d = make_sensor(s.preset, **{k: v for k, v in s.overrides.items() if k != "name"})
        what = "depth" if d.kind == "depth_camera" else "range"
        out.append(f"{s.label}: {s.preset}, {d.to_dict()['max_range']:g} m {what}")
    return "; ".join(out)


@config_app.command("list")
def list_presets() -> None:
    """List the scenario presets with their options, sensors (maximum range) and descriptions."""
    from rich.table import Table

    from relnav.sim.presets import available_presets, get_preset, preset_options

    table = Table(title="scenario presets (relnav simulate NAME --out DIR)")
    table.add_column("preset")
    table.add_column("frames", justify="right")
    table.add_column("options")
    table.add_column("sensor: preset, max range")
    table.add_column("description")
    for name in available_presets():
        sc = get_preset(name)
        table.add_row(
            name,
            str(sc.frames),
            ", ".join(preset_options(name)),
            preset_sensor_ranges(name),
            sc.description,
        )
    console.print(table)
    console.print(
        "max range: beyond it a sensor returns nothing (slant range; depth along the boresight "
        "for the Kinect); change it with --param sensors.0.overrides.max_range=M"
    )


def register(app: typer.Typer) -> None:
    """Register ``relnav config dump|list`` on ``app``."""
    app.add_typer(config_app, name="config")
