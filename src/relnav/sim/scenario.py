"""Scenarios: a validated description of a simulation, and :func:`simulate` writing a sequence.

A :class:`Scenario` fixes the target, one or more sensors on a rig, the rig's trajectory and
pointing, the target's attitude motion, the frame count and period, and a seed. :func:`simulate`
turns it into a sequence folder (``docs/DESIGN.md`` §5)::

    OUT/scans/000000.ply …            primary sensor (the first in ``sensors``)
    OUT/timestamps.txt, OUT/gt_T_target_sensor.tum, OUT/sensor.yaml
    OUT/scans_<name>/ …               every further sensor, with its own
    OUT/timestamps_<name>.txt, OUT/gt_T_target_sensor_<name>.tum, OUT/sensor_<name>.yaml
    OUT/scenario.yaml                 the resolved scenario (all defaults filled in, seed,
                                      relnav version); ``relnav simulate`` accepts it again

Frames
------
``W`` is centred on the target's centre of mass with LVLH/Hill axes for orbital cases (x radial,
y along-track, z orbit normal). The target frame is the mesh frame of
:class:`relnav.sim.targets.Target` (origin = bounding-box centre). **[interpretation]** The
procedural meshes are not watertight, so their volume centre of mass is undefined; the
bounding-box centre stands in for it unless ``target.com_offset`` (target frame, m) is given:
``T_W_target = [R_W_target | −R_W_target c]``. The rig (``T_W_rig``) comes from the trajectory
and pointing; each sensor is mounted on it, ``T_W_sensor = T_W_rig · T_rig_sensor`` with
``T_rig_sensor`` from ``offset_m`` and ``rpy_deg`` (extrinsic xyz Euler, degrees). Ground truth
per frame: ``T_target_sensor = T_W_target⁻¹ · T_W_sensor``.

Randomness
----------
``np.random.SeedSequence(seed).spawn(2 + n_sensors)`` → pointing jitter, (reserved), then one
child per sensor, each spawning one generator per frame. Equal seeds give byte-identical scan
files; changing a sensor's parameters does not change the other sensors' noise.
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import Field, field_validator, model_validator

from relnav.config import StrictModel, load_yaml, validate
from relnav.errors import ConfigError, InputError, RelnavError
from relnav.geometry.rotations import euler_to_matrix
from relnav.geometry.se3 import from_rt, invert
from relnav.sim import trajectories as _traj
from relnav.sim.attitude import make_attitude

__all__ = [
    "MAX_RAYS_PER_SCAN",
    "MAX_SIMULATED_FRAMES",
    "AttitudeSpec",
    "PointingSpec",
    "Scenario",
    "SensorSpec",
    "SensorSummary",
    "SimulationSummary",
    "TargetSpec",
    "TrajectorySpec",
    "apply_overrides",
    "default_scenario",
    "load_scenario",
    "n_simulated",
    "resolve_scenario",
    "scenario_poses",
    "scenario_yaml",
    "simulate",
]

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


# --------------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------------


class TargetSpec(StrictModel):
    """The target: a procedural ``name`` or a mesh ``path`` (exactly one).

    ``scale_to`` rescales the longest bounding-box side (m); ``seed`` drives procedural shape
    randomness (fixed by default so that scenario seeds vary only sensor noise);
    ``com_offset`` is the centre of mass in the target frame (m).
    """

    name: str | None = "envisat"
    path: str | None = None
    scale_to: float | None = Field(default=None, gt=0)
    seed: int = Field(default=0, ge=0)
    com_offset: Vec3 = (0.0, 0.0, 0.0)

    @model_validator(mode="before")
    @classmethod
    def _path_replaces_default_name(cls, data: Any) -> Any:
        if isinstance(data, dict) and data.get("path") is not None and "name" not in data:
            data = {**data, "name": None}
        return data

    @model_validator(mode="after")
    def _one_source(self) -> TargetSpec:
        if self.path is not None and self.name is not None:
            raise ValueError("give either target.name (procedural) or target.path (mesh), not both")
        if self.path is None and self.name is None:
            raise ValueError("target needs a procedural name or a mesh path")
        return self

    @property
    def spec(self) -> str:
        """What :func:`relnav.sim.targets.get_target` receives."""
        return str(self.path) if self.path is not None else str(self.name)


class SensorSpec(StrictModel):
    """A sensor preset (``relnav.sim.sensors.make_sensor``) with overrides and its mounting.

    ``name`` names the folder (``scans_<name>/`` for every sensor after the first; default the
    preset name). ``offset_m`` and ``rpy_deg`` place the sensor in the rig frame (the pointing
    frame, x towards the target, y left, z up).
    """

    preset: str = "goldeneye"
    name: str | None = None
    overrides: dict[str, Any] = Field(default_factory=dict)
    offset_m: Vec3 = (0.0, 0.0, 0.0)
    rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    @field_validator("name")
    @classmethod
    def _name_ok(cls, v: str | None) -> str | None:
        if v is not None and not _NAME_RE.match(v):
            raise ValueError("sensor name: letters, digits, '_', '-', '.' (becomes a folder name)")
        return v

    @property
    def label(self) -> str:
        """The sensor's name (``name`` or the preset)."""
        return self.name or self.preset.lower().replace("_", "-")

    @property
    def T_rig_sensor(self) -> np.ndarray:
        """Mounting transform ``(4, 4)``."""
        R = euler_to_matrix(np.deg2rad(np.asarray(self.rpy_deg)), "xyz")
        return from_rt(R, np.asarray(self.offset_m, dtype=np.float64))


class TrajectorySpec(StrictModel):
    """Chaser (rig) trajectory: ``kind`` from :func:`relnav.sim.trajectories.trajectory_kinds`
    with its keyword ``params``."""

    kind: str = "elliptic-orbit"
    params: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _known(self) -> TrajectorySpec:
        allowed = _traj.trajectory_params(self.kind) if self.kind in _traj.TRAJECTORIES else None
        if allowed is None:
            raise ValueError(
                f"unknown trajectory kind {self.kind!r}; choose one of "
                f"{', '.join(_traj.trajectory_kinds())}"
            )
        unknown = sorted(set(self.params) - set(allowed))
        if unknown:
            raise ValueError(
                f"unknown parameter(s) {', '.join(unknown)} for {self.kind!r}; "
                f"accepted: {', '.join(allowed)}"
            )
        return self


class PointingSpec(StrictModel):
    """Rig pointing: boresight at ``target`` (W, m), ``up`` hint, attitude jitter.

    ``jitter_deg``: σ of the sensor's attitude jitter (degrees), one value for the three axes or
    one per sensor axis (x boresight, y, z). ``jitter_kind``: ``white`` (independent between
    frames: a limit-cycling attitude control, thruster firings) or ``random-walk`` (the
    per-frame increments are white with that σ: a drifting attitude). The jitter is part of
    the ground truth (:func:`relnav.sim.trajectories.pointing_poses`).
    ``attitude_sigma_deg``: when set, :func:`simulate` also writes ``chaser_attitude.tum``, the
    primary sensor's inertial attitude ``R_W_sensor`` per frame as the chaser's star tracker /
    IMU would measure it (white noise of that σ per axis, degrees; seeded; position columns
    zero): the navigator's optional rotation input.
    """

    jitter_deg: float | Vec3 = 0.0
    jitter_kind: Literal["white", "random-walk"] = "white"
    attitude_sigma_deg: float | None = Field(default=None, ge=0, allow_inf_nan=False)
    up: Vec3 = (0.0, 0.0, 1.0)
    target: Vec3 = (0.0, 0.0, 0.0)

    @field_validator("jitter_deg")
    @classmethod
    def _jitter_ok(cls, v: float | Vec3) -> float | Vec3:
        values = np.atleast_1d(np.asarray(v, dtype=np.float64))
        if not (np.all(np.isfinite(values)) and np.all(values >= 0)):
            raise ValueError(f"must be finite and >= 0 (one value or one per axis), got {v!r}")
        return v


class AttitudeSpec(StrictModel):
    """Target attitude motion (see :mod:`relnav.sim.attitude`).

    ``static``: fixed at ``initial_rpy_deg``; ``spin``: about world ``axis`` at ``rate_deg_s``;
    ``tumble``: torque-free from ``inertia`` (3 principal moments or 3x3, kg m²) and body rate
    ``omega0_deg_s``. ``initial_rpy_deg`` is the attitude at t = 0 (extrinsic xyz, degrees).
    ``phase_s`` (s, default 0) enters the same motion later: the attitude at a frame's time
    ``t`` is the law's at ``t + phase_s`` (a Monte Carlo over where a tumble is when the
    sensor starts: ``benchmarks/nav/nav_phases.py``).
    """

    kind: Literal["static", "spin", "tumble"] = "static"
    axis: Literal["x", "y", "z"] | Vec3 = "z"
    rate_deg_s: float = 0.0
    inertia: Vec3 | tuple[Vec3, Vec3, Vec3] = (1.0, 2.0, 3.0)
    omega0_deg_s: Vec3 = (0.0, 0.0, 0.0)
    initial_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    phase_s: float = Field(default=0.0, ge=0, allow_inf_nan=False)

    def rotations(self, times: np.ndarray) -> np.ndarray:
        """``R_W_target`` ``(N, 3, 3)`` at ``times`` (s), the law evaluated at ``times +
        phase_s``."""
        R0 = euler_to_matrix(np.deg2rad(np.asarray(self.initial_rpy_deg)), "xyz")
        times = np.asarray(times, dtype=np.float64) + self.phase_s
        if self.kind == "static":
            return make_attitude("static", times, R0=R0)
        if self.kind == "spin":
            return make_attitude("spin", times, axis=self.axis, rate_deg_s=self.rate_deg_s, R0=R0)
        return make_attitude(
            "tumble",
            times,
            inertia=np.asarray(self.inertia, dtype=np.float64),
            omega0_deg_s=self.omega0_deg_s,
            R0=R0,
        )


class Scenario(StrictModel):
    """A complete simulation description (YAML-able; unknown keys are errors).

    Attributes
    ----------
    name, description : str
        Labels.
    seed : int
        Root seed of every random process.
    frames : int
        Number of frames (> 0) the trajectory is sampled with.
    max_frames : int, optional
        Simulate only the first ``max_frames`` of those frames (same per-frame motion and the
        same random streams as the full run, so the first frames are byte-identical).
    dt : float
        Frame period, s (> 0). Frame ``k`` is at ``t = k dt``.
    target, sensors, trajectory, pointing, attitude
        See the spec classes. The first sensor is the primary one (``scans/``).
    format : str
        Scan file format (``ply``, ``npy``, ``pcd`` …).
    relnav_version : str, optional
        Written by :func:`simulate` into ``scenario.yaml``; informational.
    """

    name: str = "scenario"
    description: str = ""
    seed: int = Field(default=0, ge=0)
    frames: int = Field(default=50, gt=0)
    max_frames: int | None = Field(default=None, gt=0)
    dt: float = Field(default=1.0, gt=0)
    target: TargetSpec = Field(default_factory=TargetSpec)
    sensors: list[SensorSpec] = Field(default_factory=lambda: [SensorSpec()], min_length=1)
    trajectory: TrajectorySpec = Field(default_factory=TrajectorySpec)
    pointing: PointingSpec = Field(default_factory=PointingSpec)
    attitude: AttitudeSpec = Field(default_factory=AttitudeSpec)
    format: str = "ply"
    relnav_version: str | None = None

    @field_validator("format")
    @classmethod
    def _fmt(cls, v: str) -> str:
        from relnav.io.pointclouds import POINT_WRITE_EXTENSIONS

        ext = "." + v.lower().lstrip(".")
        if ext not in POINT_WRITE_EXTENSIONS:
            raise ValueError(
                f"unknown scan format {v!r}; choose one of "
                f"{', '.join(e[1:] for e in POINT_WRITE_EXTENSIONS)}"
            )
        return ext[1:]

    @model_validator(mode="after")
    def _unique_sensor_names(self) -> Scenario:
        labels = [s.label for s in self.sensors]
        dup = sorted({x for x in labels if labels.count(x) > 1})
        if dup:
            raise ValueError(f"sensor names must be unique, repeated: {', '.join(dup)}")
        return self


# --------------------------------------------------------------------------------------------
# loading, overrides, resolution
# --------------------------------------------------------------------------------------------


def default_scenario() -> Scenario:
    """A small runnable scenario: GoldenEye flash LIDAR on a 2.5-loop ellipse around Envisat."""
    return Scenario(
        name="default",
        description="GoldenEye flash LIDAR on an elliptic orbit around a static Envisat-like "
        "target",
        frames=50,
        dt=10.0,
        target=TargetSpec(name="envisat"),
        sensors=[SensorSpec(preset="goldeneye")],
        trajectory=TrajectorySpec(
            kind="elliptic-orbit",
            params={"semi_major": 80.0, "semi_minor": 40.0, "loops": 1.0, "tilt_deg": 20.0},
        ),
    )


def parse_value(text: str) -> Any:
    """A command-line value parsed as YAML, and a number YAML 1.1 leaves as a string (``1e1``,
    ``1E-3``, ``1_000``) parsed as that number; unparsable text stays the text."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return _yaml_numbers(value)


def _yaml_numbers(value: Any) -> Any:
    """Strings that Python reads as numbers (``"1e1"``) → numbers, in lists and dicts too."""
    if isinstance(value, list):
        return [_yaml_numbers(v) for v in value]
    if isinstance(value, dict):
        return {k: _yaml_numbers(v) for k, v in value.items()}
    if isinstance(value, str):
        for kind in (int, float):
            try:
                return kind(value.strip())
            except ValueError:
                pass
    return value


def apply_overrides(data: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Set dotted keys in a nested scenario dict (copy returned).

    ``{"trajectory.params.loops": "3", "sensors.0.overrides.range_sigma": 0}``; string values
    are parsed as YAML (``"3"`` → 3, ``"[1, 2]"`` → list). List elements are addressed by index.
    """
    import copy

    out = copy.deepcopy(data)
    for key, raw in overrides.items():
        value = parse_value(raw) if isinstance(raw, str) else raw
        parts = str(key).split(".")
        node: Any = out
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if isinstance(node, list):
                try:
                    idx = int(part)
                    _ = node[idx]  # bounds check
                except (ValueError, IndexError):
                    raise ConfigError(f"override {key!r}: {part!r} is not a valid index") from None
                if last:
                    node[idx] = value
                else:
                    node = node[idx]
            elif isinstance(node, dict):
                if last:
                    node[part] = value
                else:
                    if node.get(part) is None:
                        node[part] = {}
                    node = node[part]
            else:
                raise ConfigError(f"override {key!r}: cannot descend into {part!r}")
    return out


def load_scenario(
    source: str | Path | dict[str, Any] | Scenario,
    *,
    overrides: dict[str, Any] | None = None,
    check: bool = True,
    label: str | None = None,
) -> Scenario:
    """Validate a scenario from a YAML file, a dict or a :class:`Scenario`.

    Parameters
    ----------
    source : path, dict or Scenario
        The scenario.
    overrides : dict, optional
        Dotted-key overrides applied before validation (see :func:`apply_overrides`).
    check : bool
        Also build the sensors (catching bad sensor parameters such as a negative range), the
        trajectory and the attitude once, so that every configuration error surfaces here as a
        :class:`ConfigError` rather than mid-simulation. The target mesh is not loaded, but a
        mesh path must exist.
    label : str, optional
        Name used in error messages (default: the file path or ``"scenario"``).

    Raises
    ------
    ConfigError
        Unknown keys, bad values, unknown kinds, with the offending key named.
    InputError
        ``target.path`` does not exist.
    """
    source_label = "scenario"
    if isinstance(source, Scenario):
        data = source.model_dump(mode="json")
    elif isinstance(source, dict):
        data = source
    else:
        source_label = str(source)
        data = load_yaml(source)
        if not data:
            raise ConfigError(f"{source}: empty scenario file (no keys)")
    if overrides:
        data = apply_overrides(data, overrides)
    label = label or source_label
    sc: Scenario = validate(Scenario, data, label)
    if check:
        _check_scenario(sc, label)
    return sc


def _build_sensor(spec: SensorSpec) -> Any:
    from relnav.sim.sensors import make_sensor

    kwargs = dict(spec.overrides)
    kwargs.pop("name", None)  # the folder name is SensorSpec.name
    sensor = make_sensor(spec.preset, **kwargs)
    sensor.name = spec.label
    return sensor


MAX_RAYS_PER_SCAN = 10_000_000
"""Largest ray pattern (or surface sample) per scan a scenario may ask for: each ray costs
~100 bytes of working memory, so this bounds one scan to ~1 GB (a 128-channel spinning LIDAR
at 0.1° has 460 800 rays)."""


MAX_SIMULATED_FRAMES = 5_000_000
"""Largest number of frames one simulation may write (its poses alone take ~1 KB per frame);
longer runs: simulate pieces with ``max_frames``."""


def n_simulated(sc: Scenario) -> int:
    """Frames actually simulated: ``frames``, or ``max_frames`` when smaller."""
    return sc.frames if sc.max_frames is None else min(sc.frames, sc.max_frames)


def _rays_per_scan(sensor: Any) -> tuple[int, str]:
    """Upper bound on the rays (points) one scan allocates, and the parameter that sets it;
    computed from the parameters without building the ray pattern."""
    if hasattr(sensor, "rows") and hasattr(sensor, "cols"):
        return int(sensor.rows) * int(sensor.cols), "rows x cols"
    if hasattr(sensor, "image_shape"):
        r, c = sensor.image_shape
        return int(r) * int(c), "width x height / decimation^2"
    if hasattr(sensor, "elevations_deg") and hasattr(sensor, "azimuth_step_deg"):
        n_az = 360.0 / float(sensor.azimuth_step_deg)
        return int(min(n_az, 1e18)) * len(sensor.elevations_deg), "elevations x 360/azimuth_step"
    if hasattr(sensor, "n_points"):
        return 4 * int(sensor.n_points), "4 x n_points"
    return 0, ""


def _check_scenario(sc: Scenario, label: str) -> None:
    for i, s in enumerate(sc.sensors):
        try:
            sensor = _build_sensor(s)
        except RelnavError as e:
            raise ConfigError(f"{label}: sensors.{i} ({s.label}): {e}") from None
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{label}: sensors.{i} ({s.label}): bad parameter: {e}") from None
        n_rays, what = _rays_per_scan(sensor)
        if n_rays > MAX_RAYS_PER_SCAN:
            raise ConfigError(
                f"{label}: sensors.{i} ({s.label}): {n_rays:.3g} rays per scan ({what}) "
                f"exceeds the limit of {MAX_RAYS_PER_SCAN:.0e}"
            )
    if n_simulated(sc) > MAX_SIMULATED_FRAMES:
        raise ConfigError(
            f"{label}: {n_simulated(sc)} frames to simulate exceeds the limit of "
            f"{MAX_SIMULATED_FRAMES} (set max_frames / --max-frames)"
        )
    try:
        times, pos = _traj.make_trajectory(
            sc.trajectory.kind, sc.frames, sc.dt, sc.trajectory.params, n_keep=n_simulated(sc)
        )
    except ConfigError as e:
        raise ConfigError(f"{label}: {e}") from None
    try:
        sc.attitude.rotations(times[:2])
    except ConfigError as e:
        raise ConfigError(f"{label}: {e}") from None
    tgt = np.asarray(sc.pointing.target)
    if np.any(np.linalg.norm(pos - tgt, axis=1) < 1e-9):
        raise ConfigError(f"{label}: the trajectory passes through the pointing target")
    if sc.target.path is not None and not Path(sc.target.path).expanduser().is_file():
        raise InputError(f"{label}: target.path: mesh file not found: {sc.target.path}")


def resolve_scenario(sc: Scenario) -> dict[str, Any]:
    """The scenario as a plain dict with every trajectory default filled in and the version."""
    from relnav import __version__

    d = sc.model_dump(mode="json")
    params = dict(_traj.trajectory_params(sc.trajectory.kind))
    params.update(sc.trajectory.params)
    d["trajectory"]["params"] = _plain(params)
    d["relnav_version"] = __version__
    return d


class _FlowListDumper(yaml.SafeDumper):
    """YAML dumper writing short lists of scalars in flow style (``[0.0, 0.0, 1.0]``)."""


def _repr_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    flow = all(not isinstance(v, dict | list) for v in data) and len(data) <= 16
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_FlowListDumper.add_representer(list, _repr_list)


def scenario_yaml(sc: Scenario | dict[str, Any], *, resolved: bool = True) -> str:
    """YAML text of a scenario that :func:`load_scenario` reads back.

    ``resolved`` fills in every trajectory default and the relnav version
    (:func:`resolve_scenario`).
    """
    if isinstance(sc, Scenario):
        d = resolve_scenario(sc) if resolved else sc.model_dump(mode="json")
    else:
        d = _plain(sc)
    return yaml.dump(d, Dumper=_FlowListDumper, sort_keys=False, allow_unicode=True, width=100)


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    return x


# --------------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------------


@dataclass
class SensorSummary:
    """Per-sensor statistics of a simulation.

    Attributes
    ----------
    name : str
        Sensor name (``""`` folder suffix for the primary is not used here).
    preset : str
        Sensor preset.
    folder : str
        ``scans`` or ``scans_<name>``.
    frames : int
        Frames simulated.
    mean_points, min_points, max_points : float, int, int
        Points per scan.
    path_length_m : float
        Length of the sensor's path in ``W`` (m).
    empty_frames : int
        Frames with no point on the target.
    """

    name: str
    preset: str
    folder: str
    frames: int
    mean_points: float
    min_points: int
    max_points: int
    path_length_m: float
    empty_frames: int


@dataclass
class SimulationSummary:
    """What :func:`simulate` did: per-sensor statistics and per-stage wall times (s)."""

    scenario: str
    seed: int
    out_dir: Path
    sensors: list[SensorSummary]
    timings: dict[str, float] = field(default_factory=dict)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per sensor (for tables)."""
        return [vars(s).copy() for s in self.sensors]


@dataclass
class _Poses:
    times: np.ndarray
    T_W_rig: np.ndarray
    T_W_target: np.ndarray


def scenario_poses(sc: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame times ``(N,)``, ``T_W_rig`` ``(N, 4, 4)`` and ``T_W_target`` ``(N, 4, 4)``.

    Deterministic given the scenario (the jitter uses the scenario's seed).
    """
    p = _poses(sc, np.random.SeedSequence(sc.seed).spawn(2 + len(sc.sensors))[0])
    return p.times, p.T_W_rig, p.T_W_target


def _poses(sc: Scenario, jitter_ss: np.random.SeedSequence, n_keep: int | None = None) -> _Poses:
    times, pos = _traj.make_trajectory(
        sc.trajectory.kind, sc.frames, sc.dt, sc.trajectory.params, n_keep=n_keep
    )
    T_W_rig = _traj.pointing_poses(
        pos,
        target=sc.pointing.target,
        up=sc.pointing.up,
        jitter_deg=sc.pointing.jitter_deg,
        jitter_kind=sc.pointing.jitter_kind,
        seed=np.random.default_rng(jitter_ss),
    )
    R = sc.attitude.rotations(times)
    c = np.asarray(sc.target.com_offset, dtype=np.float64)
    T_W_target = np.zeros((len(times), 4, 4))
    T_W_target[:, :3, :3] = R
    T_W_target[:, :3, 3] = -R @ c
    T_W_target[:, 3, 3] = 1.0
    return _Poses(times, T_W_rig, T_W_target)


CHASER_ATTITUDE_FILE = "chaser_attitude.tum"
"""The chaser's measured inertial attitude in a simulated sequence folder (when asked for)."""


def _write_chaser_attitude(
    out: Path,
    times: np.ndarray,
    T_W_sensor: np.ndarray,
    pointing: PointingSpec,
    ss: np.random.SeedSequence,
) -> None:
    """``chaser_attitude.tum``: ``R_W_sensor · exp([δ]×)``, ``δ ~ N(0, σ² I₃)`` per frame
    (``σ = pointing.attitude_sigma_deg``), position columns zero."""
    from relnav.geometry.rotations import rotvec_to_matrix
    from relnav.io.trajectories import write_tum

    n = len(times)
    sigma = math.radians(float(pointing.attitude_sigma_deg or 0.0))
    delta = np.random.default_rng(ss).normal(0.0, 1.0, (n, 3)) * sigma
    A = np.tile(np.eye(4), (n, 1, 1))
    A[:, :3, :3] = T_W_sensor[:, :3, :3] @ rotvec_to_matrix(delta)
    write_tum(out / CHASER_ATTITUDE_FILE, times, A)


def _check_output_free(out: Path, sc: Scenario, overwrite: bool) -> None:
    """The error :class:`SequenceWriter` would raise for existing scans, raised up front."""
    from relnav.io.sequences import POINT_READ_EXTENSIONS, sequence_layout

    if overwrite:
        return
    for i, spec in enumerate(sc.sensors):
        d = sequence_layout(out, None if i == 0 else spec.label).scans_dir
        if d.is_dir():
            old = [q for q in d.iterdir() if q.suffix.lower() in POINT_READ_EXTENSIONS]
            if old:
                raise InputError(
                    f"{d}: already holds {len(old)} scan files "
                    "(pass overwrite=True, or --overwrite on the command line, to replace them)"
                )


def _check_target_visible(
    sc: Scenario, sensors: list[Any], target: Any, T_ts: list[np.ndarray]
) -> None:
    """InputError before anything is written when a ray sensor's pattern never comes near
    the target's bounding sphere (out of range or pointed away in every frame)."""
    for spec, sensor, T in zip(sc.sensors, sensors, T_ts, strict=True):
        candidates = getattr(sensor, "_candidate_rays", None)
        if candidates is None:
            continue
        for k in range(len(T)):
            c = candidates(target, T[k])
            if c is not None and len(c):
                break
        else:
            raise InputError(
                f"sensor {spec.label} saw nothing of the target in any of the {len(T)} frames "
                f"(out of range, max_range {sensor.max_range:g} m, or field of view): check "
                "range/FOV/trajectory (nothing written)"
            )


def simulate(
    scenario: Scenario | dict[str, Any] | str | Path,
    out_dir: str | Path,
    *,
    progress: Callable[[int, int], None] | None = None,
    overwrite: bool = False,
    target: Any = None,
) -> SimulationSummary:
    """Simulate a scenario into the sequence folder ``out_dir``.

    Parameters
    ----------
    scenario : Scenario, dict or path
        Validated with :func:`load_scenario`.
    out_dir : str or Path
        Sequence folder (created).
    progress : callable, optional
        Called as ``progress(frames_done, frames_total)`` after every frame.
    overwrite : bool
        Replace existing scans in ``out_dir`` (otherwise an existing non-empty ``scans/`` is an
        :class:`InputError`).
    target : relnav.sim.targets.Target, optional
        A pre-built target to use instead of building ``scenario.target`` (e.g. to reuse a
        loaded mesh across runs); the scenario's ``target`` entry is still recorded.

    Returns
    -------
    SimulationSummary

    Raises
    ------
    ConfigError, InputError
        Invalid scenario, missing mesh, existing output; a sensor that saw nothing of the
        target in any frame (:class:`InputError`).
    """
    from relnav.atomic import atomic_write_text
    from relnav.io.sequences import SequenceWriter
    from relnav.sim.targets import get_target

    sc = load_scenario(scenario)
    out = Path(out_dir)
    timings = {"setup": 0.0, "scan": 0.0, "write": 0.0}
    t0 = time.perf_counter()
    children = np.random.SeedSequence(sc.seed).spawn(2 + len(sc.sensors))
    if target is None:
        target = get_target(sc.target.spec, seed=sc.target.seed, scale_to=sc.target.scale_to)
    sensors = [_build_sensor(s) for s in sc.sensors]
    n_sim = n_simulated(sc)
    # only the simulated frames are computed (the first n_sim of the whole path, identical
    # values); spawn(k) gives the first k children of spawn(frames)
    poses = _poses(sc, children[0], n_sim)
    T_target_W = invert(poses.T_W_target)
    T_ts = [T_target_W @ poses.T_W_rig @ s.T_rig_sensor for s in sc.sensors]
    frame_ss = [children[2 + i].spawn(n_sim) for i in range(len(sc.sensors))]
    resolved = resolve_scenario(sc)
    _check_target_visible(sc, sensors, target, T_ts)
    timings["setup"] = time.perf_counter() - t0

    n_sensors = len(sc.sensors)
    counts = np.zeros((n_sensors, n_sim), dtype=np.int64)
    writers: list[Any] = []
    _check_output_free(out, sc, overwrite)
    # Nothing is written until every sensor has seen the target once: a sensor that never
    # does fails the run with an empty output folder. Frames before that are buffered (empty
    # scans cost nothing; a sensor that sees early is buffered only while another does not).
    pending: list[tuple[int, list[Any]]] = []
    seen = np.zeros(n_sensors, dtype=bool)

    def open_writers() -> None:
        for i, (spec, sensor) in enumerate(zip(sc.sensors, sensors, strict=True)):
            writers.append(
                SequenceWriter(
                    out,
                    sensor=None if i == 0 else spec.label,
                    fmt=sc.format,
                    sensor_meta=sensor.to_dict(),
                    overwrite=overwrite,
                )
            )

    def write_frame(k: int, scans: list[Any]) -> None:
        tw = time.perf_counter()
        for i, pts in enumerate(scans):
            writers[i].add(pts, float(poses.times[k]), T_ts[i][k])
        timings["write"] += time.perf_counter() - tw

    try:
        for k in range(n_sim):
            scans = []
            for i, sensor in enumerate(sensors):
                ts = time.perf_counter()
                pts = sensor.scan(target, T_ts[i][k], np.random.default_rng(frame_ss[i][k]))
                timings["scan"] += time.perf_counter() - ts
                counts[i, k] = len(pts)
                seen[i] |= len(pts) > 0
                scans.append(pts)
            if writers:
                write_frame(k, scans)
            else:
                pending.append((k, scans))
                if seen.all():
                    open_writers()
                    for kk, ss in pending:
                        write_frame(kk, ss)
                    pending.clear()
            if progress is not None:
                progress(k + 1, n_sim)
        if not seen.all():
            blind = [
                f"{spec.label} (max_range {s.max_range:g} m)"
                for spec, s, v in zip(sc.sensors, sensors, seen, strict=True)
                if not v
            ]
            raise InputError(
                f"sensor {', '.join(blind)} saw nothing of the target in any of the {n_sim} "
                "frames: check range/FOV/trajectory (nothing written)"
            )
        tw = time.perf_counter()
        for w in writers:
            w.close()
        atomic_write_text(out / "scenario.yaml", scenario_yaml(resolved))
        if sc.pointing.attitude_sigma_deg is not None:
            T_s = poses.T_W_rig[:n_sim] @ sc.sensors[0].T_rig_sensor
            _write_chaser_attitude(out, poses.times[:n_sim], T_s, sc.pointing, children[1])
        timings["write"] += time.perf_counter() - tw
    finally:
        for w in writers:
            w.close()

    summaries = []
    for i, spec in enumerate(sc.sensors):
        c = counts[i]
        empty = int(np.sum(c == 0))
        if empty == n_sim:
            raise InputError(
                f"sensor {spec.label} saw nothing of the target in any of the {n_sim} "
                "frames: check range/FOV/trajectory"
            )
        if empty:
            log.warning(
                "sensor %s: %d of %d frames saw nothing of the target", spec.label, empty, n_sim
            )
        summaries.append(
            SensorSummary(
                name=spec.label,
                preset=spec.preset,
                folder="scans" if i == 0 else f"scans_{spec.label}",
                frames=n_sim,
                mean_points=float(c.mean()),
                min_points=int(c.min()),
                max_points=int(c.max()),
                path_length_m=_traj.path_length(
                    (poses.T_W_rig[:n_sim] @ spec.T_rig_sensor)[:, :3, 3]
                ),
                empty_frames=empty,
            )
        )
    timings["total"] = time.perf_counter() - t0
    log.info("simulated %s: %d frames into %s", sc.name, n_sim, out)
    return SimulationSummary(sc.name, sc.seed, out, summaries, timings)
