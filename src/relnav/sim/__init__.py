"""Simulation: targets, sensors, trajectories, attitude, scenarios and presets.

The common entry points are re-exported here (imported lazily, so ``import relnav.sim`` stays
cheap)::

    from relnav.sim import get_preset, simulate
    summary = simulate(get_preset("sim-voyager", frames=50), "out/seq")
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Scenario": "relnav.sim.scenario",
    "SimulationSummary": "relnav.sim.scenario",
    "load_scenario": "relnav.sim.scenario",
    "default_scenario": "relnav.sim.scenario",
    "scenario_yaml": "relnav.sim.scenario",
    "simulate": "relnav.sim.scenario",
    "available_presets": "relnav.sim.presets",
    "get_preset": "relnav.sim.presets",
    "make_trajectory": "relnav.sim.trajectories",
    "pointing_poses": "relnav.sim.trajectories",
    "path_length": "relnav.sim.trajectories",
    "make_attitude": "relnav.sim.attitude",
    "Target": "relnav.sim.targets",
    "get_target": "relnav.sim.targets",
    "make_sensor": "relnav.sim.sensors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'relnav.sim' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
