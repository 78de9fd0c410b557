"""Benchmark grid specification (:class:`GridSpec`, YAML via :func:`load_grid`) and its expansion
into identified jobs (:class:`Job`, :func:`job_id`, :func:`expand_jobs`): scenarios × nuisances ×
methods × seeds. Run by :func:`relnav.bench.benchmark.run_benchmark`.
"""

from __future__ import annotations

import fnmatch
import hashlib
import itertools
import json
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from relnav.config import StrictModel, load_yaml, validate
from relnav.errors import ConfigError, InputError
from relnav.sim.nuisance import NuisanceSpec

__all__ = [
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
]


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
    from relnav.pipeline import resolve_method

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
