"""Issue 11, files read wrongly: misread scans, header/body mismatches, scan-time order,
evaluation independent of the estimate's row order (items 7, 10, 12)."""

from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest

from relnav.errors import InputError
from relnav.eval.metrics import evaluate_trajectories
from relnav.geometry import random_transform
from relnav.io.pointclouds import read_points, write_points
from relnav.io.sequences import ScanSequence, write_sequence


@pytest.fixture
def cloud(rng) -> np.ndarray:
    return rng.uniform(-3.0, 3.0, (200, 3))


def test_ply_renamed_bin_is_rejected(tmp_path, cloud):  # item 7
    p = tmp_path / "a.ply"
    write_points(p, cloud)
    q = tmp_path / "a.bin"
    shutil.copy(p, q)
    with pytest.raises(InputError, match="this is a PLY file"):
        read_points(q)


def test_bin_with_absurd_values_is_rejected(tmp_path, cloud):  # item 7
    """Float64 data read as KITTI float32: the tell-tale 1e30-scale coordinates."""
    q = tmp_path / "b.bin"
    np.column_stack([cloud, np.ones(len(cloud))]).astype("<f8").tofile(q)
    with pytest.raises(InputError, match="misread"):
        read_points(q)


def _pcd(path, header_size, data: np.ndarray, points: int) -> None:
    head = (
        "VERSION .7\nFIELDS x y z\n"
        f"SIZE {header_size} {header_size} {header_size}\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA binary\n"
    )
    path.write_bytes(head.encode() + data.tobytes())


def test_pcd_size4_over_float64_data_is_rejected(tmp_path, cloud):  # item 7
    p = tmp_path / "c.pcd"
    _pcd(p, 4, cloud.astype("<f8"), len(cloud))
    with pytest.raises(InputError, match="needs"):
        read_points(p)


def test_pcd_points_below_data_length_is_rejected(tmp_path, cloud):  # item 12 (binary)
    p = tmp_path / "d.pcd"
    _pcd(p, 4, cloud.astype("<f4"), len(cloud) - 10)
    with pytest.raises(InputError, match="POINTS"):
        read_points(p)


def test_pcd_ascii_extra_rows_warn(tmp_path, cloud, caplog):  # item 12 (ascii)
    p = tmp_path / "e.pcd"
    write_points(p, cloud, binary=False)
    text = p.read_text().replace(f"POINTS {len(cloud)}", f"POINTS {len(cloud) - 5}")
    text = text.replace(f"WIDTH {len(cloud)}", f"WIDTH {len(cloud) - 5}")
    p.write_text(text)
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        pts = read_points(p)
    assert len(pts) == len(cloud) - 5
    assert "POINTS" in caplog.text


def test_ply_with_trailing_data_is_rejected(tmp_path, cloud):  # item 7
    p = tmp_path / "f.ply"
    write_points(p, cloud)
    with p.open("ab") as f:
        f.write(np.zeros(24 * 7, np.uint8).tobytes())
    with pytest.raises(InputError, match="header declares"):
        read_points(p)


def test_far_coordinates_warn_but_read(tmp_path, cloud, caplog):
    p = tmp_path / "g.npy"
    np.save(p, cloud + np.array([2e5, 0.0, 0.0]))
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        assert read_points(p).shape == cloud.shape
    assert "check the units" in caplog.text


def _seq(tmp_path, times, rng):
    return write_sequence(
        tmp_path / "seq", [rng.normal(size=(20, 3)) for _ in times], np.asarray(times, float)
    )


@pytest.mark.parametrize(
    ("times", "kind"), [([0, 1, 1, 2], "duplicate"), ([0, 2, 1], "decreasing")]
)
def test_non_increasing_scan_times_rejected(tmp_path, rng, times, kind):  # item 10
    folder = _seq(tmp_path, times, rng)
    with pytest.raises(InputError, match=f"scan times must increase: {kind}"):
        ScanSequence(folder)


def test_unknown_extensions_warn(tmp_path, rng, caplog):  # item 12
    folder = _seq(tmp_path, [0, 1], rng)
    (folder / "timestamps.txt").unlink()
    (folder / "scans" / "000002.pts").write_text("1 2 3\n")
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        seq = ScanSequence(folder)
    assert len(seq) == 2
    assert "ignoring 1 files that are not scans (.pts)" in caplog.text


def _trajectory(rng, n=40):
    t = np.arange(n, dtype=float)
    steps = [random_transform(rng, 0.2) for _ in range(n)]
    gt = np.stack([np.linalg.multi_dot([np.eye(4), *steps[: k + 1]]) for k in range(n)])
    est = np.stack([g @ random_transform(rng, 0.02) for g in gt])
    return t, est, gt


def test_evaluate_independent_of_row_order(rng):  # item 10
    t, est, gt = _trajectory(rng)
    ref = evaluate_trajectories(t, est, t, gt)
    perm = rng.permutation(len(t))
    shuffled = evaluate_trajectories(t[perm], est[perm], t, gt)
    for k in ("T_error_pct", "e_T_avg", "drift", "e_R_avg"):
        assert shuffled[k] == pytest.approx(ref[k], rel=1e-12), k


def test_equal_timestamps_warn(rng, caplog):  # item 10
    t, est, gt = _trajectory(rng)
    t_est = t.copy()
    t_est[5] = t_est[4]
    with caplog.at_level(logging.WARNING):
        evaluate_trajectories(t_est, est, t, gt, max_diff=1.5)
    assert "share their timestamp" in caplog.text


def test_relnav_evaluate_independent_of_row_order(rng, tmp_path):  # item 10, via the CLI
    import json

    from typer.testing import CliRunner

    from relnav.cli.main import app
    from relnav.io.trajectories import write_tum

    t, est, gt = _trajectory(rng)
    perm = rng.permutation(len(t))
    write_tum(tmp_path / "gt.tum", t, gt)
    write_tum(tmp_path / "sorted.tum", t, est)
    write_tum(tmp_path / "shuffled.tum", t[perm], est[perm])
    out = {}
    for name in ("sorted", "shuffled"):
        j = tmp_path / f"{name}.json"
        r = CliRunner().invoke(
            app,
            ["evaluate", str(tmp_path / f"{name}.tum"), str(tmp_path / "gt.tum"), "--json", str(j)],
        )
        assert r.exit_code == 0, r.output
        out[name] = json.loads(j.read_text())
    from relnav.eval.metrics import METRIC_KEYS

    keys = [k for k in METRIC_KEYS if k in out["sorted"] and k != "time_ms"]
    assert keys
    assert {k: out["sorted"][k] for k in keys} == {k: out["shuffled"][k] for k in keys}
