"""Simulation targets: mesh loading/rescaling and procedural satellites, capsule and asteroid.

Every :class:`Target` mesh is expressed in the **target frame**: origin at the centre of the
mesh's axis-aligned bounding box, metres. Procedural targets are built from primitives
(boxes, cylinders, surfaces of revolution) that are concatenated, not merged by boolean
operations, so they are not watertight; ray casting and surface sampling do not need it.

Procedural targets (``procedural_target``; the axes are the target frame's):

========== ==================================================================================
name       shape
========== ==================================================================================
envisat    Envisat-like: 10 m box bus along x, one 14 m × 5 m solar wing on a boom at −x,
           10 m × 1.3 m SAR antenna panel under the bus, two instrument boxes, a dish on a
           mast and rod antennas; ≈ 26 m long (x).
iridium    Iridium/Globalstar-2-like: 1.5 × 1.5 × 2.2 m bus, two 3.2 m × 1.6 m wings along
           ±y on yokes, nadir antenna panel and rods; ≈ 8.7 m span (y).
capsule    Orion-like crew module about z: 5.0 m heat-shield dish (spherical cap, R = 6 m),
           32.5° truncated cone, docking tunnel, asymmetric RCS pods and a hatch; ≈ 5.0 m
           diameter, ≈ 3.3 m tall.
voyager    Voyager-like probe: decagonal bus, 3.66 m paraboloid dish with feed, RTG boom
           with three RTGs, science boom with scan platform, magnetometer boom; ≈ 12 m.
asteroid   Seeded smooth perturbed ellipsoid with a Bennu-like equatorial ridge, optional
           craters (``craters=N``); longest extent 500 m unless ``scale_to`` is given.
========== ==================================================================================

Aliases: ``bennu`` → asteroid, ``orion`` → capsule, ``globalstar`` → iridium.
"""

from __future__ import annotations

import inspect
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from relnav.errors import ConfigError, InputError

__all__ = [
    "TARGET_ALIASES",
    "Target",
    "available_targets",
    "get_target",
    "load_target",
    "procedural_target",
]

log = logging.getLogger(__name__)

TARGET_ALIASES: dict[str, str] = {"bennu": "asteroid", "orion": "capsule", "globalstar": "iridium"}


@dataclass
class Target:
    """A target body: a triangle mesh in the target frame.

    Attributes
    ----------
    name : str
        Display name.
    mesh : trimesh.Trimesh
        Mesh in the target frame (origin = bounding-box centre), metres.
    source : str
        File path, or ``"procedural:<name>:seed=<s>"``.
    metadata : dict
        Free-form provenance (scale factor applied, procedural parameters, ...).
    """

    name: str
    mesh: trimesh.Trimesh
    source: str
    metadata: dict[str, Any] = field(default_factory=dict)
    _raycaster: Any = field(default=None, init=False, repr=False, compare=False)
    _sphere: tuple[int, np.ndarray, float] | None = field(
        default=None, init=False, repr=False, compare=False
    )
    cache: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)
    """Derived data of consumers (e.g. sensors' calibrations), keyed by the consumer."""

    @property
    def extent(self) -> float:
        """Longest side of the axis-aligned bounding box, metres."""
        return float(np.max(self.mesh.extents))

    @property
    def raycaster(self) -> Any:
        """Cached :class:`relnav.sim.raycast.RayCaster` of :attr:`mesh` (built on first use)."""
        from relnav.sim.raycast import RayCaster

        rc = self._raycaster
        if rc is None or rc.mesh is not self.mesh:
            rc = RayCaster(self.mesh)
            self._raycaster = rc
        return rc

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """``(centre (3,), radius)`` of a sphere enclosing every vertex (target frame, m).

        Centre = bounding-box centre, radius = largest vertex distance to it (not the minimal
        sphere, but cheap and exact as an enclosure).
        """
        if self._sphere is None or self._sphere[0] != id(self.mesh):
            V = np.asarray(self.mesh.vertices, dtype=np.float64)
            c = 0.5 * (V.min(axis=0) + V.max(axis=0))
            r = float(np.sqrt(((V - c) ** 2).sum(axis=1).max()))
            self._sphere = (id(self.mesh), c, r)
        return self._sphere[1], self._sphere[2]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_raycaster"] = None
        return state


# --------------------------------------------------------------------------- loading


def _read_mesh(path: Path) -> trimesh.Trimesh:
    try:
        from relnav.io.meshes import read_mesh
    except ImportError:  # relnav.io not available: read with trimesh directly
        pass
    else:
        return read_mesh(path)
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as e:  # trimesh raises many kinds of errors on bad files
        raise InputError(f"{path}: cannot read mesh: {e}") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise InputError(f"{path}: not a triangle mesh (got {type(mesh).__name__})")
    return mesh


def _check_scale_to(scale_to: float | None) -> None:
    if scale_to is not None and not (np.isfinite(scale_to) and scale_to > 0):
        raise ConfigError(f"scale_to must be a positive finite length in metres, got {scale_to}")


def _centre_and_scale(mesh: trimesh.Trimesh, scale_to: float | None) -> float:
    """Centre ``mesh`` (in place) at its bbox centre; scale its longest side to ``scale_to``."""
    lo, hi = mesh.bounds
    mesh.apply_translation(-0.5 * (lo + hi))
    ext = float(np.max(hi - lo))
    if scale_to is None:
        return 1.0
    if ext <= 0:
        raise InputError("mesh has zero extent; cannot scale it")
    s = float(scale_to) / ext
    mesh.apply_scale(s)
    return s


def load_target(
    path: str | Path, *, scale_to: float | None = None, name: str | None = None
) -> Target:
    """Load a mesh file (PLY/OBJ/STL/GLB/...) as a :class:`Target`.

    Parameters
    ----------
    path : str or Path
        Mesh file; scenes are flattened into one mesh.
    scale_to : float, optional
        Longest bounding-box side after a uniform scale, metres (``None``: keep file units).
    name : str, optional
        Display name (default: the file stem).

    Returns
    -------
    Target
        Mesh centred at its bounding-box centre (target frame).

    Raises
    ------
    InputError
        Missing, unreadable or empty mesh file.
    ConfigError
        Non-positive ``scale_to``.
    """
    _check_scale_to(scale_to)
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such mesh file")
    mesh = _read_mesh(p)
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise InputError(f"{p}: mesh has no triangles")
    if not np.isfinite(mesh.vertices).all():
        raise InputError(f"{p}: mesh has non-finite vertex coordinates")
    scale = _centre_and_scale(mesh, scale_to)
    return Target(
        name=name or p.stem,
        mesh=mesh,
        source=str(p),
        metadata={"scale": scale, "scale_to": scale_to},
    )


# --------------------------------------------------------------------------- primitives


def _subdivided(mesh: trimesh.Trimesh, max_edge: float) -> trimesh.Trimesh:
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge, max_iter=8)
    return trimesh.Trimesh(v, f, process=False)


def _box(
    extents: tuple[float, float, float], centre: tuple[float, float, float]
) -> trimesh.Trimesh:
    T = np.eye(4)
    T[:3, 3] = centre
    return trimesh.creation.box(extents=extents, transform=T)


def _rod(p0: Any, p1: Any, radius: float, sections: int = 12) -> trimesh.Trimesh:
    return trimesh.creation.cylinder(
        radius=radius, segment=np.array([p0, p1], dtype=float), sections=sections
    )


def _axis_transform(origin: Any, axis: Any) -> np.ndarray:
    """Transform taking +z to the unit ``axis`` and the origin to ``origin``."""
    T = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], np.asarray(axis, dtype=float))
    T = np.asarray(T, dtype=float)
    T[:3, 3] = origin
    return T


def _dish(
    radius: float, depth: float, origin: Any, axis: Any, sections: int = 48, rings: int = 8
) -> trimesh.Trimesh:
    """Open paraboloid dish (vertex at ``origin``, opening along ``axis``)."""
    r = np.linspace(0.0, radius, rings + 1)
    prof = np.column_stack([r, depth * (r / radius) ** 2])
    return trimesh.creation.revolve(
        prof, sections=sections, transform=_axis_transform(origin, axis)
    )


def _assemble(parts: list[trimesh.Trimesh], max_edge: float) -> trimesh.Trimesh:
    mesh = trimesh.util.concatenate([_subdivided(p, max_edge) for p in parts])
    mesh.merge_vertices()
    return mesh


# --------------------------------------------------------------------------- procedural


def _envisat(rng: np.random.Generator, *, max_edge: float = 0.5) -> trimesh.Trimesh:
    parts = [
        _box((10.0, 4.5, 4.5), (5.0, 0.0, 0.0)),  # bus, x in [0, 10]
        _rod((0.0, 0.0, 1.0), (-1.5, 0.0, 1.0), 0.12),  # solar-array boom
        _box((14.0, 5.0, 0.06), (-8.5, 0.0, 1.0)),  # solar wing x in [-15.5, -1.5]
        _box((0.3, 5.0, 0.3), (-1.65, 0.0, 1.0)),  # wing yoke / hinge bar
        _box((10.0, 1.3, 0.3), (5.0, -1.0, -2.95)),  # ASAR antenna panel
        _rod((3.0, -1.0, -2.25), (3.0, -1.0, -2.8), 0.08),  # ASAR struts
        _rod((7.0, -1.0, -2.25), (7.0, -1.0, -2.8), 0.08),
        _box((1.8, 1.5, 1.0), (7.5, 1.0, 2.75)),  # instrument (MERIS-like)
        _box((1.4, 1.2, 0.9), (3.0, -1.2, 2.7)),  # instrument (AATSR-like)
        _rod((9.0, 1.5, 2.25), (9.0, 1.5, 3.6), 0.07),  # dish mast
        _dish(0.6, 0.18, (9.0, 1.5, 3.6), (0.3, 0.2, 1.0)),  # Ka-band dish
        _rod((10.0, 1.5, -1.5), (10.5, 1.5, -1.5), 0.04),  # antennas
        _rod((8.0, 2.25, 1.5), (8.0, 3.3, 1.5), 0.04),
        _rod((1.0, -2.25, -1.5), (1.0, -3.1, -1.5), 0.04),
    ]
    return _assemble(parts, max_edge)


def _iridium(rng: np.random.Generator, *, max_edge: float = 0.2) -> trimesh.Trimesh:
    parts = [
        _box((1.5, 1.5, 2.2), (0.0, 0.0, 0.0)),  # bus
        _rod((0.0, 0.75, 0.2), (0.0, 1.15, 0.2), 0.05),  # yokes
        _rod((0.0, -0.75, 0.2), (0.0, -1.15, 0.2), 0.05),
        _box((0.04, 3.2, 1.6), (0.0, 2.75, 0.2)),  # wings y in [1.15, 4.35]
        _box((0.04, 3.2, 1.6), (0.0, -2.75, 0.2)),
        _box((1.2, 1.2, 0.15), (0.0, 0.0, -1.175)),  # nadir antenna panel
        _rod((0.4, 0.4, -1.25), (0.4, 0.4, -2.0), 0.04),  # nadir rods
        _rod((-0.4, 0.3, -1.25), (-0.4, 0.3, -1.8), 0.06),
        _rod((0.2, -0.45, -1.25), (0.2, -0.45, -1.6), 0.05),
        _rod((0.5, -0.5, 1.1), (0.5, -0.5, 1.7), 0.03),  # zenith rods
        _dish(0.25, 0.08, (-0.4, -0.3, 1.1), (0.0, 0.0, 1.0), sections=32, rings=4),
        _box((0.35, 0.5, 0.3), (0.925, 0.2, 0.6)),  # side equipment box
    ]
    return _assemble(parts, max_edge)


def _capsule(rng: np.random.Generator, *, max_edge: float = 0.3) -> trimesh.Trimesh:
    r_base, r_shield = 2.5, 6.0
    depth = r_shield - math.sqrt(r_shield**2 - r_base**2)  # heat-shield cap depth
    cone_h = 2.3
    r_top = r_base - cone_h * math.tan(math.radians(32.5))
    tunnel_r, tunnel_h = 0.8, 0.45
    a = np.linspace(0.0, math.asin(r_base / r_shield), 10)
    shield = np.column_stack([r_shield * np.sin(a), -depth + r_shield * (1 - np.cos(a))])
    prof = np.vstack(
        [
            shield,
            [[r_base, 0.0], [r_top, cone_h], [tunnel_r, cone_h]],
            [[tunnel_r, cone_h + tunnel_h], [0.0, cone_h + tunnel_h]],
        ]
    )
    body = trimesh.creation.revolve(prof, sections=72)
    tan_c = math.tan(math.radians(32.5))

    def on_cone(az_deg: float, z: float, size: tuple[float, float, float]) -> trimesh.Trimesh:
        az = math.radians(az_deg)
        r = r_base - z * tan_c
        T = trimesh.transformations.rotation_matrix(az, [0, 0, 1])
        T = T @ trimesh.transformations.translation_matrix([r - 0.5 * size[0] + 0.12, 0, z])
        T = T @ trimesh.transformations.rotation_matrix(math.radians(-32.5), [0, 1, 0])
        return trimesh.creation.box(extents=size, transform=T)

    parts = [
        body,
        on_cone(20.0, 1.6, (0.35, 0.5, 0.4)),  # RCS pods, deliberately uneven
        on_cone(115.0, 1.4, (0.35, 0.4, 0.35)),
        on_cone(200.0, 1.7, (0.35, 0.6, 0.45)),
        on_cone(290.0, 1.2, (0.35, 0.4, 0.3)),
        on_cone(160.0, 0.6, (0.3, 1.0, 0.8)),  # hatch
    ]
    return _assemble(parts, max_edge)


def _voyager(rng: np.random.Generator, *, max_edge: float = 0.3) -> trimesh.Trimesh:
    bus_r, bus_h = 0.89, 0.47
    dish_z = 0.5 * bus_h + 0.25
    mag_dir = np.array([-1.0, 0.3, -0.12])
    mag_dir /= np.linalg.norm(mag_dir)
    mag_start = bus_r * mag_dir
    parts = [
        trimesh.creation.cylinder(radius=bus_r, height=bus_h, sections=10),  # decagonal bus
        _rod((0, 0, 0.5 * bus_h), (0, 0, dish_z), 0.3, 16),  # dish support
        _dish(1.83, 0.55, (0, 0, dish_z), (0, 0, 1), sections=64, rings=12),  # HGA, 3.66 m
        _rod((0, 0, dish_z), (0, 0, dish_z + 1.2), 0.06),  # feed / subreflector support
        trimesh.creation.cylinder(
            radius=0.22, height=0.05, transform=_axis_transform((0, 0, dish_z + 1.2), (0, 0, 1))
        ),
        _rod((0, -bus_r, 0), (0, -3.0, -0.2), 0.06),  # RTG boom
        _rod((0, -2.0, -0.13), (0, -2.6, -0.17), 0.2, 16),  # RTGs
        _rod((0, -2.65, -0.17), (0, -3.25, -0.2), 0.2, 16),
        _rod((0, -3.3, -0.2), (0, -3.9, -0.23), 0.2, 16),
        _rod((0, bus_r, 0), (0, 2.3, 0.1), 0.06),  # science boom
        _box((0.6, 0.5, 0.55), (0.0, 2.55, 0.1)),  # scan platform
        _rod((0.15, 2.55, 0.35), (0.6, 2.55, 0.55), 0.1),  # camera
        _rod(mag_start, mag_start + 10.0 * mag_dir, 0.05, 8),  # magnetometer boom
        _box((0.3, 0.3, 0.3), tuple(mag_start + 10.0 * mag_dir)),
    ]
    return _assemble(parts, max_edge)


def _asteroid(
    rng: np.random.Generator,
    *,
    subdivisions: int = 5,
    craters: int = 0,
    axes: tuple[float, float, float] = (1.0, 0.95, 0.9),
    ridge_height: float = 0.06,
    ridge_width_deg: float = 14.0,
    roughness: float = 0.03,
) -> trimesh.Trimesh:
    """Perturbed ellipsoid; radius function of the unit direction ``u``.

    ``r(u) = r_ell(u) · (1 + ridge(lat) + Σ waves(u) + Σ craters(u))`` with a Gaussian equatorial
    ridge of relative height ``ridge_height``, ``12`` random smooth cosine waves of total
    relative amplitude ``roughness``, and ``craters`` bowl-shaped craters with raised rims.
    """
    if not 1 <= int(subdivisions) <= 7:
        raise ConfigError(f"asteroid: subdivisions must be in 1..7, got {subdivisions}")
    if int(craters) < 0:
        raise ConfigError(f"asteroid: craters must be >= 0, got {craters}")
    a = np.asarray(axes, dtype=float)
    if a.shape != (3,) or not np.all(a > 0):
        raise ConfigError(f"asteroid: axes must be 3 positive numbers, got {axes}")
    sph = trimesh.creation.icosphere(subdivisions=int(subdivisions))
    u = np.asarray(sph.vertices, dtype=float)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = 1.0 / np.sqrt(((u / a) ** 2).sum(axis=1))
    lat = np.arcsin(np.clip(u[:, 2], -1.0, 1.0))
    f = 1.0 + ridge_height * np.exp(-((lat / math.radians(ridge_width_deg)) ** 2))
    n_waves = 12
    k = rng.normal(size=(n_waves, 3))
    k *= (rng.uniform(1.0, 4.0, n_waves) / np.linalg.norm(k, axis=1))[:, None]
    amp = rng.uniform(0.5, 1.0, n_waves) / np.linalg.norm(k, axis=1)
    amp *= roughness / amp.sum() * 2.0
    phase = rng.uniform(0.0, 2 * math.pi, n_waves)
    f += (amp[None, :] * np.cos(u @ k.T + phase[None, :])).sum(axis=1)
    for _ in range(int(craters)):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        rho = math.exp(rng.uniform(math.log(0.05), math.log(0.3)))  # angular radius, rad
        dep = 0.15 * rho
        s = np.arccos(np.clip(u @ c, -1.0, 1.0)) / rho
        bowl = np.where(s < 1.0, -dep * (1.0 - s**2), 0.0)
        rim = 0.3 * dep * np.exp(-(((s - 1.0) / 0.2) ** 2))
        f += bowl + rim
    return trimesh.Trimesh(u * (r * f)[:, None], sph.faces.copy(), process=False)


_BUILDERS: dict[str, tuple[Callable[..., trimesh.Trimesh], float | None]] = {
    "envisat": (_envisat, None),
    "iridium": (_iridium, None),
    "capsule": (_capsule, None),
    "voyager": (_voyager, None),
    "asteroid": (_asteroid, 500.0),
}


def available_targets() -> list[str]:
    """Names of the procedural targets (aliases in :data:`TARGET_ALIASES` also work)."""
    return sorted(_BUILDERS)


def procedural_target(
    name: str, *, seed: int = 0, scale_to: float | None = None, **params: Any
) -> Target:
    """Build a procedural target (no data files needed).

    Parameters
    ----------
    name : str
        One of :func:`available_targets` or an alias (``bennu``, ``orion``, ``globalstar``).
    seed : int
        Seed of the random shape parameters (used by ``asteroid``; recorded in ``source``).
    scale_to : float, optional
        Longest bounding-box side in metres (default: natural size; 500 m for ``asteroid``).
    **params
        Builder options, e.g. ``craters=N``, ``subdivisions=5`` (asteroid) or ``max_edge``
        (largest triangle edge of the satellites, m).

    Raises
    ------
    ConfigError
        Unknown name or parameter, bad ``scale_to``.
    """
    key = TARGET_ALIASES.get(str(name).lower(), str(name).lower())
    if key not in _BUILDERS:
        raise ConfigError(
            f"unknown procedural target {name!r}; available: "
            f"{', '.join(available_targets() + sorted(TARGET_ALIASES))}"
        )
    _check_scale_to(scale_to)
    builder, default_extent = _BUILDERS[key]
    allowed = [p for p in inspect.signature(builder).parameters if p != "rng"]
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise ConfigError(
            f"procedural target {key!r}: unknown parameter(s) {unknown}; allowed: {allowed}"
        )
    rng = np.random.default_rng(int(seed))
    mesh = builder(rng, **params)
    scale = _centre_and_scale(mesh, scale_to if scale_to is not None else default_extent)
    log.debug("procedural target %s: %d faces, scale %.4g", key, len(mesh.faces), scale)
    return Target(
        name=str(name),
        mesh=mesh,
        source=f"procedural:{key}:seed={int(seed)}",
        metadata={"procedural": key, "seed": int(seed), "params": dict(params), "scale": scale},
    )


def get_target(spec: str | Path, *, seed: int = 0, scale_to: float | None = None) -> Target:
    """A procedural target by name, or a mesh file by path.

    Raises
    ------
    ConfigError
        ``spec`` is neither a procedural name nor an existing file and does not look like a path.
    InputError
        ``spec`` looks like a mesh path but the file is missing or unreadable.
    """
    s = str(spec)
    key = TARGET_ALIASES.get(s.lower(), s.lower())
    if key in _BUILDERS and not Path(s).is_file():
        return procedural_target(s, seed=seed, scale_to=scale_to)
    p = Path(s)
    if p.is_file() or p.suffix or "/" in s or "\\" in s:
        return load_target(p, scale_to=scale_to)
    raise ConfigError(
        f"unknown target {s!r}: not a procedural target "
        f"({', '.join(available_targets() + sorted(TARGET_ALIASES))}) nor a mesh file"
    )
