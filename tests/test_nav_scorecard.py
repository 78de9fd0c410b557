"""The navigation suite's scorecard: relnav against its targets, sequence by sequence."""

from __future__ import annotations

import math

import numpy as np

from relnav.bench.nav_suite import TARGETS, relnav_ratios, scorecard, scorecard_table


def _result(ape, rpe_t, rpe_r, ms, wrong=0, wrong_flagged=0, right_flagged=0, n=100):
    return {
        "ape": ape,
        "rpe_t": rpe_t,
        "rpe_r": rpe_r,
        "ms": ms,
        "wall_s": ms / 10,
        "n_steps": n,
        "wrong": wrong,
        "wrong_flagged": wrong_flagged,
        "right_flagged": right_flagged,
    }


def test_each_metric_is_compared_with_its_own_best_peer_and_misses_are_named():
    results = {
        "good": {
            "relnav": _result(1.0, 0.1, 0.1, 1.0, wrong=10, wrong_flagged=10, right_flagged=1),
            "kiss-icp": _result(2.0, 0.5, 0.2, 1.0),
            "small-gicp": _result(5.0, 0.2, 0.9, 0.5),
            "icp-plane": _result(0.1, 0.01, 0.01, 0.1),  # relnav's own baseline: not a peer
        },
        "bad": {
            "relnav": _result(1.0, 0.3, 0.1, 2.0, wrong=10, wrong_flagged=8, right_flagged=6),
            "kiss-icp": _result(1.2, 0.4, 0.2, 1.0),
            "o3d-fpfh-ransac": {"error": "ImportError: no open3d"},
        },
    }
    rows = {r["sequence"]: r for r in scorecard(results)}
    good, bad = rows["good"], rows["bad"]
    assert math.isclose(good["rpe_t"], 0.1 / 0.2) and math.isclose(good["rpe_r"], 0.5)
    assert good["best"] == "kiss-icp" and good["misses"] == []
    assert math.isclose(good["right_flagged"], 1 / 90)
    assert math.isclose(bad["ape"], 1.0 / 1.2)
    assert bad["misses"] == ["ape", "rpe_t", "wrong_flagged", "right_flagged", "time"]
    table = scorecard_table(results)
    assert "| bad | **0.83** |" in table and "**80% of 10**" in table
    assert TARGETS["ratio"] == 0.7


def test_a_sequence_without_relnav_or_peers_is_left_out_and_no_wrong_step_is_no_miss():
    results = {
        "peers only": {"kiss-icp": _result(1.0, 0.1, 0.1, 1.0)},
        "relnav only": {"relnav": _result(1.0, 0.1, 0.1, 1.0)},
        "clean": {"relnav": _result(0.1, 0.01, 0.01, 1.0), "kiss-icp": _result(1, 1, 1, 1.0)},
        "lost": {"relnav": _result(9, 9, 9, 1.0, wrong=100), "kiss-icp": _result(9, 9, 9, 1.0)},
    }
    assert relnav_ratios(results["peers only"]) is None
    rows = scorecard(results)
    assert [r["sequence"] for r in rows] == ["clean", "lost"]
    assert math.isnan(rows[0]["wrong_flagged"]) and rows[0]["misses"] == []
    assert math.isnan(rows[1]["right_flagged"])
    assert rows[1]["misses"] == ["ape", "rpe_t", "rpe_r", "wrong_flagged"]
    table = scorecard_table(results)
    assert "no wrong step" in table and "no right step" in table


def test_run_method_returns_each_steps_evidence_beside_its_verdict(tmp_path):
    """``per_step`` gives, for every step, the navigator's truth-free evidence (the flag
    studies' input) aligned with the suite's wrong/flagged verdict."""
    from relnav.bench.nav_suite import EVIDENCE, run_method
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    simulate(get_preset("sim-voyager", max_frames=6, seed=1), tmp_path / "seq")
    steps = run_method(tmp_path / "seq", "relnav", per_step=True)["steps"]
    n = len(steps["wrong"])
    assert n == 5 and len(steps["flagged"]) == n
    assert set(steps["evidence"]) == {*EVIDENCE, "fitness"}
    assert all(len(v) == n for v in steps["evidence"].values())
    for key in ("error_t", "error_r", "sigma_t", "sigma_r"):  # the step's error and its own 1σ
        assert len(steps[key]) == n and np.all(steps[key] >= 0), key
    assert np.array_equal(steps["wrong"], (steps["error_t"] > 0.5) | (steps["error_r"] > 5.0))
    ev = steps["evidence"]
    assert np.all(np.isfinite(ev["step_sigma_t"])) and np.all(ev["step_sigma_t"] > 0)
    assert np.all((ev["fitness"] >= 0) & (ev["fitness"] <= 1))
