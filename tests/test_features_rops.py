"""RoPS descriptor and RoPS LRF: oracles, rigid-motion invariance, normalisation, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.features import compute, get_descriptor
from relnav.features.rops import rops, rops_rotations
from relnav.geometry import mean_resolution, random_transform, transform_points
from relnav.geometry.lrf import rops_local_mesh, rops_lrf

# Tolerances (one place). Descriptors are float32 with entries O(1e-3..1e-1); in float64 the
# transformed cloud changes local coordinates by ~1e-15, so on keypoints with a well-defined LRF
# the descriptors agree to float32 rounding. "Well defined" = relative eigenvalue gaps and
# relative sign sums above MARGIN (independent NumPy oracle); rounding perturbs them by ~1e-15,
# so 1e-3 is a wide safety factor while keeping most keypoints of the bumpy test surface.
DESC_ATOL = 1e-6
LRF_ATOL = 1e-8
MARGIN = 1e-3


def bumpy_surface(seed: int, n: int = 500) -> np.ndarray:
    """Generic non-planar height field z = f(x, y) on [-1, 1]², placed 5 m ahead, (n, 3)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.0, 1.0, (n, 2))
    z = np.zeros(n)
    for _ in range(6):
        c = rng.uniform(-1, 1, 2)
        z += rng.uniform(-0.3, 0.3) * np.exp(-np.sum((xy - c) ** 2, axis=1) / 0.15)
    z += 0.1 * xy[:, 0] ** 2 - 0.05 * xy[:, 0] * xy[:, 1]
    return np.c_[xy, z] + np.array([5.0, 0.0, 0.0])


def oracle_lrf(P: np.ndarray, i: int, r: float) -> tuple[np.ndarray, float]:
    """Straight NumPy RoPS point LRF (rows x, y, z) and its definedness margin."""
    p = P[i]
    V = P[np.linalg.norm(P - p, axis=1) <= r] - p
    d = np.linalg.norm(V, axis=1)
    w = (r - d) ** 2
    C = np.einsum("n,ni,nj->ij", w, V, V)
    lam, E = np.linalg.eigh(C)
    x, z = E[:, 2], E[:, 0]
    m = (w[:, None] * V).sum(0)
    s = float((w * d).sum())
    gap = min(lam[2] - lam[1], lam[1] - lam[0]) / lam[2]
    sign = min(abs(m @ x), abs(m @ z)) / s
    x = x if m @ x >= 0 else -x
    z = z if m @ z >= 0 else -z
    return np.stack([x, np.cross(z, x), z]), float(min(gap, sign))


def oracle_rops(local: np.ndarray, n_bins: int = 5) -> np.ndarray:
    """Direct transcription of ALGORITHMS §A.4 on LRF-local points (before L1 normalisation)."""
    feats = []
    for R in rops_rotations(3):
        Q = local @ R.T
        lo, hi = Q.min(0), Q.max(0)
        for a, b in ((0, 1), (0, 2), (1, 2)):
            D = np.zeros((n_bins, n_bins))
            for q in Q:
                i = min(int((q[a] - lo[a]) / ((hi[a] - lo[a]) / n_bins)), n_bins - 1)
                j = min(int((q[b] - lo[b]) / ((hi[b] - lo[b]) / n_bins)), n_bins - 1)
                D[i, j] += 1
            D /= len(Q)
            ii, jj = np.meshgrid(np.arange(1, n_bins + 1), np.arange(1, n_bins + 1), indexing="ij")
            mi, mj = (ii * D).sum(), (jj * D).sum()
            mom = [((ii - mi) ** m * (jj - mj) ** k * D).sum() for m, k in ((1, 1), (2, 1), (1, 2))]
            mom.append(((ii - mi) ** 2 * (jj - mj) ** 2 * D).sum())
            nz = D[D > 0]
            feats.extend([*mom, -(nz * np.log(nz)).sum()])
    return np.array(feats)


@pytest.fixture(scope="module")
def surface() -> tuple[np.ndarray, float]:
    P = bumpy_surface(7)
    return P, 8.0 * mean_resolution(P)


def test_registry_entry() -> None:
    spec = get_descriptor("rops")
    assert (spec.dim, spec.radius_factor, spec.needs_normals) == (135, 20.0, False)


def test_rotations_angle_set() -> None:
    R = rops_rotations(3)
    assert R.shape == (9, 3, 3)
    ang = np.degrees(np.arccos((np.trace(R, axis1=1, axis2=2) - 1) / 2))
    np.testing.assert_allclose(ang, np.tile([22.5, 45.0, 67.5], 3), atol=1e-9)
    np.testing.assert_allclose(R[1] @ [1.0, 0, 0], [1, 0, 0], atol=1e-12)  # x-axis rotation
    np.testing.assert_allclose(R[4] @ [0, 1.0, 0], [0, 1, 0], atol=1e-12)  # y-axis rotation
    with pytest.raises(ConfigError):
        rops_rotations(0)


def test_lrf_matches_oracle_and_is_orthonormal(surface) -> None:
    P, r = surface
    kp = np.arange(0, len(P), 5)
    L = rops_lrf(P, kp, r, lrf="points")
    assert L.shape == (kp.size, 3, 3)
    n_checked = 0
    for k, i in enumerate(kp):
        ref, margin = oracle_lrf(P, i, r)
        if margin < MARGIN:
            continue
        n_checked += 1
        np.testing.assert_allclose(L[k], ref, atol=LRF_ATOL)
        np.testing.assert_allclose(L[k] @ L[k].T, np.eye(3), atol=1e-12)
        assert np.linalg.det(L[k]) == pytest.approx(1.0, abs=1e-12)
    assert n_checked > 0.5 * kp.size


def test_lrf_is_equivariant(surface) -> None:
    P, r = surface
    T = random_transform(np.random.default_rng(3), max_translation=2.0)
    kp = np.arange(0, len(P), 3)
    good = np.array([oracle_lrf(P, i, r)[1] >= MARGIN for i in kp])
    L0 = rops_lrf(P, kp, r, lrf="points")
    L1 = rops_lrf(transform_points(T, P), kp, r, lrf="points")
    # axes rotate with the cloud: rows of L1 = R · rows of L0
    np.testing.assert_allclose(L1[good], L0[good] @ T[:3, :3].T, atol=LRF_ATOL)


def test_mesh_lrf_oracle_and_equivariance() -> None:
    # Height-field mesh on a regular grid (generic bumps → well-defined frames).
    g = np.linspace(-1, 1, 21)
    X, Y = np.meshgrid(g, g, indexing="ij")
    Z = 0.3 * np.sin(2.1 * X + 0.3) * np.cos(1.7 * Y - 0.2) + 0.1 * X**2
    V = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    ij = np.arange(21 * 21).reshape(21, 21)
    a, b, c, d = ij[:-1, :-1].ravel(), ij[1:, :-1].ravel(), ij[1:, 1:].ravel(), ij[:-1, 1:].ravel()
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    r = 0.45
    kp = np.array([ij[10, 10], ij[5, 13], ij[14, 6]])
    L = rops_lrf(V, kp, r, triangles=F)
    for k, i in enumerate(kp):  # oracle: §A.4 mesh formulas in NumPy
        p = V[i]
        inside = np.flatnonzero(np.linalg.norm(V - p, axis=1) <= r)
        tri = F[np.isin(F, inside).any(axis=1)]
        Q = V[tri] - p  # (M, 3, 3)
        area = 0.5 * np.linalg.norm(np.cross(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]), axis=1)
        w = area / area.sum() * (r - np.linalg.norm(Q.mean(1), axis=1)) ** 2
        S = Q.sum(1)
        Cj = (np.einsum("mi,mj->mij", S, S) + np.einsum("mai,maj->mij", Q, Q)) / 12
        _, E = np.linalg.eigh(np.einsum("m,mij->ij", w, Cj))
        h = (w[:, None] * S).sum(0)
        x = E[:, 2] * np.sign(h @ E[:, 2])
        z = E[:, 0] * np.sign(h @ E[:, 0])
        np.testing.assert_allclose(L[k], np.stack([x, np.cross(z, x), z]), atol=LRF_ATOL)
    T = random_transform(np.random.default_rng(5), max_translation=1.0)
    L1 = rops_lrf(transform_points(T, V), kp, r, triangles=F)
    np.testing.assert_allclose(L1, L @ T[:3, :3].T, atol=LRF_ATOL)
    D = rops(V, kp, radius=r, triangles=F)
    assert np.isfinite(D).all()
    with pytest.raises(InputError):
        rops_lrf(V, kp, r, triangles=F + 10_000)


def test_descriptor_matches_oracle(surface) -> None:
    P, r = surface
    kp = np.array([10, 123, 321])
    L = rops_lrf(P, kp, r)
    D = rops(P, kp, radius=r)
    for k, i in enumerate(kp):
        local = (P[np.linalg.norm(P - P[i], axis=1) <= r] - P[i]) @ L[k].T
        ref = oracle_rops(local)
        np.testing.assert_allclose(D[k], ref / np.abs(ref).sum(), rtol=1e-5, atol=1e-7)


def test_rigid_motion_invariance(surface) -> None:
    P, r = surface
    kp = np.arange(0, len(P), 2)
    good = np.array([oracle_lrf(P, i, r)[1] >= MARGIN for i in kp])
    assert good.sum() > 0.5 * kp.size
    D0 = compute("rops", P, radius=r, keypoints=kp)
    for seed in (1, 2):
        T = random_transform(np.random.default_rng(seed), max_translation=3.0)
        D1 = compute("rops", transform_points(T, P), radius=r, keypoints=kp)
        np.testing.assert_allclose(D1[good], D0[good], atol=DESC_ATOL)


def test_shape_dtype_and_l1_norm(surface) -> None:
    P, r = surface
    D = compute("rops", P, radius=r)
    assert D.shape == (len(P), 135) and D.dtype == np.float32
    ok = np.isfinite(D).all(axis=1)
    assert ok.sum() > 0.9 * len(P)
    np.testing.assert_allclose(np.abs(D[ok]).sum(axis=1), 1.0, rtol=1e-5)
    assert np.isnan(D[~ok]).all()
    ent = D[ok][:, 4::5]
    assert (ent >= 0).all() and (ent.max(axis=1) > 0).all()


def test_entropy_base_scales_entropy_only(surface) -> None:
    P, r = surface
    kp = np.array([5, 50, 250])
    De = rops(P, kp, radius=r).astype(np.float64)
    D2 = rops(P, kp, radius=r, entropy_base=2.0).astype(np.float64)
    # the vectors differ only by a per-row scale and 1/ln 2 on the entropy entries
    moments = np.ones(135, dtype=bool)
    moments[4::5] = False
    c = (D2[:, moments] ** 2).sum(1) / (D2[:, moments] * De[:, moments]).sum(1)
    np.testing.assert_allclose(D2[:, moments], c[:, None] * De[:, moments], rtol=1e-4, atol=1e-8)
    np.testing.assert_allclose(D2[:, ~moments], c[:, None] * De[:, ~moments] / np.log(2), rtol=1e-4)
    with pytest.raises(ConfigError):
        rops(P, kp, radius=r, entropy_base=1.0)


@pytest.mark.parametrize(
    "cloud",
    [
        np.zeros((1, 3)),
        np.array([[0.0, 0, 0], [0.01, 0, 0]]),
        np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]]),  # 4 points
        np.tile([[1.0, 2.0, 3.0]], (12, 1)),  # duplicates
        np.c_[np.linspace(0, 0.1, 20), np.linspace(0, 0.05, 20), np.zeros(20)] + 4.0,  # line
    ],
    ids=["1pt", "2pt", "4pt", "duplicates", "collinear"],
)
def test_degenerate_input_gives_nan_rows(cloud: np.ndarray) -> None:
    D = compute("rops", cloud, radius=0.5)
    assert D.shape == (len(cloud), 135)
    assert np.isnan(D).all()
    L = rops_lrf(cloud, np.arange(len(cloud)), 0.5)
    assert np.isnan(L).all()


def test_isolated_point_is_nan_others_valid(surface) -> None:
    P, r = surface
    Q = np.vstack([P, [[50.0, 50.0, 50.0]]])
    D = compute("rops", Q, radius=r, keypoints=np.array([0, 1, len(P)]))
    assert np.isnan(D[2]).all() and np.isfinite(D[:2]).all()


def test_bad_arguments() -> None:
    P = bumpy_surface(1, 50)
    with pytest.raises(InputError):
        rops_lrf(P, np.array([0]), -1.0)
    with pytest.raises(InputError):
        rops_lrf(P, np.array([50]), 0.3)
    with pytest.raises(InputError):
        rops(P[:, :2], np.array([0]), radius=0.3)
    with pytest.raises(ConfigError):
        rops(P, np.array([0]), radius=0.3, n_bins=0)
    assert rops(P, np.zeros(0, dtype=np.int64), radius=0.3).shape == (0, 135)


def test_support_neighbourhoods_grid_and_kdtree_agree() -> None:
    from scipy.spatial import cKDTree

    from relnav.geometry.lrf import support_csr

    rng = np.random.default_rng(4)
    P = np.vstack([rng.normal(size=(300, 3)), np.tile([[0.5, 0.5, 0.5]], (4, 1))])  # + duplicates
    kp = np.array([0, 7, 300, 301, 150])
    ref = cKDTree(P).query_ball_point(P[kp], r=0.6)
    for tree in (None, cKDTree(P)):
        flat, off = support_csr(P, kp, 0.6, tree)
        for k in range(kp.size):
            assert sorted(flat[off[k] : off[k + 1]].tolist()) == sorted(ref[k])
    # a grid with more than 2^62 cells falls back to the kd-tree
    Q = np.array([[0.0, 0, 0], [1e-3, 0, 0], [1e20, 1e20, 1e20]])
    flat, off = support_csr(Q, np.array([0, 2]), 0.01)
    assert sorted(flat[off[0] : off[1]].tolist()) == [0, 1] and flat[off[1] : off[2]].tolist() == [
        2
    ]


def test_local_mesh_lrf_equals_mesh_lrf_on_an_independent_delaunay(surface) -> None:
    """Default frame = mesh LRF on scipy's Delaunay of the tangent-plane projection (oracle)."""
    from scipy.spatial import Delaunay

    P, r = surface
    me = 3.0 * mean_resolution(P)
    n_checked = 0
    for i in (10, 123, 321, 400):
        v = P - P[i]
        d = np.linalg.norm(v, axis=1)
        sup = d <= r
        C = ((r - d[sup]) ** 2 * v[sup].T) @ v[sup]
        _, V = np.linalg.eigh(C)
        nb = np.flatnonzero(d <= r + me)
        uv = v[nb] @ V[:, [2, 1]]
        tri = nb[Delaunay(uv).simplices]
        e = np.linalg.norm(P[tri] - P[np.roll(tri, 1, axis=1)], axis=2).max(axis=1)
        tri = tri[(e <= me) & sup[tri].any(axis=1)]
        ref = rops_lrf(P, np.array([i]), r, triangles=tri)[0]
        got = rops_lrf(P, np.array([i]), r, max_edge=me)[0]
        if np.isfinite(ref).all():
            n_checked += 1
            np.testing.assert_allclose(got, ref, atol=1e-9)
    assert n_checked >= 3


def test_local_mesh_csr_reproduces_the_default_frame_and_descriptor(surface) -> None:
    """Each keypoint's CSR triangles, given as its mesh, give the default frame and descriptor.

    This is what keeps ``tests/data/pcl``'s ``rops_local`` (PCL's RoPS on these triangles) a valid
    reference for the default ``rops``: both come from one triangulation routine.
    """
    P, r = surface
    kp = np.arange(0, P.shape[0], 7)
    off, tris = rops_local_mesh(P, kp, r)
    assert off.shape == (kp.size + 1,) and off[0] == 0 and off[-1] == tris.shape[0]
    assert tris.shape[1] == 3 and tris.dtype == np.int64
    me = 3.0 * mean_resolution(P)
    lrf = rops_lrf(P, kp, r)
    D = rops(P, kp, radius=r)
    n_defined = 0
    for k, i in enumerate(kp):
        t = tris[off[k] : off[k + 1]]
        assert t.shape[0] > 0
        # PCL's rule for the triangles of a support: at least one vertex within r; edges ≤ 3·Tr
        assert (np.linalg.norm(P[t] - P[i], axis=2) <= r).any(axis=1).all()
        assert np.linalg.norm(P[t] - P[np.roll(t, 1, axis=1)], axis=2).max() <= me
        got = rops_lrf(P, np.array([i]), r, triangles=t)[0]
        np.testing.assert_allclose(got, lrf[k], atol=LRF_ATOL)  # NaN where both are NaN
        np.testing.assert_allclose(
            rops(P, np.array([i]), radius=r, triangles=t)[0], D[k], atol=DESC_ATOL
        )
        n_defined += bool(np.isfinite(got).all())
    assert n_defined >= 0.9 * kp.size


def test_local_mesh_csr_edge_cases(surface) -> None:
    P, r = surface
    off, tris = rops_local_mesh(P, np.zeros(0, dtype=np.int64), r)
    assert off.tolist() == [0] and tris.shape == (0, 3)
    # a keypoint whose support has fewer than 5 points has no triangles (and no frame)
    far = np.vstack([P, P[:4] + 100.0])
    off, tris = rops_local_mesh(far, np.array([P.shape[0], 0]), r)
    assert off[1] == 0 and off[2] > 0 and np.isnan(rops_lrf(far, [P.shape[0]], r)).all()
    # a shorter max_edge drops triangles
    _, tris2 = rops_local_mesh(P, np.array([0]), r, max_edge=mean_resolution(P))
    assert tris2.shape[0] < tris.shape[0] - off[1]
    with pytest.raises(ConfigError):
        rops_local_mesh(P, np.array([0]), r, max_edge=0.0)
    with pytest.raises(InputError):
        rops_local_mesh(P, np.array([0]), -1.0)


def test_lrf_option_validated(surface) -> None:
    P, r = surface
    with pytest.raises(ConfigError):
        rops(P, np.array([0]), radius=r, lrf="mesh")
    with pytest.raises(ConfigError):
        rops_lrf(P, np.array([0]), r, max_edge=-1.0)
    a = rops(P, np.array([7]), radius=r, lrf="points")
    b = rops(P, np.array([7]), radius=r)
    assert np.isfinite(a).all() and np.isfinite(b).all()
