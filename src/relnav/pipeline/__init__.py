"""Run a sequence with any method and write its run folder (the library's pipeline).

:class:`OdometryPipeline` (and :func:`run_pipeline`) run a preset, a registered tracker
(``relnav``) or a registration method over a sequence, stream the estimate, then write the run
folder: ``estimate.tum`` (+ ``estimate_causal.tum`` for a smoother), ``diagnostics.csv``,
``metrics.json`` and ``errors.png`` with ground truth, the navigator's relative state
(``state.csv``, ``state.png``, ``state_errors.png``) and ``run.json``; they return one
:class:`PipelineResult`. ``relnav odometry``, ``relnav demo`` and the benchmark worker call it.

Modules: :mod:`~relnav.pipeline.run` (the pipeline), :mod:`~relnav.pipeline.outputs` (the run
folder), :mod:`~relnav.pipeline.registry` (method names that are trackers:
:func:`register_tracker`).

Layer: above odometry, navigation and eval (it imports them), below bench and cli (they call it).
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "OdometryPipeline": "relnav.pipeline.run",
    "PipelineResult": "relnav.pipeline.run",
    "make_tracker": "relnav.pipeline.run",
    "resolve_method": "relnav.pipeline.run",
    "run_pipeline": "relnav.pipeline.run",
    "run_sequence": "relnav.pipeline.run",
    "PoseFormat": "relnav.pipeline.outputs",
    "write_run_outputs": "relnav.pipeline.outputs",
    "available_trackers": "relnav.pipeline.registry",
    "register_tracker": "relnav.pipeline.registry",
    "tracker_entry": "relnav.pipeline.registry",
    "unregister_tracker": "relnav.pipeline.registry",
}
"""Re-exported lazily: ``import relnav.pipeline`` (and the CLI, which imports
:mod:`relnav.pipeline.outputs` at start-up) stays cheap; the registry, and with it the navigator
and paper 2's methods, is imported on first use."""

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'relnav.pipeline' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)
