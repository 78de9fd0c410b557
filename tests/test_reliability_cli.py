"""Issue 11, bad options and configs: one clear error line before the run, never a traceback.

Sequence ``base`` = ``relnav simulate sim-voyager --max-frames 6`` (as in the issue).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import ConfigError, InputError, RelnavError
from relnav.odometry import Odometry, run_sequence
from relnav.registration import get_registration

runner = CliRunner()


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rel") / "base"
    r = runner.invoke(app, ["simulate", "sim-voyager", "--max-frames", "6", "--out", str(out)])
    assert r.exit_code == 0, r.output
    return out


def _odo(base: Path, out: Path, *args: str):
    return runner.invoke(app, ["odometry", str(base), "--out", str(out), *args])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-m", "icp-point", "-O", "max_iter=abc"], "max_iter='abc'"),  # item 1
        (["-m", "icp-point", "-O", "gate_rotation_deg=abc"], "gate_rotation_deg"),  # item 2
        (["-m", "icp-point", "--max-frames", "-2"], "max_frames must be >= 0"),  # item 4
        (["-m", "icp-point", "-O", "initial_pose=abc"], "initial_pose"),  # item 11
        (["-m", "icp-point", "-O", "max_iter=0"], "must be >= 1"),
        (["-m", "icp-point", "-O", "max_iter=2.5"], "fractional part"),
        (["-m", "icp-point", "-O", "gate_rotation_deg=-5"], "greater than 0"),
        (["-m", "icp-point", "-O", "gate_translation=.nan"], "finite"),
        (["-m", "feature:"], "empty spec"),
        (["-m", "paper1", "-O", "descriptor_options.radius_factor=-1"], "option of the feature"),
        (["-m", "paper1", "-O", "descriptor_options.mode=bogus"], "bad descriptor_options"),
        (["-m", "paper1", "-O", "radius_factor=-1"], "radius_factor=-1 out of range (must be > 0)"),
        (["-m", "icp-point", "-O", "max_itr=3"], "did you mean 'max_iter'"),
        (["-m", "paper1", "-O", "estimator_options.alpha0=0.3"], "did you mean 'alpha'"),
        (["-m", "icp-point", "-O", "initial_pose=[1,2,3]"], "16 (4x4) or 12"),
        (["-m", "icp-point", "--motion-prior", "bogus"], "motion_prior"),
        (
            [
                "-m",
                "icp-point",
                "--motion-prior",
                "identity",
                "-O",
                "motion_prior=constant_velocity",
            ],
            "disagree",
        ),
    ],
)
def test_bad_option_is_one_config_error_before_the_run(base, tmp_path, args, needle):
    out = tmp_path / "o"
    r = _odo(base, out, *args)
    assert isinstance(r.exception, RelnavError), r.output
    assert needle in str(r.exception)
    assert "\n" not in str(r.exception)
    assert not (out / "estimate.tum").exists()  # rejected before any frame


def test_motion_prior_as_option_is_accepted(base, tmp_path):  # item 3
    r = _odo(base, tmp_path / "o", "-m", "icp-point", "-O", "motion_prior=identity")
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("opt", ["gate_rotation_deg=1E2", "max_iter=1E1", "gate_translation=1_000"])
def test_numbers_yaml_leaves_as_strings_are_numbers(base, tmp_path, opt):
    """YAML 1.1 reads ``1E0`` as a string; it used to reach ``np.radians`` (found by the
    property test)."""
    r = _odo(base, tmp_path / "o", "-m", "icp-point", "--max-frames", "3", "-O", opt)
    assert r.exit_code == 0, r.output


def test_help_example_option_works(base, tmp_path):  # "Also": the --help example
    r = runner.invoke(app, ["odometry", "--help"], env={"COLUMNS": "160"})
    assert "estimator_options.alpha=0.3" in r.output
    r = _odo(
        base,
        tmp_path / "o",
        "-m",
        "paper1",
        "--max-frames",
        "2",
        "-O",
        "estimator_options.alpha=0.3",
    )
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("n", ["0", "1"])
def test_max_frames_below_two_writes_estimate_and_exits_0(base, tmp_path, n):
    out = tmp_path / "o"
    r = _odo(base, out, "-m", "icp-point", "--max-frames", n)
    assert r.exit_code == 0, r.output
    assert "evaluation needs at least two frames" in r.output
    assert len((out / "estimate.tum").read_text().splitlines()) == int(n)


def test_cli_prints_one_line_and_nonzero_exit(base, tmp_path):
    """Through the real console script: exit 1, one stderr line, no traceback."""
    code = "from relnav.cli.main import main; main()"
    args = ["odometry", str(base), "-m", "icp-point", "-O", "max_iter=abc", "--out", str(tmp_path)]
    p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    assert p.returncode == 1
    assert "Traceback" not in p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), p.stderr


def test_api_validates_too():
    with pytest.raises(ConfigError, match="max_iter"):
        get_registration("icp-point", max_iter="abc")
    with pytest.raises(ConfigError, match="gate_rotation_deg"):
        Odometry("icp-point", gate_rotation_deg=-5)
    with pytest.raises(ConfigError, match="max_frames"):
        run_sequence([np.zeros((5, 3))], "icp-point", max_frames=-2)
    with pytest.raises(ConfigError, match="rigid"):
        run_sequence([np.zeros((5, 3))], "icp-point", initial_pose=2 * np.eye(4))


def test_empty_scans_folder_is_an_error(tmp_path):  # item 13
    (tmp_path / "seq" / "scans").mkdir(parents=True)
    r = _odo(tmp_path / "seq", tmp_path / "o")
    assert isinstance(r.exception, InputError) and "no scan files" in str(r.exception)


def test_empty_yaml_is_an_error(tmp_path):  # item 13
    y = tmp_path / "empty.yaml"
    y.write_text("")
    r = runner.invoke(app, ["simulate", str(y), "--out", str(tmp_path / "s")])
    assert isinstance(r.exception, ConfigError) and "empty scenario" in str(r.exception)
    assert not (tmp_path / "s").exists()


def test_existing_output_names_the_flag(base):  # "Also"
    r = runner.invoke(app, ["simulate", "sim-voyager", "--max-frames", "2", "--out", str(base)])
    assert isinstance(r.exception, InputError) and "--overwrite" in str(r.exception)


def test_huge_sensor_is_rejected_before_allocating(tmp_path):  # item 5
    r = runner.invoke(
        app,
        [
            "simulate",
            "sim-voyager",
            "--max-frames",
            "2",
            "--param",
            "sensors.0.overrides.n_points=1000000000000",
            "--out",
            str(tmp_path / "s"),
        ],
    )
    assert isinstance(r.exception, ConfigError) and "rays per scan" in str(r.exception)


def test_too_many_frames_is_a_config_error(tmp_path):
    r = runner.invoke(
        app, ["simulate", "sim-voyager", "--frames", "100000000", "--out", str(tmp_path / "s")]
    )
    assert isinstance(r.exception, ConfigError) and "--max-frames" in str(r.exception)


def test_frames_do_not_cost_when_max_frames_is_small(tmp_path):  # item 6
    """1e8 path frames, 2 simulated: must finish (it used to allocate ~100 GB) and give the
    same first frames as a path of the same length simulated in full would (checked on a
    length that can be simulated in full)."""
    import tracemalloc

    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import scenario_poses, simulate

    tracemalloc.start()
    simulate(get_preset("sim-voyager", frames=100_000_000, max_frames=2), tmp_path / "a")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 200e6  # bytes; the full path would need > 1e10
    # the first frames of a long path are the full path's first frames, bit for bit
    full = get_preset("sim-voyager", frames=5000)
    t_full, rig_full, tgt_full = scenario_poses(full)
    from relnav.io.sequences import ScanSequence

    simulate(get_preset("sim-voyager", frames=5000, max_frames=3), tmp_path / "b")
    seq = ScanSequence(tmp_path / "b")
    assert np.array_equal(seq.timestamps, t_full[:3])
    T_ts = np.linalg.inv(tgt_full[:3]) @ rig_full[:3]
    np.testing.assert_allclose(seq.gt_poses, T_ts, atol=1e-9)


def test_blind_sensor_fails_before_writing(tmp_path):  # "Also"
    out = tmp_path / "s"
    r = runner.invoke(
        app,
        [
            "simulate",
            "sim-voyager",
            "--max-frames",
            "3",
            "--param",
            "sensors.0.overrides.max_range=0.5",
            "--out",
            str(out),
        ],
    )
    assert isinstance(r.exception, InputError) and "saw nothing" in str(r.exception)
    assert not out.exists() or not any(out.rglob("*.ply"))
