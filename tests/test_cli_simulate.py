"""CLI smoke tests: relnav simulate | view | config."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import ConfigError, InputError
from relnav.io.sequences import ScanSequence
from relnav.sim.scenario import load_scenario

REPO = Path(__file__).resolve().parents[1]
runner = CliRunner()


def test_simulate_preset_and_view(tmp_path):
    out = tmp_path / "seq"
    r = runner.invoke(app, ["simulate", "sim-bennu", "--out", str(out), "--frames", "3"])
    assert r.exit_code == 0, r.output
    assert "mean" in r.output and "lidar" in r.output
    seq = ScanSequence(out)
    assert len(seq) == 3 and seq.gt_poses.shape == (3, 4, 4)
    sc = load_scenario(out / "scenario.yaml")
    assert sc.name == "sim-bennu" and sc.frames == 3
    png = tmp_path / "v.png"
    r = runner.invoke(app, ["view", str(out), "--out", str(png), "--frames", "2"])
    assert r.exit_code == 0, r.output
    assert png.stat().st_size > 10_000
    # rerun into the same folder: refused without --overwrite
    r = runner.invoke(app, ["simulate", "sim-bennu", "--out", str(out), "--frames", "2"])
    assert isinstance(r.exception, InputError)
    r = runner.invoke(
        app, ["simulate", "sim-bennu", "--out", str(out), "--frames", "2", "--overwrite"]
    )
    assert r.exit_code == 0, r.output
    assert len(ScanSequence(out)) == 2


def test_simulate_li_rotating_params(tmp_path):
    out = tmp_path / "li"
    r = runner.invoke(
        app,
        [
            "simulate",
            "li-rotating",
            "--out",
            str(out),
            "-n",
            "2",
            "--param",
            "distance=2.4",
            "--param",
            "axis=y",
            "--seed",
            "5",
        ],
    )
    assert r.exit_code == 0, r.output
    sc = load_scenario(out / "scenario.yaml")
    assert sc.seed == 5 and sc.attitude.axis == "y"
    assert sc.trajectory.params["position"] == [-2.4, 0.0, 0.0]
    assert ScanSequence.sensors(out) == ["", "lidar"]
    r = runner.invoke(app, ["view", str(out), "--sensor", "lidar", "-o", str(tmp_path / "l.png")])
    assert r.exit_code == 0, r.output


def test_simulate_bad_params(tmp_path):
    r = runner.invoke(app, ["simulate", "sim-orion", "--out", str(tmp_path), "-p", "distance=3"])
    assert isinstance(r.exception, ConfigError) and "distance" in str(r.exception)
    r = runner.invoke(app, ["simulate", "no-such-preset", "--out", str(tmp_path)])
    assert isinstance(r.exception, ConfigError) and "preset" in str(r.exception)
    r = runner.invoke(app, ["simulate", "sim-orion", "--out", str(tmp_path), "-p", "oops"])
    assert isinstance(r.exception, ConfigError)


def test_config_dump_round_trip(tmp_path):
    r = runner.invoke(app, ["config", "dump"])
    assert r.exit_code == 0, r.output
    d = yaml.safe_load(r.output)
    assert load_scenario(d).name == "default"
    f = tmp_path / "orion.yaml"
    r = runner.invoke(app, ["config", "dump", "--preset", "sim-orion", "--out", str(f)])
    assert r.exit_code == 0, r.output
    assert f.read_text() == r.output
    # the dumped preset runs, and dotted --param keys override it
    out = tmp_path / "seq"
    r = runner.invoke(
        app,
        [
            "simulate",
            str(f),
            "--out",
            str(out),
            "-n",
            "2",
            "-p",
            "sensors.0.overrides.n_points=100",
            "--scale-to",
            "3.0",
        ],
    )
    assert r.exit_code == 0, r.output
    sc = load_scenario(out / "scenario.yaml")
    assert sc.sensors[0].overrides["n_points"] == 100 and sc.target.scale_to == 3.0
    r = runner.invoke(app, ["config", "list"])
    assert r.exit_code == 0 and "li-rotating" in r.output


def test_example_config_simulates(tmp_path):
    cfg = REPO / "configs" / "scenario_cw_tumbling.yaml"
    out = tmp_path / "cw"
    r = runner.invoke(app, ["simulate", str(cfg), "--out", str(out), "--frames", "3"])
    assert r.exit_code == 0, r.output
    seq = ScanSequence(out)
    assert len(seq) == 3 and min(len(seq[i]) for i in range(3)) > 100
    sc = load_scenario(out / "scenario.yaml")
    assert sc.attitude.kind == "tumble" and sc.trajectory.kind == "cw"
    assert np.isfinite(seq.gt_poses).all()


def test_subprocess_bad_yaml_one_line_error(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nframes: 0\nsensors:\n  - preset: vlp16\n    colour: red\n")
    exe = Path(sys.executable).parent / "relnav"
    if not exe.exists():
        pytest.skip("relnav console script not installed")
    p = subprocess.run(
        [str(exe), "simulate", str(bad), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode != 0
    assert "Traceback" not in p.stderr + p.stdout
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, p.stderr
    assert "error" in lines[0] and "frames" in lines[0] and "colour" in lines[0]


def test_simulate_help_lists_every_preset():
    from relnav.sim.presets import available_presets

    r = CliRunner(env={"COLUMNS": "200"}).invoke(app, ["simulate", "--help"])
    assert r.exit_code == 0, r.output
    for name in available_presets():
        assert name in r.output, name


def test_param_numbers_in_exponent_form_are_numbers(tmp_path):
    """YAML 1.1 reads 1e1 as a string: --param values still reach the scenario as numbers."""
    from relnav.cli.simulate import build_scenario
    from relnav.sim.scenario import parse_value

    assert parse_value("1e1") == 10.0 and isinstance(parse_value("1e1"), float)
    assert parse_value("1_000") == 1000 and parse_value("2") == 2
    assert parse_value("y") == "y" and parse_value("[1, 2e0]") == [1, 2.0]
    sc = build_scenario("sim-eoi", max_frames=2, params={"trajectory.params.semi_minor": "1e1"})
    assert sc.trajectory.params["semi_minor"] == 10.0
    sc = build_scenario("li-rotating", max_frames=2, params={"distance": "2.4e0"})
    assert sc.model_dump()["frames"] >= 2
    out = tmp_path / "seq"
    r = runner.invoke(
        app,
        [
            "simulate",
            "sim-eoi",
            "--out",
            str(out),
            "--max-frames",
            "2",
            "--param",
            "trajectory.params.semi_minor=1e1",
        ],
    )
    assert r.exit_code == 0, r.output
    assert load_scenario(out / "scenario.yaml").trajectory.params["semi_minor"] == 10.0
