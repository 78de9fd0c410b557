"""Run a sequence with any method and write its run folder: :class:`OdometryPipeline`.

The library's one way to run and evaluate a method on a sequence (``relnav odometry``,
``relnav demo`` and the benchmark worker call it)::

    from relnav.io import ScanSequence
    from relnav.pipeline import OdometryPipeline

    seq = ScanSequence("seq")
    result = OdometryPipeline("relnav").run(seq, out="runs/relnav")
    result.metrics["ape_trans_rmse"], result.status, result.outputs

A method is a preset (``paper1``), a registered tracker (``relnav``;
:mod:`relnav.pipeline.registry`) or a registration method string (``icp-point``). The run streams
``estimate.tum`` and ``diagnostics.csv`` into ``out`` as frames come; :meth:`OdometryPipeline.write`
then writes the rest of the run folder (:func:`relnav.pipeline.outputs.write_run_outputs`).
Progress is a callback, ``progress(i, step)``: drawing it is the caller's business (the CLI's
progress bar).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from relnav.odometry.runner import OdometryRun
from relnav.odometry.runner import make_tracker as _odometry_tracker
from relnav.odometry.runner import run_sequence as _run_odometry
from relnav.odometry.tracker import TrackerEntry
from relnav.pipeline.outputs import PoseFormat, write_run_outputs
from relnav.pipeline.registry import available_trackers, builds_navigator, tracker_entry
from relnav.scan import Scan

__all__ = [
    "OdometryPipeline",
    "PipelineResult",
    "make_tracker",
    "resolve_method",
    "run_pipeline",
    "run_sequence",
]


def resolve_method(
    name: str, options: dict[str, Any] | None = None
) -> tuple[str, dict[str, Any], str | None]:
    """:func:`relnav.odometry.presets.resolve_method` knowing the registered trackers: a preset
    name, a tracker name (``relnav``) or a method string → ``(method, options, preset or None)``.

    Raises
    ------
    ConfigError
        Unknown name (with the closest known names).
    """
    from relnav.odometry.presets import resolve_method as _resolve

    return _resolve(name, options, trackers=tuple(available_trackers()))


def _method(method: Any) -> Any:
    """A registered tracker's name → its :class:`TrackerEntry`; anything else unchanged."""
    if isinstance(method, str) and (entry := tracker_entry(method)) is not None:
        return entry
    return method


def make_tracker(method: Any, **options: Any) -> Any:
    """The tracker for ``method`` (a registered tracker's name, a :class:`TrackerEntry`, a
    registration method string or object): :func:`relnav.odometry.runner.make_tracker` with the
    registry's names. ``options``: ``initial_pose``, ``motion_prior`` and the method's own."""
    return _odometry_tracker(_method(method), **options)


def run_sequence(sequence: Sequence[Scan], method: Any = "relnav", **kwargs: Any) -> OdometryRun:
    """:func:`relnav.odometry.run_sequence` with the registry's names (``relnav``): same
    arguments, same :class:`~relnav.odometry.OdometryRun`, no files beyond ``out``'s stream."""
    return _run_odometry(sequence, _method(method), **kwargs)


def _as_method(method: Any, options: dict[str, Any] | None) -> tuple[str, Any, dict, str | None]:
    """``(name, what the odometry layer runs, options, preset)`` for any form of method."""
    from relnav.errors import ConfigError

    if isinstance(method, str):
        name, opts, preset = resolve_method(method, options)
        return name, _method(name), opts, preset
    opts = dict(options or {})
    if isinstance(method, TrackerEntry):
        return method.name, method, opts, None
    if isinstance(method, type) and callable(getattr(method, "register_frame", None)):
        # matplotlib drops legend labels that start with "_": a class's name without them
        name = str(getattr(method, "name", method.__name__)).lstrip("_") or "tracker"
        caps = frozenset(getattr(method, "capabilities", ()))
        return name, TrackerEntry(name, method, caps), opts, None
    if callable(getattr(method, "register_frame", None)):
        raise ConfigError(
            f"a {type(method).__name__} instance cannot be restarted at the run's start pose: "
            "give its class (or register_tracker(name, cls) and its name)"
        )
    if callable(getattr(method, "register", None)):  # a registration object: frame to frame
        return str(getattr(method, "name", type(method).__name__)), method, opts, None
    raise ConfigError(
        f"method: a name, a tracker class or a registration object, got {type(method).__name__}"
    )


@dataclass
class PipelineResult:
    """What :meth:`OdometryPipeline.run` returns (and :meth:`OdometryPipeline.write` completes).

    Attributes
    ----------
    run : OdometryRun
        Poses ``(N, 4, 4)`` ``T_world_sensor``, times (s), flags, per-frame details.
    method : str
        Method string or tracker name the run used (a preset expanded).
    preset : str or None
        The preset name when the method was one.
    options : dict
        The method's options (a preset's merged with the user's).
    status : {"complete", "interrupted", "failed"}
        ``interrupted``: Ctrl-C with ``on_interrupt="stop"`` (the frames until then are kept);
        ``failed``: every frame failed (:attr:`failed` says why).
    wall_s : float
        Wall-clock seconds of the run (frames and smoother; not the folder's writing).
    out : Path or None
        The run folder.
    metrics : dict
        Every metric against the ground truth (:func:`relnav.eval.metrics.evaluate_trajectories`,
        plus time, flags, a smoother's causal figures, the navigator's state), ``{}`` without
        ground truth or before :meth:`OdometryPipeline.write`.
    outputs : list of str
        Files of the run folder (``run.json``'s ``outputs``), after :meth:`OdometryPipeline.write`.
    failed : str or None
        The first failure's reason when every frame failed.
    state_records : list or None
        The navigator's compact per-frame records for its relative state (streamed runs).
    """

    run: OdometryRun
    method: str
    preset: str | None
    options: dict[str, Any]
    status: str
    wall_s: float
    out: Path | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    failed: str | None = None
    state_records: list[Any] | None = field(default=None, repr=False)

    @property
    def interrupted(self) -> dict[str, int] | None:
        """``{"at_frame", "of"}`` after Ctrl-C (``on_interrupt="stop"``), else ``None``."""
        return self.run.options.get("interrupted")


class OdometryPipeline:
    """One method, ready to run sequences and write their run folders.

    Parameters
    ----------
    method : str, tracker class, TrackerEntry or Registration
        Preset name, registered tracker (``relnav``) or registration method string; or a tracker
        class (built as ``cls(initial_pose=T0, **options)``, :mod:`relnav.odometry.tracker`),
        or a registration object (run frame to frame by :class:`relnav.odometry.Odometry`).
    options : dict, optional
        Method options (they override a preset's); ``motion_prior`` and ``initial_pose`` may be
        among them.
    motion_prior : {"constant_velocity", "identity"}, optional
        Pairwise odometry's prior; default: the options', else the preset's, else
        ``constant_velocity``.
    validate : bool
        Build the tracker once now, so that bad options fail before any frame is read.

    Raises
    ------
    ConfigError
        Unknown method or bad options.
    """

    def __init__(
        self,
        method: Any = "relnav",
        options: dict[str, Any] | None = None,
        *,
        motion_prior: str | None = None,
        validate: bool = True,
    ) -> None:
        self.method, self._target, opts, self.preset = _as_method(method, options)
        if validate:
            make_tracker(self._target, **opts)  # bad options fail here, not after frame 0
        prior = opts.pop("motion_prior", None)
        self.motion_prior = motion_prior or prior or "constant_velocity"
        self.initial_pose = opts.pop("initial_pose", "gt")
        self.options = opts

    @property
    def entry(self) -> TrackerEntry | None:
        """The tracker the method names (registered, or the class given), or ``None``
        (pairwise odometry)."""
        return self._target if isinstance(self._target, TrackerEntry) else None

    @property
    def is_navigator(self) -> bool:
        """Whether the method is the navigator (its run folder has the relative state)."""
        return builds_navigator(self.entry)

    @property
    def label(self) -> str:
        """The preset name, else the method."""
        return self.preset or self.method

    def run(
        self,
        sequence: Sequence[Scan],
        *,
        out: str | Path | None = None,
        initial_pose: Any = None,
        max_frames: int | None = None,
        progress: Callable[[int, Any], None] | None = None,
        stream: bool = True,
        strict: bool = False,
        on_interrupt: str = "raise",
        state: bool = False,
    ) -> PipelineResult:
        """Run the method over ``sequence``.

        Parameters
        ----------
        sequence : sequence of Scan
            E.g. a :class:`relnav.io.ScanSequence` (its ground truth gives the start pose).
        out : str or Path, optional
            Run folder: with ``stream``, ``estimate.tum`` and ``diagnostics.csv`` are written
            there as frames come (memory stays flat).
        initial_pose : (4, 4) array, "gt", "identity" or None, optional
            Default: the options', else ``"gt"`` (the ground truth's first pose when there is
            one, else the identity).
        max_frames : int, optional
            Stop after this many frames.
        progress : callable, optional
            ``progress(i, step)`` after each frame.
        stream : bool
            Stream into ``out`` and keep only poses, times and flags in memory; ``False`` keeps
            every step (the folder is written by :meth:`write`).
        strict : bool
            An unreadable scan aborts the run (default: the frame is flagged, the run goes on).
        on_interrupt : {"raise", "stop"}
            Ctrl-C: re-raise, or keep the frames estimated (status ``interrupted``).
        state : bool
            Keep the navigator's compact per-frame records for its relative state (a streamed
            run of the navigator; an in-memory run keeps its steps anyway).

        Returns
        -------
        PipelineResult
        """
        from relnav.errors import InputError

        if len(sequence) == 0:
            raise InputError("the sequence has no scans to run odometry on")
        records: list[Any] | None = [] if state else None
        on_frame = progress
        if records is not None:
            from relnav.navigation.state import StateRecord

            def on_frame(i: int, step: Any) -> None:
                records.append(StateRecord.from_step(step))
                if progress is not None:
                    progress(i, step)

        start = self.initial_pose if initial_pose is None else initial_pose
        folder = Path(out) if out is not None else None
        t0 = time.perf_counter()
        run = _run_odometry(
            sequence,
            self._target,
            initial_pose=start,
            motion_prior=self.motion_prior,
            max_frames=max_frames,
            progress=on_frame,
            out=folder if stream else None,
            keep_steps=not stream,
            strict=strict,
            on_interrupt=on_interrupt,
            **self.options,
        )
        wall = time.perf_counter() - t0
        failed = _all_failed(run)
        interrupted = run.options.get("interrupted")
        status = "interrupted" if interrupted else ("failed" if failed else "complete")
        return PipelineResult(
            run,
            self.method,
            self.preset,
            dict(self.options),
            status,
            wall,
            out=folder,
            failed=failed,
            state_records=records,
        )

    def write(
        self,
        result: PipelineResult,
        sequence: Any,
        out: str | Path | None = None,
        *,
        command: str = "pipeline",
        fmt: PoseFormat | str = PoseFormat.tum,
        seed: int | None = None,
        errors_plot: bool = True,
        extra_outputs: list[str] | None = None,
        state_options: dict[str, Any] | None = None,
    ) -> dict[str, Any]:
        """Write ``result``'s run folder (:func:`relnav.pipeline.outputs.write_run_outputs`):
        the estimate, diagnostics, with ground truth metrics and ``errors.png``, the navigator's
        relative state, and ``run.json`` (``command`` and ``seed`` recorded there). Sets
        ``result.metrics`` and ``result.outputs``; returns the metrics.

        Raises
        ------
        ConfigError
            No folder (neither ``out`` nor the run's).
        """
        from relnav.errors import ConfigError
        from relnav.io.runinfo import read_run_info

        folder = Path(out) if out is not None else result.out
        if folder is None:
            raise ConfigError("write needs an output folder (out)")
        run = result.run
        if result.state_records is not None:
            frames = result.state_records if not result.interrupted else []
        else:
            frames = None  # the run's own steps (an in-memory run)
        metrics = write_run_outputs(
            folder,
            run,
            sequence,
            command=command,
            preset=result.preset,
            fmt=PoseFormat(fmt),
            seed=seed,
            timings={"wall_s": result.wall_s},
            errors_plot=errors_plot,
            extra_outputs=extra_outputs,
            state_steps=frames,
            state_options=state_options,
            status=result.status,
        )
        result.out = folder
        result.metrics = metrics
        result.outputs = list((read_run_info(folder) or {}).get("outputs", []))
        return metrics


def run_pipeline(
    sequence: Sequence[Scan],
    method: str = "relnav",
    *,
    out: str | Path | None = None,
    options: dict[str, Any] | None = None,
    command: str = "pipeline",
    state: bool | None = None,
    state_options: dict[str, Any] | None = None,
    **run_options: Any,
) -> PipelineResult:
    """Run ``method`` over ``sequence`` and, with ``out``, write its run folder.

    ``state``: the navigator's relative state in the folder (default: on for the navigator).
    ``run_options`` go to :meth:`OdometryPipeline.run` (``max_frames``, ``progress``,
    ``initial_pose``, ``strict`` …). Without ``out`` the run stays in memory (no files) and
    ``metrics`` is empty.
    """
    pipe = OdometryPipeline(method, options)
    if out is None:
        return pipe.run(sequence, stream=False, **run_options)
    want_state = pipe.is_navigator if state is None else bool(state)
    result = pipe.run(sequence, out=out, state=want_state, **run_options)
    pipe.write(result, sequence, command=command, state_options=state_options)
    return result


def _all_failed(run: OdometryRun) -> str | None:
    """The first failure's reason when every frame failed (none registered), else ``None``."""
    counts = run.status_counts()
    n_failed = counts.get("failed", 0)
    if not n_failed or n_failed + counts.get("first", 0) != sum(counts.values()):
        return None
    for row in run.diagnostics():
        if row.get("status") == "failed" and row.get("message"):
            return str(row["message"])
    return "no reason recorded"
