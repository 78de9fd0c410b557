"""The map solver's registrations from several starts (``MapSolver.solve_starts``): the first
from the prediction, the others only when that one is usable, the same in one or two threads."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.geometry.lie import exp_se3
from relnav.navigation.gicp import left_information
from relnav.navigation.multistart import rotated_starts
from relnav.navigation.options import navigator_config
from relnav.navigation.repeated import RepeatedPoints
from relnav.navigation.solver import MapSolver, point_spacing


def _box(rng: np.random.Generator, n: int = 600) -> np.ndarray:
    """Points on three faces of a 4 × 3 × 2 m box (sensor frame, 20 m ahead), 1 cm noise."""
    u = rng.uniform(-0.5, 0.5, size=(n, 2))
    face = rng.integers(0, 3, size=n)
    P = np.zeros((n, 3))
    P[face == 0] = np.c_[u[face == 0] * [4, 3], np.full((face == 0).sum(), -1.0)]
    P[face == 1] = np.c_[u[face == 1, 0] * 4, np.full((face == 1).sum(), -1.5), u[face == 1, 1] * 2]
    P[face == 2] = np.c_[np.full((face == 2).sum(), -2.0), u[face == 2] * [3, 2]]
    return P + np.array([0.0, 0.0, 20.0]) + rng.normal(scale=0.01, size=P.shape)


def _solver(threads: int, P_map: np.ndarray, screen: int = 1) -> MapSolver:
    config = navigator_config({"solver.threads": threads, "prior.jitter_screen": screen})
    solver = MapSolver(config, RepeatedPoints(config.solver))
    solver.spacing0 = point_spacing(P_map)
    solver.map = solver.new_map()
    solver.map.insert(P_map, 0)
    solver.first_sigma = (1.0, 0.1)
    return solver


def _prior(T: np.ndarray) -> np.ndarray:
    return left_information(T, np.diag([0.1**2] * 3 + [np.radians(2.0) ** 2] * 3))


@pytest.mark.parametrize("threads", [1, 2])
def test_every_start_is_answered_in_order_when_the_first_is_usable(threads):
    rng = np.random.default_rng(4)
    P_map, P = _box(rng), _box(rng)
    T_true = exp_se3(np.array([0.05, -0.03, 0.02, 0.0, 0.01, -0.005]))
    T_pred, Lam = np.eye(4), _prior(np.eye(4))
    starts = rotated_starts(T_pred, np.radians(0.5), 1)
    solver = _solver(threads, P_map)
    answers = solver.solve_starts(
        P @ T_true[:3, :3].T + T_true[:3, 3], T_pred, Lam, 3.0, 20.0, 2.0, Lam, starts
    )
    assert len(answers) == 1 + len(starts) and answers[0]["usable"]
    # the first is the plain registration from the prediction, the others from their starts
    alone = _solver(1, P_map).solve(
        P @ T_true[:3, :3].T + T_true[:3, 3], T_pred, Lam, 3.0, 20.0, 2.0, Lam_fit=Lam
    )
    np.testing.assert_array_equal(answers[0]["T"], alone["T"])
    single = _solver(1, P_map).solve_starts(
        P @ T_true[:3, :3].T + T_true[:3, 3], T_pred, Lam, 3.0, 20.0, 2.0, Lam, starts
    )
    for a, b in zip(answers, single, strict=True):
        np.testing.assert_array_equal(a["T"], b["T"])
        assert a["rms"] == b["rms"] or (np.isnan(a["rms"]) and np.isnan(b["rms"]))


@pytest.mark.parametrize("threads", [1, 2])
def test_an_unusable_first_answer_stands_alone(threads):
    rng = np.random.default_rng(5)
    P_map = _box(rng)
    far = _box(rng) + np.array([500.0, 0.0, 0.0])  # nowhere near the map
    T_pred, Lam = np.eye(4), _prior(np.eye(4))
    starts = rotated_starts(T_pred, np.radians(0.5), 1)
    answers = _solver(threads, P_map).solve_starts(far, T_pred, Lam, 3.0, 20.0, 2.0, Lam, starts)
    assert len(answers) == 1 and not answers[0]["usable"]


@pytest.mark.parametrize("threads", [1, 2])
def test_screened_starts_are_the_best_fitting_subset_answers_registered_on_the_whole_scan(
    threads,
):
    """With ``prior.jitter_screen`` = 3 every start is registered on every third scan point;
    the ``jitter_screen_keep`` (2) of lowest robust RMS there are registered on the whole scan
    from where they ended, and only they follow the first answer."""
    rng = np.random.default_rng(6)
    P_map, P = _box(rng), _box(rng)
    T_true = exp_se3(np.array([0.05, -0.03, 0.02, 0.0, 0.01, -0.005]))
    Q = P @ T_true[:3, :3].T + T_true[:3, 3]
    T_pred, Lam = np.eye(4), _prior(np.eye(4))
    starts = rotated_starts(T_pred, np.radians(1.0), 2)
    solver = _solver(threads, P_map, screen=3)
    answers = solver.solve_starts(Q, T_pred, Lam, 3.0, 20.0, 2.0, Lam, starts)
    assert len(answers) == 1 + 2 and all(a["usable"] for a in answers)
    ref = _solver(1, P_map, screen=3)
    info = ref.map.information
    sub = [ref.register_on_map(Q[::3], info, S, T_pred, Lam, 3.0, 20.0) for S in starts]
    rms = np.array([f.rms for f in sub])
    assert len(np.unique(rms)) > 1  # the starts did end in different places
    for a, j in zip(answers[1:], np.argsort(rms, kind="stable")[:2], strict=True):
        whole = ref.register_on_map(Q, info, sub[j].T, T_pred, Lam, 3.0, 20.0)
        np.testing.assert_array_equal(a["T"], whole.T)
