"""Every simulated sensor has a maximum range (issue 42): beyond it the scan is empty, within it
nothing changes, and a scenario that never sees the target says so in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import ConfigError
from relnav.geometry.se3 import from_rt
from relnav.sim.sensors import available_sensors, make_sensor
from relnav.sim.sensors.surface import HPR_MAX_RANGE_M
from relnav.sim.targets import get_target


def _look_at(position: tuple[float, float, float]) -> np.ndarray:
    """T_target_sensor of a sensor at ``position`` looking at the origin (+x), z up."""
    p = np.asarray(position, dtype=float)
    x = -p / np.linalg.norm(p)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), p)


@pytest.fixture(scope="module")
def voyager():  # type: ignore[no-untyped-def]
    return get_target("voyager")


def test_every_sensor_preset_has_a_finite_max_range() -> None:
    for name in available_sensors():
        s = make_sensor(name)
        assert 0 < s.max_range < math.inf, name
        assert 0 < s.to_dict()["max_range"] <= s.max_range  # depth camera: depth, not slant
    assert make_sensor("surface-hpr").max_range == HPR_MAX_RANGE_M == 3000.0


@pytest.mark.parametrize("mode", ["fixed", "resample"])
def test_hpr_sensor_beyond_range_is_empty_within_unchanged(voyager, mode: str) -> None:  # type: ignore[no-untyped-def]
    kw = dict(n_points=150, model_cloud=mode, noise_sigma=0.01, model_views=60)
    limited = make_sensor("surface-hpr", **kw)
    unlimited = make_sensor("surface-hpr", **kw, max_range=math.inf)
    near = _look_at((40.0, 15.0, 8.0))
    a = limited.scan_detailed(voyager, near, np.random.default_rng(3))
    b = unlimited.scan_detailed(voyager, near, np.random.default_rng(3))
    assert len(a.points) > 50
    np.testing.assert_array_equal(a.points, b.points)  # within range: byte-identical
    np.testing.assert_array_equal(a.face_index, b.face_index)
    for dist in (HPR_MAX_RANGE_M + 100.0, 1e7):  # just beyond and at 10 000 km
        far = _look_at((dist, 0.0, 0.0))
        assert limited.scan(voyager, far, np.random.default_rng(3)).shape == (0, 3)
    # without a limit the sensor still "sees" the probe at 10 000 km (what the issue found)
    assert len(unlimited.scan(voyager, _look_at((1e7, 0.0, 0.0)), np.random.default_rng(3)))


def test_ray_sensor_beyond_range_is_empty(voyager) -> None:  # type: ignore[no-untyped-def]
    flash = make_sensor("goldeneye", rows=32, cols=32)
    assert len(flash.scan(voyager, _look_at((30.0, 0.0, 0.0)), np.random.default_rng(0))) > 0
    far = _look_at((flash.max_range + 50.0, 0.0, 0.0))
    assert flash.scan(voyager, far, np.random.default_rng(0)).shape == (0, 3)


@pytest.mark.parametrize("bad", [0.0, -5.0, "far", float("nan")])
def test_max_range_is_validated(bad: object) -> None:
    with pytest.raises(ConfigError, match="max_range"):
        make_sensor("surface-hpr", max_range=bad)


def test_scenario_out_of_range_is_one_error_line(tmp_path) -> None:  # type: ignore[no-untyped-def]
    r = CliRunner().invoke(
        app,
        [
            "simulate",
            "sim-voyager",
            "--max-frames",
            "2",
            "--out",
            str(tmp_path / "far"),
            "--param",
            "trajectory.params.semi_major=1e7",
            "--param",
            "trajectory.params.semi_minor=5e6",
        ],
    )
    assert r.exit_code == 1
    msg = str(r.exception)
    assert "saw nothing of the target" in msg and "max_range 3000 m" in msg


def test_config_list_names_each_presets_sensor_range() -> None:
    from relnav.cli.config_cmd import preset_sensor_ranges

    assert preset_sensor_ranges("sim-voyager") == "lidar: surface-hpr, 3000 m range"
    assert preset_sensor_ranges("real-fb") == "vlp16: vlp16, 100 m range"
    assert preset_sensor_ranges("li-rotating") == (
        "kinect: kinect1, 6 m depth; lidar: hdl64, 120 m range"
    )
    r = CliRunner().invoke(app, ["config", "list"])
    assert r.exit_code == 0, r.output
    assert "max range" in r.output and "sensors.0.overrides.max_range" in " ".join(r.output.split())
    assert "surface-hpr" in r.output and "3000" in r.output  # the cells, however wrapped
