"""The sensor presets and kinds by name: :func:`make_sensor`, :func:`sensor_from_dict`."""

from __future__ import annotations

from typing import Any

import numpy as np

from relnav.errors import ConfigError
from relnav.sim.sensors.base import (
    Sensor,
)
from relnav.sim.sensors.depth_camera import DepthCamera
from relnav.sim.sensors.flash import FlashLidar
from relnav.sim.sensors.rotating import ScanningLidar
from relnav.sim.sensors.surface import HPR_MAX_RANGE_M, SurfaceSampler

# --------------------------------------------------------------------------- presets

_RS32_ELEVATIONS = (
    # [interpretation] non-linear 32-beam table, -25..+15°, 1/3° pitch near the horizon
    # (the manufacturer's exact factory table was not checked).
    -25.0,
    -15.6,
    -11.3,
    -8.8,
    -7.3,
    -6.1,
    -5.3,
    *[round(-14.0 / 3.0 + k / 3.0, 4) for k in range(19)],  # -4.667 .. +1.333
    2.333,
    3.333,
    4.667,
    7.0,
    10.333,
    15.0,
)


def _spinning(
    elevations_deg: tuple[float, ...],
    azimuth_step_deg: float,
    min_range: float,
    max_range: float,
    range_sigma: float,
) -> dict[str, Any]:
    """Parameters of a 360° scanning LIDAR preset (degrees, metres)."""
    return dict(
        elevations_deg=elevations_deg,
        azimuth_step_deg=azimuth_step_deg,
        azimuth_fov_deg=(-180.0, 180.0),
        min_range=min_range,
        max_range=max_range,
        range_sigma=range_sigma,
    )


_FLASH_128 = dict(rows=128, cols=128, fov_h_deg=45.0, fov_v_deg=45.0, min_range=1.0)
"""The 128×128, 45°×45° focal plane shared by the GoldenEye and DragonEye presets."""

_PRESETS: dict[str, tuple[type[Sensor], dict[str, Any]]] = {
    "vlp16": (
        ScanningLidar,
        _spinning(tuple(float(e) for e in range(-15, 16, 2)), 0.2, 0.5, 100.0, 0.03),
    ),
    # [interpretation] 64 beams evenly spaced +2..-24.9° (≈0.427°)
    "hdl64": (
        ScanningLidar,
        _spinning(
            tuple(float(e) for e in np.round(np.linspace(2.0, -24.9, 64), 6)),
            0.1728,
            0.9,
            120.0,
            0.01,
        ),
    ),
    "rs32": (ScanningLidar, _spinning(_RS32_ELEVATIONS, 0.2, 0.4, 200.0, 0.03)),
    "goldeneye": (FlashLidar, dict(_FLASH_128, max_range=3000.0, range_sigma=0.10)),
    "dragoneye": (FlashLidar, dict(_FLASH_128, max_range=1500.0, range_sigma=0.15)),
    "flash256": (
        FlashLidar,
        dict(
            # [interpretation] a dense 256×256 flash LIDAR (65 536 pixels), 30°×30°, 2 cm
            rows=256,
            cols=256,
            fov_h_deg=30.0,
            fov_v_deg=30.0,
            min_range=0.5,
            max_range=1000.0,
            range_sigma=0.02,
        ),
    ),
    "kinect1": (DepthCamera, {}),
    # max_range: HPR_MAX_RANGE_M (3 km), the class default, written out for `relnav config`
    "surface-hpr": (
        SurfaceSampler,
        dict(n_points=500, hpr_radius_factor=100.0, max_range=HPR_MAX_RANGE_M),
    ),
}

_KINDS: dict[str, type[Sensor]] = {
    c.kind: c for c in (ScanningLidar, FlashLidar, DepthCamera, SurfaceSampler)
}


def available_sensors() -> list[str]:
    """Names of the sensor presets accepted by :func:`make_sensor`."""
    return list(_PRESETS)


def _construct(cls: type[Sensor], kwargs: dict[str, Any], what: str) -> Sensor:
    import inspect

    allowed = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise ConfigError(f"{what}: unknown parameter(s) {unknown}; allowed: {allowed}")
    missing = [
        p
        for p, prm in inspect.signature(cls.__init__).parameters.items()
        if p != "self" and prm.default is inspect.Parameter.empty and p not in kwargs
    ]
    if missing:
        raise ConfigError(f"{what}: missing parameter(s) {missing}")
    return cls(**kwargs)  # type: ignore[call-arg]


def make_sensor(name: str, **overrides: Any) -> Sensor:
    """A sensor preset by name, with optional parameter overrides.

    Presets: ``vlp16``, ``hdl64``, ``rs32`` (scanning), ``goldeneye``, ``dragoneye`` (flash,
    128×128, 45°×45°), ``flash256`` (dense flash, 256×256, 30°×30°), ``kinect1`` (depth
    camera), ``surface-hpr`` (paper 1's HPR sampler).
    See ALGORITHMS.md §H for the numbers.

    Raises
    ------
    ConfigError
        Unknown preset or parameter, or an invalid value (negative range, min > max, ...).
    """
    key = str(name).lower().replace("_", "-")
    if key not in _PRESETS:
        raise ConfigError(f"unknown sensor {name!r}; available: {', '.join(available_sensors())}")
    cls, params = _PRESETS[key]
    kwargs: dict[str, Any] = {"name": key, **params, **overrides}
    return _construct(cls, kwargs, f"sensor {key!r}")


def sensor_from_dict(d: dict[str, Any]) -> Sensor:
    """Rebuild a sensor from :meth:`Sensor.to_dict` output (e.g. a ``sensor.yaml``).

    A dict with ``preset`` (and optional overrides) instead of ``kind`` is passed to
    :func:`make_sensor`.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"sensor description must be a mapping, got {type(d).__name__}")
    d = dict(d)
    if "preset" in d and "kind" not in d:
        return make_sensor(d.pop("preset"), **d)
    kind = d.pop("kind", None)
    if kind not in _KINDS:
        raise ConfigError(f"sensor kind {kind!r} unknown; expected one of {sorted(_KINDS)}")
    return _construct(_KINDS[kind], d, f"sensor kind {kind!r}")
