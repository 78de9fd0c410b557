"""The relative state after the run (``relnav odometry``'s ``state.csv``): the navigator's poses
through paper 2's twistor UKF with Clohessy–Wiltshire dynamics, the target's body rates and
inertia (:mod:`.relative`, :mod:`.inertia`, :mod:`.rigid_body`) and the fit of its noise scales
(:mod:`.noise_fit`)."""

from relnav.navigation.state.relative import (
    STATE_PRESETS,
    TORQUE_FREE_SHARES,
    StateRecord,
    check_state_options,
    drift_covariance,
    map_drift_shares,
    map_offset_rotation,
    measurement_covariance,
    nees_band,
    pose_noise,
    relative_state,
    scale_drift,
    split_rotation_drift,
    startup_bias,
    state_options,
    with_map_rotation_offset,
)

__all__ = [
    "STATE_PRESETS",
    "StateRecord",
    "TORQUE_FREE_SHARES",
    "check_state_options",
    "drift_covariance",
    "map_drift_shares",
    "map_offset_rotation",
    "measurement_covariance",
    "nees_band",
    "pose_noise",
    "relative_state",
    "scale_drift",
    "split_rotation_drift",
    "startup_bias",
    "state_options",
    "with_map_rotation_offset",
]
