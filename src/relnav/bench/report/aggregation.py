"""Method classification (which table a grid method belongs in) and aggregation over seeds."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

APPENDIX_COLUMNS: tuple[tuple[str, str], ...] = (
    ("drift", "drift (m)"),
    ("T_error_pct", "T_error (%)"),
    ("e_T_max", "e^T_max (m)"),
    ("e_T_avg", "e^T_avg (m)"),
    ("e_x_max", "max X (m)"),
    ("e_y_max", "max Y (m)"),
    ("e_z_max", "max Z (m)"),
    ("e_x_avg", "avg X (m)"),
    ("e_y_avg", "avg Y (m)"),
    ("e_z_avg", "avg Z (m)"),
    ("e_R_avg", "e^R_avg (°)"),
    ("e_R_max", "e^R_max (°)"),
    ("e_RT", "e^RT (m²+°²)"),
    ("time_ms", "t (ms)"),
)
"""(metric key, header) of the Appendix-A columns, in the paper's order."""

_EXTRA_KEYS = ("path_length", "n_frames", "mean_points", "n_flagged", "e_RT_trans", "e_RT_rot")

DESCRIPTOR_NAMES = {
    "hods": "HoD-S",
    "fpfh": "FPFH",
    "shot": "SHOT",
    "hod": "HoD",
    "rops": "RoPS",
    "trisi": "TriSI",
    "spin": "Spin",
}
FILTER_NAMES = {
    "hinf": "H∞",
    "kalman": "Kalman",
    "alphabeta": "αβ",
    "sdre": "SDRE",
    "svd": "SVD",
    "icp": "ICP (on correspondences)",
}
_FILTER_ORDER = ("hinf", "kalman", "alphabeta", "sdre", "svd")
_PAPER_FILTERS = ("hinf", "kalman", "alphabeta", "sdre")
_DESC_ORDER = ("hods", "fpfh", "shot", "hod", "rops", "trisi", "spin")
_COMPETITORS = ("icp-point", "icp-plane", "icp-x84", "s4pcs", "sicp-point", "sicp-plane")
_BASELINES = (
    "o3d-fpfh-ransac",
    "o3d-icp-point",
    "o3d-icp-plane",
    "kiss-icp",
    "small-gicp",
    "kiss-matcher",
    "kiss-matcher-icp",
    "relnav",  # relnav's own navigator: beyond paper 1, reported beside the tools users pick
)
_ICP_FAST = ("icp-point", "icp-plane", "icp-x84")
_DEFAULT_ITER = {"icp-plane": 1000}
_ITER_KEYS = ("max_iter", "max_icp")


# --------------------------------------------------------------------------------------------
# method classification and aggregation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MethodInfo:
    """What a method label is, for placing it in the tables.

    Attributes
    ----------
    label, method : str
        Grid label and method string.
    family : str
        ``"feature"``, ``"clgv"``, ``"competitor"`` (Paper 1's six), ``"baseline"`` (the
        ``[baselines]`` extra and relnav's own navigator, methods beyond paper 1) or
        ``"other"``.
    descriptor, grouper, estimator : str or None
        Parts of ``feature:`` / ``clgv:`` methods.
    iterations : int or None
        ICP / Sparse-ICP iteration cap (defaults: 20, 1000 for ``icp-plane``).
    default : bool
        No options (apart from the iteration cap for ICP variants).
    """

    label: str
    method: str
    family: str
    descriptor: str | None = None
    grouper: str | None = None
    estimator: str | None = None
    iterations: int | None = None
    default: bool = True

    @property
    def display(self) -> str:
        """Human name: ``HoD-S/αβ``, ``HoD-S/αβ (RANSAC)``, ``CLGV (HoD-S)``, the label."""
        if self.family == "feature" and self.descriptor and self.estimator:
            d = DESCRIPTOR_NAMES.get(self.descriptor, self.descriptor)
            f = FILTER_NAMES.get(self.estimator, self.estimator)
            g = "" if self.grouper == "gcc" else f" ({(self.grouper or '').upper()})"
            return f"{d}/{f}{g}" + ("" if self.default else f" [{self.label}]")
        if self.family == "clgv" and self.descriptor:
            return f"CLGV ({DESCRIPTOR_NAMES.get(self.descriptor, self.descriptor)})"
        return self.label


def classify_method(label: str, method: str, options: dict[str, Any] | None = None) -> MethodInfo:
    """Classify a grid method (see :class:`MethodInfo`)."""
    options = dict(options or {})
    prefix, _, spec = method.partition(":")
    prefix = prefix.strip().lower()
    if prefix == "feature":
        parts = (spec or "hods+gcc+alphabeta").split("+")
        parts += [None] * (3 - len(parts))  # type: ignore[list-item]
        d, g, e = (p.strip().lower() if p else None for p in parts[:3])
        return MethodInfo(label, method, "feature", d, g, e, None, not options)
    if prefix == "clgv":
        return MethodInfo(
            label,
            method,
            "clgv",
            (spec or "hods").strip().lower(),
            "clgv",
            "svd",
            None,
            not options,
        )
    if prefix in _COMPETITORS:
        it = next((int(options[k]) for k in _ITER_KEYS if k in options), None)
        rest = {k: v for k, v in options.items() if k not in _ITER_KEYS}
        iters = it if it is not None else _DEFAULT_ITER.get(prefix, 20)
        return MethodInfo(
            label, method, "competitor", iterations=iters, default=not rest and it is None
        )
    if prefix in _BASELINES:
        return MethodInfo(label, method, "baseline", default=not options)
    return MethodInfo(label, method, "other", default=not options)


@dataclass
class Aggregate:
    """Metrics of one (scenario, nuisance, method) over seeds.

    Attributes
    ----------
    scenario, nuisance : str
        Labels.
    info : MethodInfo
        The method.
    n_runs, n_ok : int
        Jobs in the store for it, and those with status ``ok`` and finite metrics.
    mean, std : dict
        Mean and sample standard deviation (NaN with one seed) per metric.
    seeds : list of int
        Seeds with status ``ok``.
    errors : list of str
        Errors of the failed jobs.
    rows : list of dict
        The ``ok`` store rows.
    """

    scenario: str
    nuisance: str
    info: MethodInfo
    n_runs: int = 0
    n_ok: int = 0
    mean: dict[str, float] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list, repr=False)

    def m(self, key: str) -> float:
        """Mean of ``key`` (NaN when absent)."""
        return self.mean.get(key, float("nan"))


def aggregate(rows: Iterable[dict[str, Any]]) -> dict[tuple[str, str, str], Aggregate]:
    """Group store rows by (scenario, nuisance, method label) and average over seeds."""
    groups: dict[tuple[str, str, str], Aggregate] = {}
    for r in rows:
        key = (r["scenario"], r["nuisance"], r["method_label"])
        if key not in groups:
            opts = r.get("method_options")
            opts = json.loads(opts) if isinstance(opts, str) and opts else (opts or {})
            groups[key] = Aggregate(
                r["scenario"], r["nuisance"], classify_method(r["method_label"], r["method"], opts)
            )
        a = groups[key]
        a.n_runs += 1
        if r.get("status") == "ok" and math.isfinite(float(r.get("e_RT", float("nan")))):
            a.rows.append(r)
            a.seeds.append(int(r["seed"]))
        elif r.get("status") != "ok" or r.get("error"):
            a.errors.append(str(r.get("error") or "no metrics"))
    keys = [k for k, _ in APPENDIX_COLUMNS] + list(_EXTRA_KEYS)
    for a in groups.values():
        a.n_ok = len(a.rows)
        for k in keys:
            v = np.array([float(r.get(k, np.nan)) for r in a.rows], dtype=float)
            v = v[np.isfinite(v)]
            a.mean[k] = float(v.mean()) if v.size else float("nan")
            a.std[k] = float(v.std(ddof=1)) if v.size > 1 else float("nan")
    return groups
