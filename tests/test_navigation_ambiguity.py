"""The navigator's ambiguity flag (``integrity.ambiguity_rms``): two registration answers that fit
the scan about equally well but lie farther apart than the flag limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry.rotations import rotvec_to_matrix
from relnav.navigation.integrity import ambiguity, disagreement
from relnav.navigation.options import navigator_config
from relnav.registration.result import RegistrationResult


def _answer(t=(0.0, 0.0, 0.0), yaw_deg: float = 0.0, rms: float = 1.0, usable: bool = True):
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(np.array([0.0, 0.0, math.radians(yaw_deg)]))
    T[:3, 3] = t
    return {"T": T, "rms": rms, "usable": usable}


CONFIG = navigator_config({"integrity.ambiguity_rms": 1.02})


def test_an_almost_as_good_answer_beyond_the_limits_is_ambiguous():
    best = _answer(rms=1.0)
    far = _answer(t=(0.8, 0.0, 0.0), rms=1.01)  # 0.8 m away, 1 % worse
    info = ambiguity(best, [best, _answer(t=(0.1, 0, 0), rms=1.0), far], CONFIG)
    assert info["ambiguity_t"] == pytest.approx(0.8)
    assert info["ambiguity_rms_ratio"] == pytest.approx(1.01)
    # a rotation beyond 5° counts as well
    info = ambiguity(best, [best, _answer(yaw_deg=7.0, rms=1.015)], CONFIG)
    assert info["ambiguity_r_deg"] == pytest.approx(7.0)
    # and the step is flagged with the reason
    result = RegistrationResult(T_target_source=best["T"], fitness=1.0, info=dict(info))
    assert disagreement(result, CONFIG).startswith("ambiguous")


@pytest.mark.parametrize(
    "other",
    [
        _answer(t=(0.8, 0.0, 0.0), rms=1.05),  # clearly worse fit
        _answer(t=(0.3, 0.0, 0.0), yaw_deg=3.0, rms=1.0),  # within both flag limits
        _answer(t=(0.8, 0.0, 0.0), rms=1.0, usable=False),  # not a usable answer
    ],
)
def test_worse_near_or_unusable_answers_are_not(other):
    best = _answer(rms=1.0)
    info = ambiguity(best, [best, other], CONFIG)
    assert info == {}
    assert (
        disagreement(RegistrationResult(T_target_source=best["T"], fitness=1.0, info=info), CONFIG)
        == ""
    )


def test_on_by_default_and_checked():
    assert navigator_config({}).integrity.ambiguity_rms == 1.02
    assert navigator_config({"integrity.ambiguity_rms": 0}).integrity.ambiguity_rms == 0.0
    with pytest.raises(ConfigError):
        navigator_config({"integrity.ambiguity_rms": -1.0})
