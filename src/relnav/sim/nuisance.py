"""Nuisances applied to finished scans: range noise, outliers, density loss, occlusion.

Paper 1 evaluated its methods on clean simulations only; the robustness benchmark
(``configs/robustness.yaml``) post-processes simulated (or recorded) scans with the nuisances
below, each seeded, so that error-versus-nuisance curves can be drawn. Points are in the
**sensor frame** (origin = sensor, DESIGN §3).

Order of application (each stage is skipped at its neutral value):

1. **density**: keep a uniformly random subset of ``round(keep_fraction · N)`` points;
2. **occlusion** (``occlusion_fraction`` f of the points removed):

   - ``"halfspace"``: a random unit direction ``u``; points with ``u·p`` above the
     ``(1 − f)`` quantile are removed (a plane cuts away one side of the cloud);
   - ``"cone"``: a cone with its apex at the sensor and its axis towards a random point of the
     cloud; the ``f`` fraction of points closest in angle to the axis are removed (something
     between the sensor and the target hides a patch);

3. **range noise**: ``p ← p + n p/‖p‖``, ``n ~ N(0, range_sigma_m²)`` (along the ray);
4. **outliers**: ``round(outlier_fraction · N')`` points (``N'`` = points after stages 1–3)
   drawn uniformly in the cloud's axis-aligned bounding box enlarged ×1.2 about its centre
   ("shot noise"), appended to the scan.

**[interpretation]** Occlusion and outliers are parameterised by fractions of the scan (not by
angles or densities) so that one number means the same on every scenario; the alternative —
a fixed cone half-angle — is available as ``occlusion_half_angle_deg``.
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from relnav.config import StrictModel, validate
from relnav.errors import ConfigError, InputError

__all__ = ["NuisanceSpec", "apply_nuisance", "nuisance_rng", "write_nuisance_sequence"]

log = logging.getLogger(__name__)


class NuisanceSpec(StrictModel):
    """Nuisance parameters (all neutral by default).

    Attributes
    ----------
    range_sigma_m : float
        Standard deviation of the Gaussian range noise added along each ray, m (>= 0).
    outlier_fraction : float
        Outliers added, as a fraction of the scan's points, in [0, 1].
    keep_fraction : float
        Fraction of points kept by random decimation, in (0, 1].
    occlusion : {"none", "halfspace", "cone"}
        Occlusion model.
    occlusion_fraction : float
        Fraction of points removed by the occlusion, in [0, 0.95].
    occlusion_half_angle_deg : float, optional
        ``"cone"`` only: a fixed half-angle (degrees) instead of ``occlusion_fraction``.
    """

    range_sigma_m: float = Field(default=0.0, ge=0.0)
    outlier_fraction: float = Field(default=0.0, ge=0.0, le=1.0)
    keep_fraction: float = Field(default=1.0, gt=0.0, le=1.0)
    occlusion: Literal["none", "halfspace", "cone"] = "none"
    occlusion_fraction: float = Field(default=0.0, ge=0.0, le=0.95)
    occlusion_half_angle_deg: float | None = Field(default=None, gt=0.0, lt=90.0)

    @model_validator(mode="after")
    def _occlusion_consistent(self) -> NuisanceSpec:
        if self.occlusion == "none" and (
            self.occlusion_fraction > 0 or self.occlusion_half_angle_deg is not None
        ):
            raise ValueError("occlusion_fraction/half_angle given but occlusion is 'none'")
        if self.occlusion_half_angle_deg is not None and self.occlusion != "cone":
            raise ValueError("occlusion_half_angle_deg needs occlusion: cone")
        return self

    @property
    def is_identity(self) -> bool:
        """True when every stage is neutral (the scans are left untouched)."""
        return (
            self.range_sigma_m == 0.0
            and self.outlier_fraction == 0.0
            and self.keep_fraction == 1.0
            and (
                self.occlusion == "none"
                or (self.occlusion_fraction == 0.0 and self.occlusion_half_angle_deg is None)
            )
        )

    def active(self) -> dict[str, Any]:
        """The non-neutral parameters only (``{}`` for the identity)."""
        default = NuisanceSpec()
        return {
            k: v for k, v in self.model_dump().items() if v != getattr(default, k) and v is not None
        }

    @property
    def label(self) -> str:
        """Short text label, e.g. ``"range_sigma_m=0.02"`` or ``"clean"``."""
        act = self.active()
        return ",".join(f"{k}={v}" for k, v in act.items()) if act else "clean"

    @property
    def key(self) -> str:
        """Stable 10-hex-digit hash of the active parameters (``"clean"`` for the identity)."""
        act = self.active()
        if not act:
            return "clean"
        blob = json.dumps(act, sort_keys=True).encode()
        return hashlib.sha1(blob).hexdigest()[:10]

    @classmethod
    def parse(cls, data: NuisanceSpec | dict[str, Any] | None) -> NuisanceSpec:
        """Validate ``data`` (``None`` → identity); :class:`ConfigError` on bad values."""
        if data is None:
            return cls()
        if isinstance(data, NuisanceSpec):
            return data
        if not isinstance(data, dict):
            raise ConfigError(f"nuisance must be a mapping, got {type(data).__name__}")
        return validate(cls, data, "nuisance")


def nuisance_rng(seed: int, spec: NuisanceSpec, frame: int) -> np.random.Generator:
    """The generator used for ``frame``: a pure function of (seed, nuisance, frame)."""
    h = int(hashlib.sha1(spec.key.encode()).hexdigest()[:8], 16)
    return np.random.default_rng(np.random.SeedSequence([int(seed), h, int(frame)]))


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / max(float(np.linalg.norm(v)), 1e-12)


def apply_nuisance(points: np.ndarray, spec: NuisanceSpec, rng: np.random.Generator) -> np.ndarray:
    """Apply ``spec`` to one scan (see the module docstring for the stages).

    Parameters
    ----------
    points : (N, 3) float64
        Scan points in the sensor frame, m.
    spec : NuisanceSpec
        Nuisance parameters.
    rng : numpy.random.Generator
        Random source (see :func:`nuisance_rng`).

    Returns
    -------
    (M, 3) float64
        New array (the input is not modified); ``M`` may differ from ``N``.

    Raises
    ------
    InputError
        ``points`` is not ``(N, 3)`` or contains non-finite values.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"apply_nuisance: expected points of shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise InputError("apply_nuisance: points contain non-finite values")
    P = P.copy()
    if spec.is_identity or len(P) == 0:
        return P
    # 1. density
    if spec.keep_fraction < 1.0:
        k = max(1, round(spec.keep_fraction * len(P)))
        idx = np.sort(rng.choice(len(P), size=k, replace=False))
        P = P[idx]
    # 2. occlusion
    if spec.occlusion != "none" and len(P) > 1:
        if spec.occlusion == "halfspace":
            if spec.occlusion_fraction > 0:
                u = _unit(rng)
                s = P @ u
                cut = np.quantile(s, 1.0 - spec.occlusion_fraction)
                keep = s < cut
                P = P[keep] if keep.any() else P[[int(np.argmin(s))]]
        else:
            axis = P[int(rng.integers(len(P)))]
            axis = axis / max(float(np.linalg.norm(axis)), 1e-12)
            norms = np.maximum(np.linalg.norm(P, axis=1), 1e-12)
            ang = np.arccos(np.clip(P @ axis / norms, -1.0, 1.0))
            if spec.occlusion_half_angle_deg is not None:
                keep = ang > np.radians(spec.occlusion_half_angle_deg)
            elif spec.occlusion_fraction > 0:
                n_rm = round(spec.occlusion_fraction * len(P))
                keep = np.ones(len(P), dtype=bool)
                keep[np.argsort(ang, kind="stable")[:n_rm]] = False
            else:
                keep = np.ones(len(P), dtype=bool)
            P = P[keep] if keep.any() else P[[int(np.argmax(ang))]]
    # 3. range noise along the ray
    if spec.range_sigma_m > 0:
        norms = np.linalg.norm(P, axis=1, keepdims=True)
        dirs = np.divide(P, norms, out=np.zeros_like(P), where=norms > 0)
        P = P + dirs * rng.normal(0.0, spec.range_sigma_m, size=(len(P), 1))
    # 4. outliers in the enlarged bounding box
    if spec.outlier_fraction > 0:
        n_out = round(spec.outlier_fraction * len(P))
        if n_out:
            lo, hi = P.min(axis=0), P.max(axis=0)
            c, half = 0.5 * (lo + hi), 0.5 * 1.2 * (hi - lo)
            P = np.vstack([P, c + rng.uniform(-1.0, 1.0, size=(n_out, 3)) * half])
    return P


def write_nuisance_sequence(
    source: str | Path,
    out_dir: str | Path,
    spec: NuisanceSpec,
    *,
    seed: int,
    max_frames: int | None = None,
    overwrite: bool = False,
) -> Path:
    """Copy the sequence folder ``source`` to ``out_dir`` with ``spec`` applied to every scan.

    Timestamps, ground truth and sensor metadata are kept; ``scenario.yaml`` (if any) gains a
    ``nuisance`` entry with the parameters and the seed. Frame ``k`` uses
    :func:`nuisance_rng` ``(seed, spec, k)``, so the output is a pure function of the inputs.

    Parameters
    ----------
    source, out_dir : str or Path
        Input and output sequence folders.
    spec : NuisanceSpec
        Nuisance parameters.
    seed : int
        Seed of the nuisance draws.
    max_frames : int, optional
        Only the first ``max_frames`` scans.
    overwrite : bool
        Replace an existing output.

    Returns
    -------
    Path
        ``out_dir``.
    """
    from relnav.io.sequences import ScanSequence, write_sequence

    seq = ScanSequence(source)
    n = len(seq) if max_frames is None else min(len(seq), int(max_frames))
    gt = seq.gt_poses
    scenario = seq.scenario or {}
    scenario = dict(scenario)
    scenario["nuisance"] = {**spec.active(), "seed": int(seed)}
    times = seq.timestamps[:n]

    def scans() -> Any:
        for k in range(n):
            yield apply_nuisance(seq[k].points, spec, nuisance_rng(seed, spec, k))

    write_sequence(
        out_dir,
        scans(),
        times,
        gt_poses=None if gt is None else gt[:n],
        sensor_meta=seq.sensor_meta,
        scenario=scenario,
        fmt="npy",
        overwrite=overwrite,
    )
    log.info("wrote %s (%s, seed %d, %d frames)", out_dir, spec.label, seed, n)
    return Path(out_dir)
