"""Issue 42's CLI polish: did-you-mean, full-width tables off a terminal, printed paths."""

from __future__ import annotations

import pytest

from relnav.config import check_options, did_you_mean
from relnav.errors import ConfigError


def test_did_you_mean_offers_the_three_nearest_names_only():
    names = [f"opt_{i}" for i in range(200)] + ["max_points", "max_map_points", "min_points"]
    hint = did_you_mean("max_pointz", names)
    assert hint.startswith(" (did you mean 'max_points'")
    assert hint.count("'") == 6  # three names
    assert did_you_mean("zzzz", names) == ""
    assert did_you_mean("max_itr", ["max_iter", "gate"]) == " (did you mean 'max_iter'?)"


def _many(*, max_points: int = 1, max_map_points: int = 2, min_points: int = 3) -> None:
    """A target with many options (the navigator has ~100)."""


def test_unknown_option_message_is_short_with_many_options():
    import inspect

    params = [
        inspect.Parameter(f"option_{i:03d}", inspect.Parameter.KEYWORD_ONLY, default=0)
        for i in range(120)
    ]

    def target(**kw):  # signature set below: 120 keyword options + 3 near names
        pass

    base = list(inspect.signature(_many).parameters.values())[:3]
    target.__signature__ = inspect.Signature(base + params)
    with pytest.raises(ConfigError) as e:
        check_options(target, {"max_pointz": 100}, where="method 'x'")
    msg = str(e.value)
    assert "did you mean 'max_points', 'max_map_points' or 'min_points'?" in msg
    assert "123 options accepted" in msg and "option_050" not in msg
    assert len(msg) < 200 and "\n" not in msg
    with pytest.raises(ConfigError) as e:
        check_options(_many, {"zzz": 1}, where="m")  # few options: all of them listed
    assert "accepted: max_map_points, max_points, min_points" in str(e.value)


def test_tables_are_full_width_when_stdout_is_not_a_terminal(monkeypatch):
    import io

    from rich.table import Table

    from relnav.cli._common import PIPE_WIDTH, CliConsole

    monkeypatch.delenv("COLUMNS", raising=False)
    table = Table()
    for i in range(12):
        table.add_column(f"kiss-icp-method-{i}")
    table.add_row(*(f"{1.8812345e-05 * (i + 1):.6e}" for i in range(12)))
    buf = io.StringIO()
    con = CliConsole(file=buf)
    assert not con.is_terminal and con.width == PIPE_WIDTH
    con.print(table)
    text = buf.getvalue()
    assert "…" not in text and "1.881234e-05" in text and "kiss-icp-method-11" in text
    # COLUMNS or an explicit width still decide
    monkeypatch.setenv("COLUMNS", "80")
    assert CliConsole(file=io.StringIO()).width == 80
    assert CliConsole(file=io.StringIO(), width=100).width == 100


def test_piped_cli_table_is_not_cut(tmp_path):
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    r = subprocess.run(
        [sys.executable, "-m", "relnav.cli.main", "methods"],
        capture_output=True,
        text=True,
        env=env,
        stdin=subprocess.DEVNULL,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert "…" not in r.stdout
    assert "constant-velocity filter of pose and velocity as the prior" in r.stdout


def _helix(n: int = 40, turn: float = 1.0) -> tuple:
    """A target-frame path with turning attitude (``turn`` scales the angles): times (N,),
    poses (N, 4, 4)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    t = np.arange(n, dtype=float)
    P = np.tile(np.eye(4), (n, 1, 1))
    a = 0.05 * t
    P[:, :3, 3] = np.c_[20 * np.cos(a), 20 * np.sin(a), 0.3 * t]
    P[:, :3, :3] = Rotation.from_rotvec(turn * np.c_[0.01 * t, 0.02 * t, a]).as_matrix()
    return t, P


def _evaluate(tmp_path, est_lines_or_poses, *extra, turn: float = 1.0, gt=None):
    from typer.testing import CliRunner

    from relnav.cli.main import app
    from relnav.io.trajectories import write_tum

    t, G = _helix(turn=turn)
    write_tum(tmp_path / "gt.tum", t, G if gt is None else gt)
    est = tmp_path / "est.tum"
    if isinstance(est_lines_or_poses, str):
        est.write_text(est_lines_or_poses)
    else:
        write_tum(est, t, est_lines_or_poses)
    r = CliRunner().invoke(
        app,
        [
            "evaluate",
            str(est),
            str(tmp_path / "gt.tum"),
            "--json",
            str(tmp_path / "m.json"),
            *extra,
        ],
    )
    assert r.exit_code == 0, r.output
    import json

    return r.output, json.loads((tmp_path / "m.json").read_text())["warnings"]


def test_evaluate_suggests_align_for_frames_that_differ_by_a_constant_transform(tmp_path):
    import numpy as np

    t, G = _helix()
    # a run started from the identity: E_k = G_0^-1 G_k (plus small noise)
    E = np.linalg.inv(G[0]) @ G
    E[:, :3, 3] += np.random.default_rng(0).normal(0, 0.01, (len(t), 3))
    out, warnings = _evaluate(tmp_path, E)
    assert len(warnings) == 1 and "--align" in warnings[0] and "constant" in warnings[0]
    assert "warning:" in out and "--align" in out
    # aligned: nothing to say
    _, warnings = _evaluate(tmp_path, E, "--align", "first")
    assert warnings == []
    # an estimate that drifts from the right start: no frame hint
    D = G.copy()
    D[:, :3, 3] += np.c_[0.05 * t, np.zeros_like(t), np.zeros_like(t)]
    _, warnings = _evaluate(tmp_path, D)
    assert warnings == []


def test_evaluate_warns_when_most_rotation_errors_are_near_180_deg(tmp_path):
    from relnav.geometry.rotations import matrix_to_quat

    t, G = _helix(turn=0.1)  # attitudes within ~12° of the identity
    q = matrix_to_quat(G[:, :3, :3])  # x y z w
    lines = "".join(
        f"{ti:.6f} {p[0, 3]:.9f} {p[1, 3]:.9f} {p[2, 3]:.9f} {qi[3]:.9f} {qi[0]:.9f} "
        f"{qi[1]:.9f} {qi[2]:.9f}\n"
        for ti, p, qi in zip(t, G, q, strict=True)
    )  # quaternions written w-first
    _, warnings = _evaluate(tmp_path, lines, turn=0.1)
    assert len(warnings) == 1 and "180" in warnings[0] and "w-first" in warnings[0]


def test_benchmark_ctrl_c_prints_one_line(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) on a Dask benchmark:
    exit 130, one 'interrupted' line, no traceback from the CLI process or its workers."""
    import os
    import signal
    import subprocess
    import sys
    import time

    grid = tmp_path / "grid.yaml"
    grid.write_text(
        "schema_version: 1\nname: ctrlc\nscenarios:\n  - {preset: sim-bennu, max_frames: 30}\n"
        "seeds: 40\nmethods:\n  - icp-point\n  - feature:hods+gcc+alphabeta\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    env["PYTHONUNBUFFERED"] = "1"
    cmd = [sys.executable, "-m", "relnav.cli.main", "benchmark", str(grid)]
    proc = subprocess.Popen(
        [*cmd, "--out", str(tmp_path / "b"), "--no-report", "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        env=env,
        start_new_session=True,
    )
    try:
        seen = []
        while not any("jobs on 2 local workers" in ln for ln in seen) and len(seen) < 20:
            seen.append(proc.stdout.readline())  # the grid's summary, printed before the cluster
            if not seen[-1]:
                break
        assert any("jobs on 2 local workers" in ln for ln in seen), (seen, proc.stderr.read())
        time.sleep(6)  # the cluster up and jobs running
        assert proc.poll() is None, "the benchmark ended before Ctrl-C"
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err and "Traceback" not in out, err[-2000:]
    lines = [ln for ln in out.splitlines() if "interrupted" in ln]
    assert len(lines) == 1 and "rerun the same command to resume" in lines[0]
    assert err.strip() == "", err[-2000:]


def test_consistency_alarm_has_one_line_of_meaning():
    from relnav.cli._common import consistency_meaning

    assert consistency_meaning("NIS", 6.1, (5.5, 6.5)) is None
    hi = consistency_meaning("NIS", 35.0, (5.5, 6.5))
    lo = consistency_meaning("NEES", 2.0, (11.0, 13.0))
    assert "\n" not in hi and "overconfident" in hi and "innovations" in hi
    assert "\n" not in lo and "cautious" in lo and "ground truth" in lo


def test_error_envelope_and_figures_like_evo(tmp_path):
    import numpy as np

    from relnav.eval.plots import plot_errors, plot_trajectories, step_envelope

    env = step_envelope(np.array([[9.0, 9.0], [0.1, 1.0], [0.1, 1.0], [np.nan, 1.0], [0.1, 1.0]]))
    assert env[0, 0] == 0 and np.isclose(env[2, 0], 3 * np.sqrt(0.02))
    assert np.isnan(env[3, 0]) and np.isnan(env[4, 0]) and np.isclose(env[4, 1], 6.0)
    t, G = _helix()
    good = G.copy()
    good[:, :3, 3] += 0.01
    lost = G.copy()
    lost[:, :3, 3] += np.linspace(0, 50, len(t))[:, None]
    est = {"lost": lost, "good": good}
    p = plot_trajectories(tmp_path / "t.png", G, est, title="t")
    q = plot_errors(tmp_path / "e.png", G, est, step_sigmas={"good": np.full((len(t), 2), 0.01)})
    for f in (p, q):
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_state_figures_title_says_which_command_made_them():
    from types import SimpleNamespace

    from relnav.eval.track_plots import state_title

    nav = SimpleNamespace(filter="ukf", meta={"method": "relnav"})
    assert state_title(nav).startswith("relnav odometry — relnav: relative state")
    assert state_title(SimpleNamespace(filter="ekf", meta={"observer": "cbd"})) == (
        "relnav track — EKF"
    )


def test_sequence_name_for_titles(tmp_path):
    from relnav.cli.compare import sequence_name

    seq = tmp_path / "sequence"
    seq.mkdir()
    assert sequence_name(str(seq)) == "sequence"
    (seq / "scenario.yaml").write_text("name: sim-voyager\n")
    assert sequence_name(str(seq)) == "sim-voyager (sequence)"
    assert sequence_name(str(tmp_path / "gt.tum")) == "gt.tum"


def test_evaluate_explains_a_legacy_euler_peak_far_above_the_geodesic_error(tmp_path):
    from scipy.spatial.transform import Rotation

    _, G = _helix(turn=0.0)
    G[:, :3, :3] = Rotation.from_euler("z", 179.99, degrees=True).as_matrix()
    E = G.copy()
    E[:, :3, :3] = Rotation.from_euler("z", -179.99, degrees=True).as_matrix()  # 0.02° away
    out, _ = _evaluate(tmp_path, E, turn=0.0, gt=G)
    assert "note: e_R_euler_peak" in out and "e_R_max is the rotation error" in out
    out, _ = _evaluate(tmp_path, G, turn=0.0, gt=G)
    assert "note: e_R_euler_peak" not in out
