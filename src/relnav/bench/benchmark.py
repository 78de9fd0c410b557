"""Benchmark grid runner: scenarios × nuisances × methods × seeds, in parallel with Dask.

A **grid** (YAML, :class:`GridSpec`) lists scenarios (paper presets, scenario YAML files or
existing sequence folders), methods (method strings, with ``{a,b}`` brace expansion, or
``{method, label, options}`` entries), Monte Carlo seeds and optional nuisance levels
(:mod:`relnav.sim.nuisance`). One **job** = one (scenario, nuisance, method, seed) odometry run.

How a grid runs (:func:`run_benchmark`):

1. Jobs are expanded and identified by :func:`job_id`, a hash of everything that determines
   their result (scenario spec, seed, nuisance, method, options). Jobs already in the results
   store (:mod:`relnav.bench.store`) with status ``ok`` or ``failed`` are skipped, so a killed
   run resumes where it stopped; ``force=True`` reruns everything, ``retry_failed=True`` reruns
   failed jobs.
2. Each (scenario, seed) sequence is simulated **once** into ``OUT/sequences/`` and reused by
   every method (nuisance variants are derived from it, also once). A folder is only used
   once its ``.complete`` marker exists (it is written to a temporary name and renamed).
3. Jobs run on a Dask cluster: ``LocalCluster(n_workers=N, threads_per_worker=1,
   processes=True)`` by default, or an existing scheduler (``scheduler="tcp://host:8786"``).
   ``workers=0`` runs everything in this process (debugging, tests). Each result row is
   written to ``OUT/results.sqlite`` and committed as soon as its job finishes; a job that
   raises is recorded as ``failed`` with its error and the grid goes on.
4. Every job writes ``OUT/runs/<job_id>/estimate.tum`` and ``diagnostics.csv``; its metrics
   are computed **from those files** with the defaults of ``relnav evaluate`` (timestamp
   association, no alignment), so ``relnav evaluate`` on them gives the stored numbers.

Determinism: a job is a pure function of (scenario spec, seed, nuisance, method, options):
the scenario seed drives the sensor noise and pointing jitter, the nuisance draws use
:func:`relnav.sim.nuisance.nuisance_rng`, and the methods' own random parts (RANSAC, CLGV,
Super4PCS, Open3D) keep their fixed default seeds **[interpretation: the Monte Carlo seed varies
the data, not the estimator]**. Only the timing columns differ between runs, except for
the Open3D-based baselines (``o3d-*``): Open3D's parallel reductions and RANSAC are not
bit-reproducible from one process to another (differences from 1e-12 relative up to ~1 %
after a few frames of ``o3d-fpfh-ransac``). Every relnav-native method, KISS-ICP and
small_gicp give bit-identical metrics in-process, on a ``LocalCluster`` or on hand-started
``dask worker`` processes.

On a cluster, ``OUT`` should be on a shared file system; otherwise every worker simulates the
sequences it needs itself (same seeds → same data) and the estimate files stay on the workers.
Numba's on-disk cache (``cache=True``) is shared by the worker processes of one machine: set
``NUMBA_CACHE_DIR`` to a writable folder when the package is installed read-only.
"""

from __future__ import annotations

import fnmatch
import hashlib
import itertools
import json
import logging
import os
import platform
import re
import shutil
import socket
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from relnav.config import StrictModel, dump_yaml, load_yaml, validate
from relnav.errors import ConfigError, InputError
from relnav.sim.nuisance import NuisanceSpec

__all__ = [
    "BenchmarkSummary",
    "GridSpec",
    "Job",
    "MethodEntry",
    "ReportOptions",
    "ScenarioEntry",
    "SweepSpec",
    "expand_jobs",
    "expand_methods",
    "job_id",
    "load_grid",
    "failed_row",
    "prepare_sequence",
    "read_grid",
    "run_benchmark",
    "run_job",
]

log = logging.getLogger(__name__)

GRID_FILE = "grid.yaml"
STORE_FILE = "results.sqlite"
RUNS_LOG = "runs.jsonl"
_MARKER = ".complete"


# --------------------------------------------------------------------------------------------
# grid specification
# --------------------------------------------------------------------------------------------


class ScenarioEntry(StrictModel):
    """One scenario of a grid: exactly one of ``preset``, ``scenario`` or ``sequence``.

    Attributes
    ----------
    name : str, optional
        Label in tables and figures (default: the preset name, file stem or folder name).
    preset : str, optional
        A :func:`relnav.sim.presets.get_preset` name (``sim-bennu`` …).
    scenario : str, optional
        Scenario YAML file (relative paths are relative to the grid file).
    sequence : str, optional
        Existing sequence folder (user data); seeds then only change the nuisance draws.
    sensor : str, optional
        Second-sensor name of a sequence folder (``scans_<sensor>/``).
    frames : int, optional
        Resample the whole path with this many frames (presets: same duration).
    max_frames : int, optional
        Only the first ``max_frames`` frames, at the scenario's own frame rate.
    options : dict
        Preset options (e.g. ``distance`` for ``li-rotating``).
    """

    name: str | None = None
    preset: str | None = None
    scenario: str | None = None
    sequence: str | None = None
    sensor: str | None = None
    frames: int | None = Field(default=None, gt=0)
    max_frames: int | None = Field(default=None, gt=0)
    options: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _one_source(self) -> ScenarioEntry:
        given = [k for k in ("preset", "scenario", "sequence") if getattr(self, k)]
        if len(given) != 1:
            raise ValueError("give exactly one of preset, scenario or sequence")
        if self.sequence and self.frames is not None:
            raise ValueError("frames cannot be changed for a recorded sequence (use max_frames)")
        return self

    @property
    def kind(self) -> str:
        """``"preset"``, ``"scenario"`` or ``"sequence"``."""
        return "preset" if self.preset else "scenario" if self.scenario else "sequence"

    @property
    def label(self) -> str:
        """The name used in tables."""
        if self.name:
            return self.name
        if self.preset:
            return self.preset
        return Path(str(self.scenario or self.sequence)).stem


class MethodEntry(StrictModel):
    """One method of a grid: a method string, options and a label."""

    method: str
    label: str | None = None
    options: dict[str, Any] = Field(default_factory=dict)

    @property
    def name(self) -> str:
        """Label (default: the method string, plus ``[k=v,…]`` when options are given)."""
        if self.label:
            return self.label
        if not self.options:
            return self.method
        opts = ",".join(f"{k}={v}" for k, v in sorted(self.options.items()))
        return f"{self.method}[{opts}]"


class SweepSpec(StrictModel):
    """A one-parameter nuisance sweep (robustness curves).

    ``values`` of ``parameter`` are applied one at a time on top of ``fixed`` (e.g.
    ``{occlusion: cone}``); the clean level is added to every sweep as its neutral point.
    """

    name: str | None = None
    parameter: Literal[
        "range_sigma_m",
        "outlier_fraction",
        "keep_fraction",
        "occlusion_fraction",
        "occlusion_half_angle_deg",
    ]
    values: list[float] = Field(min_length=1)
    fixed: dict[str, Any] = Field(default_factory=dict)

    @property
    def label(self) -> str:
        """Sweep name (default: the parameter, plus the fixed occlusion kind)."""
        if self.name:
            return self.name
        occ = self.fixed.get("occlusion")
        return f"{self.parameter}-{occ}" if occ else self.parameter

    def levels(self) -> list[NuisanceSpec]:
        """One :class:`NuisanceSpec` per value (validated)."""
        out = []
        for v in self.values:
            data = {**self.fixed, self.parameter: v}
            if self.parameter in ("occlusion_fraction", "occlusion_half_angle_deg") and not (v > 0):
                data = {}  # the clean level
            out.append(NuisanceSpec.parse(data))
        return out


class ReportOptions(StrictModel):
    """Options of the report written from a grid (see :mod:`relnav.bench.report`).

    Attributes
    ----------
    tradeoff_tolerance : float
        Best accuracy–time trade-off = the fastest combination whose ``e^RT`` is within
        ``(1 + tolerance)`` of the best **[interpretation of the paper's "most appealing"]**.
    discard_worst_descriptor : bool
        Paper 1 §4: drop the least accurate descriptor per scenario before normalising.
    normalisation_constant : float
        Constant multiplying the normalised ``e^RT`` (paper 1 §4, for log plots).
    plot_seed : int, optional
        Seed whose runs are drawn in the trajectory/error figures (default: the first seed).
    """

    tradeoff_tolerance: float = Field(default=0.25, ge=0.0)
    discard_worst_descriptor: bool = True
    normalisation_constant: float = Field(default=1000.0, gt=0.0)
    plot_seed: int | None = None


class GridSpec(StrictModel):
    """A benchmark grid (the YAML file given to ``relnav benchmark``).

    Attributes
    ----------
    schema_version : int
        1.
    name, description : str
        Labels.
    scenarios : list of ScenarioEntry
        Plain strings are preset names.
    methods : list of MethodEntry
        Plain strings are method strings; ``{a,b}`` groups expand to every combination, e.g.
        ``feature:{hods,shot}+gcc+{alphabeta,kalman}`` (4 methods).
    seeds : list of int
        Monte Carlo seeds (an integer ``n`` means ``0 … n−1``).
    nuisances : list of NuisanceSpec
        Extra nuisance levels (each one applied to every scenario and seed).
    sweeps : list of SweepSpec
        One-parameter nuisance sweeps (expanded into levels; the clean level is always run).
    report : ReportOptions
        Report options.
    warmup_frames : int
        Before the timed run, each job runs its method on the first ``warmup_frames`` frames
        (discarded) so that one-off costs (numba cache loading, imports) do not enter
        ``time_ms``; 0 disables. It does not change any accuracy metric.
    base_dir : str, optional
        Folder that relative scenario/sequence paths are resolved against (set by
        :func:`load_grid` to the grid file's folder).
    """

    schema_version: int = 1
    name: str = "benchmark"
    description: str = ""
    scenarios: list[ScenarioEntry] = Field(min_length=1)
    methods: list[MethodEntry] = Field(min_length=1)
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    nuisances: list[NuisanceSpec] = Field(default_factory=list)
    sweeps: list[SweepSpec] = Field(default_factory=list)
    report: ReportOptions = Field(default_factory=ReportOptions)
    warmup_frames: int = Field(default=2, ge=0)
    base_dir: str | None = None

    @field_validator("scenarios", mode="before")
    @classmethod
    def _scenario_strings(cls, v: Any) -> Any:
        if isinstance(v, list):
            return [{"preset": s} if isinstance(s, str) else s for s in v]
        return v

    @field_validator("methods", mode="before")
    @classmethod
    def _method_strings(cls, v: Any) -> Any:
        if not isinstance(v, list):
            return v
        out: list[Any] = []
        for m in v:
            if isinstance(m, str):
                out.extend({"method": s} for s in expand_methods(m))
            elif isinstance(m, dict) and isinstance(m.get("method"), str) and "{" in m["method"]:
                for s in expand_methods(m["method"]):
                    out.append({**m, "method": s, "label": None})
            else:
                out.append(m)
        return out

    @field_validator("seeds", mode="before")
    @classmethod
    def _seed_count(cls, v: Any) -> Any:
        if isinstance(v, int) and not isinstance(v, bool):
            if v < 1:
                raise ValueError("seeds: a count must be >= 1")
            return list(range(v))
        if isinstance(v, dict):
            start, count = int(v.get("start", 0)), int(v.get("count", 1))
            return list(range(start, start + count))
        return v

    @model_validator(mode="after")
    def _unique(self) -> GridSpec:
        for what, names in (
            ("scenario", [s.label for s in self.scenarios]),
            ("method", [m.name for m in self.methods]),
            ("seed", [str(s) for s in self.seeds]),
        ):
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise ValueError(f"duplicate {what} name(s): {', '.join(dup)}")
        if any(s < 0 for s in self.seeds):
            raise ValueError("seeds must be >= 0")
        return self

    def nuisance_levels(self) -> list[NuisanceSpec]:
        """Every nuisance level of the grid, the clean level first, without duplicates."""
        levels = [NuisanceSpec()]
        for s in self.sweeps:
            levels.extend(s.levels())
        levels.extend(self.nuisances)
        seen: dict[str, NuisanceSpec] = {}
        for lv in levels:
            seen.setdefault(lv.key, lv)
        return list(seen.values())

    def grid_hash(self) -> str:
        """Hash of the resolved grid (12 hex digits)."""
        blob = json.dumps(self.model_dump(mode="json", exclude={"base_dir"}), sort_keys=True)
        return hashlib.sha1(blob.encode()).hexdigest()[:12]


_BRACES = re.compile(r"\{([^{}]*)\}")


def expand_methods(pattern: str) -> list[str]:
    """Brace expansion of a method pattern.

    >>> expand_methods("feature:{hods,shot}+gcc+alphabeta")
    ['feature:hods+gcc+alphabeta', 'feature:shot+gcc+alphabeta']
    """
    parts = _BRACES.split(pattern)
    literals, groups = parts[0::2], parts[1::2]
    if not groups:
        return [pattern.strip()]
    choices = [[c.strip() for c in g.split(",") if c.strip()] for g in groups]
    if any(not c for c in choices):
        raise ConfigError(f"method pattern {pattern!r}: empty {{}} group")
    out = []
    for combo in itertools.product(*choices):
        s = literals[0]
        for c, lit in zip(combo, literals[1:], strict=True):
            s += c + lit
        out.append(s.strip())
    return out


def load_grid(
    source: str | Path | dict[str, Any] | GridSpec,
    *,
    seeds: int | None = None,
    max_frames: int | None = None,
    scenarios: Iterable[str] | None = None,
    methods: Iterable[str] | None = None,
) -> GridSpec:
    """Read and validate a grid, optionally narrowed (the CLI's subset options).

    Parameters
    ----------
    source : path, dict or GridSpec
        Grid YAML file (relative paths inside resolve against its folder), mapping or model.
    seeds : int, optional
        Keep only the first ``seeds`` seeds.
    max_frames : int, optional
        Cap every scenario at its first ``max_frames`` frames.
    scenarios : iterable of str, optional
        Keep only these scenario labels (glob patterns allowed).
    methods : iterable of str, optional
        Keep only method labels matching one of these glob patterns.

    Raises
    ------
    ConfigError
        Invalid grid, or a narrowing that leaves nothing to run.
    """
    if isinstance(source, GridSpec):
        grid = source.model_copy(deep=True)
    elif isinstance(source, dict):
        grid = validate(GridSpec, source, "grid")
    else:
        p = Path(source)
        data = load_yaml(p)
        grid = validate(GridSpec, data, str(p))
        if grid.base_dir is None:
            grid.base_dir = str(p.resolve().parent)
    upd: dict[str, Any] = {}
    if seeds is not None:
        if seeds < 1:
            raise ConfigError(f"--seeds must be >= 1, got {seeds}")
        upd["seeds"] = grid.seeds[:seeds]
    if max_frames is not None:
        if max_frames < 2:
            raise ConfigError(f"--max-frames must be >= 2, got {max_frames}")
        upd["scenarios"] = [
            s.model_copy(update={"max_frames": min(s.max_frames or max_frames, max_frames)})
            for s in grid.scenarios
        ]
    if scenarios:
        pats = list(scenarios)
        keep = [
            s
            for s in upd.get("scenarios", grid.scenarios)
            if any(fnmatch.fnmatch(s.label, p) for p in pats)
        ]
        if not keep:
            raise ConfigError(f"no scenario matches {pats}")
        upd["scenarios"] = keep
    if methods:
        pats = list(methods)
        keep_m = [m for m in grid.methods if any(fnmatch.fnmatch(m.name, p) for p in pats)]
        if not keep_m:
            raise ConfigError(f"no method matches {pats}")
        upd["methods"] = keep_m
    if upd:
        data = grid.model_dump(mode="json")
        data.update(
            {
                k: [x.model_dump(mode="json") for x in v] if k != "seeds" else v
                for k, v in upd.items()
            }
        )
        grid = validate(GridSpec, data, "grid")
    return grid


# --------------------------------------------------------------------------------------------
# jobs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """One (scenario, nuisance, method, seed) run; plain data, sent to the workers as a dict.

    Attributes
    ----------
    job_id : str
        :func:`job_id` of the spec.
    scenario, scenario_kind : str
        Scenario label and kind (preset, scenario, sequence).
    scenario_spec : dict
        Canonical description of the scenario (what the sequence is made from).
    seed : int
        Monte Carlo seed.
    nuisance : dict
        Active nuisance parameters (``{}`` = clean).
    nuisance_label : str
        Text label of the nuisance level.
    method, method_label : str
        Method string and label.
    options : dict
        Method options.
    sequence_rel : str
        Sequence folder: relative to the benchmark folder, or absolute for user sequences.
    base_rel : str
        The clean sequence the nuisance variant is derived from (equal to ``sequence_rel`` for
        clean jobs).
    warmup_frames : int
        Untimed warm-up frames (not part of the job's identity).
    """

    job_id: str
    scenario: str
    scenario_kind: str
    scenario_spec: dict[str, Any]
    seed: int
    nuisance: dict[str, Any]
    nuisance_label: str
    method: str
    method_label: str
    options: dict[str, Any]
    sequence_rel: str
    base_rel: str
    warmup_frames: int = 2

    def as_dict(self) -> dict[str, Any]:
        """Plain-dict form (what :func:`run_job` takes)."""
        return dict(self.__dict__)


def _canonical(x: Any) -> str:
    return json.dumps(x, sort_keys=True, separators=(",", ":"), default=str)


def job_id(
    scenario_spec: dict[str, Any],
    seed: int,
    nuisance: dict[str, Any],
    method: str,
    options: dict[str, Any],
) -> str:
    """Identifier of a job: 16 hex digits of the SHA-1 of its canonical JSON description."""
    blob = _canonical(
        {
            "scenario": scenario_spec,
            "seed": int(seed),
            "nuisance": nuisance,
            "method": method,
            "options": options,
        }
    )
    return hashlib.sha1(blob.encode()).hexdigest()[:16]


def _resolve_path(base_dir: str | None, p: str) -> Path:
    q = Path(p).expanduser()
    if not q.is_absolute() and base_dir:
        q = Path(base_dir) / q
    return q.resolve()


def _scenario_spec(entry: ScenarioEntry, base_dir: str | None) -> dict[str, Any]:
    if entry.kind == "preset":
        return {
            "preset": str(entry.preset).lower().replace("_", "-"),
            "frames": entry.frames,
            "max_frames": entry.max_frames,
            "options": dict(entry.options),
        }
    if entry.kind == "scenario":
        path = _resolve_path(base_dir, str(entry.scenario))
        return {
            "scenario": load_yaml(path),
            "frames": entry.frames,
            "max_frames": entry.max_frames,
        }
    path = _resolve_path(base_dir, str(entry.sequence))
    if not path.is_dir():
        raise InputError(f"grid scenario {entry.label!r}: no such sequence folder {path}")
    return {"sequence": str(path), "sensor": entry.sensor, "max_frames": entry.max_frames}


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name)


def expand_jobs(grid: GridSpec) -> list[Job]:
    """Every job of ``grid``, in a stable order (scenario, nuisance, seed, method).

    For ``sequence`` scenarios the clean level runs once (the first seed) since the data do not
    depend on the seed; nuisance levels run for every seed.
    """
    from relnav.odometry.presets import resolve_method

    resolved: dict[int, tuple[str, dict[str, Any]]] = {}
    for i, m in enumerate(grid.methods):
        try:  # method strings, relnav's navigator and named presets (expanded here)
            name, opts, _ = resolve_method(m.method, dict(m.options))
        except ConfigError as e:
            raise ConfigError(f"grid method {m.method!r}: {e}") from None
        resolved[i] = (name, opts)
    jobs: list[Job] = []
    levels = grid.nuisance_levels()
    for entry in grid.scenarios:
        spec = _scenario_spec(entry, grid.base_dir)
        shash = hashlib.sha1(_canonical(spec).encode()).hexdigest()[:8]
        folder = f"sequences/{_safe(entry.label)}-{shash}"
        for lv in levels:
            act = lv.active()
            seeds = grid.seeds
            if entry.kind == "sequence" and lv.is_identity:
                seeds = grid.seeds[:1]
            for seed in seeds:
                if entry.kind == "sequence":
                    base = str(spec["sequence"])
                else:
                    base = f"{folder}/seed{seed}"
                seq = base if lv.is_identity else f"{folder}/seed{seed}-{lv.key}"
                for i, m in enumerate(grid.methods):
                    method, options = resolved[i]
                    jid = job_id(spec, seed, act, method, options)
                    jobs.append(
                        Job(
                            jid,
                            entry.label,
                            entry.kind,
                            spec,
                            int(seed),
                            act,
                            lv.label,
                            method,
                            m.name,
                            dict(options),
                            seq,
                            base,
                            grid.warmup_frames,
                        )
                    )
    ids = [j.job_id for j in jobs]
    if len(set(ids)) != len(ids):
        raise ConfigError("the grid contains the same job twice (identical scenario entries?)")
    return jobs


# --------------------------------------------------------------------------------------------
# worker side: sequences and jobs (pure functions of their arguments, importable by workers)
# --------------------------------------------------------------------------------------------


def _abs(root: str | Path, rel: str) -> Path:
    p = Path(rel)
    return p if p.is_absolute() else Path(root) / p


def _scenario_for(spec: dict[str, Any], seed: int) -> Any:
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import load_scenario

    if "preset" in spec:
        return get_preset(
            spec["preset"],
            frames=spec.get("frames"),
            max_frames=spec.get("max_frames"),
            seed=seed,
            **spec.get("options", {}),
        )
    data = dict(spec["scenario"])
    data["seed"] = int(seed)
    if spec.get("frames") is not None:
        data["frames"] = spec["frames"]
    if spec.get("max_frames") is not None:
        data["max_frames"] = spec["max_frames"]
    return load_scenario(data)


def _publish(tmp: Path, final: Path) -> None:
    (tmp / _MARKER).write_text(datetime.now(UTC).isoformat(timespec="seconds") + "\n")
    if final.exists():
        if (final / _MARKER).exists():  # another worker finished first: identical content
            shutil.rmtree(tmp, ignore_errors=True)
            return
        shutil.rmtree(final, ignore_errors=True)  # left over by a killed run
    try:
        os.replace(tmp, final)
    except OSError:
        if not (final / _MARKER).exists():
            raise
        shutil.rmtree(tmp, ignore_errors=True)


def prepare_sequence(job: dict[str, Any], out_root: str, base_dir: str | None = None) -> str:
    """Make sure the sequence of ``job`` exists on disk; returns its folder.

    Clean simulated sequences are simulated from ``job["scenario_spec"]`` with
    ``job["seed"]``; nuisance variants are written from the clean folder (``base_dir`` when
    given, else prepared first). Existing complete folders are reused. Pure: the content
    depends only on (scenario spec, seed, nuisance).
    """
    from relnav.sim.scenario import simulate

    final = _abs(out_root, job["sequence_rel"])
    if job["scenario_kind"] == "sequence" and not job["nuisance"]:
        if not final.is_dir():
            raise InputError(f"{final}: sequence folder not found on this machine")
        return str(final)
    if (final / _MARKER).exists():
        return str(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f"{final.name}.tmp-{uuid.uuid4().hex[:8]}")
    try:
        if not job["nuisance"]:
            simulate(_scenario_for(job["scenario_spec"], job["seed"]), tmp)
        else:
            from relnav.sim.nuisance import write_nuisance_sequence

            if base_dir is None:
                clean = {**job, "nuisance": {}, "sequence_rel": job["base_rel"]}
                base_dir = prepare_sequence(clean, out_root)
            write_nuisance_sequence(
                base_dir,
                tmp,
                NuisanceSpec.parse(job["nuisance"]),
                seed=job["seed"],
                max_frames=job["scenario_spec"].get("max_frames"),
            )
        _publish(tmp, final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return str(final)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"local:{os.getpid()}"


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _base_row(job: dict[str, Any]) -> dict[str, Any]:
    from relnav import __version__

    return {
        "job_id": job["job_id"],
        "scenario": job["scenario"],
        "scenario_kind": job["scenario_kind"],
        "scenario_spec": job["scenario_spec"],
        "nuisance": job["nuisance_label"],
        "nuisance_params": job["nuisance"],
        "method": job["method"],
        "method_label": job["method_label"],
        "method_options": job["options"],
        "seed": job["seed"],
        "relnav_version": __version__,
        "host": socket.gethostname(),
        "worker": _worker_name(),
    }


def failed_row(job: dict[str, Any], error: BaseException | str) -> dict[str, Any]:
    """The store row of a job that could not run (``status = "failed"``)."""
    row = _base_row(job)
    msg = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    row.update(status="failed", error=msg[:2000], finished_at=_now())
    return row


def run_job(job: dict[str, Any], out_root: str, sequence_dir: str | None = None) -> dict[str, Any]:
    """Run one job and return its store row (never raises: failures become ``failed`` rows).

    Parameters
    ----------
    job : dict
        :meth:`Job.as_dict`.
    out_root : str
        Benchmark folder (``runs/<job_id>/`` is written there).
    sequence_dir : str, optional
        The prepared sequence (from :func:`prepare_sequence`); prepared here when ``None``.

    Returns
    -------
    dict
        Store row: identity columns, status, metrics (:data:`relnav.eval.metrics.METRIC_KEYS`,
        from the written files as ``relnav evaluate`` computes them, plus ``time_ms`` = mean
        time per registered frame), per-stage mean times (ms), points per scan, timestamps.
    """
    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.io.trajectories import read_tum
    from relnav.odometry import run_sequence

    started = _now()
    t0 = time.perf_counter()
    row = _base_row(job)
    row["started_at"] = started
    try:
        if sequence_dir is None:
            sequence_dir = prepare_sequence(job, out_root)
        spec = job["scenario_spec"]
        seq = ScanSequence(sequence_dir, sensor=spec.get("sensor"))
        max_frames = spec.get("max_frames") if job["scenario_kind"] == "sequence" else None
        warm = int(job.get("warmup_frames", 0))
        if warm >= 2 and len(seq) >= 2:
            run_sequence(seq, job["method"], max_frames=warm, **job["options"])
        run = run_sequence(seq, job["method"], max_frames=max_frames, **job["options"])
        out = Path(out_root) / "runs" / job["job_id"]
        paths = run.write(out)
        diag = run.diagnostics()
        reg = diag[1:] or diag
        stages = {
            k: float(np.mean([float(d[k]) for d in reg])) for k in diag[0] if k.startswith("t_")
        }
        row.update(stages)
        row["mean_points"] = float(np.mean([d["n_points"] for d in diag]))
        row["n_flagged"] = run.n_flagged
        row["estimate_path"] = str(paths["estimate"].relative_to(out_root))
        row["sequence_path"] = (
            str(Path(sequence_dir).relative_to(out_root))
            if Path(sequence_dir).is_relative_to(out_root)
            else str(sequence_dir)
        )
        gt_file = seq.layout.gt
        if gt_file.is_file():
            t_est, P_est = read_tum(paths["estimate"])
            t_gt, P_gt = read_tum(gt_file)
            row.update(evaluate_trajectories(t_est, P_est, t_gt, P_gt))
            row["error"] = ""
        else:
            row["error"] = "no ground truth: timing only"
        row["time_ms"] = run.mean_time_ms
        row["status"] = "ok"
    except Exception as e:  # a failing method must not stop the grid
        log.warning(
            "job %s (%s on %s) failed: %s", job["job_id"], job["method"], job["scenario"], e
        )
        row.update(failed_row(job, e))
    row["finished_at"] = _now()
    row["wall_s"] = time.perf_counter() - t0
    row["started_at"] = started
    return row


def _worker_setup() -> dict[str, Any]:
    """Run on every worker once: its pid and numba's cache setting (logged at INFO)."""
    import numba

    cache_dir = numba.config.CACHE_DIR or "(next to the sources / user cache)"
    return {"pid": os.getpid(), "numba_cache_dir": cache_dir, "numba": numba.__version__}


# --------------------------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------------------------


@dataclass
class BenchmarkSummary:
    """What :func:`run_benchmark` did.

    Attributes
    ----------
    out_dir : Path
        Benchmark folder.
    grid_hash : str
        :meth:`GridSpec.grid_hash`.
    n_jobs, n_skipped, n_ok, n_failed : int
        Jobs in the grid, skipped as already finished, run now with status ok / failed.
    wall_s : float
        Wall-clock time of this invocation, s.
    executor : str
        ``"in-process"``, ``"LocalCluster(n_workers=N)"`` or the scheduler address.
    n_workers : int
        Workers (processes) used.
    failures : list of (job label, error)
        Jobs that failed in this invocation.
    """

    out_dir: Path
    grid_hash: str
    n_jobs: int
    n_skipped: int
    n_ok: int = 0
    n_failed: int = 0
    wall_s: float = 0.0
    executor: str = ""
    n_workers: int = 0
    failures: list[tuple[str, str]] = field(default_factory=list)


ProgressFn = Callable[[int, int, dict[str, Any]], None]


def _write_grid(grid: GridSpec, out: Path) -> None:
    from relnav.atomic import atomic_write_text

    data = grid.model_dump(mode="json")
    data["grid_hash"] = grid.grid_hash()
    atomic_write_text(out / GRID_FILE, dump_yaml(data))


def read_grid(out_dir: str | Path) -> GridSpec:
    """The resolved grid saved by :func:`run_benchmark` in ``out_dir``."""
    p = Path(out_dir) / GRID_FILE
    if not p.is_file():
        raise InputError(f"{out_dir}: no {GRID_FILE} (not a benchmark folder?)")
    data = load_yaml(p)
    data.pop("grid_hash", None)
    return validate(GridSpec, data, str(p))


def run_benchmark(
    grid: GridSpec | str | Path,
    out_dir: str | Path,
    *,
    workers: int = 2,
    scheduler: str | None = None,
    force: bool = False,
    retry_failed: bool = False,
    progress: ProgressFn | None = None,
    lock_timeout: float | None = None,
) -> BenchmarkSummary:
    """Run every unfinished job of ``grid`` into ``out_dir`` (see the module docstring).

    Parameters
    ----------
    grid : GridSpec or path
        The grid (:func:`load_grid`).
    out_dir : str or Path
        Benchmark folder: ``grid.yaml``, ``results.sqlite``, ``sequences/``, ``runs/``,
        ``runs.jsonl`` (one line per invocation: wall time, workers, host, jobs).
    workers : int
        Local worker processes (``LocalCluster``); 0 = run in this process, serially.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); ``workers`` is ignored.
    force : bool
        Rerun every job, finished or not.
    retry_failed : bool
        Rerun jobs recorded as failed.
    progress : callable, optional
        ``progress(done, total, row)`` after each job is stored.
    lock_timeout : float, optional
        Seconds to wait for another benchmark holding ``out_dir`` (default: as long as it
        takes; it then skips the jobs the other one finished).

    Returns
    -------
    BenchmarkSummary

    Notes
    -----
    Local workers are separate processes started with ``spawn``: a script calling this
    function must guard its entry point with ``if __name__ == "__main__":``.
    """
    from relnav.io.locks import FolderLock

    if not isinstance(grid, GridSpec):
        grid = load_grid(grid)
    if workers < 0:
        raise ConfigError(f"workers must be >= 0, got {workers}")
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    # One benchmark at a time per folder: a second process waits, then skips what the first
    # finished (the lock dies with its holder, even on SIGKILL).
    with FolderLock(out, timeout=lock_timeout, what="relnav benchmark"):
        return _run_locked(grid, out, workers, scheduler, force, retry_failed, progress)


def _run_locked(
    grid: GridSpec,
    out: Path,
    workers: int,
    scheduler: str | None,
    force: bool,
    retry_failed: bool,
    progress: ProgressFn | None,
) -> BenchmarkSummary:
    from relnav.bench.store import ResultsStore

    _write_grid(grid, out)
    jobs = expand_jobs(grid)
    gh = grid.grid_hash()
    t0 = time.perf_counter()
    started = _now()
    load0 = _loadavg()
    with ResultsStore(out / STORE_FILE) as store:
        store.set_meta("last_grid_hash", gh)
        if force:
            done: set[str] = set()
        else:
            done = store.finished_ids(("ok",) if retry_failed else ("ok", "failed"))
        pending = [j for j in jobs if j.job_id not in done]
        summary = BenchmarkSummary(out, gh, len(jobs), len(jobs) - len(pending))
        log.info(
            "grid %s: %d jobs, %d already finished, %d to run",
            grid.name,
            len(jobs),
            summary.n_skipped,
            len(pending),
        )

        def record(row: dict[str, Any]) -> None:
            row["grid_hash"] = gh
            row["grid_name"] = grid.name
            store.put(row)
            if row.get("status") == "ok":
                summary.n_ok += 1
            else:
                summary.n_failed += 1
                summary.failures.append(
                    (f"{row['method_label']} on {row['scenario']} seed {row['seed']}", row["error"])
                )
            if progress is not None:
                progress(summary.n_ok + summary.n_failed, len(pending), row)

        try:
            if pending:
                if scheduler is None and workers == 0:
                    summary.executor, summary.n_workers = "in-process", 1
                    _run_serial(pending, out, record)
                else:
                    _run_dask(pending, out, record, workers, scheduler, summary)
        finally:
            summary.wall_s = time.perf_counter() - t0
            info = {
                "started_at": started,
                "finished_at": _now(),
                "wall_s": round(summary.wall_s, 2),
                "grid": grid.name,
                "grid_hash": gh,
                "executor": summary.executor or "none",
                "n_workers": summary.n_workers,
                "host": socket.gethostname(),
                "cpu_count": os.cpu_count(),
                "cpu": platform.processor() or platform.machine(),
                "python": platform.python_version(),
                "n_jobs": len(jobs),
                "n_skipped": summary.n_skipped,
                "n_ok": summary.n_ok,
                "n_failed": summary.n_failed,
                "completed": summary.n_ok + summary.n_failed == len(pending),
                "load_avg_start": load0,
                "load_avg_end": _loadavg(),
            }
            with (out / RUNS_LOG).open("a") as f:
                f.write(json.dumps(info) + "\n")
    return summary


def _loadavg() -> float | None:
    """1-minute load average (None where unavailable): how shared the machine was."""
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def _run_serial(pending: list[Job], out: Path, record: Callable[[dict[str, Any]], None]) -> None:
    prepared: dict[str, str | BaseException] = {}
    for job in pending:
        d = job.as_dict()
        key = job.sequence_rel
        if key not in prepared:
            try:
                prepared[key] = prepare_sequence(d, str(out))
            except Exception as e:
                log.warning("preparing %s failed: %s", key, e)
                prepared[key] = e
        seq = prepared[key]
        if isinstance(seq, BaseException):
            record(failed_row(d, f"sequence preparation failed: {type(seq).__name__}: {seq}"))
            continue
        record(run_job(d, str(out), seq))


def _run_dask(
    pending: list[Job],
    out: Path,
    record: Callable[[dict[str, Any]], None],
    workers: int,
    scheduler: str | None,
    summary: BenchmarkSummary,
) -> None:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as e:  # pragma: no cover - dask is a core dependency
        raise ConfigError(
            "the benchmark needs dask.distributed: pip install 'dask[distributed]'"
        ) from e

    dlog = logging.getLogger("distributed")
    if not log.isEnabledFor(logging.DEBUG):
        dlog.setLevel(logging.WARNING)
    cluster = None
    if scheduler is not None:
        client = Client(scheduler, timeout="30s")
        summary.executor = str(scheduler)
    else:
        cluster = LocalCluster(
            n_workers=max(1, workers),
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
        summary.executor = f"LocalCluster(n_workers={max(1, workers)})"
    try:
        info = client.run(_worker_setup)
        summary.n_workers = len(info)
        log.info("workers: %s", info)
        root = str(out)
        prep: dict[str, Any] = {}
        by_key = {}
        for job in pending:
            by_key.setdefault(job.sequence_rel, job)
        # clean sequences first, then the nuisance variants derived from them
        for key, job in by_key.items():
            if job.nuisance:
                continue
            prep[key] = client.submit(
                prepare_sequence, job.as_dict(), root, key=f"prep-{_hash(key)}", pure=False
            )
        for key, job in by_key.items():
            if not job.nuisance:
                continue
            d = job.as_dict()
            base = prep.get(job.base_rel)
            if base is None:
                clean = {**d, "nuisance": {}, "sequence_rel": job.base_rel}
                base = client.submit(
                    prepare_sequence, clean, root, key=f"prep-{_hash(job.base_rel)}", pure=False
                )
                prep[job.base_rel] = base
            prep[key] = client.submit(
                prepare_sequence, d, root, base, key=f"prep-{_hash(key)}", pure=False
            )
        futs = []
        job_of: dict[str, Job] = {}
        for job in pending:
            fut = client.submit(
                run_job,
                job.as_dict(),
                root,
                prep[job.sequence_rel],
                key=f"job-{job.job_id}",
                pure=False,
            )
            futs.append(fut)
            job_of[fut.key] = job
        for fut in as_completed(futs):
            job = job_of[fut.key]
            try:
                row = fut.result()
            except Exception as e:  # preparation failed, worker died, …
                row = failed_row(job.as_dict(), e)
            record(row)
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _hash(s: str) -> str:
    return hashlib.sha1(s.encode()).hexdigest()[:12]
