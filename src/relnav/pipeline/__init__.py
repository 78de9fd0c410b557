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

from relnav.pipeline.outputs import PoseFormat, write_run_outputs
from relnav.pipeline.registry import (
    available_trackers,
    register_tracker,
    tracker_entry,
    unregister_tracker,
)
from relnav.pipeline.run import (
    OdometryPipeline,
    PipelineResult,
    make_tracker,
    resolve_method,
    run_pipeline,
    run_sequence,
)

__all__ = [
    "OdometryPipeline",
    "PipelineResult",
    "PoseFormat",
    "available_trackers",
    "make_tracker",
    "register_tracker",
    "resolve_method",
    "run_pipeline",
    "run_sequence",
    "tracker_entry",
    "unregister_tracker",
    "write_run_outputs",
]
