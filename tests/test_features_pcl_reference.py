"""relnav descriptors against PCL 1.13 on the committed fixture ``tests/data/pcl``.

The fixture (two procedural-target clouds, 1 500 float32 surface samples with exact normals,
150 keypoints each, radius 10·Tr) and PCL's outputs were written by
``benchmarks/paper1/pcl_reference/regenerate.py`` (see its docstring; PCL is not needed here). The
bar is a median per-keypoint Pearson correlation ≥ 0.99 on each cloud (issue 16).

RoPS has two PCL references: ``rops`` (PCL's ``ROPSEstimation`` on PCL's greedy-projection mesh)
and ``rops_local`` (PCL's ``ROPSEstimation`` at each keypoint alone, given that keypoint's local
triangles exactly as relnav's default builds them, ``rops_local_triangles``): the like-for-like
reference of the default ``rops``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relnav.features.fpfh import fpfh
from relnav.features.rops import rops
from relnav.features.shot import shot
from relnav.features.trisi import spin
from relnav.geometry.lrf import rops_local_mesh

FIXTURE = Path(__file__).parent / "data" / "pcl" / "pcl_reference.npz"
CLOUDS = ("voyager", "asteroid")
MEDIAN_MIN = 0.99


@pytest.fixture(scope="module")
def ref() -> dict[str, np.ndarray]:
    with np.load(FIXTURE) as z:
        return {k: z[k] for k in z.files}


def _cloud(ref: dict[str, np.ndarray], c: str):
    P = ref[f"{c}/points"].astype(np.float64)
    N = ref[f"{c}/normals"].astype(np.float64)
    return P, N, ref[f"{c}/keypoints"].astype(np.int64), float(ref[f"{c}/radius"])


def correlations(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-row Pearson correlation of the rows finite in both (≥ 90 % of the rows must be)."""
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    assert ok.mean() >= 0.9, f"only {ok.sum()} of {len(ok)} rows finite in both"
    x = a[ok].astype(np.float64)
    y = b[ok].astype(np.float64)
    x -= x.mean(axis=1, keepdims=True)
    y -= y.mean(axis=1, keepdims=True)
    return (x * y).sum(axis=1) / np.sqrt((x * x).sum(axis=1) * (y * y).sum(axis=1))


def test_fixture_is_small_and_complete(ref) -> None:
    assert FIXTURE.stat().st_size < 1_000_000
    for c in CLOUDS:
        K = ref[f"{c}/keypoints"].shape[0]
        for key, dim in (
            ("spin", 153),
            ("rops", 135),
            ("rops_local", 135),
            ("fpfh", 33),
            ("shot", 352),
        ):
            assert ref[f"{c}/{key}"].shape == (K, dim)
        assert ref[f"{c}/triangles"].shape[1] == 3
        off = ref[f"{c}/rops_local_offsets"]
        assert off.shape == (K + 1,) and off[-1] == ref[f"{c}/rops_local_triangles"].shape[0]


@pytest.mark.parametrize("c", CLOUDS)
def test_spin_pcl_layout_equals_pcl(ref, c: str) -> None:
    P, N, kp, r = _cloud(ref, c)
    cc = correlations(spin(P, kp, radius=r, normals=N, layout="pcl", width=8), ref[f"{c}/spin"])
    assert np.median(cc) >= MEDIAN_MIN
    # every rule of PCL is reproduced: not only the median, every keypoint
    assert cc.min() >= 0.999
    # the "guo" layout is a different descriptor (length 225): not comparable, and the old
    # relnav grid (r/w spacing, sphere, β-major) is far from PCL's
    assert spin(P, kp[:3], radius=r, normals=N).shape == (3, 225)


@pytest.mark.parametrize("c", CLOUDS)
def test_rops_on_pcl_mesh_equals_pcl(ref, c: str) -> None:
    P, _, kp, r = _cloud(ref, c)
    D = rops(P, kp, radius=r, triangles=ref[f"{c}/triangles"])
    cc = correlations(D, ref[f"{c}/rops"])
    assert np.median(cc) >= MEDIAN_MIN and np.percentile(cc, 5) >= MEDIAN_MIN


@pytest.mark.parametrize("c", CLOUDS)
def test_default_rops_equals_pcl_on_the_same_local_mesh(ref, c: str) -> None:
    """Default RoPS (``lrf="local_mesh"``) against PCL's RoPS on the same local triangles.

    Measured: correlation 1.0000 on every keypoint of both clouds (min > 1 − 1e-13).
    """
    P, _, kp, r = _cloud(ref, c)
    off = ref[f"{c}/rops_local_offsets"].astype(np.int64)
    tris = ref[f"{c}/rops_local_triangles"].astype(np.int64)
    # the fixture's triangles are still the ones the default builds (else: regenerate.py)
    got_off, got_tris = rops_local_mesh(P, kp, r)
    np.testing.assert_array_equal(got_off, off)
    np.testing.assert_array_equal(got_tris, tris)
    cc = correlations(rops(P, kp, radius=r), ref[f"{c}/rops_local"])
    assert cc.size == kp.size
    assert np.median(cc) >= MEDIAN_MIN and np.percentile(cc, 5) >= MEDIAN_MIN
    assert cc.min() >= 0.999


@pytest.mark.parametrize("c", CLOUDS)
def test_rops_on_each_local_mesh_equals_pcl(ref, c: str) -> None:
    """The fixture's triangles of each keypoint as ``triangles=``: PCL's ``rops_local`` row.

    Independent of how relnav triangulates (the triangles are read from the fixture).
    """
    P, _, kp, r = _cloud(ref, c)
    off = ref[f"{c}/rops_local_offsets"]
    tris = ref[f"{c}/rops_local_triangles"]
    D = np.vstack(
        [
            rops(P, kp[k : k + 1], radius=r, triangles=tris[off[k] : off[k + 1]])
            for k in range(kp.size)
        ]
    )
    cc = correlations(D, ref[f"{c}/rops_local"])
    assert np.median(cc) >= MEDIAN_MIN and cc.min() >= 0.999


@pytest.mark.parametrize("c", CLOUDS)
def test_rops_without_pcl_mesh_is_close_but_not_equal(ref, c: str) -> None:
    """Default (local mesh) and point frames against PCL's RoPS on PCL's greedy mesh: not equal.

    Measured median 0.9347 (voyager) and 0.9531 (asteroid) for the default, 0.9391 / 0.9530 for
    ``lrf="points"``: the RoPS x axis (largest scatter eigenvalue) depends on which triangles
    cover the support, so another triangulation of the same points gives another descriptor —
    PCL against itself with greedy-projection mu = 4 instead of 2.5 correlates 0.94-0.95 on these
    clouds, and PCL on relnav's local meshes (``rops_local``, equal to relnav's default) against
    PCL on its greedy mesh is the default's 0.93-0.95. This guards the measured level.
    """
    P, _, kp, r = _cloud(ref, c)
    for lrf in ("local_mesh", "points"):
        cc = correlations(rops(P, kp, radius=r, lrf=lrf), ref[f"{c}/rops"])
        assert np.median(cc) >= 0.9


@pytest.mark.parametrize("c", CLOUDS)
def test_fpfh_and_shot_equal_pcl(ref, c: str) -> None:
    P, N, kp, r = _cloud(ref, c)
    cf = correlations(fpfh(P, kp, radius=r, normals=N), ref[f"{c}/fpfh"])
    cs = correlations(shot(P, kp, radius=r, normals=N, layout="pcl"), ref[f"{c}/shot"])
    assert np.median(cf) >= MEDIAN_MIN and np.median(cs) >= MEDIAN_MIN
