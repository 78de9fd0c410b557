"""Local 2D Delaunay triangulation (``relnav.geometry.local_mesh``) against scipy's Qhull."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from relnav.geometry.local_mesh import delaunay_2d


def _tri_set(t: np.ndarray) -> set[tuple[int, ...]]:
    return set(map(tuple, np.sort(t, axis=1).tolist()))


@pytest.mark.parametrize("n", [3, 4, 10, 60, 250])
def test_equals_qhull_on_random_points(n: int) -> None:
    uv = np.random.default_rng(n).normal(size=(n, 2)) * 1e-3 + 7.0  # offset and tiny scale
    got = delaunay_2d(uv)
    assert _tri_set(got) == _tri_set(Delaunay(uv).simplices)
    a = uv[got]
    cross = (a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1]) - (a[:, 1, 1] - a[:, 0, 1]) * (
        a[:, 2, 0] - a[:, 0, 0]
    )
    assert (cross > 0).all()  # counter-clockwise


def test_spatially_sorted_input() -> None:
    uv = np.random.default_rng(5).random((400, 2))
    uv = uv[np.lexsort(uv.T)]  # as a grid radius search returns points
    assert _tri_set(delaunay_2d(uv)) == _tri_set(Delaunay(uv).simplices)


def test_regular_grid_covers_the_square() -> None:
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(5.0)), axis=-1).reshape(-1, 2)
    t = delaunay_2d(g)
    a = g[t]
    area = 0.5 * np.abs(
        (a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
        - (a[:, 1, 1] - a[:, 0, 1]) * (a[:, 2, 0] - a[:, 0, 0])
    )
    assert len(t) == 2 * 5 * 4 and area.sum() == pytest.approx(20.0)


def test_degenerate_sets() -> None:
    assert delaunay_2d(np.zeros((0, 2))).shape == (0, 3)
    assert delaunay_2d(np.zeros((2, 2))).shape == (0, 3)
    assert delaunay_2d(np.ones((5, 2))).shape == (0, 3)  # all coincident
    assert delaunay_2d(np.c_[np.arange(6.0), 2 * np.arange(6.0)]).shape == (0, 3)  # collinear
    uv = np.random.default_rng(1).random((30, 2))
    dup = np.vstack([uv, uv[:5]])  # duplicates are skipped, not triangulated twice
    t = delaunay_2d(dup)
    t = np.where(t >= 30, t - 30, t)  # either copy of a duplicate may be the vertex
    assert _tri_set(t) == _tri_set(Delaunay(uv).simplices)
