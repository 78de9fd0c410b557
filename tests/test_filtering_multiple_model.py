"""A bank of filters weighed by their innovations' likelihood (relnav.filtering.multiple_model)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import multivariate_normal

from relnav.errors import InputError
from relnav.filtering.multiple_model import mix_tracks, model_probabilities
from relnav.filtering.pose_filter import UpdateInfo
from relnav.filtering.track_result import TrackResult


def test_update_log_likelihood_is_the_gaussian_density(rng):
    A = rng.normal(size=(6, 6))
    S = A @ A.T + np.eye(6)
    nu = rng.normal(size=6)
    info = UpdateInfo(True, float(nu @ np.linalg.solve(S, nu)), nu, "", S, np.eye(6))
    expected = multivariate_normal(np.zeros(6), S).logpdf(nu)
    assert info.log_likelihood == pytest.approx(expected, rel=1e-12)
    assert np.isnan(UpdateInfo(False, message="rejected early").log_likelihood)


def test_model_probabilities_follow_the_evidence_with_a_floor():
    K = 50
    L = np.column_stack([np.full(K, -1.0), np.full(K, -2.0), np.full(K, np.nan)])
    L[:5] = np.nan  # no evidence yet: equal weights
    L[10, 2] = -0.5  # the third member has an update only once: scored like the worst
    P = model_probabilities(L, floor=1e-3)
    np.testing.assert_allclose(P.sum(axis=1), 1.0)
    np.testing.assert_allclose(P[:5], 1.0 / 3.0)
    assert P[-1, 0] > 0.99 and P[-1, 1] >= 1e-3 * 0.99 and P[-1, 2] >= 1e-3 * 0.99
    # one step of evidence: Bayes' rule from equal priors
    p = model_probabilities(np.array([[0.0, np.log(0.5)]]), floor=0.0)
    np.testing.assert_allclose(p[0], [2.0 / 3.0, 1.0 / 3.0])
    # a member that lost comes back when the evidence turns (the floor prevents lock-in)
    turn = np.vstack([np.tile([-1.0, -3.0], (40, 1)), np.tile([-3.0, -1.0], (10, 1))])
    assert model_probabilities(turn, floor=1e-3)[-1, 1] > 0.9
    assert model_probabilities(turn, floor=0.0)[-1, 1] < 1e-6
    with pytest.raises(InputError):
        model_probabilities(np.zeros(5))
    with pytest.raises(InputError):
        model_probabilities(np.zeros((5, 2)), floor=0.5)


def _track(K: int, pos: np.ndarray, quat: np.ndarray, var: float, ll: np.ndarray) -> TrackResult:
    z3 = np.zeros((K, 3))
    return TrackResult(
        time=np.arange(K, dtype=float),
        position=np.tile(pos, (K, 1)),
        velocity=z3.copy(),
        quat=np.tile(quat, (K, 1)),
        omega=z3.copy(),
        covariance=np.tile(np.eye(12) * var, (K, 1, 1)),
        status=["update"] * K,
        nis=np.ones(K),
        observed=np.full((K, 7), np.nan),
        filter="ukf",
        log_likelihood=ll,
    )


def test_mix_tracks_is_the_moment_matched_mixture():
    K = 3
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    q1 = Rotation.from_rotvec([0.0, 0.0, 0.02]).as_quat()
    a = _track(K, np.array([0.0, 0.0, 0.0]), q0, 1e-4, np.array([np.nan, 0.0, 0.0]))
    b = _track(K, np.array([1.0, 0.0, 0.0]), q1, 4e-4, np.array([np.nan, np.log(1 / 3), 0.0]))
    m = mix_tracks([a, b], ["a", "b"], floor=0.0)
    w = m.model_probability[1]
    np.testing.assert_allclose(w, [0.75, 0.25])
    np.testing.assert_allclose(m.position[1], [0.25, 0.0, 0.0])
    # attitude: averaged in the tangent space, 1/4 of the way to b
    np.testing.assert_allclose(Rotation.from_quat(m.quat[1]).as_rotvec(), [0, 0, 0.005], atol=1e-12)
    # covariance: the members' average plus their spread about the mean
    assert m.covariance[1][0, 0] == pytest.approx(0.75 * 1e-4 + 0.25 * 4e-4 + 0.75 * 0.25)
    assert m.covariance[1][8, 8] == pytest.approx(
        0.75 * 1e-4 + 0.25 * 4e-4 + 0.75 * 0.25 * 0.02**2, rel=1e-9
    )
    assert m.meta["models"] == ["a", "b"] and m.status[1] == "update"
    # the mixture's predictive likelihood of step 1 (equal priors)
    assert m.log_likelihood[1] == pytest.approx(np.log(0.5 * 1.0 + 0.5 / 3.0))
    # identical members: the mixture is each of them
    same = mix_tracks([a, a])
    np.testing.assert_allclose(same.position, a.position)
    np.testing.assert_allclose(same.covariance, a.covariance)
    with pytest.raises(InputError):
        mix_tracks([a, _track(2, np.zeros(3), q0, 1e-4, np.zeros(2))])
    with pytest.raises(InputError):
        mix_tracks([a, b], ["only one label"])


def test_a_bank_of_trackers_prefers_the_model_that_generated_the_data(tmp_path):
    """Constant-rate observations: a bank of a tight and a loose process noise ends on the tight
    one; the likelihoods are those of the updates; the CSV carries the probabilities."""
    import csv

    from relnav.filtering.tracker import Tracker
    from relnav.fusion.observers import simulate_observations

    t, obs, truth = simulate_observations(30, 4.5, seed=3)
    loose = {"position": 1e-2, "velocity": 1e-2, "attitude": 0.05, "omega": 0.02}
    tight = {"position": 1e-4, "velocity": 1e-4, "attitude": 4e-3, "omega": 1e-4}
    bank = [Tracker("ukf", q=q).run(t, obs, truth=truth) for q in (loose, tight)]
    for r in bank:
        upd = r.updated
        assert np.all(np.isfinite(r.log_likelihood[upd])) and np.all(
            np.isnan(r.log_likelihood[~upd])
        )
    m = mix_tracks(bank, ["loose", "tight"])
    assert m.model_probability[-1, 1] > 0.9
    rows = list(csv.DictReader(m.to_csv(tmp_path / "m.csv").open()))
    assert {"log_likelihood", "p_model0", "p_model1"} <= set(rows[0])
    assert float(rows[-1]["p_model1"]) == pytest.approx(m.model_probability[-1, 1], rel=1e-6)


def test_an_observation_the_most_probable_member_rejects_is_no_evidence():
    """model_probabilities(rejected=…): a step the leading member gated leaves the
    probabilities as they were, however much better a looser member scored it; a step only a
    trailing member gated still counts; mix_tracks reads the rejections from the statuses."""
    L = np.array([[-1.0, -3.0], [-30.0, -2.0], [-1.0, -3.0]])  # step 1: an outlier
    rejected = np.array([[False, False], [True, False], [False, False]])
    plain = model_probabilities(L, floor=1e-3)
    held = model_probabilities(L, floor=1e-3, rejected=rejected)
    assert plain[1, 1] > 0.99  # scored like any step, the outlier hands over the bank
    np.testing.assert_allclose(held[1], held[0])  # no evidence
    assert held[2, 0] > held[0, 0]
    counted = model_probabilities(L, floor=1e-3, rejected=rejected[:, ::-1])
    np.testing.assert_allclose(counted, plain)  # the trailing member's rejection counts
    with pytest.raises(InputError):
        model_probabilities(L, rejected=np.zeros((2, 2), dtype=bool))
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    a = _track(3, np.zeros(3), q0, 1e-4, L[:, 0])
    b = _track(3, np.zeros(3), q0, 1e-4, L[:, 1])
    a.status[1] = "flagged: gated (NIS 40.0 > χ²_6(0.999))"
    np.testing.assert_allclose(mix_tracks([a, b]).model_probability, held)
