"""Issue 12 defects, end to end through the CLI: install hints, presets, run.json, slips."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from relnav.cli.main import app, main
from relnav.errors import ConfigError, RelnavError
from relnav.odometry.presets import METHOD_PRESETS
from relnav.pipeline import resolve_method

runner = CliRunner()


@pytest.fixture(scope="module")
def seq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out = tmp_path_factory.mktemp("eco") / "seq"
    simulate(get_preset("sim-voyager", max_frames=5, seed=1), out)
    return out


@pytest.fixture
def wide(monkeypatch: pytest.MonkeyPatch) -> None:
    """A wide CLI console, so long cells are not wrapped across lines."""
    from relnav.cli._common import console

    monkeypatch.setattr(console, "width", 250)


def _main(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture, *args: str) -> str:
    """Run the real entry point (the one-line error printer) and return stdout + stderr."""
    monkeypatch.setattr(sys, "argv", ["relnav", *args])
    with pytest.raises(SystemExit) as e:
        main()
    assert e.value.code not in (0, None)
    cap = capsys.readouterr()
    return cap.out + cap.err


# --- defect 1: install hints keep the extra's name ----------------------------------------


def test_error_line_keeps_the_extra_in_brackets(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "kiss_icp", None)  # as on a base install
    text = _main(monkeypatch, capsys, "odometry", str(tmp_path), "-m", "kiss-icp", "-o", "x")
    assert "pip install 'relnav[baselines]'" in text
    assert "Traceback" not in text and "0/" not in text  # before any progress bar


def test_methods_table_and_help_keep_the_extra(monkeypatch, wide):
    import relnav.cli.methods as methods_mod

    monkeypatch.setattr(methods_mod, "_extra_available", lambda extra, method="": extra is None)
    res = runner.invoke(app, ["methods"])
    assert res.exit_code == 0, res.output
    assert "pip install 'relnav[baselines]'" in res.output
    res = runner.invoke(app, ["view", "--help"], terminal_width=200)
    assert "[viz]" in res.output
    res = runner.invoke(app, ["odometry", "--help"], terminal_width=200)
    assert "[viz]" in res.output


# --- defect 2: named presets ----------------------------------------------------------------


def test_presets_are_listed_with_their_expansion_and_usable(seq, tmp_path, wide):
    res = runner.invoke(app, ["methods"])
    assert res.exit_code == 0, res.output
    for name, p in METHOD_PRESETS.items():
        assert name in res.output
        for part in p.expansion().split(" -O "):  # one "-O key=value" per line
            assert part in res.output, part
    assert "-O grouper_options.seeds=all" in METHOD_PRESETS["extended"].expansion()
    out = tmp_path / "ext"
    res = runner.invoke(app, ["odometry", str(seq), "-m", "extended", "-o", str(out)])
    assert res.exit_code == 0, res.output
    info = json.loads((out / "run.json").read_text())
    assert info["preset"] == "extended" and info["method"] == "feature:hods+gcc+svd"
    assert info["options"]["method_options"]["gate_rotation_deg"] == 15.0


def test_user_options_override_a_preset():
    method, opts, preset = resolve_method("extended", {"grouper_options": {"eps": 3}})
    assert preset == "extended" and method == "feature:hods+gcc+svd"
    assert opts["grouper_options"] == {"seeds": "all", "eps": 3}
    assert METHOD_PRESETS["extended"].options["grouper_options"] == {"seeds": "all"}


# --- defect 7: did you mean, before the progress bar -----------------------------------------


def test_unknown_method_suggests_and_fails_before_work(seq, tmp_path):
    with pytest.raises(ConfigError, match="did you mean 'icp-point'"):
        resolve_method("icp_point")
    res = runner.invoke(app, ["odometry", str(seq), "-m", "icp_point", "-o", str(tmp_path / "o")])
    assert isinstance(res.exception, RelnavError) and "did you mean" in str(res.exception)
    assert "0/" not in res.output and not (tmp_path / "o").exists()
    res = runner.invoke(app, ["demo", "-o", str(tmp_path / "d"), "-m", "icp_point"])
    assert isinstance(res.exception, RelnavError) and not (tmp_path / "d").exists()


def test_li_rotating_path_length_is_the_target_frame_path(tmp_path):
    from relnav.cli.simulate import _target_frame_path
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    s = simulate(get_preset("li-rotating", max_frames=3), tmp_path / "li")
    assert s.sensors[0].path_length_m == pytest.approx(0.0, abs=1e-9)  # world frame: static
    assert _target_frame_path(tmp_path / "li", "scans", 0.0) > 0.1


# --- defect 3: runs describe themselves; evaluate keeps odometry's numbers -----------------


def test_run_json_and_evaluate_does_not_clobber_odometry_metrics(seq, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["odometry", str(seq), "-m", "icp-point", "-o", str(out)])
    assert res.exit_code == 0, res.output
    info = json.loads((out / "run.json").read_text())
    assert info["method"] == "icp-point" and info["preset"] is None
    assert info["seed"] == 1  # from the simulated scenario
    assert info["sequence"]["path"] == str(seq) and info["sequence"]["frames"] == 5
    h1 = info["sequence"]["content_hash"]
    assert {"relnav", "numpy", "scipy", "numba"} <= set(info["versions"])
    assert info["timings"]["median_frame_ms"] > 0 and info["flags"]["frames"] == 5
    assert set(info["outputs"]) >= {"estimate.tum", "diagnostics.csv", "metrics.json", "run.json"}
    before = json.loads((out / "metrics.json").read_text())
    assert before["time_ms"] > 0

    # the Quickstart's evaluate into the same metrics.json keeps odometry's time and flags
    gt = seq / "gt_T_target_sensor.tum"
    args = ["evaluate", str(out / "estimate.tum"), str(gt), "--json", str(out / "metrics.json")]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    after = json.loads((out / "metrics.json").read_text())
    assert after["time_ms"] == before["time_ms"]
    assert after["flagged_frames"] == before["flagged_frames"]
    assert after["e_T_avg"] == pytest.approx(before["e_T_avg"], abs=1e-12)

    # same inputs → same content hash; a changed scan → another hash
    runner.invoke(app, ["odometry", str(seq), "-m", "icp-point", "-o", str(tmp_path / "r2")])
    assert json.loads((tmp_path / "r2" / "run.json").read_text())["sequence"]["content_hash"] == h1


# --- relnav compare ------------------------------------------------------------------------------


def test_compare_runs_on_the_sequence_ground_truth_equals_evaluate_and_evo(seq, tmp_path):
    runs = []
    for m in ("icp-point", "feature:hods+gcc+svd"):
        out = tmp_path / m.replace(":", "_").replace("+", "_")
        res = runner.invoke(app, ["odometry", str(seq), "-m", m, "-o", str(out)])
        assert res.exit_code == 0, res.output
        runs.append(out)
    doc = tmp_path / "cmp" / "compare.json"
    args = ["compare", *map(str, runs), "--json", str(doc), "--plot-dir", str(tmp_path / "cmp")]
    res = runner.invoke(app, [*args, "--align", "sim3", "--delta", "2"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "cmp" / "compare.png").is_file()
    assert (tmp_path / "cmp" / "trajectories.png").is_file()
    got = json.loads(doc.read_text())
    assert set(got["runs"]) == {"icp-point", "feature:hods+gcc+svd"}
    gt = seq / "gt_T_target_sensor.tum"
    for run, label in zip(runs, ("icp-point", "feature:hods+gcc+svd"), strict=True):
        ev = tmp_path / f"{run.name}.json"
        args = ["evaluate", str(run / "estimate.tum"), str(gt), "--json", str(ev)]
        assert runner.invoke(app, [*args, "--align", "sim3", "--delta", "2"]).exit_code == 0
        ref = json.loads(ev.read_text())
        for key in ("ape_trans_rmse", "ape_rot_median", "rpe_trans_max", "rpe_rot_std", "e_RT"):
            assert got["runs"][label][key] == pytest.approx(ref[key], abs=1e-12), key

    # against evo itself, on the TUM files (--gt given, files instead of folders)
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.core import sync
    from evo.tools import file_interface

    est = runs[0] / "estimate.tum"
    ref_traj = file_interface.read_tum_trajectory_file(str(gt))
    est_traj = file_interface.read_tum_trajectory_file(str(est))
    ref_traj, est_traj = sync.associate_trajectories(ref_traj, est_traj, max_diff=0.01)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref_traj, est_traj))
    res = runner.invoke(app, ["compare", str(est), "--gt", str(gt), "--json", str(doc)])
    assert res.exit_code == 0, res.output
    mine = json.loads(doc.read_text())["runs"]["estimate"]
    for stat, value in ape.get_all_statistics().items():
        assert mine[f"ape_trans_{stat}"] == pytest.approx(value, rel=1e-9, abs=1e-12), stat


def test_compare_refuses_runs_of_different_sequences(seq, tmp_path):
    a = tmp_path / "a.tum"
    a.write_text((seq / "gt_T_target_sensor.tum").read_text())
    res = runner.invoke(app, ["compare", str(a)])
    assert isinstance(res.exception, RelnavError) and "give --gt" in str(res.exception)
    res = runner.invoke(app, ["compare", str(tmp_path / "nope")])
    assert isinstance(res.exception, RelnavError) and "no such" in str(res.exception)


# --- track writes TUM, fuse runs over a sequence against its ground truth -----------------------


@pytest.fixture(scope="module")
def li_seq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out = tmp_path_factory.mktemp("li") / "li"
    simulate(get_preset("li-rotating", max_frames=3), out)
    return out


def test_fuse_over_a_sequence_against_its_ground_truth(li_seq, tmp_path):
    out = tmp_path / "fz"
    res = runner.invoke(app, ["fuse", str(li_seq), "--out", str(out), "--max-frames", "2"])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "fuse.json").read_text())
    assert doc["pairs"] == 2 and doc["has_ground_truth"] and doc["lidar"] == "scans_lidar"
    rows = (out / "fuse.csv").read_text().splitlines()
    assert len(rows) == 3 and "rot_err_deg" in rows[0]
    assert (out / "fuse_errors.png").is_file()
    info = json.loads((out / "run.json").read_text())
    assert info["command"] == "fuse" and info["method"] == "cga-sphere"
    assert info["flags"]["pairs"] == 2 and info["sequence"]["content_hash"]
    # paper 2's registration on its own scene: degrees and centimetres, not a wild pose
    assert doc["ok"] >= 1
    assert doc["rotation_error_deg"]["max"] < 5.0
    assert doc["translation_error_m"]["max"] < 0.3


def test_track_writes_the_target_pose_as_tum(li_seq, tmp_path):
    from relnav.io.trajectories import read_tum

    out = tmp_path / "tr"
    res = runner.invoke(app, ["track", str(li_seq), "--out", str(out), "--no-plots"])
    assert res.exit_code == 0, res.output
    t, P = read_tum(out / "target_pose.tum")
    t_gt, P_gt = read_tum(out / "target_pose_gt.tum")
    assert len(t) == len(t_gt) == 3
    assert abs(P[-1, :3, 3] - P_gt[-1, :3, 3]).max() < 0.5  # the target's position, metres
    doc = tmp_path / "e.json"
    args = ["evaluate", str(out / "target_pose.tum"), str(out / "target_pose_gt.tum")]
    assert runner.invoke(app, [*args, "--json", str(doc)]).exit_code == 0
    assert json.loads(doc.read_text())["n_matched"] == 3
    info = json.loads((out / "run.json").read_text())
    assert info["command"] == "track" and info["method"].startswith("ukf")
    assert "target_pose.tum" in info["outputs"] and info["flags"]["frames"] == 3


def test_evaluate_mixes_tum_and_kitti_files(seq, tmp_path):
    from relnav.io.trajectories import read_tum, write_kitti

    t, P = read_tum(seq / "gt_T_target_sensor.tum")
    write_kitti(tmp_path / "gt_kitti.txt", P)  # no times.txt: borrows the TUM file's times
    doc = tmp_path / "e.json"
    args = ["evaluate", str(seq / "gt_T_target_sensor.tum"), str(tmp_path / "gt_kitti.txt")]
    res = runner.invoke(app, [*args, "--json", str(doc)])
    assert res.exit_code == 0, res.output
    e = json.loads(doc.read_text())
    assert e["gt_format"] == "kitti" and e["n_matched"] == len(t)
    assert e["e_T_max"] < 1e-9
    write_kitti(tmp_path / "short.txt", P[:3])
    res = runner.invoke(
        app, ["evaluate", str(seq / "gt_T_target_sensor.tum"), str(tmp_path / "short.txt")]
    )
    assert isinstance(res.exception, RelnavError) and "times.txt" in str(res.exception)
    (tmp_path / "bad.txt").write_text("1 2 3 4 5\n")
    res = runner.invoke(app, ["evaluate", str(tmp_path / "bad.txt"), str(tmp_path / "short.txt")])
    assert isinstance(res.exception, RelnavError) and "expected 8" in str(res.exception)
