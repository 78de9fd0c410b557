"""The navigation suite is defined once, in YAML: the grids ``configs/nav-<group>.yaml`` list
each group's sequences and ``configs/nav/<name>.yaml`` is each sequence's scenario.
:mod:`relnav.bench.nav_suite` reads them; these tests check that every file is a valid scenario
in exactly one group, that the groups hold the sequences the published tables were made on, and
that the loader fails clearly on a bad folder."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pytest

from relnav.bench import nav_suite
from relnav.bench.grid import load_grid
from relnav.config import load_yaml
from relnav.errors import ConfigError
from relnav.sim.scenario import Scenario

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"

# the sequences behind README's and docs/navigator.md's tables: a change here is a change of
# the published benchmark, not a refactoring
EXPECTED = {
    "suite": [
        "eros-ellipse-64",
        "aura-ellipse-64",
        "iridium-helical-64",
        "orion-inclined-64",
        "envisat-tumble-64",
        "voyager-ellipse-128",
        "asteroid-helical-128",
    ],
    "holdout": [
        "comet-ellipse-64",
        "voyager-helical-64",
        "aura-tumble-64",
        "capsule-ellipse-128",
        "orion-tilt60-64",
        "capsule-ellipse-64",
        "orion-ellipse-64",
        "aura-inclined-64",
        "asteroid-ellipse-64",
        "voyager-inclined-64",
    ],
    "stress": [
        "envisat-jitter0",
        "envisat-jitter0.25",
        "envisat-jitter0.5",
        "envisat-jitter1",
        "envisat-jitter2",
        "envisat-walk0.5",
        "voyager-sparse30",
        "voyager-approach",
        "aura-farstart",
    ],
    "tumbling-holdout": [
        "voyager-tumble-64",
        "iridium-tumble-64",
        "orion-tumble-64",
        "eros-tumble-64",
        "capsule-tumble-64",
        "comet-tumble-64",
        "probe-tumble-64",
    ],
    "jitter-holdout": ["aura-jitter1", "aura-jitter2", "eros-jitter2", "voyager-walk1"],
    "manoeuvre": [
        "eros-cw-burn0.05",
        "eros-cw-burn0.1",
        "eros-cw-burn0.2",
        "aura-vbar-burn0.05",
        "aura-vbar-burn0.1",
        "aura-vbar-burn0.2",
        "aura-vbar-coast",
        "envisat-vbar-burn0.1",
    ],
    "jitter-check": ["comet-jitter1", "voyager-jitter1.5", "aura-walk0.5", "eros-jitter0.75"],
    "jitter-learning": ["iridium-jitter1.5", "asteroid-jitter1", "comet-walk1", "eros-jitter1.5"],
    "jitter-choice": ["orion-jitter1", "probe-jitter1.5", "iridium-walk1", "aura-jitter1.5"],
}


def test_groups_list_the_expected_sequences_in_order():
    for name, expected in EXPECTED.items():
        assert list(nav_suite.group(name)) == expected, name
    assert list(nav_suite.suite()) == EXPECTED["suite"]
    assert list(nav_suite.holdout()) == EXPECTED["holdout"]
    assert list(nav_suite.stress()) == EXPECTED["stress"]
    assert list(nav_suite.tumbling_holdout()) == EXPECTED["tumbling-holdout"]
    assert list(nav_suite.jitter_holdout()) == EXPECTED["jitter-holdout"]
    assert nav_suite.sequence_names(jittered=True) == EXPECTED["jitter-holdout"]
    assert list(nav_suite.manoeuvre()) == EXPECTED["manoeuvre"]
    assert nav_suite.sequence_names(manoeuvred=True) == EXPECTED["manoeuvre"]
    assert list(nav_suite.jitter_check()) == EXPECTED["jitter-check"]
    assert nav_suite.sequence_names(named="jitter-check") == EXPECTED["jitter-check"]


@pytest.mark.parametrize(
    ("flags", "group"),
    [
        ([], None),
        (["--holdout"], "holdout"),
        (["--stress"], "stress"),
        (["--jitter-holdout"], "jitter-holdout"),
        (["--manoeuvre"], "manoeuvre"),
        (["--group", "jitter-check"], "jitter-check"),
        (["--group", "jitter-learning"], "jitter-learning"),
        (["--group", "jitter-choice"], "jitter-choice"),
        (["--group", "holdout"], "holdout"),
    ],
)
def test_the_benchmarks_group_flags_select_that_group(flags, group):
    # every navigation benchmark takes add_sequence_arguments' flags: each must be honoured
    p = argparse.ArgumentParser()
    nav_suite.add_sequence_arguments(p)
    names = nav_suite.selected_names(p.parse_args(flags))
    expected = EXPECTED[group] if group else [*nav_suite.suite(), *nav_suite.paper()]
    assert names == expected
    only = nav_suite.selected_names(p.parse_args([*flags, "--only", names[-1]]))
    assert names[-1] in only and set(only) <= set(names)


def test_every_scenario_file_is_valid_and_in_exactly_one_group():
    files = sorted(p.stem for p in (CONFIGS / "nav").glob("*.yaml"))
    grouped = [n for names in EXPECTED.values() for n in names]
    assert sorted(grouped) == files  # no orphan file, no sequence without its file
    for stem in files:
        sc = load_yaml(CONFIGS / "nav" / f"{stem}.yaml")
        assert sc["name"] == stem
        Scenario.model_validate(nav_suite.group(_group_of(stem))[stem])


def _group_of(name: str) -> str:
    return next(g for g, names in EXPECTED.items() if name in names)


def test_stress_group_has_the_documented_jitter_levels():
    stress = nav_suite.stress()
    for j in nav_suite.JITTER_DEG:
        sc = stress[f"envisat-jitter{j:g}"]
        assert sc["pointing"]["jitter_deg"] == pytest.approx(j)
        assert sc["pointing"]["attitude_sigma_deg"] == pytest.approx(nav_suite.ATTITUDE_SIGMA)


def test_paper_presets_are_the_grid_ones_each_beside_its_resample_twin():
    paper = nav_suite.paper()
    expected = [f"{p}{s}" for p in nav_suite.PAPER_PRESETS for s in ("", "-resample")]
    assert list(paper) == expected
    for name, sc in paper.items():
        assert sc["name"] == name
        assert sc["max_frames"] == 60
    grid = load_grid(CONFIGS / "nav-suite.yaml")
    for entry in grid.scenarios:
        if entry.kind == "preset":
            resample = entry.label.endswith("-resample")
            assert entry.options == ({"model_cloud": "resample"} if resample else {})


@pytest.mark.parametrize("group", nav_suite.GROUPS)
def test_every_grid_gives_relnav_the_mission_input(group):
    grid = load_grid(CONFIGS / f"nav-{group}.yaml")
    relnav = [m for m in grid.methods if m.method == "relnav"]
    assert len(relnav) == 1 and relnav[0].name == "relnav"
    assert relnav[0].options.keys() == nav_suite.MISSION.keys()
    assert nav_suite.MISSION["orbit.mean_motion"] == pytest.approx(2 * math.pi / 5553.6)
    for key, value in nav_suite.MISSION.items():
        assert relnav[0].options[key] == pytest.approx(value, rel=1e-12)


def _tmp_configs(tmp_path: Path, scenario: str) -> Path:
    (tmp_path / "nav").mkdir(parents=True)
    (tmp_path / "nav" / "one.yaml").write_text(scenario, encoding="utf-8")
    for g in nav_suite.GROUPS:
        (tmp_path / f"nav-{g}.yaml").write_text(
            f"schema_version: 1\nname: nav-{g}\nscenarios:\n  - {{scenario: nav/one.yaml}}\n"
            "methods: [icp-point]\n",
            encoding="utf-8",
        )
    return tmp_path


def test_a_missing_mesh_falls_back_to_its_procedural_stand_in(tmp_path, monkeypatch):
    scenario = "name: one\ntarget: {path: ../no/such/eros.ply, scale_to: 9.0}\nformat: npy\n"
    monkeypatch.setenv("RELNAV_CONFIGS", str(_tmp_configs(tmp_path / "c", scenario)))
    assert nav_suite.configs_dir() == tmp_path / "c"
    assert nav_suite.suite()["one"]["target"] == {"name": "asteroid", "scale_to": 9.0}


def test_bad_folders_and_files_raise_config_errors(tmp_path, monkeypatch):
    with pytest.raises(ConfigError, match="unknown navigation group"):
        nav_suite.group("nope")
    bad = "name: one\nframes: -3\n"
    monkeypatch.setenv("RELNAV_CONFIGS", str(_tmp_configs(tmp_path / "c", bad)))
    with pytest.raises(ConfigError, match="frames"):
        nav_suite.suite()
    misnamed = "name: two\n"
    monkeypatch.setenv("RELNAV_CONFIGS", str(_tmp_configs(tmp_path / "d", misnamed)))
    with pytest.raises(ConfigError, match="is not 'one'"):
        nav_suite.suite()
    unknown_mesh = "name: one\ntarget: {path: ../no/such/thing.ply}\n"
    monkeypatch.setenv("RELNAV_CONFIGS", str(_tmp_configs(tmp_path / "e", unknown_mesh)))
    with pytest.raises(ConfigError, match="no procedural stand-in"):
        nav_suite.suite()
