"""`relnav demo` end to end on a few frames: one folder per method, run.json, plots, table."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from relnav.cli.demo import DEMO_METHODS, default_methods, run_folder_name
from relnav.cli.main import app


def test_demo_writes_one_folder_per_method_and_a_narrow_table(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner(env={"COLUMNS": "80"}).invoke(
        app, ["demo", "--out", str(out), "--frames", "6"], terminal_width=80
    )
    assert res.exit_code == 0, res.output
    for name in ("metrics.json", "trajectory.png", "errors.png", "run.json"):
        assert (out / name).is_file(), name
    assert not (out / "estimate.tum").exists()  # no anonymous estimate: one folder per method
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["methods"]) == set(default_methods())
    assert set(DEMO_METHODS) <= set(metrics["methods"])
    for m, row in metrics["methods"].items():
        assert row["n_frames"] == 6
        assert row["e_RT"] >= 0
        folder = out / "runs" / run_folder_name(m)
        assert metrics["folders"][m] == f"runs/{run_folder_name(m)}"
        for name in ("estimate.tum", "diagnostics.csv", "metrics.json", "errors.png", "run.json"):
            assert (folder / name).is_file(), (m, name)
        assert len((folder / "estimate.tum").read_text().splitlines()) == 6
        info = json.loads((folder / "run.json").read_text())
        assert info["command"] == "demo" and info["seed"] == 0
        assert info["sequence"]["frames"] == 6
        assert info["versions"]["relnav"]
        assert info["flags"]["frames"] == 6
        per = json.loads((folder / "metrics.json").read_text())
        assert per["time_ms"] is not None
        if "causal" in per:  # a smoother (relnav): the table shows its causal poses
            assert (folder / "estimate_causal.tum").is_file()
            assert per["causal"]["e_T_avg"] == row["e_T_avg"]
            assert per["e_T_avg"] == row["smoothed"]["e_T_avg"]
        else:
            assert per["e_T_avg"] == row["e_T_avg"]
    p1 = json.loads((out / "runs" / "paper1" / "run.json").read_text())
    assert p1["preset"] == "paper1" and p1["method"] == "feature:hods+gcc+alphabeta"
    # the table fits 80 columns: no cut labels, and a legend for the letters
    lines = res.output.splitlines()
    paths = [line for line in lines if str(out) in line]  # printed whole, as typed
    for m in metrics["methods"]:
        assert any(line.endswith(f"{out / 'runs' / run_folder_name(m)}/") for line in paths), m
    assert f"wrote {out / 'trajectory.png'}" in paths
    lines = [line for line in lines if line not in paths]
    assert all(len(line) <= 80 for line in lines), max(lines, key=len)
    assert "…" not in res.output
    assert "relnav" in res.output and "paper1" in res.output
    assert "rpe_trans_rmse" in res.output


def test_odometry_runs_the_navigator_by_default(tmp_path):
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    seq = tmp_path / "seq"
    simulate(get_preset("sim-voyager", max_frames=4), seq)
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["odometry", str(seq), "--out", str(out)])
    assert res.exit_code == 0, res.output
    info = json.loads((out / "run.json").read_text())
    assert info["method"] == "relnav"
    assert len((out / "estimate.tum").read_text().splitlines()) == 4
    for name in ("state.csv", "state.png", "state_errors.png"):  # the full relative state
        assert (out / name).is_file(), name
    state = json.loads((out / "metrics.json").read_text())["state"]
    for key in ("nees_blocks_mean", "nees_given_rest_mean"):  # each block alone, given the rest
        assert set(state[key]) == {"position", "velocity", "attitude", "omega"}, key
    quiet = tmp_path / "quiet"
    res = CliRunner().invoke(app, ["odometry", str(seq), "--out", str(quiet), "--no-state"])
    assert res.exit_code == 0, res.output
    assert not (quiet / "state.csv").exists()
    res = CliRunner().invoke(
        app, ["odometry", str(seq), "-m", "icp-point", "--out", str(quiet), "--state"]
    )
    assert res.exit_code != 0 and "needs the navigator" in str(res.exception)
    # relative-state options: the adaptive bank writes its members' probabilities; a wrong
    # option is refused before the run
    bank = tmp_path / "bank"
    res = CliRunner().invoke(
        app, ["odometry", str(seq), "--out", str(bank), "-S", "angular_acceleration=adaptive"]
    )
    assert res.exit_code == 0, res.output
    header = (bank / "state.csv").read_text().splitlines()[0].split(",")
    assert {"p_model0", "p_model1", "p_model2", "log_likelihood"} <= set(header)
    bad = tmp_path / "bad"
    res = CliRunner().invoke(app, ["odometry", str(seq), "--out", str(bad), "-S", "drift=z"])
    assert res.exit_code != 0 and "drift" in str(res.exception)
    assert not (bad / "estimate.tum").exists()
    res = CliRunner().invoke(
        app, ["odometry", str(seq), "--out", str(bad), "--no-state", "-S", "drift=map"]
    )
    assert res.exit_code != 0 and "needs the full state" in str(res.exception)


def test_demo_side_by_side_equals_one_after_the_other(tmp_path):
    """--jobs 2 runs the methods in worker processes: the same estimates and metrics as --jobs 1
    (only the measured times differ)."""
    outs = {}
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}"
        args = ["demo", "--out", str(out), "--frames", "4", "-m", "icp-point", "-m", "paper1"]
        res = CliRunner().invoke(app, [*args, "--jobs", str(jobs)])
        assert res.exit_code == 0, res.output
        outs[jobs] = json.loads((out / "metrics.json").read_text())["methods"]
    for m in ("icp-point", "paper1"):
        a, b = outs[1][m], outs[2][m]
        timing = {k for k in a if k.startswith("time_")}
        assert {k: v for k, v in a.items() if k not in timing} == {
            k: v for k, v in b.items() if k not in timing
        }, m
        est = [(tmp_path / f"j{j}" / "runs" / m / "estimate.tum").read_text() for j in (1, 2)]
        assert est[0] == est[1]


def test_demo_worker_death_is_an_error_not_a_hang(tmp_path):
    import os
    import signal

    import pytest

    from relnav.cli.demo import _Workers
    from relnav.errors import RelnavError
    from relnav.pipeline import resolve_method
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    seq = tmp_path / "seq"
    simulate(get_preset("sim-voyager", max_frames=4), seq)
    jobs = [(seq, m, *resolve_method(m), tmp_path / "runs" / m, 0) for m in ("icp-point", "paper1")]
    workers = _Workers(1)

    class Bar:  # kills the worker at the CLI process's first frame
        killed = False

        def advance(self, task: object) -> None:
            if not Bar.killed:
                Bar.killed = True
                for p in workers._procs:
                    os.kill(p.pid, signal.SIGKILL)

    try:
        with pytest.raises(RelnavError, match="worker process died"):
            workers.run(jobs, Bar(), {"icp-point": 0, "paper1": 1})
    finally:
        workers.close()
