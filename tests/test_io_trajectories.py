"""relnav.io.trajectories: TUM/KITTI round trips, normalisation, comments, malformed lines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relnav.errors import InputError
from relnav.geometry import quat_to_matrix, random_transform
from relnav.io import read_kitti, read_tum, write_kitti, write_tum


@pytest.fixture
def poses(rng: np.random.Generator) -> np.ndarray:
    P = np.stack([random_transform(rng) for _ in range(25)])
    P[:, :3, 3] *= 50.0  # translations up to ~100 m
    return P


def test_tum_round_trip(tmp_path: Path, poses: np.ndarray, rng: np.random.Generator) -> None:
    t = 1.6e9 + np.cumsum(rng.uniform(0.05, 0.15, size=len(poses)))  # unix-epoch style
    f = write_tum(tmp_path / "sub" / "traj.tum", t, poses)
    t2, P2 = read_tum(f)
    np.testing.assert_array_equal(t2, t)  # repr formatting round-trips exactly
    np.testing.assert_allclose(P2, poses, rtol=0, atol=1e-9)
    assert all(len(line.split()) == 8 for line in f.read_text().splitlines())


def test_tum_byte_identical(tmp_path: Path, poses: np.ndarray) -> None:
    t = np.arange(len(poses)) * 0.1
    a = write_tum(tmp_path / "a.tum", t, poses)
    b = write_tum(tmp_path / "b.tum", t.copy(), poses.copy())
    assert a.read_bytes() == b.read_bytes()


def test_tum_known_line_comments_and_normalisation(tmp_path: Path) -> None:
    f = tmp_path / "hand.txt"
    # quaternion (0, 0, 2, 2) is 90 deg about z once normalised; commas also accepted
    f.write_text(
        "# timestamp tx ty tz qx qy qz qw\n\n1.5 1 2 3 0 0 2 2\n2.0, 0, 0, 0, 0, 0, 0, 1\n"
    )
    t, P = read_tum(f)
    np.testing.assert_array_equal(t, [1.5, 2.0])
    expected = np.eye(4)
    expected[:3, :3] = quat_to_matrix(np.array([0, 0, np.sqrt(0.5), np.sqrt(0.5)]))
    expected[:3, 3] = [1, 2, 3]
    np.testing.assert_allclose(P[0], expected, atol=1e-15)
    np.testing.assert_allclose(P[0][:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_array_equal(P[1], np.eye(4))


def test_tum_empty_file(tmp_path: Path) -> None:
    (tmp_path / "e.tum").write_text("# nothing\n")
    t, P = read_tum(tmp_path / "e.tum")
    assert t.shape == (0,) and P.shape == (0, 4, 4)
    write_tum(tmp_path / "e2.tum", t, P)
    assert read_tum(tmp_path / "e2.tum")[1].shape == (0, 4, 4)


@pytest.mark.parametrize(
    ("text", "msg"),
    [
        ("0 0 0 0 0 0 0 1\n1 2 3\n", "line 2: expected 8"),
        ("# c\n0 0 0 0 0 0 0 1\n0 a 0 0 0 0 0 1\n", "line 3: non-numeric"),
        ("0 0 0 0 0 0 0 0\n", "line 1: zero-length quaternion"),
        ("0 nan 0 0 0 0 0 1\n", "line 1: NaN"),
    ],
)
def test_tum_malformed_lines(tmp_path: Path, text: str, msg: str) -> None:
    f = tmp_path / "bad.tum"
    f.write_text(text)
    with pytest.raises(InputError, match=rf"bad\.tum: {msg}"):
        read_tum(f)


def test_tum_missing_and_write_validation(tmp_path: Path, poses: np.ndarray) -> None:
    with pytest.raises(InputError, match=r"none\.tum: no such file"):
        read_tum(tmp_path / "none.tum")
    with pytest.raises(InputError, match="3 timestamps for 25 poses"):
        write_tum(tmp_path / "x.tum", [0.0, 1.0, 2.0], poses)
    with pytest.raises(InputError, match="shape"):
        write_tum(tmp_path / "x.tum", [0.0], np.eye(3)[None])
    bad = poses.copy()
    bad[4, 0, 3] = np.nan
    with pytest.raises(InputError, match="pose 4"):
        write_tum(tmp_path / "x.tum", np.arange(25.0), bad)


def test_kitti_round_trip(tmp_path: Path, poses: np.ndarray) -> None:
    f = write_kitti(tmp_path / "poses.txt", poses)
    lines = f.read_text().splitlines()
    assert len(lines) == len(poses) and all(len(s.split()) == 12 for s in lines)
    np.testing.assert_array_equal(np.array(lines[0].split(), dtype=float), poses[0, :3, :].ravel())
    P2 = read_kitti(f)
    np.testing.assert_allclose(P2, poses, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(P2[:, 3], np.tile([0, 0, 0, 1.0], (len(poses), 1)))
    assert write_kitti(tmp_path / "b.txt", poses).read_bytes() == f.read_bytes()


def test_kitti_malformed(tmp_path: Path) -> None:
    f = tmp_path / "k.txt"
    f.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"k\.txt: line 2: expected 12"):
        read_kitti(f)
