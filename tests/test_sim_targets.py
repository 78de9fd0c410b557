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
    assert 2_000 <= len(t.mesh.faces) <= 30_000
    assert np.isfinite(t.mesh.vertices).all()
    assert t.source == f"procedural:{name}:seed=0"
    # every face has positive area (the surface sampler and ray caster need real triangles)
    assert (t.mesh.area_faces > 0).mean() > 0.999


def test_capsule_is_orion_sized(built: dict[str, Target]) -> None:
    ext = np.sort(built["capsule"].mesh.extents)
    np.testing.assert_allclose(ext[1:], [5.0, 5.0], atol=0.05)  # diameter
    assert 3.2 <= ext[0] <= 3.4  # height (Orion: 3.3 m)
    assert np.argmin(built["capsule"].mesh.extents) == 2  # axis along z


def test_envisat_is_long_along_x(built: dict[str, Target]) -> None:
    ext = built["envisat"].mesh.extents
    assert np.argmax(ext) == 0 and ext[1] < 10 and ext[2] < 10


def test_asteroid_seeded_reproducible_and_seed_dependent() -> None:
    a = procedural_target("asteroid", seed=7, subdivisions=3)
    b = procedural_target("asteroid", seed=7, subdivisions=3)
    c = procedural_target("asteroid", seed=8, subdivisions=3)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.faces, b.mesh.faces)
    n_body = 642  # icosphere(3) vertices come first
    assert not np.allclose(a.mesh.vertices[:n_body], c.mesh.vertices[:n_body])
    assert a.source == "procedural:asteroid:seed=7"


def test_asteroid_craters_and_ridge() -> None:
    plain = procedural_target("asteroid", seed=1, subdivisions=4, craters=0, boulders=0)
    cratered = procedural_target("asteroid", seed=1, subdivisions=4, craters=15, boulders=0)
    assert not np.allclose(plain.mesh.vertices, cratered.mesh.vertices)
    assert cratered.metadata["drawn"]["craters"] == 15
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


# ------------------------------------------------------------------- richer capsule / asteroid


def _components(mesh: trimesh.Trimesh) -> np.ndarray:
    """Connected-component label of every face."""
    return trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))


@pytest.mark.parametrize(("name", "params"), [("capsule", {}), ("asteroid", {"subdivisions": 4})])
def test_same_seed_same_mesh_bytes(name: str, params: dict) -> None:
    a = procedural_target(name, seed=3, **params).mesh
    b = procedural_target(name, seed=3, **params).mesh
    assert a.vertices.tobytes() == b.vertices.tobytes()
    assert a.faces.tobytes() == b.faces.tobytes()


def test_asteroid_default_counts_are_seeded_and_in_range() -> None:
    drawn = []
    for seed in range(5):
        t = procedural_target("asteroid", seed=seed, subdivisions=3)
        d = t.metadata["drawn"]
        assert 15 <= d["craters"] <= 25 and 30 <= d["boulders"] <= 60
        # body + one component per boulder (buried faces dropped, the rest stays connected)
        labels = _components(t.mesh)
        assert labels.max() + 1 == 1 + d["boulders"]
        assert np.bincount(labels).max() == 1280  # the body: icosphere(3)
        drawn.append((d["craters"], d["boulders"], tuple(d["facet_normal"])))
    assert len(set(drawn)) == 5  # the seed changes every draw
    other = procedural_target("asteroid", seed=1, subdivisions=3)
    assert (
        other.metadata["drawn"]
        == procedural_target("asteroid", seed=1, subdivisions=3).metadata["drawn"]
    )


def test_asteroid_different_seed_different_shape_same_extent() -> None:
    a = procedural_target("asteroid", seed=11, subdivisions=4).mesh
    b = procedural_target("asteroid", seed=12, subdivisions=4).mesh
    assert a.vertices.shape != b.vertices.shape or not np.allclose(a.vertices, b.vertices)
    na = len(trimesh.creation.icosphere(4).vertices)  # body vertices come first
    assert (
        np.abs(
            np.linalg.norm(a.vertices[:na], axis=1) - np.linalg.norm(b.vertices[:na], axis=1)
        ).max()
        > 10.0
    )
    for m in (a, b):
        ext = np.sort(m.extents)[::-1]
        assert ext[0] == pytest.approx(500.0, abs=1e-6)
        assert 0.75 < ext[2] / ext[0] < ext[1] / ext[0] < 1.0  # Bennu-like, slightly oblate


def test_asteroid_boulders_do_not_change_the_body_and_sit_on_it() -> None:
    from relnav.sim.raycast import RayCaster
    from relnav.sim.targets import _asteroid

    # the builder's own frame (origin = body centre), before centring and scaling
    bare = _asteroid(np.random.default_rng(4), subdivisions=4, boulders=0)
    full = _asteroid(np.random.default_rng(4), subdivisions=4, boulders=40)
    nb, fb = len(bare.vertices), len(bare.faces)
    assert np.array_equal(full.vertices[:nb], bare.vertices)
    assert np.array_equal(full.faces[:fb], bare.faces)
    assert full.metadata["asteroid"]["boulders"] == 40
    # every kept boulder face has a vertex on or above the body surface; some are sunk below
    V = full.vertices[nb:]
    F = full.faces[fb:] - nb
    dist = np.linalg.norm(V, axis=1)
    r_body, _ = RayCaster(bare).cast(np.zeros_like(V), V / dist[:, None])
    above = dist >= r_body
    assert above[F].any(axis=1).all()
    assert (~above).sum() > 40
    # boulder sizes: a few large ones (radius 0.06-0.11 of a ~1.0 body) and many small ones
    labels = _components(full)
    sizes = [
        np.ptp(full.vertices[np.unique(full.faces[labels == k])], axis=0).max()
        for k in range(1, labels.max() + 1)
    ]
    assert len(sizes) == 40
    assert 3 <= sum(s > 0.1 for s in sizes) <= 5 and max(sizes) < 0.3
    assert sum(s < 0.08 for s in sizes) >= 30


def test_asteroid_has_a_flat_facet_and_top_shape() -> None:
    from relnav.sim.targets import _asteroid

    m = _asteroid(np.random.default_rng(2), subdivisions=4, craters=0, boulders=0)
    n = np.asarray(m.metadata["asteroid"]["facet_normal"])
    h = m.vertices @ n
    on_plane = np.abs(h - h.max()) < 1e-9
    assert on_plane.sum() >= 30  # many vertices on one plane
    flat = _asteroid(np.random.default_rng(2), subdivisions=4, craters=0, boulders=0, facet_depth=0)
    hf = flat.vertices @ n
    assert (np.abs(hf - hf.max()) < 1e-9).sum() <= 2
    assert flat.metadata["asteroid"]["facet_normal"] is None
    # top shape: mid-latitudes pulled in relative to the plain ellipsoid-with-ridge
    ell = _asteroid(
        np.random.default_rng(2), subdivisions=4, craters=0, boulders=0, facet_depth=0, top_shape=0
    )
    u = ell.vertices / np.linalg.norm(ell.vertices, axis=1, keepdims=True)
    lat = np.degrees(np.arcsin(u[:, 2]))
    mid = (np.abs(lat) > 30) & (np.abs(lat) < 60)
    eq, pole = np.abs(lat) < 2, np.abs(lat) > 85
    r_top, r_ell = np.linalg.norm(flat.vertices, axis=1), np.linalg.norm(ell.vertices, axis=1)
    assert (r_top[mid] < r_ell[mid] - 1e-3).all()
    np.testing.assert_allclose(r_top[eq], r_ell[eq], rtol=0.01)
    assert (r_top <= r_ell + 1e-12).all()  # the double cone lies inside the convex ellipsoid
    assert r_top[pole].min() > 0.97 * r_ell[pole].min()  # poles barely moved


@pytest.mark.parametrize(
    "bad",
    [
        {"craters": -1},
        {"boulders": 2.5},
        {"boulders": "many"},
        {"top_shape": 1.5},
        {"facet_depth": -0.1},
        {"boulder_scale": float("nan")},
        {"ridge_width_deg": 0},
    ],
)
def test_asteroid_bad_options(bad: dict) -> None:
    with pytest.raises(ConfigError, match=next(iter(bad))):
        procedural_target("asteroid", subdivisions=2, **bad)


def _one_sided_hausdorff(src: trimesh.Trimesh, dst: trimesh.Trimesh, n: int = 3000) -> float:
    """Largest distance from ``n`` seeded surface samples of ``src`` to the surface of ``dst``."""
    pts, _ = trimesh.sample.sample_surface(src, n, seed=0)
    _, d, _ = trimesh.proximity.closest_point(dst, pts)
    return float(d.max())


def test_capsule_is_not_rotationally_symmetric(built: dict[str, Target]) -> None:
    m = built["capsule"].mesh
    # the axis of revolution is the z axis of the target frame (bbox centred in x and y)
    assert _one_sided_hausdorff(m, m, 1000) < 1e-9  # oracle: identical meshes
    for deg in (90.0, 180.0, 45.0, 120.0, 10.0):
        rot = m.copy()
        rot.apply_transform(trimesh.transformations.rotation_matrix(np.radians(deg), [0, 0, 1]))
        h = max(_one_sided_hausdorff(rot, m), _one_sided_hausdorff(m, rot))
        assert h > 0.1, deg  # a pod / fairing / hatch lands where there is bare cone


def test_capsule_parts_are_closed_and_windows_recessed(built: dict[str, Target]) -> None:
    m = built["capsule"].mesh
    labels = _components(m)
    assert labels.max() + 1 == 15  # body, 3 pads, ring, top hatch, ridge, fairing, hatch, 6 pods
    for k in range(labels.max() + 1):
        part = trimesh.Trimesh(m.vertices, m.faces[labels == k], process=True)
        assert part.is_watertight and part.volume > 0, k
    # horizontal rays towards the axis at the windows' mid height: a window (az 136°) is
    # deeper than the bare cone between two windows (az 127°) by 7 cm / cos(32.5°)
    from relnav.sim.raycast import RayCaster

    z_heat_shield = m.bounds[0, 2]  # builder z = -0.546 (heat-shield apex)
    z = z_heat_shield + (6.0 - np.sqrt(6.0**2 - 2.5**2)) + 1.175
    az = np.radians([136.0, 127.0, 118.0])
    d = -np.column_stack([np.cos(az), np.sin(az), np.zeros(3)])
    r, f = RayCaster(m).cast(-5.0 * d + [0.0, 0.0, z], d)
    assert (f >= 0).all()
    expect = 0.07 / np.cos(np.radians(32.5))
    assert r[0] - r[1] == pytest.approx(expect, abs=0.01)
    assert r[2] - r[1] == pytest.approx(expect, abs=0.01)
