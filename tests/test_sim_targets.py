"""Targets: procedural shapes, mesh loading/rescaling, lookup by name or path."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import trimesh

from relnav.errors import ConfigError, InputError
from relnav.sim.targets import (
    TARGET_ALIASES,
    Target,
    available_targets,
    get_target,
    load_target,
    procedural_target,
)

MESH_NAMES = ["voyager", "orion", "aura", "eros", "comet67p"]  # as in conftest.py

# (name, axis-sorted extents lower bounds, upper bounds) as documented in sim/targets.py
EXPECTED = {
    "envisat": (25.5, 26.5),
    "iridium": (8.0, 10.0),
    "capsule": (4.9, 5.1),
    "voyager": (11.0, 13.5),
    "asteroid": (499.999, 500.001),
}


@pytest.fixture(scope="module")
def built() -> dict[str, Target]:
    return {n: procedural_target(n) for n in available_targets()}


def test_available_targets_lists_the_documented_shapes() -> None:
    assert available_targets() == sorted(EXPECTED)
    assert TARGET_ALIASES == {"bennu": "asteroid", "orion": "capsule", "globalstar": "iridium"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_procedural_extent_centre_and_resolution(built: dict[str, Target], name: str) -> None:
    t = built[name]
    lo, hi = EXPECTED[name]
    assert lo <= t.extent <= hi
    np.testing.assert_allclose(t.mesh.bounds.mean(axis=0), 0.0, atol=1e-9)
    assert 2_000 <= len(t.mesh.faces) <= 25_000
    assert np.isfinite(t.mesh.vertices).all()
    assert t.source == f"procedural:{name}:seed=0"
    # every face has positive area (the surface sampler and ray caster need real triangles)
    assert (t.mesh.area_faces > 0).mean() > 0.999


def test_capsule_is_orion_sized(built: dict[str, Target]) -> None:
    ext = np.sort(built["capsule"].mesh.extents)
    np.testing.assert_allclose(ext[1:], [5.0, 5.0], atol=0.05)  # diameter
    assert 3.0 <= ext[0] <= 3.6  # height


def test_envisat_is_long_along_x(built: dict[str, Target]) -> None:
    ext = built["envisat"].mesh.extents
    assert np.argmax(ext) == 0 and ext[1] < 10 and ext[2] < 10


def test_asteroid_seeded_reproducible_and_seed_dependent() -> None:
    a = procedural_target("asteroid", seed=7, subdivisions=3)
    b = procedural_target("asteroid", seed=7, subdivisions=3)
    c = procedural_target("asteroid", seed=8, subdivisions=3)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.faces, b.mesh.faces)
    assert not np.allclose(a.mesh.vertices, c.mesh.vertices)
    assert a.source == "procedural:asteroid:seed=7"


def test_asteroid_craters_and_ridge() -> None:
    plain = procedural_target("asteroid", seed=1, subdivisions=4)
    cratered = procedural_target("asteroid", seed=1, subdivisions=4, craters=15)
    assert not np.allclose(plain.mesh.vertices, cratered.mesh.vertices)
    # Bennu-like ridge: the equatorial radius exceeds the mean radius at mid latitudes
    v = plain.mesh.vertices
    r = np.linalg.norm(v, axis=1)
    lat = np.degrees(np.arcsin(v[:, 2] / r))
    assert r[np.abs(lat) < 3].mean() > 1.03 * r[(np.abs(lat) > 25) & (np.abs(lat) < 35)].mean()


def test_aliases_and_scale_to() -> None:
    bennu = procedural_target("bennu", subdivisions=3)
    ast = procedural_target("asteroid", subdivisions=3)
    assert np.array_equal(bennu.mesh.vertices, ast.mesh.vertices)
    assert bennu.name == "bennu" and bennu.source.startswith("procedural:asteroid")
    orion = procedural_target("orion", scale_to=10.0)
    assert orion.extent == pytest.approx(10.0, abs=1e-9)
    assert get_target("globalstar").source.startswith("procedural:iridium")


def test_procedural_bad_requests() -> None:
    with pytest.raises(ConfigError, match="unknown procedural target"):
        procedural_target("deathstar")
    with pytest.raises(ConfigError, match="unknown parameter"):
        procedural_target("envisat", craters=3)
    with pytest.raises(ConfigError, match="scale_to"):
        procedural_target("envisat", scale_to=-1.0)
    with pytest.raises(ConfigError, match="subdivisions"):
        procedural_target("asteroid", subdivisions=0)


def test_load_target_roundtrip_recentres_and_scales(tmp_path) -> None:
    m = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    m.apply_translation([10.0, -3.0, 2.0])
    path = tmp_path / "box.stl"
    m.export(path)
    t = load_target(path)
    np.testing.assert_allclose(t.mesh.extents, [2.0, 1.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(t.mesh.bounds.mean(axis=0), 0.0, atol=1e-6)
    assert t.name == "box" and t.source == str(path)
    t2 = load_target(path, scale_to=7.0, name="crate")
    assert t2.extent == pytest.approx(7.0, abs=1e-9) and t2.name == "crate"
    np.testing.assert_allclose(t2.mesh.extents, [7.0, 3.5, 1.75], atol=1e-5)


def test_load_target_errors(tmp_path) -> None:
    with pytest.raises(InputError, match="no such"):
        load_target(tmp_path / "missing.ply")
    bad = tmp_path / "corrupt.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n\x00\x01garbage")
    with pytest.raises(InputError):
        load_target(bad)
    with pytest.raises(ConfigError):
        load_target(bad, scale_to=0.0)


def test_get_target_by_name_and_path(tmp_path) -> None:
    assert get_target("capsule").source == "procedural:capsule:seed=0"
    path = tmp_path / "tetra.obj"
    trimesh.creation.icosahedron().export(path)
    assert get_target(str(path), scale_to=3.0).extent == pytest.approx(3.0)
    with pytest.raises(ConfigError, match="unknown target"):
        get_target("nonsense")
    with pytest.raises(InputError):
        get_target(str(tmp_path / "nope.ply"))


@pytest.mark.parametrize("mesh_name", MESH_NAMES)
def test_shared_meshes_scale_to_10(shared_targets, mesh_name: str) -> None:
    path = shared_targets / f"{mesh_name}.ply"
    if not path.is_file():
        pytest.skip(f"{path} absent")
    t = load_target(path, scale_to=10.0)
    assert t.extent == pytest.approx(10.0, abs=1e-9)
    np.testing.assert_allclose(t.mesh.bounds.mean(axis=0), 0.0, atol=1e-9)
    assert get_target(path, scale_to=10.0).extent == pytest.approx(10.0, abs=1e-9)


def test_target_pickles_without_its_raycaster(built: dict[str, Target]) -> None:
    t = procedural_target("iridium")
    o = np.array([[20.0, 0.0, 0.0]])
    d = np.array([[-1.0, 0.0, 0.0]])
    r0, f0 = t.raycaster.cast(o, d)
    t2 = pickle.loads(pickle.dumps(t))
    r1, f1 = t2.raycaster.cast(o, d)
    assert np.array_equal(r0, r1) and np.array_equal(f0, f1) and np.isfinite(r0[0])
    c, rho = t.bounding_sphere
    assert np.all(np.linalg.norm(t.mesh.vertices - c, axis=1) <= rho + 1e-12)
