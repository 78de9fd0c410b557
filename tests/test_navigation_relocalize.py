"""Relocalisation of relnav's navigator: a kidnapped navigator, unrelated scans, no-loss runs."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from nav_scenarios import flash_orbit
from relnav.errors import ConfigError
from relnav.geometry.se3 import invert
from relnav.navigation import Navigator
from relnav.navigation.relocalize import max_clique
from relnav.scan import Scan
from relnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def orbit(tmp_path_factory):
    from relnav.io.sequences import ScanSequence

    out = tmp_path_factory.mktemp("reloc") / "seq"
    simulate(flash_orbit("reloc-test", max_frames=36), out)
    return ScanSequence(out)


@pytest.fixture(scope="module")
def other_target(tmp_path_factory):
    """Scans of an unrelated object (a satellite) from the same orbit."""
    from relnav.io.sequences import ScanSequence

    out = tmp_path_factory.mktemp("reloc") / "other"
    simulate(
        flash_orbit("reloc-other", max_frames=6, target={"name": "envisat", "scale_to": 14.0}), out
    )
    return ScanSequence(out)


def _error(T: np.ndarray, G: np.ndarray) -> tuple[float, float]:
    e = invert(G) @ T
    c = np.clip((np.trace(e[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.linalg.norm(e[:3, 3])), math.degrees(math.acos(c))


def _run(seq, frames, **options):
    """Navigator over ``frames``, re-timed one frame period apart (a gap is then a kidnap)."""
    nav = Navigator(initial_pose=seq.gt_poses[frames[0]], **options)
    dt = float(seq.timestamps[1] - seq.timestamps[0])
    steps = [
        nav.register_frame(Scan(points=seq[k].points, time=i * dt)) for i, k in enumerate(frames)
    ]
    return nav, steps


KIDNAP = list(range(0, 15)) + list(range(25, 36))  # 10 frames (36° of orbit, ~35 m) missing


@pytest.mark.parametrize("method", ["clique", "gcc"])
def test_kidnapped_navigator_is_relocalised(orbit, method):
    gt = orbit.gt_poses
    i0 = KIDNAP.index(25)
    _, off = _run(orbit, KIDNAP, **{"reloc.enabled": False})
    # without relocalisation the navigator tracks a corrupted map: tens of metres off
    assert _error(off[-1].pose, gt[KIDNAP[-1]])[0] > 10.0
    nav, on = _run(orbit, KIDNAP, **{"reloc.method": method})
    first = [
        i for i, s in enumerate(on) if s.result is not None and s.result.info.get("relocalised")
    ]
    assert first and first[0] - i0 <= 3
    assert "relocalise" in on[first[0]].result.timings
    assert on[first[0]].status == "ok" and on[first[0]].result.message.startswith("relocalised")
    for i in range(first[0] + 1, len(KIDNAP)):  # back on track: within 0.5 m and 5°
        et, er = _error(on[i].pose, gt[KIDNAP[i]])
        assert et < 0.5 and er < 5.0, (i, et, er)
    assert len(nav.finalize()) == len(KIDNAP)


def _attempted(steps) -> int:
    return sum("relocalise" in s.result.timings for s in steps if s.result is not None)


def test_random_points_do_not_relocalise(orbit):
    rng = np.random.default_rng(7)
    nav, steps = _run(orbit, list(range(12)))
    for _ in range(8):
        pts = rng.normal(size=(250, 3)) * 5.0 + [50.0, 0.0, 0.0]
        steps.append(nav.register_frame(pts))
    assert _attempted(steps) >= 2  # the navigator did try
    assert not any(s.result.info.get("relocalised") for s in steps[12:])
    assert all(s.status != "ok" for s in steps[12:])


def test_attempts_are_spaced_while_lost(orbit):
    rng = np.random.default_rng(3)
    junk = [rng.normal(size=(250, 3)) * 5.0 + [50.0, 0.0, 0.0] for _ in range(9)]
    counts = []
    for every in (1, 3):
        nav, steps = _run(orbit, list(range(12)), **{"reloc.every": every})
        steps += [nav.register_frame(p) for p in junk]
        counts.append(_attempted(steps))
    assert counts[0] >= 6 and counts[1] < counts[0]


def test_unrelated_object_does_not_relocalise(orbit, other_target):
    nav, steps = _run(orbit, list(range(12)))
    for k in range(len(other_target)):
        steps.append(nav.register_frame(other_target[k].points))
    assert _attempted(steps) >= 1
    assert not any(s.result.info.get("relocalised") for s in steps[12:])


def test_no_loss_no_relocalisation(orbit):
    frames = list(range(24))
    nav_on, on = _run(orbit, frames)
    nav_off, off = _run(orbit, frames, **{"reloc.enabled": False})
    assert _attempted(on) == 0
    np.testing.assert_array_equal(np.stack([s.pose for s in on]), np.stack([s.pose for s in off]))
    np.testing.assert_array_equal(nav_on.finalize(), nav_off.finalize())


def _brute_clique(A: np.ndarray) -> int:
    n = len(A)
    for size in range(n, 0, -1):
        for c in itertools.combinations(range(n), size):
            if all(A[a, b] for a, b in itertools.combinations(c, 2)):
                return size
    return 0


@pytest.mark.parametrize("seed", range(6))
def test_max_clique_is_maximum(seed):
    rng = np.random.default_rng(seed)
    n = 14
    A = rng.random((n, n)) < 0.35
    planted = rng.choice(n, 5, replace=False)
    A[np.ix_(planted, planted)] = True
    A = A | A.T
    np.fill_diagonal(A, False)
    members, exact = max_clique(A)
    assert exact
    assert len(members) == _brute_clique(A)
    assert all(A[a, b] for a, b in itertools.combinations(members, 2))


def test_max_clique_empty_and_bounded():
    members, exact = max_clique(np.zeros((0, 0), bool))
    assert members.size == 0 and exact
    A = np.ones((40, 40), bool)
    np.fill_diagonal(A, False)
    members, exact = max_clique(A, max_nodes=5)
    assert not exact and len(members) >= 2


def test_bad_relocalisation_options():
    with pytest.raises(ConfigError, match="unknown descriptor"):
        Navigator(reloc={"descriptor": "nope"})
    with pytest.raises(ConfigError, match=r"reloc\.method"):
        Navigator(reloc={"method": "ransac"})
    with pytest.raises(ConfigError, match=r"reloc\.lost_after"):
        Navigator(reloc={"lost_after": 0})
