"""Names, units and definitions of the trajectory metrics (:data:`METRIC_DOCS`, the one table
that defines every key), the store's column list :data:`METRIC_KEYS`, evo's statistic names and
the deprecated aliases. Computed by :mod:`relnav.eval.metrics`.
"""

from __future__ import annotations

import logging
from typing import Literal

__all__ = [
    "ALIGN_METHODS",
    "DELTA_UNITS",
    "DEPRECATED_ALIASES",
    "EVO_KEYS",
    "METRIC_DOCS",
    "METRIC_KEYS",
    "STAT_NAMES",
    "metric_units",
]

log = logging.getLogger(__name__)


AlignMethod = Literal["none", "first", "se3", "sim3"]
DeltaUnit = Literal["frames", "m", "deg", "rad"]

ALIGN_METHODS: tuple[str, ...] = ("none", "first", "se3", "sim3")
DELTA_UNITS: tuple[str, ...] = ("frames", "m", "deg", "rad")
STAT_NAMES: tuple[str, ...] = ("rmse", "mean", "median", "std", "min", "max", "sse")
"""evo's statistics (``evo.core.metrics.StatisticsType``), in evo's order."""
EVO_KEYS: tuple[str, ...] = tuple(
    f"{rel}_{stat}"
    for rel in ("ape_trans", "ape_rot", "rpe_trans", "rpe_rot")
    for stat in STAT_NAMES
)
"""evo-named keys of :func:`compute_metrics` (APE/RPE translation in m, rotation in deg)."""
DEPRECATED_ALIASES: dict[str, str] = {
    "ape_rot_rmse_deg": "ape_rot_rmse",
    "rpe_rot_rmse_deg": "rpe_rot_rmse",
    "e_R_euler_max": "e_R_euler_peak",
}
"""Old key → current key; the old keys are still written (same value)."""
RotationError = Literal["geodesic", "euler_mean_diff"]
AngleUnit = Literal["deg", "rad"]

#: Keys always present in the dictionary returned by :func:`compute_metrics`, in report order
#: (also the benchmark store's columns, so it keeps the deprecated aliases; :data:`EVO_KEYS`
#: and ``e_R_euler_peak`` are present as well).
METRIC_KEYS: tuple[str, ...] = (
    "n_frames",
    "path_length",
    "duration_s",
    "drift",
    "T_error_pct",
    "e_T_avg",
    "e_T_max",
    "e_x_max",
    "e_y_max",
    "e_z_max",
    "e_x_avg",
    "e_y_avg",
    "e_z_avg",
    "e_R_avg",
    "e_R_max",
    "e_R_euler_avg",
    "e_R_euler_max",
    "e_RT",
    "e_RT_trans",
    "e_RT_rot",
    "ape_trans_rmse",
    "ape_rot_rmse_deg",
    "rpe_trans_rmse",
    "rpe_rot_rmse_deg",
    "rpe_delta",
    "time_ms",
)


_P1 = "paper 1 §3.2"
METRIC_DOCS: dict[str, tuple[str, str, str]] = {
    "n_frames": ("", "relnav", "associated poses compared"),
    "path_length": ("m", _P1, "L_GT = Σ ‖t_k+1 − t_k‖ of the ground truth"),
    "duration_s": ("s", "relnav", "time span of the associated poses"),
    "drift": ("m", _P1, "end-point error ‖Δ_N‖"),
    "T_error_pct": ("%", _P1, "T_error = 100 · drift / L_GT"),
    "e_T_avg": ("m", _P1 + " eq. 27", "e^T_avg = sqrt(mean ‖Δ_k‖²): an RMSE (= ape_trans_rmse)"),
    "e_T_max": ("m", _P1 + " eq. 28", "e^T_max = max ‖Δ_k‖ (= ape_trans_max)"),
    "e_x_max": ("m", _P1 + " Table A1", "max |Δ_k,x|"),
    "e_y_max": ("m", _P1 + " Table A1", "max |Δ_k,y|"),
    "e_z_max": ("m", _P1 + " Table A1", "max |Δ_k,z|"),
    "e_x_avg": ("m", _P1 + " Table A1", "mean |Δ_k,x|"),
    "e_y_avg": ("m", _P1 + " Table A1", "mean |Δ_k,y|"),
    "e_z_avg": ("m", _P1 + " Table A1", "mean |Δ_k,z|"),
    "e_R_avg": ("deg", _P1 + " eq. 29", "e^R_avg = sqrt(mean θ_k²), θ_k geodesic: an RMSE"),
    "e_R_max": ("deg", _P1 + " eq. 30", "e^R_max = max θ_k"),
    "e_R_euler_avg": ("deg", _P1 + " (legacy)", "sqrt(mean ē_k²), ē_k = mean-Euler difference"),
    "e_R_euler_peak": ("deg", _P1 + " (legacy)", "signed ē_k of largest magnitude (can be < 0)"),
    "e_RT": ("m² + deg²", _P1 + " eq. 31", "e^RT = e_RT_trans + e_RT_rot (Burgard, consecutive)"),
    "e_RT_trans": ("m²", _P1 + " eq. 31", "mean ‖t(E_k)‖² over consecutive frames"),
    "e_RT_rot": ("deg²", _P1 + " eq. 31", "mean angle(E_k)² over consecutive frames"),
    "rpe_delta": ("", "evo --delta", "RPE pair distance (unit in rpe_delta_unit)"),
    "time_ms": ("ms", "relnav", "processing time per frame"),
}
for _rel, _what, _unit in (
    ("ape_trans", "evo_ape -r trans_part: ‖t(T_gt⁻¹ T_est)‖", "m"),
    ("ape_rot", "evo_ape -r angle_deg: angle(T_gt⁻¹ T_est)", "deg"),
    ("rpe_trans", "evo_rpe -r trans_part: ‖t(E_i)‖", "m"),
    ("rpe_rot", "evo_rpe -r angle_deg: angle(E_i)", "deg"),
):
    for _stat in STAT_NAMES:
        _u = _unit + "²" if _stat == "sse" else _unit
        METRIC_DOCS[f"{_rel}_{_stat}"] = (_u, "evo", f"{_stat} of {_what}")
for _old, _new in DEPRECATED_ALIASES.items():
    METRIC_DOCS[_old] = (METRIC_DOCS[_new][0], "deprecated", f"alias of {_new}")
"""Every metric key → ``(unit, origin, definition)``: the single place metrics are named."""


def metric_units(e_rt_rot_unit: AngleUnit = "deg") -> dict[str, str]:
    """Unit of every key of :func:`compute_metrics` (``""`` for counts).

    Parameters
    ----------
    e_rt_rot_unit : {"deg", "rad"}
        Angle unit used inside ``e^RT`` (see :func:`compute_metrics`).
    """
    a2 = "deg²" if e_rt_rot_unit == "deg" else "rad²"
    units = {k: v[0] for k, v in METRIC_DOCS.items()}
    units |= {
        "n_frames": "",
        "path_length": "m",
        "duration_s": "s",
        "drift": "m",
        "T_error_pct": "%",
        "e_RT": f"m² + {a2}",
        "e_RT_trans": "m²",
        "e_RT_rot": a2,
        "ape_trans_rmse": "m",
        "ape_rot_rmse_deg": "deg",
        "rpe_trans_rmse": "m",
        "rpe_rot_rmse_deg": "deg",
        "rpe_delta": "frames",
        "time_ms": "ms",
    }
    for k in METRIC_KEYS:
        if k.startswith("e_R_"):
            units.setdefault(k, "deg")
        elif k.startswith(("e_T_", "e_x", "e_y", "e_z")):
            units.setdefault(k, "m")
    return units
