"""Simulation targets: mesh loading/rescaling and procedural satellites, capsule and asteroid.

Every :class:`Target` mesh is expressed in the **target frame**: origin at the centre of the
mesh's axis-aligned bounding box, metres. Procedural targets are built from primitives
(boxes, cylinders, surfaces of revolution) that are concatenated, not merged by boolean
operations, so the whole mesh is not one closed surface (the capsule's parts are each closed;
the asteroid's boulders are open below the surface); ray casting and surface sampling do not
need it.

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
           32.5° truncated cone, docking tunnel with a docking ring and an off-axis hatch,
           four windows recessed on the side hatch's side, six RCS pods at uneven azimuths,
           a forward-bay-cover ridge (partial ring), an umbilical fairing and heat-shield
           pads, so it is NOT rotationally symmetric; ≈ 5.0 m diameter, ≈ 3.3 m tall.
voyager    Voyager-like probe: decagonal bus, 3.66 m paraboloid dish with feed, RTG boom
           with three RTGs, science boom with scan platform, magnetometer boom; ≈ 12 m.
asteroid   Seeded Bennu-like rubble pile: spinning-top ellipsoid with an equatorial ridge, a
           flat facet, 15–25 craters and 30–60 boulders (counts seeded; ``craters=N``,
           ``boulders=N``, ``top_shape``, ``facet_depth``, ... override); longest extent
           500 m unless ``scale_to`` is given.
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
from relnav.geometry.rotations import random_rotation

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


def _revolved_grid(prof: np.ndarray, az: np.ndarray) -> np.ndarray:
    """(M, K, 3) grid of the profile ``(r, z)`` (M, 2) revolved about +z at azimuths ``az``."""
    r, z = prof[:, 0][:, None], prof[:, 1][:, None]
    c, s = np.cos(az)[None, :], np.sin(az)[None, :]
    return np.stack([r * c, r * s, np.broadcast_to(z, (len(prof), len(az)))], axis=-1)


def _grid_mesh(P: np.ndarray, *, wrap: bool, cap: bool = False) -> trimesh.Trimesh:
    """Triangulate a (M, K, 3) grid (rows: profile points, columns: azimuths).

    Rows whose points coincide (profile points on the axis) collapse to one vertex.
    ``wrap`` joins the last column to the first (full revolution). ``cap`` closes the first and
    last columns with triangle fans; it expects a convex closed profile whose last row repeats
    the first. The faces are oriented outwards for a counter-clockwise ``(r, z)`` profile and
    flipped if the (closed) result has a negative signed volume.
    """
    M, K = P.shape[:2]
    idx = np.arange(M * K).reshape(M, K)
    for i in range(M):
        if np.ptp(P[i], axis=0).max() < 1e-12:
            idx[i] = idx[i, 0]
    cur = np.arange(K) if wrap else np.arange(K - 1)
    nxt = (cur + 1) % K
    a, b = idx[:-1][:, cur], idx[:-1][:, nxt]
    c, d = idx[1:][:, nxt], idx[1:][:, cur]
    faces = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    if cap:
        for j, flip in ((0, False), (K - 1, True)):
            ring = idx[:-1, j]
            fan = np.stack([np.full(len(ring) - 2, ring[0]), ring[1:-1], ring[2:]], -1)
            faces.append(fan[:, ::-1] if flip else fan)
    F = np.concatenate(faces)
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    mesh = trimesh.Trimesh(P.reshape(-1, 3).copy(), F, process=False)
    mesh.remove_unreferenced_vertices()
    V = mesh.vertices
    signed = np.einsum(
        "ij,ij->", V[mesh.faces[:, 0]], np.cross(*V[mesh.faces[:, 1:]].swapaxes(0, 1))
    )
    if signed < 0:
        mesh.invert()
    return mesh


def _capsule(rng: np.random.Generator, *, max_edge: float = 0.3) -> trimesh.Trimesh:
    """Orion-like crew module, axis +z, heat shield at the bottom (deterministic; no ``rng``).

    Parts (all closed, concatenated): the body of revolution (spherical-cap heat shield
    R = 6 m, 5.0 m base, 32.5° cone 2.3 m high, 1.6 m docking tunnel 0.35 m high) with four
    windows recessed 7 cm into the cone on the hatch side (azimuths 118°, 136°, 184°, 202°);
    a docking ring on the tunnel and an off-axis hatch inside it; a side hatch (az 160°); six
    RCS pods at uneven azimuths and heights; a forward-bay-cover ridge around the upper cone,
    interrupted over az −25°..25°; an umbilical fairing along the cone at az 300°; three
    heat-shield compression pads at uneven azimuths (40°, 165°, 290°).
    Overall ≈ 5.0 m diameter, ≈ 3.3 m tall.
    """
    r_base, r_shield, cone_h = 2.5, 6.0, 2.3
    alpha = math.radians(32.5)  # cone half-angle (side wall to the axis), as on Orion
    tan_a = math.tan(alpha)
    depth = r_shield - math.sqrt(r_shield**2 - r_base**2)  # heat-shield cap depth
    tunnel_r, tunnel_h = 0.8, 0.35
    top = cone_h + tunnel_h

    def r_cone(z: float) -> float:
        return r_base - z * tan_a

    def frame(az_deg: float, z: float) -> np.ndarray:
        """Cone-surface frame: x outward normal, y tangential (+az), z up the generatrix."""
        az = math.radians(az_deg)
        n = np.array(
            [math.cos(alpha) * math.cos(az), math.cos(alpha) * math.sin(az), math.sin(alpha)]
        )
        t = np.array([-math.sin(az), math.cos(az), 0.0])
        T = np.eye(4)
        T[:3, :3] = np.column_stack([n, t, np.cross(n, t)])
        T[:3, 3] = [r_cone(z) * math.cos(az), r_cone(z) * math.sin(az), z]
        return T

    def on_cone(
        az_deg: float, z: float, size: tuple[float, float, float], proud: float
    ) -> trimesh.Trimesh:
        """Box (normal, tangential, along-generatrix sizes) standing ``proud`` m off the cone."""
        T = frame(az_deg, z) @ trimesh.transformations.translation_matrix(
            [proud - 0.5 * size[0], 0.0, 0.0]
        )
        return trimesh.creation.box(extents=size, transform=T)

    # ---- body of revolution, with profile rows and azimuth columns at the window edges
    win_az = (118.0, 136.0, 184.0, 202.0)
    win_w, win_z, win_depth, eps = 0.42, (1.0, 1.35), 0.07, 0.02
    a = np.linspace(0.0, math.asin(r_base / r_shield), 10)
    shield = np.column_stack([r_shield * np.sin(a), -depth + r_shield * (1 - np.cos(a))])
    cone_z = np.array([0.0, win_z[0], win_z[0] + eps, win_z[1] - eps, win_z[1], cone_h])
    cone = np.column_stack([r_base - cone_z * tan_a, cone_z])
    prof = np.vstack([shield, cone[1:], [[tunnel_r, cone_h], [tunnel_r, top], [0.0, top]]])
    r_win = r_cone(0.5 * sum(win_z))
    half = math.degrees(0.5 * win_w / r_win)
    d_eps = math.degrees(eps / r_win)
    edges = np.array([[c - half, c - half + d_eps, c + half - d_eps, c + half] for c in win_az])
    base = np.arange(0.0, 360.0, 5.0)
    base = base[np.abs(base[:, None] - edges.ravel()[None, :]).min(axis=1) > 1.0]
    az_deg = np.sort(np.concatenate([base, edges.ravel()]))
    P = _revolved_grid(prof, np.radians(az_deg))
    rows = np.flatnonzero(
        (prof[:, 1] >= win_z[0] + eps - 1e-9) & (prof[:, 1] <= win_z[1] - eps + 1e-9)
    )
    rows = rows[(prof[rows, 0] > tunnel_r + 1e-9)]  # cone rows only
    for e in edges:
        cols = np.flatnonzero((az_deg >= e[1] - 1e-9) & (az_deg <= e[2] + 1e-9))
        th = np.radians(az_deg[cols])
        n = np.column_stack(
            [
                math.cos(alpha) * np.cos(th),
                math.cos(alpha) * np.sin(th),
                np.full(len(th), math.sin(alpha)),
            ]
        )
        P[np.ix_(rows, cols)] -= win_depth * n[None, :, :]
    body = _grid_mesh(P, wrap=True)

    # ---- docking ring and off-axis hatch on top of the tunnel
    ring_prof = np.array(
        [[0.55, top - 0.01], [0.8, top - 0.01], [0.8, top + 0.11], [0.55, top + 0.11]]
    )
    ring = _grid_mesh(
        _revolved_grid(
            np.vstack([ring_prof, ring_prof[:1]]), np.radians(np.arange(0.0, 360.0, 7.5))
        ),
        wrap=True,
    )
    top_hatch = trimesh.creation.cylinder(
        radius=0.28,
        height=0.08,
        sections=24,
        transform=trimesh.transformations.translation_matrix([0.2, -0.1, top + 0.03]),
    )

    # ---- forward-bay-cover ridge: a partial ring hugging the upper cone
    z0, z1 = 1.92, 2.02
    ridge_prof = np.array(
        [
            [r_cone(z0) - 0.04, z0],
            [r_cone(z0) + 0.08, z0],
            [r_cone(z1) + 0.08, z1],
            [r_cone(z1) - 0.04, z1],
            [r_cone(z0) - 0.04, z0],
        ]
    )
    ridge = _grid_mesh(
        _revolved_grid(ridge_prof, np.radians(np.linspace(25.0, 335.0, 63))), wrap=False, cap=True
    )

    # ---- umbilical fairing: a half-buried cylinder along the cone generatrix
    fairing = trimesh.creation.cylinder(
        radius=0.18,
        height=1.0 / math.cos(alpha),
        sections=16,
        transform=frame(300.0, 0.95) @ trimesh.transformations.translation_matrix([0.06, 0, 0]),
    )

    def on_shield(az_deg: float, rho: float, size: tuple[float, float, float]) -> trimesh.Trimesh:
        """Box on the heat shield at radius ``rho``, aligned with the sphere's outward normal."""
        az = math.radians(az_deg)
        c = np.array([0.0, 0.0, r_shield - depth])  # centre of the heat-shield sphere
        p = np.array(
            [rho * math.cos(az), rho * math.sin(az), c[2] - math.sqrt(r_shield**2 - rho**2)]
        )
        T = _axis_transform(p, p - c)
        T = T @ trimesh.transformations.translation_matrix([0.0, 0.0, 0.5 * size[2] - 0.04])
        return trimesh.creation.box(extents=size, transform=T)

    parts = [
        body,
        # heat-shield attachment: three compression pads at uneven azimuths
        on_shield(40.0, 1.95, (0.35, 0.3, 0.1)),
        on_shield(165.0, 2.05, (0.3, 0.3, 0.1)),
        on_shield(290.0, 1.9, (0.4, 0.3, 0.1)),
        ring,
        top_hatch,
        ridge,
        fairing,
        on_cone(160.0, 0.6, (0.3, 1.0, 0.8), 0.08),  # side (crew) hatch
        # RCS thruster pods at uneven azimuths and heights
        on_cone(12.0, 1.55, (0.30, 0.55, 0.40), 0.15),
        on_cone(71.0, 1.70, (0.30, 0.40, 0.35), 0.15),
        on_cone(97.0, 1.25, (0.28, 0.45, 0.30), 0.13),
        on_cone(233.0, 1.60, (0.30, 0.60, 0.45), 0.16),
        on_cone(262.0, 1.35, (0.26, 0.40, 0.30), 0.12),
        on_cone(338.0, 1.75, (0.30, 0.45, 0.35), 0.15),
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


_CRATERS_DEFAULT = (15, 25)
_BOULDERS_DEFAULT = (30, 60)
_LARGE_BOULDERS = (3, 5)


def _boulder_sizes(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """Boulder radii in body units: 3–5 large ones (0.06–0.11), the rest a power law.

    The small ones follow a cumulative size distribution ``N(>s) ∝ s^-2.5`` on
    ``[0.012, 0.04]`` (boulder counts on rubble piles are steep power laws).
    """
    n_large = min(n, int(rng.integers(_LARGE_BOULDERS[0], _LARGE_BOULDERS[1] + 1)))
    large = rng.uniform(0.06, 0.11, n_large)
    q, s_min, s_max = 2.5, 0.012, 0.04
    u = rng.random(n - n_large)
    small = s_min * (1.0 - u * (1.0 - (s_min / s_max) ** q)) ** (-1.0 / q)
    return scale * np.concatenate([large, small])


def _asteroid(
    rng: np.random.Generator,
    *,
    subdivisions: int = 5,
    craters: int | None = None,
    boulders: int | None = None,
    axes: tuple[float, float, float] = (1.0, 0.95, 0.9),
    ridge_height: float = 0.06,
    ridge_width_deg: float = 14.0,
    roughness: float = 0.03,
    top_shape: float = 0.3,
    facet_depth: float = 0.05,
    boulder_scale: float = 1.0,
) -> trimesh.Trimesh:
    """Bennu-like rubble pile: a star-shaped body plus partly buried boulders.

    Body radius along the unit direction ``u`` (icosphere of ``subdivisions``)::

        r(u) = min(r_top(u) · (1 + ridge(lat) + Σ waves(u)), facet(u)) · (1 + Σ craters(u))

    - ``r_top`` blends the ellipsoid of semi-axes ``axes`` with weight ``top_shape`` towards
      the double cone through its equator and poles (Bennu's spinning-top shape).
    - ``ridge``: Gaussian equatorial ridge, relative height ``ridge_height``, width
      ``ridge_width_deg``; ``waves``: 12 random smooth cosines of total relative amplitude
      ``roughness``.
    - ``facet``: one flat facet, a plane cutting ``facet_depth`` (relative) off the body
      around a seeded direction within ±40° latitude (**[interpretation]** of "not a perfect
      spheroid"; ``facet_depth=0`` disables it).
    - ``craters``: bowl-shaped craters with raised rims, angular radii log-uniform in
      0.04–0.3 rad; ``None`` (default) = a seeded count in 15..25, ``0`` = none.
    - ``boulders``: irregular lumps (perturbed, stretched icospheres, 80 triangles each)
      sitting on the surface, ``None`` (default) = a seeded count in 30..60 of which 3–5 are
      large (radius 0.06–0.11 body units) and the rest small (0.012–0.04, steep power law),
      times ``boulder_scale``. Each is sunk by 60–100 % of its radius and its faces lying
      entirely inside the body are dropped, so surface samples do not land inside the body
      (the boulders are therefore open below the surface; the body is closed).

    Every feature draws from its own child stream of ``rng`` (``rng.spawn``), so e.g. changing
    ``craters`` does not move the boulders' directions. The body comes first in the mesh (the
    icosphere's vertices and faces, in order), then the boulders. The drawn counts and the
    facet's unit normal are recorded in ``mesh.metadata["asteroid"]``.
    """
    if not 1 <= int(subdivisions) <= 7:
        raise ConfigError(f"asteroid: subdivisions must be in 1..7, got {subdivisions}")
    for key, val in (("craters", craters), ("boulders", boulders)):
        if val is not None and not (
            isinstance(val, int | np.integer) and not isinstance(val, bool) and val >= 0
        ):
            raise ConfigError(f"asteroid: {key} must be an integer >= 0 (or None), got {val!r}")
    a = np.asarray(axes, dtype=float)
    if a.shape != (3,) or not np.all(a > 0):
        raise ConfigError(f"asteroid: axes must be 3 positive numbers, got {axes}")
    checks = (
        ("top_shape", top_shape, 0.0, 1.0),
        ("facet_depth", facet_depth, 0.0, 0.5),
        ("ridge_height", ridge_height, 0.0, 1.0),
        ("roughness", roughness, 0.0, 0.5),
        ("boulder_scale", boulder_scale, 0.0, 5.0),
    )
    for key, val, lo, hi in checks:
        if not (isinstance(val, int | float | np.number) and np.isfinite(val) and lo <= val <= hi):
            raise ConfigError(f"asteroid: {key} must be in [{lo}, {hi}], got {val}")
    if not (isinstance(ridge_width_deg, int | float | np.number) and ridge_width_deg > 0):
        raise ConfigError(f"asteroid: ridge_width_deg must be > 0, got {ridge_width_deg}")
    rng_waves, rng_facet, rng_craters, rng_boulders = rng.spawn(4)

    n_waves = 12
    k = rng_waves.normal(size=(n_waves, 3))
    k *= (rng_waves.uniform(1.0, 4.0, n_waves) / np.linalg.norm(k, axis=1))[:, None]
    amp = rng_waves.uniform(0.5, 1.0, n_waves) / np.linalg.norm(k, axis=1)
    amp *= roughness / amp.sum() * 2.0
    phase = rng_waves.uniform(0.0, 2 * math.pi, n_waves)

    def smooth_radius(u: np.ndarray) -> np.ndarray:
        r = 1.0 / np.sqrt(((u / a) ** 2).sum(axis=1))
        if top_shape > 0:
            rho = np.hypot(u[:, 0], u[:, 1])
            with np.errstate(invalid="ignore", divide="ignore"):
                r_eq = rho / np.hypot(u[:, 0] / a[0], u[:, 1] / a[1])  # equator radius at az
            r_eq = np.where(rho > 1e-12, r_eq, a[0])
            r_cone = 1.0 / (rho / r_eq + np.abs(u[:, 2]) / a[2])
            r = (1.0 - top_shape) * r + top_shape * r_cone
        lat = np.arcsin(np.clip(u[:, 2], -1.0, 1.0))
        f = 1.0 + ridge_height * np.exp(-((lat / math.radians(ridge_width_deg)) ** 2))
        f += (amp[None, :] * np.cos(u @ k.T + phase[None, :])).sum(axis=1)
        return r * f

    lat_f = rng_facet.uniform(-math.radians(40.0), math.radians(40.0))
    lon_f = rng_facet.uniform(0.0, 2 * math.pi)
    n_f = np.array([math.cos(lat_f) * math.cos(lon_f), math.cos(lat_f) * math.sin(lon_f)])
    n_f = np.append(n_f, math.sin(lat_f))
    d_f = (1.0 - facet_depth) * float(smooth_radius(n_f[None, :])[0])

    n_craters = (
        int(rng_craters.integers(_CRATERS_DEFAULT[0], _CRATERS_DEFAULT[1] + 1))
        if craters is None
        else int(craters)
    )
    c_dir = rng_craters.normal(size=(n_craters, 3))
    c_dir /= np.linalg.norm(c_dir, axis=1, keepdims=True)
    c_rho = np.exp(rng_craters.uniform(math.log(0.04), math.log(0.3), n_craters))  # rad

    def radius(u: np.ndarray) -> np.ndarray:
        r = smooth_radius(u)
        if facet_depth > 0:
            cos_f = u @ n_f
            with np.errstate(divide="ignore"):
                r = np.where(cos_f > 1e-9, np.minimum(r, d_f / np.maximum(cos_f, 1e-9)), r)
        g = np.ones(len(u))
        for c, rho in zip(c_dir, c_rho, strict=True):
            dep = 0.15 * rho
            s = np.arccos(np.clip(u @ c, -1.0, 1.0)) / rho
            g += np.where(s < 1.0, -dep * (1.0 - s**2), 0.0)
            g += 0.3 * dep * np.exp(-(((s - 1.0) / 0.2) ** 2))
        return r * g

    sph = trimesh.creation.icosphere(subdivisions=int(subdivisions))
    u = np.asarray(sph.vertices, dtype=float)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    body = trimesh.Trimesh(u * radius(u)[:, None], sph.faces.copy(), process=False)

    n_boulders = (
        int(rng_boulders.integers(_BOULDERS_DEFAULT[0], _BOULDERS_DEFAULT[1] + 1))
        if boulders is None
        else int(boulders)
    )
    info = {
        "craters": n_craters,
        "boulders": 0,
        "facet_normal": n_f.tolist() if facet_depth > 0 else None,
    }
    if n_boulders == 0 or boulder_scale == 0:
        log.debug("asteroid: %d craters, no boulders", n_craters)
        body.metadata["asteroid"] = info
        return body
    sizes = _boulder_sizes(rng_boulders, n_boulders, boulder_scale)
    b_dir = rng_boulders.normal(size=(n_boulders, 3))
    b_dir /= np.linalg.norm(b_dir, axis=1, keepdims=True)
    rock = trimesh.creation.icosphere(subdivisions=1)
    rv = np.asarray(rock.vertices, dtype=float)
    rocks_v, rocks_f = [], []
    for s, c in zip(sizes, b_dir, strict=True):
        stretch = np.sort(rng_boulders.uniform(0.55, 1.0, 3))[::-1]
        stretch[0] = 1.0
        v = rv * stretch * rng_boulders.uniform(0.8, 1.15, (len(rv), 1))
        R = random_rotation(rng_boulders)
        sink = rng_boulders.uniform(0.6, 1.0)
        centre = c * (float(radius(c[None, :])[0]) + (1.0 - sink) * s)
        rocks_v.append(centre + s * (v @ R.T))
        rocks_f.append(rock.faces)
    # drop boulder faces lying entirely inside the body (radial test against the body mesh)
    from relnav.sim.raycast import RayCaster

    V = np.concatenate(rocks_v)
    dist = np.linalg.norm(V, axis=1)
    r_body, _ = RayCaster(body).cast(np.zeros_like(V), V / dist[:, None])
    inside = dist < r_body
    F = np.concatenate([f + i * len(rv) for i, f in enumerate(rocks_f)])
    F = F[~inside[F].all(axis=1)]
    rocks = trimesh.Trimesh(V, F, process=False)
    rocks.remove_unreferenced_vertices()
    log.debug(
        "asteroid: %d craters, %d boulders (%d of %d faces above the surface)",
        n_craters,
        n_boulders,
        len(F),
        n_boulders * len(rock.faces),
    )
    mesh = trimesh.util.concatenate([body, rocks])
    mesh.metadata["asteroid"] = {**info, "boulders": n_boulders}
    return mesh


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
        Builder options, e.g. ``craters=N``, ``boulders=N``, ``subdivisions=5``,
        ``top_shape``, ``facet_depth``, ``boulder_scale`` (asteroid; see ``_asteroid``) or
        ``max_edge`` (largest triangle edge of the satellites and capsule, m).

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
        metadata={
            "procedural": key,
            "seed": int(seed),
            "params": dict(params),
            "scale": scale,
            **({"drawn": mesh.metadata[key]} if key in mesh.metadata else {}),
        },
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
