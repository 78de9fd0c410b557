"""Paper 1's simulated clouds: :class:`SurfaceSampler` (model cloud or fresh surface samples,
then hidden-point removal from the sensor position, then noise)."""

from __future__ import annotations

import logging
import math
from typing import Any, ClassVar

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.sim.hpr import hidden_point_removal
from relnav.sim.model_cloud import ModelCloud, mesh_fingerprint, model_cloud_for
from relnav.sim.noise import (
    as_generator,
    dropout_mask,
    range_noise_points,
)
from relnav.sim.sensors.base import (
    Sensor,
    SensorReturn,
    _check_fov,
    _check_pose,
    _check_prob,
    _check_ranges,
    _int,
    _num,
)
from relnav.sim.targets import Target

log = logging.getLogger(__name__)

HPR_MAX_RANGE_M = 3000.0
"""Default maximum range of :class:`SurfaceSampler` (and so of paper 1's five HPR presets), m:
a space flash LIDAR of the GoldenEye class (the ``goldeneye`` preset's 3 km)
**[interpretation]**. The presets fly at 12-75 m, so their scans do not change."""


class SurfaceSampler(Sensor):
    """Paper 1's simulated clouds: points of the target's surface + hidden point removal.

    Per frame: take the surface points (see ``model_cloud``), transform them to the sensor
    frame, keep the points visible from the sensor origin by HPR
    (:func:`relnav.sim.hpr.hidden_point_removal`), then crop to ``[min_range, max_range]`` and
    the optional field of view, apply dropout and noise (drawn from the scan's ``rng``).

    Parameters
    ----------
    name : str
        Sensor name.
    n_points : int
        Wanted number of VISIBLE points per frame, on average (calibrates ``n_surface`` or
        ``model_voxel`` when they are None).
    n_surface : int, optional
        ``resample`` only: surface samples per frame. ``None`` = calibrate once per target: the
        mean HPR visible fraction ``f`` over 8 fixed viewpoints (cube-corner directions at 3×
        the bounding radius, fixed seed) gives ``n_surface = n_points / f`` (two fixed-point
        passes, since HPR's kept fraction depends on density). Independent of the scan order,
        hence deterministic.
    hpr_radius_factor : float
        HPR flipping radius over the farthest point distance, ``10**γ`` (default 100,
        ``γ = 2`` **[interpretation]**). Smaller → sparser, more aggressive removal.
    min_range, max_range : float
        Range crop of the slant range, metres (``0 <= min_range < max_range``). Default
        ``max_range``: :data:`HPR_MAX_RANGE_M` (3 km, a flash LIDAR of the GoldenEye class
        **[interpretation]**: paper 1 gives none); ``inf`` removes the limit. Beyond it the
        scan is empty, like a target out of sight.
    fov_h_deg, fov_v_deg : float, optional
        Rectangular pinhole field of view centred on +x, degrees (None: no crop).
    noise_sigma : float
        1σ Gaussian noise, metres: along the line of sight (``noise_mode="range"``, default)
        or on each coordinate (``"isotropic"``).
    dropout : float
        Probability that a visible point is lost.
    model_cloud : {"resample", "fixed"}
        ``"fixed"`` = paper 1's data generation: ONE complete model cloud per target, rendered
        from ``model_views`` views of a tessellated sphere and merged
        (:mod:`relnav.sim.model_cloud`), shared by every frame, so consecutive noiseless scans
        share points. ``"resample"`` = fresh area-weighted uniform surface samples every frame
        (harsher: no point repeats between scans).
    model_views : int
        ``fixed``: views of the tessellated sphere (paper 1: 800).
    model_resolution : int
        ``fixed``: pixels per side of each rendered view **[interpretation]**.
    model_thinning : {"random", "voxel", "none"}
        ``fixed``: how the merged views are thinned to the wanted density (see
        :mod:`relnav.sim.model_cloud`; ``random`` by default **[interpretation]**).
    model_size : int, optional
        ``fixed``/``random``: points of the model cloud. ``None`` = calibrate once per target
        so that about ``n_points`` points are visible from the same 8 viewpoints as
        ``n_surface`` (fixed-point iteration ``size ← size · n_points / count``).
    model_voxel : float, optional
        ``fixed``/``voxel``: voxel edge, m. ``None`` = calibrate likewise
        (``v ← v · sqrt(count / n_points)``).
    model_seed : int
        ``fixed``: seed of the rendering (view-sphere rotation, pixel-grid rolls). Like the
        target's own seed it is fixed by default, so scenario seeds vary only the noise.
    """

    kind: ClassVar[str] = "surface_sampler"

    def __init__(
        self,
        name: str,
        n_points: int = 500,
        n_surface: int | None = None,
        hpr_radius_factor: float = 100.0,
        min_range: float = 0.0,
        max_range: float = HPR_MAX_RANGE_M,
        fov_h_deg: float | None = None,
        fov_v_deg: float | None = None,
        noise_sigma: float = 0.0,
        noise_mode: str = "range",
        dropout: float = 0.0,
        model_cloud: str = "resample",
        model_views: int = 800,
        model_resolution: int = 64,
        model_thinning: str = "random",
        model_size: int | None = None,
        model_voxel: float | None = None,
        model_seed: int = 0,
    ) -> None:
        self.name = str(name)
        self.n_points = _int("n_points", n_points)
        if model_cloud not in ("resample", "fixed"):
            raise ConfigError(f"model_cloud must be 'fixed' or 'resample', got {model_cloud!r}")
        self.model_cloud = model_cloud
        self.model_views = _int("model_views", model_views)
        self.model_resolution = _int("model_resolution", model_resolution, lo=2)
        if self.model_resolution > 4096:
            raise ConfigError(f"model_resolution must be <= 4096, got {self.model_resolution}")
        if model_thinning not in ("random", "voxel", "none"):
            raise ConfigError(
                f"model_thinning must be 'random', 'voxel' or 'none', got {model_thinning!r}"
            )
        self.model_thinning = model_thinning
        self.model_size = None if model_size is None else _int("model_size", model_size)
        self.model_voxel = (
            None if model_voxel is None else _num("model_voxel", model_voxel, lo=0.0, lo_open=True)
        )
        if self.model_voxel is not None and not math.isfinite(self.model_voxel):
            raise ConfigError(f"model_voxel must be finite, got {self.model_voxel}")
        self.model_seed = _int("model_seed", model_seed, lo=0)
        self.n_surface = None if n_surface is None else _int("n_surface", n_surface)
        self.hpr_radius_factor = _num("hpr_radius_factor", hpr_radius_factor, lo=1.0, lo_open=True)
        self.min_range, self.max_range_m = _check_ranges(min_range, max_range)
        self.fov_h_deg = None if fov_h_deg is None else _check_fov("fov_h_deg", fov_h_deg)
        self.fov_v_deg = None if fov_v_deg is None else _check_fov("fov_v_deg", fov_v_deg)
        self.noise_sigma = _num("noise_sigma", noise_sigma, lo=0.0)
        if noise_mode not in ("range", "isotropic"):
            raise ConfigError(f"noise_mode must be 'range' or 'isotropic', got {noise_mode!r}")
        self.noise_mode = noise_mode
        self.dropout = _check_prob("dropout", dropout)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "name": self.name,
            "n_points": self.n_points,
            "n_surface": self.n_surface,
            "hpr_radius_factor": self.hpr_radius_factor,
            "min_range": self.min_range,
            "max_range": self.max_range_m,
            "fov_h_deg": self.fov_h_deg,
            "fov_v_deg": self.fov_v_deg,
            "noise_sigma": self.noise_sigma,
            "noise_mode": self.noise_mode,
            "dropout": self.dropout,
            "model_cloud": self.model_cloud,
            "model_views": self.model_views,
            "model_resolution": self.model_resolution,
            "model_thinning": self.model_thinning,
            "model_size": self.model_size,
            "model_voxel": self.model_voxel,
            "model_seed": self.model_seed,
        }

    @property
    def max_range(self) -> float:
        return float(self.max_range_m)

    # -- fixed model cloud ------------------------------------------------------------------

    def _model(self, target: Target, param: float) -> ModelCloud:
        return model_cloud_for(
            target,
            n_views=self.model_views,
            resolution=self.model_resolution,
            thinning=self.model_thinning,
            size=int(param) if self.model_thinning == "random" else 0,
            voxel=float(param) if self.model_thinning == "voxel" else 0.0,
            seed=self.model_seed,
        )

    def model_cloud_of(self, target: Target) -> ModelCloud:
        """The fixed model cloud of ``target`` (rendered and cached on first use)."""
        param = {"random": self.model_size, "voxel": self.model_voxel, "none": 0.0}[
            self.model_thinning
        ]
        if param is None:
            key = ("surface_sampler.model", mesh_fingerprint(target), self.n_points,
                   self.hpr_radius_factor, self.model_views, self.model_resolution,
                   self.model_thinning, self.model_seed)  # fmt: skip
            param = _MODEL_PARAM_CACHE.get(key)
            if param is None:
                param = self._calibrate_model(target)
                _MODEL_PARAM_CACHE[key] = param
                log.info(
                    "SurfaceSampler %s: model cloud of %s, %d views, %s thinning (%.4g), "
                    "%d points for ~%d visible",
                    self.name,
                    target.name,
                    self.model_views,
                    self.model_thinning,
                    param,
                    self._model(target, param).points.shape[0],
                    self.n_points,
                )
        return self._model(target, param)

    def _calibrate_model(self, target: Target) -> float:
        """Model-cloud size (random) or voxel edge (voxel) giving ~``n_points`` visible."""
        c, rho = target.bounding_sphere
        views = c + 3.0 * rho * _CUBE_CORNERS
        voxel = self.model_thinning == "voxel"
        x = (
            math.sqrt(float(target.mesh.area) / (4.0 * self.n_points))
            if voxel
            else 3.0 * self.n_points
        )
        for _ in range(10):
            P = self._model(target, x).points
            count = np.mean(
                [hidden_point_removal(P, w, self.hpr_radius_factor).size for w in views]
            )
            ratio = max(float(count), 1.0) / self.n_points
            if abs(ratio - 1.0) < 0.02:
                break
            if voxel:
                x = x * math.sqrt(ratio)
            else:
                x_new = max(1, round(x / ratio))
                if x_new >= P.shape[0] and x >= P.shape[0]:
                    log.warning(
                        "SurfaceSampler %s: the merged views of %s (%d points) give only ~%d "
                        "visible points; raise model_resolution",
                        self.name,
                        target.name,
                        P.shape[0],
                        count,
                    )
                    break
                x = float(x_new)
        return float(x)

    # -- sampling -------------------------------------------------------------------------

    @staticmethod
    def _sampling_tables(
        target: Target,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        key = ("surface_sampler.tables", id(target.mesh))
        tab = target.cache.get(key)
        if tab is None:
            V = np.asarray(target.mesh.vertices, dtype=np.float64)
            F = np.asarray(target.mesh.faces, dtype=np.int64)
            v0 = V[F[:, 0]]
            e1 = V[F[:, 1]] - v0
            e2 = V[F[:, 2]] - v0
            n = np.cross(e1, e2)
            dbl = np.linalg.norm(n, axis=1)
            cdf = np.cumsum(0.5 * dbl)
            if not cdf[-1] > 0:
                raise InputError(f"target {target.name!r}: mesh has zero surface area")
            normals = np.divide(n, dbl[:, None], out=np.zeros_like(n), where=dbl[:, None] > 0)
            tab = (v0, e1, e2, cdf / cdf[-1], normals)
            target.cache[key] = tab
        return tab

    def sample_surface(
        self, target: Target, n: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """``n`` uniform surface samples (target frame, m) and their face indices.

        Draws ``n`` uniforms (face, area-weighted) then ``2n`` (barycentric) from ``rng``.
        """
        v0, e1, e2, cdf, _ = self._sampling_tables(target)
        f = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(cdf) - 1)
        ab = rng.random((n, 2))
        flip = ab.sum(axis=1) > 1.0
        ab[flip] = 1.0 - ab[flip]
        pts = v0[f] + ab[:, :1] * e1[f] + ab[:, 1:] * e2[f]
        return pts, f.astype(np.int64)

    def surface_samples_for(self, target: Target) -> int:
        """Surface samples per frame for ``target`` (``n_surface`` or the calibration)."""
        if self.n_surface is not None:
            return self.n_surface
        key = ("surface_sampler.n_surface", id(target.mesh), self.n_points, self.hpr_radius_factor)
        n = target.cache.get(key)
        if n is None:
            n = self._calibrate(target)
            target.cache[key] = n
            log.info(
                "SurfaceSampler %s: %d surface samples per frame on %s for ~%d visible points",
                self.name,
                n,
                target.name,
                self.n_points,
            )
        return int(n)

    def _calibrate(self, target: Target) -> int:
        c, rho = target.bounding_sphere
        views = c + 3.0 * rho * _CUBE_CORNERS
        n = 4 * self.n_points
        for _ in range(2):
            rng = np.random.default_rng(0)
            frac = []
            for v in views:
                pts, _ = self.sample_surface(target, n, rng)
                vis = hidden_point_removal(pts, v, self.hpr_radius_factor)
                frac.append(vis.size / n)
            f = max(float(np.mean(frac)), 1e-3)
            n = max(round(self.n_points / f), self.n_points)
        return n

    def scan_detailed(
        self, target: Target, T_target_sensor: np.ndarray, rng: np.random.Generator
    ) -> SensorReturn:
        T = _check_pose(T_target_sensor)
        gen = as_generator(rng)
        c_t, rho = target.bounding_sphere
        dist = float(np.linalg.norm(c_t - T[:3, 3]))
        if dist - rho > self.max_range_m or dist + rho < self.min_range:
            return SensorReturn.empty()  # no point can be in range: nothing drawn (as rays)
        if self.model_cloud == "fixed":
            mc = self.model_cloud_of(target)
            pts_t, faces = mc.points, mc.faces
        else:
            pts_t, faces = self.sample_surface(target, self.surface_samples_for(target), gen)
        R, t = T[:3, :3], T[:3, 3]
        pts_s = (pts_t - t) @ R
        vis = hidden_point_removal(pts_s, np.zeros(3), self.hpr_radius_factor)
        p = pts_s[vis]
        r = np.linalg.norm(p, axis=1)
        keep = (r >= self.min_range) & (r <= self.max_range_m)
        if self.fov_h_deg is not None or self.fov_v_deg is not None:
            keep &= p[:, 0] > 0
            with np.errstate(divide="ignore", invalid="ignore"):
                if self.fov_h_deg is not None:
                    keep &= np.abs(p[:, 1] / p[:, 0]) <= math.tan(math.radians(self.fov_h_deg) / 2)
                if self.fov_v_deg is not None:
                    keep &= np.abs(p[:, 2] / p[:, 0]) <= math.tan(math.radians(self.fov_v_deg) / 2)
        vis = vis[keep]
        vis = vis[dropout_mask(vis.size, self.dropout, gen)]
        if vis.size == 0:
            return SensorReturn.empty()
        p = pts_s[vis]
        r = np.linalg.norm(p, axis=1)
        if self.noise_sigma > 0:
            if self.noise_mode == "range":
                p = range_noise_points(p, self.noise_sigma, gen)
            else:
                p = p + self.noise_sigma * gen.standard_normal(p.shape)
        normals = self._sampling_tables(target)[4][faces[vis]] @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_inc = np.abs(np.einsum("ij,ij->i", normals, pts_s[vis])) / r
        return SensorReturn(
            points=np.ascontiguousarray(p, dtype=np.float64),
            ray_index=np.full(vis.size, -1, dtype=np.int64),
            face_index=faces[vis],
            true_range=r,
            incidence=np.arccos(np.clip(np.nan_to_num(cos_inc), 0.0, 1.0)),
        )


_CUBE_CORNERS = np.array(
    [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64
) / math.sqrt(3.0)
_MODEL_PARAM_CACHE: dict[tuple, float] = {}
