"""The navigation suite's grid (``configs/nav-suite.yaml``) runs the sequences of
``benchmarks/nav_suite.py``: the README's table comes from the script and says the grid is the
same suite, so the two must not drift apart."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from relnav.bench.grid import load_grid
from relnav.config import load_yaml

REPO = Path(__file__).resolve().parents[1]


def _nav_suite():
    spec = importlib.util.spec_from_file_location("nav_suite", REPO / "benchmarks" / "nav_suite.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def nav_suite():
    return _nav_suite()


def test_grid_has_every_suite_sequence_and_no_other(nav_suite):
    grid = load_grid(REPO / "configs" / "nav-suite.yaml")
    labels = [s.label for s in grid.scenarios]
    assert len(labels) == len(set(labels))
    assert set(labels) == set(nav_suite.suite()) | set(nav_suite.paper())


def test_grid_presets_match_the_script(nav_suite):
    """Paper 1's presets: same frames and the same data generation (``model_cloud``)."""
    grid = load_grid(REPO / "configs" / "nav-suite.yaml")
    for entry in grid.scenarios:
        if entry.kind != "preset":
            continue
        assert entry.max_frames == 60, entry.label
        resample = entry.label.endswith("-resample")
        assert entry.options == ({"model_cloud": "resample"} if resample else {}), entry.label
        assert f"{entry.preset}{'-resample' if resample else ''}" == entry.label


_NAV = _nav_suite()


@pytest.mark.parametrize("name", sorted({**_NAV.suite(), **_NAV.holdout(), **_NAV.stress()}))
def test_written_scenarios_match_the_script(nav_suite, name):
    """``configs/nav/*.yaml`` (written by ``nav_suite.py --write-configs``) are the script's
    scenarios: same sensor, path, timing, attitude and seed (the target only by name or mesh
    file, whose path the writer makes relative)."""
    written = load_yaml(REPO / "configs" / "nav" / f"{name}.yaml")
    ours = {**nav_suite.suite(), **nav_suite.holdout(), **nav_suite.stress()}[name]
    for key in ("sensors", "frames", "dt", "trajectory", "attitude", "pointing", "seed"):
        a, b = written.get(key), ours.get(key)
        if isinstance(b, dict | list | tuple):
            assert _plain(a) == _plain(b), (name, key)
        else:
            assert a == pytest.approx(b), (name, key)
    target = ours["target"]
    assert written["target"]["scale_to"] == target["scale_to"]
    if "path" in target:
        assert Path(written["target"]["path"]).name == Path(target["path"]).name


def _plain(x):
    """Tuples as lists, floats rounded (YAML round trip)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, float):
        return round(x, 9)
    return x


def test_grid_gives_relnav_the_scripts_mission_input(nav_suite):
    grid = load_grid(REPO / "configs" / "nav-suite.yaml")
    relnav = [m for m in grid.methods if m.method == "relnav"]
    assert len(relnav) == 1 and relnav[0].name == "relnav"
    assert relnav[0].options.keys() == nav_suite.MISSION.keys()
    for key, value in nav_suite.MISSION.items():
        assert relnav[0].options[key] == pytest.approx(value, rel=1e-12)
