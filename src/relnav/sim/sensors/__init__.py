"""Simulated range sensors: scanning and flash LIDAR, Kinect-v1 depth camera, HPR sampler.

Every sensor maps ``(target, T_target_sensor, rng)`` to an ``(N, 3)`` float64 cloud in the
**sensor frame** (x forward = boresight, y left, z up; REP-103, also for the depth camera).
``T_target_sensor`` maps sensor coordinates to target coordinates (the sensor's pose in the
target frame).

Ray sensors (:class:`ScanningLidar`, :class:`FlashLidar`, :class:`DepthCamera`) cast one ray
per beam/pixel against the target mesh (first hit, float64-exact range; see
:mod:`relnav.sim.raycast`), gate the true range, reject grazing incidence, drop returns at
random and add noise. Rays that cannot reach the target's bounding sphere are never cast,
which only saves time: the output is identical to casting them.

:class:`SurfaceSampler` reproduces paper 1's simulated clouds: one complete model point cloud
rendered once per target from a tessellated sphere of views (``model_cloud="fixed"``, paper 1's
data generation) or fresh uniform surface samples every frame (``"resample"``), then
hidden-point removal (Katz et al. 2007) from the sensor position, then optional noise.

Random numbers are drawn in a fixed order from the ``rng`` passed to :meth:`Sensor.scan`
(and only for returns that survive the deterministic gates), so a given generator state
gives byte-identical clouds.
"""

from __future__ import annotations

from relnav.sim.sensors.base import Sensor, SensorReturn
from relnav.sim.sensors.depth_camera import DepthCamera
from relnav.sim.sensors.flash import FlashLidar
from relnav.sim.sensors.presets import available_sensors, make_sensor, sensor_from_dict
from relnav.sim.sensors.rotating import ScanningLidar
from relnav.sim.sensors.surface import SurfaceSampler

__all__ = [
    "DepthCamera",
    "FlashLidar",
    "ScanningLidar",
    "Sensor",
    "SensorReturn",
    "SurfaceSampler",
    "available_sensors",
    "make_sensor",
    "sensor_from_dict",
]
