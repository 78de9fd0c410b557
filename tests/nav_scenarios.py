"""Scenarios shared by the navigator's tests (imported by them; not a test module)."""

from __future__ import annotations

from typing import Any

import numpy as np

from relnav.geometry.rotations import angle_between_rotations


def flash(rows: int, range_sigma: float = 0.02) -> dict[str, Any]:
    """A ``rows``×``rows`` flash LIDAR (the goldeneye preset) with ``range_sigma`` (m) of range
    noise."""
    return {
        "preset": "goldeneye",
        "name": "flash",
        "overrides": {"rows": rows, "cols": rows, "range_sigma": range_sigma},
    }


FLASH_64 = flash(64)
"""A 64×64 flash LIDAR with 2 cm range noise."""


def attitude_errors_deg(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Rotation angle (deg) of ``gt⁻¹ est`` per pose ``(N, 4, 4)``."""
    est, gt = np.asarray(est), np.asarray(gt)
    return np.atleast_1d(np.degrees(angle_between_rotations(gt[:, :3, :3], est[:, :3, :3])))


def flash_orbit(
    name: str,
    *,
    seed: int = 3,
    frames: int = 250,
    dt: float = 55.5,
    max_frames: int | None = None,
    target: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """2.5 loops of an elliptic orbit (55 × 42 m, tilted 20°) around ``target`` (default the
    procedural asteroid, 14 m) seen by a 64×64 flash LIDAR with 2 cm range noise."""
    sc: dict[str, Any] = {
        "name": name,
        "seed": seed,
        "frames": frames,
        "dt": dt,
        "format": "npy",
        "target": target or {"name": "asteroid", "scale_to": 14.0},
        "sensors": [dict(FLASH_64)],
        "trajectory": {
            "kind": "elliptic-orbit",
            "params": {"semi_major": 55.0, "semi_minor": 42.0, "loops": 2.5, "tilt_deg": 20.0},
        },
    }
    if max_frames is not None:
        sc["max_frames"] = max_frames
    return sc
