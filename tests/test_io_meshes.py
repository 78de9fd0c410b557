"""relnav.io.meshes: round trips per format, scenes flattened with transforms, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from relnav.errors import InputError
from relnav.io import MESH_EXTENSIONS, read_mesh, write_mesh


def _sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.parametrize("ext", MESH_EXTENSIONS)
def test_mesh_round_trip(tmp_path: Path, ext: str) -> None:
    box = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    f = write_mesh(tmp_path / f"box{ext}", box)
    m = read_mesh(f)
    assert isinstance(m, trimesh.Trimesh)
    assert len(m.faces) == 12
    np.testing.assert_allclose(
        _sorted_rows(np.asarray(m.vertices)), _sorted_rows(box.vertices), atol=1e-6
    )
    assert m.volume == pytest.approx(6.0, rel=1e-6)


def test_scene_is_concatenated_with_transforms(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.creation.box(), transform=trimesh.transformations.translation_matrix([5, 0, 0])
    )
    scene.add_geometry(trimesh.creation.box())
    f = tmp_path / "scene.glb"
    scene.export(f)
    m = read_mesh(f)
    assert len(m.faces) == 24
    np.testing.assert_allclose(m.bounds, [[-0.5, -0.5, -0.5], [5.5, 0.5, 0.5]], atol=1e-6)


def test_single_node_transform_applied(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.creation.box(), transform=trimesh.transformations.translation_matrix([0, 0, 2])
    )
    scene.export(tmp_path / "one.glb")
    np.testing.assert_allclose(read_mesh(tmp_path / "one.glb").bounds[:, 2], [1.5, 2.5], atol=1e-6)


def test_bad_meshes(tmp_path: Path, rng: np.random.Generator) -> None:
    with pytest.raises(InputError, match=r"none\.ply: no such file"):
        read_mesh(tmp_path / "none.ply")
    (tmp_path / "m.xyz").write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"m\.xyz.*unknown mesh extension"):
        read_mesh(tmp_path / "m.xyz")
    trimesh.PointCloud(rng.normal(size=(10, 3))).export(tmp_path / "cloud.ply")
    with pytest.raises(InputError, match=r"cloud\.ply.*no triangle faces"):
        read_mesh(tmp_path / "cloud.ply")
    (tmp_path / "junk.stl").write_bytes(b"\x00" * 30)
    with pytest.raises(InputError, match=r"junk\.stl"):
        read_mesh(tmp_path / "junk.stl")
    with pytest.raises(InputError, match="without faces"):
        write_mesh(
            tmp_path / "e.ply",
            trimesh.Trimesh(vertices=np.zeros((3, 3)), faces=np.zeros((0, 3), int)),
        )


def test_shared_targets_load(shared_targets: Path) -> None:
    files = sorted(shared_targets.glob("*.ply"))
    assert files
    m = read_mesh(files[0])
    assert len(m.faces) > 100 and np.isfinite(m.vertices).all()
