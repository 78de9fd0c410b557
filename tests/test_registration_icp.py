"""ICP baselines (icp-point, icp-plane, icp-x84): known answers, Open3D oracle, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.geometry.normals import estimate_normals
from relnav.geometry.rotations import hat, rotation_angle
from relnav.geometry.se3 import exp_se3, from_rt, invert, kabsch, log_se3, transform_points
from relnav.registration import PreparedRegistration, available_methods, get_registration
from relnav.registration.icp import (
    ICP,
    PAPER_GATE,
    PAPER_ROTATION_TOL,
    PAPER_TRANSLATION_TOL,
    KDTree,
    _jacobi_eigh,
    information_ratio,
    kabsch_pairs,
    point_information,
    prepare_cloud,
    reject_nb,
    reject_outliers,
)

ICP_METHODS = ["icp-point", "icp-plane", "icp-x84"]


# --------------------------------------------------------------------------- helpers


def bumpy_surface(n: int, rng: np.random.Generator, size: float = 1.0) -> np.ndarray:
    """Random samples of a non-symmetric bumpy surface patch (``size`` m across)."""
    xy = rng.uniform(-0.5, 0.5, (n, 2))
    centres = np.array([[0.2, 0.1], [-0.25, 0.3], [0.05, -0.3], [-0.3, -0.2]])
    heights = np.array([0.15, -0.1, 0.12, 0.08])
    z = 0.1 * xy[:, 0] ** 2
    for c, h in zip(centres, heights, strict=True):
        z += h * np.exp(-np.sum((xy - c) ** 2, axis=1) / 0.02)
    return size * np.column_stack([xy, z])


def motion(rng: np.random.Generator, rot_deg: float, trans: float) -> np.ndarray:
    xi = rng.normal(size=6)
    xi[:3] *= trans / np.linalg.norm(xi[:3])
    xi[3:] *= np.deg2rad(rot_deg) / np.linalg.norm(xi[3:])
    return exp_se3(xi)


def errors(gt: np.ndarray, T: np.ndarray, pts: np.ndarray) -> tuple[float, float]:
    """Rotation error (deg) and RMS displacement of ``pts`` (m) between ``T`` and ``gt``."""
    d = transform_points(T, pts) - transform_points(gt, pts)
    return float(np.rad2deg(rotation_angle((invert(gt) @ T)[:3, :3]))), float(
        np.sqrt((d**2).sum(axis=1).mean())
    )


def look_at(pos: np.ndarray) -> np.ndarray:
    x = -pos / np.linalg.norm(pos)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), pos)


def satellite_pair(seed: int, rot_deg: float, frac: float, target: str = "voyager"):
    """Two surface-HPR scans of a target; the sensor moves about the target centre.

    Returns ``source (scan 2), target (scan 1), T_target_source (ground truth), extent``.
    """
    sim_targets = pytest.importorskip("relnav.sim.targets")
    sim_sensors = pytest.importorskip("relnav.sim.sensors")
    rng = np.random.default_rng(seed)
    tg = sim_targets.get_target(target)
    sensor = sim_sensors.make_sensor("surface-hpr")
    d = rng.normal(size=3)
    T1 = look_at(d / np.linalg.norm(d) * 3.0 * tg.extent)
    T2 = motion(rng, rot_deg, frac * tg.extent) @ T1  # about the target centre
    P1 = sensor.scan(tg, T1, rng)
    P2 = sensor.scan(tg, T2, rng)
    return P2, P1, invert(T1) @ T2, tg.extent


@pytest.fixture(scope="module")
def surface_pair():
    """Independent samplings of one bumpy patch (1 m), source moved by a small motion."""
    rng = np.random.default_rng(7)
    tgt = bumpy_surface(1500, rng)
    gt = motion(rng, 3.0, 0.03)  # T_target_source
    src = transform_points(invert(gt), bumpy_surface(1500, rng))
    return src, tgt, gt


# --------------------------------------------------------------------------- building blocks


def test_registry_specs_and_protocol():
    methods = available_methods()
    for m in ICP_METHODS:
        assert m in methods
        reg = get_registration(m)
        assert isinstance(reg, PreparedRegistration)
        assert reg.thresholds == "scale"
    paper = get_registration("icp-point:paper")
    assert paper.thresholds == "paper" and paper.name == "icp-point:paper"
    from relnav.errors import ConfigError

    with pytest.raises(ConfigError):
        get_registration("icp-point:nonsense")
    with pytest.raises(ConfigError):
        get_registration("icp-plane", no_such_option=1)
    with pytest.raises(ConfigError):
        ICP("plane", max_correspondence_distance=-1.0)
    assert get_registration("icp-point").max_iter == 20
    assert get_registration("icp-x84").max_iter == 20
    assert get_registration("icp-plane").max_iter == 1000


def test_kdtree_matches_ckdtree():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(2000, 3))
    P[:500] *= 0.01  # uneven density
    Q = rng.normal(size=(700, 3)) * 1.2
    T = motion(rng, 20.0, 0.5)
    tree = KDTree(P, leaf_size=8)
    X, idx, dist = tree.nn(Q, 0.3, T=T)
    np.testing.assert_allclose(X, transform_points(T, Q), atol=1e-12)
    d_ref, i_ref = cKDTree(P).query(X, distance_upper_bound=0.3)
    found = np.isfinite(d_ref)
    assert np.array_equal(idx >= 0, found)
    assert np.array_equal(idx[found], i_ref[found])
    np.testing.assert_allclose(dist[found], d_ref[found], rtol=1e-12)
    # unbounded, self-excluded: the nearest OTHER point
    _, j, d = tree.nn(P, exclude_self=True)
    d2, i2 = cKDTree(P).query(P, k=2)
    assert np.array_equal(j, i2[:, 1])
    np.testing.assert_allclose(d, d2[:, 1], rtol=1e-12)
    # cKDTree-compatible query (other modules use it): missing -> (inf, n)
    dq, iq = tree.query(X, k=1, distance_upper_bound=0.3)
    np.testing.assert_array_equal(iq, np.where(found, i_ref, tree.n))
    np.testing.assert_allclose(dq[found], d_ref[found], rtol=1e-12)
    assert np.isinf(dq[~found]).all()
    dk, ik = tree.query(Q[:5], k=3)
    assert dk.shape == ik.shape == (5, 3)


@pytest.mark.parametrize("n", [1, 7, 3000])
def test_kd_knn_equals_ckdtree(n):
    """The numba k-NN (the navigator's map neighbourhoods) gives cKDTree's neighbours and the
    same distances to the bit; missing neighbours are (inf, -1)."""
    from relnav.geometry.kdtree import kd_build, kd_knn

    rng = np.random.default_rng(n)
    P = rng.normal(size=(n, 3))
    P[: n // 3] *= 0.01  # uneven density
    Q = np.concatenate([P[: min(n, 100)], rng.normal(size=(200, 3))])
    k = 10
    d, i = kd_knn(*kd_build(P, 8), Q, k)
    m = min(k, n)
    d_ref, i_ref = cKDTree(P).query(Q, k=m)
    assert np.array_equal(d[:, :m], d_ref.reshape(len(Q), m))
    assert np.array_equal(i[:, :m], i_ref.reshape(len(Q), m))
    assert np.isinf(d[:, m:]).all() and (i[:, m:] == -1).all()
    # within a bound: the same list cut where the distance reaches the bound
    from relnav.geometry.kdtree import kd_knn_within

    bound = np.full(len(Q), 0.3)
    dw, iw = kd_knn_within(*kd_build(P, 8), Q, k, bound**2)
    keep = d < bound[:, None]
    assert np.array_equal(np.where(keep, d, np.inf), dw)
    assert np.array_equal(np.where(keep, i, -1), iw)


@pytest.mark.parametrize("n", [1, 9, 2000])
def test_kd_build_select_is_kd_build_tree(n):
    """The quickselect build gives kd_build's nodes and splits, the same nearest neighbours."""
    from relnav.geometry.kdtree import kd_build, kd_build_select, kd_knn, kd_query

    rng = np.random.default_rng(n)
    P = rng.normal(size=(n, 3))
    P[: n // 3] *= 0.01  # uneven density
    a, b = kd_build(P, 8), kd_build_select(P, 8)
    assert np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3])
    assert sorted(b[1]) == list(range(n)) and np.array_equal(b[0], P[b[1]])
    Q = rng.normal(size=(500, 3))
    na, nb = kd_query(*a, Q, np.eye(4), 0.5, False), kd_query(*b, Q, np.eye(4), 0.5, False)
    assert all(np.array_equal(x, y) for x, y in zip(na, nb, strict=True))
    ka, kb = kd_knn(*a, Q, 5), kd_knn(*b, Q, 5)
    assert all(np.array_equal(x, y) for x, y in zip(ka, kb, strict=True))


def test_small_kernels_match_numpy():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    A = A + A.T
    w, V = _jacobi_eigh(A)
    np.testing.assert_allclose(V @ np.diag(w) @ V.T, A, atol=1e-12)
    np.testing.assert_allclose(np.sort(w), np.linalg.eigvalsh(A), atol=1e-12)
    X = rng.normal(size=(40, 3))
    Y = transform_points(motion(rng, 120.0, 2.0), X) + 0.01 * rng.normal(size=(40, 3))
    idx = np.arange(40)
    np.testing.assert_allclose(kabsch_pairs(X, Y, idx, idx), kabsch(X, Y), atol=1e-12)
    # a mirrored planar set must still give a proper rotation
    Xp = X.copy()
    Xp[:, 2] = 0.0
    Ym = Xp * [-1.0, 1.0, 1.0]
    assert np.linalg.det(kabsch_pairs(Xp, Ym, idx, idx)[:3, :3]) == pytest.approx(1.0)
    info, _ = point_information(X, Y, idx, idx)
    ref = sum(np.hstack([np.eye(3), -hat(p)]).T @ np.hstack([np.eye(3), -hat(p)]) for p in X)
    np.testing.assert_allclose(info, ref, atol=1e-10)


def test_outlier_rules_known_answers():
    d = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 10.0])
    # mean 1.9, std 2.7: 2.5σ keeps everything but 10 (1.9 + 6.75 = 8.65)
    assert reject_outliers(d, "std", 2.5).tolist() == [True] * 9 + [False]
    d2 = np.array([0.9, 1.0, 1.1, 1.0, 1.2, 0.8, 5.0])
    # median 1.0, MAD 0.1: keep |d − 1| ≤ 0.52
    assert reject_outliers(d2, "x84", 5.2).tolist() == [True] * 6 + [False]
    assert reject_outliers(d2, "none", 0.0).all()
    rng = np.random.default_rng(2)
    for _ in range(5):  # the compiled twin used inside the ICP loop agrees
        d3 = rng.exponential(size=int(rng.integers(1, 300)))
        for code, rule, f in ((0, "none", 0.0), (1, "std", 2.5), (2, "x84", 5.2)):
            assert np.array_equal(reject_nb(d3, code, f), reject_outliers(d3, rule, f))


# --------------------------------------------------------------------------- known answers


@pytest.mark.parametrize("method", ICP_METHODS)
def test_exact_recovery_same_points(method):
    """Source = the target's own points (80 %) moved: the exact motion comes back."""
    rng = np.random.default_rng(3)
    tgt = bumpy_surface(1200, rng)
    gt = motion(rng, 3.0, 0.03)
    src = transform_points(invert(gt), tgt[rng.permutation(1200)[:960]])
    res = get_registration(method, max_iter=200).register(src, tgt)
    assert res.ok and res.converged, res.message
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < 1e-5 and disp < 1e-6
    assert res.n_correspondences == 960
    assert res.fitness > 0.95  # the 2.5σ rule trims the tail of ~1e-16 residuals
    assert res.inlier_rmse < 1e-6


@pytest.mark.parametrize(
    ("method", "tol_deg", "tol_m"),
    # point-to-point converges to a point biased by the independent samplings (≈ 1/3 of the
    # 2.5 cm spacing here, also when started AT the truth); point-to-plane does not
    [("icp-point", 0.6, 0.01), ("icp-x84", 0.6, 0.01), ("icp-plane", 0.05, 0.001)],
)
def test_recovers_small_motion_independent_sampling(method, tol_deg, tol_m, surface_pair):
    src, tgt, gt = surface_pair
    rot0, disp0 = errors(gt, np.eye(4), src)
    assert rot0 == pytest.approx(3.0) and disp0 > 0.03
    res = get_registration(method).register(src, tgt)
    assert res.ok, res.message
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < tol_deg and disp < tol_m, (rot, disp)
    assert 0.9 < res.fitness <= 1.0
    assert set(res.timings) >= {"prepare", "iterate", "evaluate"}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_small_motion_on_satellite_scans(seed):
    """Two simulated scans of Voyager, sensor moved by 4° and 4 % of the target size."""
    src, tgt, gt, extent = satellite_pair(seed, 4.0, 0.04)
    rot0, disp0 = errors(gt, np.eye(4), src)
    assert rot0 == pytest.approx(4.0) and disp0 > 0.04 * extent
    for method in ICP_METHODS:
        res = get_registration(method).register(src, tgt)
        assert res.ok, (method, res.message)
        rot, disp = errors(gt, res.T_target_source, src)
        assert rot < 1.0 and disp < 0.01 * extent, (method, rot, disp / extent)


def test_x84_rejects_gross_outliers(surface_pair):
    src, tgt, gt = surface_pair
    rng = np.random.default_rng(11)
    outliers = rng.uniform(-0.5, 0.5, (450, 3)) * [1.0, 1.0, 0.6] + [0.0, 0.0, 0.35]
    src_o = np.vstack([src, outliers])
    res = get_registration("icp-x84", max_correspondence_distance=np.inf).register(src_o, tgt)
    assert res.ok
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < 0.6 and disp < 0.01  # as good as without outliers (see above)
    assert res.n_inliers < res.n_correspondences  # the rule removed pairs
    plain = ICP("point", std_factor=0.0, max_correspondence_distance=np.inf).register(src_o, tgt)
    assert errors(gt, plain.T_target_source, src)[1] > 2 * disp  # no rule: dragged away


def test_scale_invariance_of_default_thresholds(surface_pair):
    """Scale-aware defaults: the same geometry 500× larger gives the same (scaled) motion."""
    src, tgt, _ = surface_pair
    for method in ("icp-point", "icp-plane"):
        a = get_registration(method).register(src, tgt)
        b = get_registration(method).register(500.0 * src, 500.0 * tgt)
        assert a.info["n_iterations"] == b.info["n_iterations"]
        np.testing.assert_allclose(b.T_target_source[:3, :3], a.T_target_source[:3, :3], atol=1e-9)
        np.testing.assert_allclose(
            b.T_target_source[:3, 3], 500.0 * a.T_target_source[:3, 3], rtol=1e-7, atol=1e-9
        )
        assert b.info["gate"] == pytest.approx(500.0 * a.info["gate"])


def test_paper_thresholds_are_absolute(surface_pair):
    src, tgt, _ = surface_pair
    res = get_registration("icp-point:paper").register(src, tgt)
    assert res.info["gate"] == PAPER_GATE == 0.01
    assert res.info["translation_tol"] == PAPER_TRANSLATION_TOL
    assert res.info["rotation_tol"] == PAPER_ROTATION_TOL == 0.009
    # 0.01 m is below this patch's spacing after a 3 cm motion: hardly any correspondence
    assert res.status in ("ok", "failed")
    over = get_registration("icp-point:paper", max_correspondence_distance=0.2)
    assert over.register(src, tgt).info["gate"] == 0.2


def test_prepared_equals_register(surface_pair):
    src, tgt, _ = surface_pair
    reg = get_registration("icp-plane")
    a = reg.register(src, tgt)
    b = reg.register_prepared(reg.prepare(src), reg.prepare(tgt))
    np.testing.assert_array_equal(a.T_target_source, b.T_target_source)
    assert a.n_inliers == b.n_inliers


@pytest.mark.parametrize("method", ["icp-point", "icp-plane"])
def test_covariance_matches_monte_carlo(method):
    """σ²(JᵀJ)⁻¹ (left twist [ρ, φ], target frame) agrees with the spread of estimates."""
    rng = np.random.default_rng(5)
    tgt = bumpy_surface(600, rng)
    normals = estimate_normals(tgt, k=10)
    gt = motion(rng, 1.0, 0.01)
    base = transform_points(invert(gt), tgt)
    sigma = 0.002
    reg = get_registration(method, max_correspondence_distance=0.05, max_iter=50)
    twists, covs = [], []
    for _ in range(60):
        if method == "icp-plane":  # noise along the normals only (the modelled residual)
            noise = (
                sigma
                * rng.normal(size=(600, 1))
                * transform_points(from_rt(invert(gt)[:3, :3]), normals)
            )
        else:
            noise = sigma * rng.normal(size=(600, 3))
        res = reg.register(base + noise, tgt, target_normals=normals)
        assert res.ok and res.covariance is not None
        twists.append(log_se3(res.T_target_source @ invert(gt)))
        covs.append(res.covariance)
    emp = np.cov(np.array(twists).T)
    pred = np.mean(covs, axis=0)
    assert np.allclose(pred, pred.T) and np.all(np.linalg.eigvalsh(pred) > 0)
    ratio = np.diag(emp) / np.diag(pred)
    assert np.all((ratio > 0.45) & (ratio < 2.2)), ratio


# --------------------------------------------------------------------------- Open3D oracle


@pytest.mark.parametrize("kind", ["point", "plane"])
def test_matches_open3d_icp(kind, surface_pair):
    o3d = pytest.importorskip("open3d")
    reg_mod = o3d.pipelines.registration
    src, tgt, _ = surface_pair
    normals = estimate_normals(tgt, k=10)
    gate, iters = 0.08, 25
    init = motion(np.random.default_rng(2), 1.0, 0.01)
    ps = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
    pt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt))
    pt.normals = o3d.utility.Vector3dVector(normals)
    est = (
        reg_mod.TransformationEstimationPointToPoint()
        if kind == "point"
        else reg_mod.TransformationEstimationPointToPlane()
    )
    crit = reg_mod.ICPConvergenceCriteria(
        relative_fitness=0.0, relative_rmse=0.0, max_iteration=iters
    )
    ref = reg_mod.registration_icp(ps, pt, gate, init, est, crit)
    ours = get_registration(
        f"icp-{kind}",
        open3d_compatible=True,
        max_correspondence_distance=gate,
        max_iter=iters,
        relative_fitness=0.0,
        relative_rmse=0.0,
    ).register(src, tgt, init=init, target_normals=normals)
    assert ours.ok
    np.testing.assert_allclose(ours.T_target_source, np.asarray(ref.transformation), atol=1e-6)
    assert ours.fitness == pytest.approx(ref.fitness, abs=1e-12)
    assert ours.inlier_rmse == pytest.approx(ref.inlier_rmse, rel=1e-6)
    assert ours.info["n_iterations"] == iters


# --------------------------------------------------------------------------- bad input

_GOOD = np.random.default_rng(9).normal(size=(200, 3))
_LINE = np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0])
BAD_CASES = {
    "empty": (np.zeros((0, 3)), _GOOD, None),
    "one point": (_GOOD[:1], _GOOD, None),
    "three points": (_GOOD[:3], _GOOD, None),
    "coincident": (np.ones((50, 3)), _GOOD, None),
    "collinear": (_LINE, _GOOD, None),
    "all nan": (np.full((50, 3), np.nan), _GOOD, None),
    "target empty": (_GOOD, np.zeros((0, 3)), None),
    "target collinear": (_GOOD, _LINE, None),
    "wrong shape": (_GOOD[:, :2], _GOOD, None),
    "not numeric": ([["a", "b", "c"]], _GOOD, None),
    "nan init": (_GOOD, _GOOD, np.full((4, 4), np.nan)),
    "non-rigid init": (_GOOD, _GOOD, np.diag([2.0, 1.0, 1.0, 1.0])),
    "far apart": (_GOOD + 100.0, _GOOD, None),
}


@pytest.mark.parametrize("method", ICP_METHODS)
@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_input_is_flagged_not_raised(method, case):
    src, tgt, init = BAD_CASES[case]
    res = get_registration(method).register(src, tgt, init=init)
    assert res.status in ("degenerate", "failed"), (case, res.status)
    assert res.message
    assert np.isfinite(res.T_target_source).all()
    if case == "far apart":
        assert res.status == "failed" and "gate" in res.message


@pytest.mark.parametrize("method", ICP_METHODS)
def test_partial_nan_points_are_dropped(method, surface_pair):
    src, tgt, _ = surface_pair
    dirty = src.copy()
    dirty[::50] = np.nan
    a = get_registration(method).register(dirty, tgt)
    b = get_registration(method).register(src[np.isfinite(dirty).all(axis=1)], tgt)
    assert a.ok and a.info["n_dropped_source"] == 30
    np.testing.assert_allclose(a.T_target_source, b.T_target_source, atol=1e-12)


def test_identical_clouds_give_identity(surface_pair):
    _, tgt, _ = surface_pair
    for method in ICP_METHODS:
        res = get_registration(method).register(tgt, tgt)
        assert res.ok and res.converged
        np.testing.assert_allclose(res.T_target_source, np.eye(4), atol=1e-12)


def test_point_to_plane_on_a_plane_is_degenerate():
    rng = np.random.default_rng(4)
    plane = np.column_stack([rng.uniform(-1, 1, (400, 2)), np.zeros(400)])
    moved = plane + np.array([0.01, 0.02, 0.01])
    res = get_registration("icp-plane").register(moved, plane)
    assert res.status == "degenerate" and "6 DoF" in res.message
    assert np.isfinite(res.T_target_source).all()


def test_prepare_cloud_reports_dropped_and_status():
    P = np.vstack([_GOOD, [[np.nan, 0.0, 0.0], [np.inf, 1.0, 1.0]]])
    c = prepare_cloud(P, normals="pca")
    assert c.ok and c.n_dropped == 2 and c.points.shape == (200, 3)
    assert c.normals is not None and np.isfinite(c.normals).all()
    assert np.isfinite(c.resolution) and c.resolution > 0
    assert prepare_cloud(np.ones((10, 3))).status == "degenerate"


def test_information_ratio_is_origin_free(surface_pair):
    """The degeneracy ratio does not change when the scene is 1 km from the sensor."""
    src, tgt, _ = surface_pair
    far = np.array([1000.0, -300.0, 50.0])
    a = get_registration("icp-plane").register(src, tgt)
    b = get_registration("icp-plane").register(src + far, tgt + far)
    assert a.info["information_ratio"] > 1e-3
    # (not bit-identical: normals and the ICP path see rounding of 1 km coordinates)
    assert b.info["information_ratio"] == pytest.approx(a.info["information_ratio"], rel=2e-2)
    assert information_ratio(np.eye(6), np.zeros(3), 1.0) == 1.0


@pytest.mark.parametrize("method", ["icp-point", "icp-plane"])
def test_odometry_with_prepared_clouds(method):
    """Odometry reuses prepared clouds and the motion prior; the chained poses follow truth."""
    from relnav.odometry import Odometry

    sim_targets = pytest.importorskip("relnav.sim.targets")
    sim_sensors = pytest.importorskip("relnav.sim.sensors")
    rng = np.random.default_rng(0)
    tg = sim_targets.get_target("voyager")
    sensor = sim_sensors.make_sensor("surface-hpr")
    T = look_at(np.array([3.0, 0.5, 1.0]) * tg.extent)
    step = exp_se3(np.r_[0.0, 0.02 * tg.extent, 0.0, 0.0, 0.0, np.deg2rad(2.0)])
    gt_poses, odo = [], Odometry(method, initial_pose=T)
    for _ in range(5):
        gt_poses.append(T)
        out = odo.register_frame(sensor.scan(tg, T, rng))
        T = step @ T
    assert out.status == "ok" and not out.used_prior
    rot, disp = errors(gt_poses[-1], out.pose, np.zeros((1, 3)))
    assert rot < 2.0 and disp < 0.03 * tg.extent, (rot, disp / tg.extent)
