"""Paper 1's published results, transcribed from its Appendix A and Tables 3–6 and B1.

Used by :mod:`relnav.bench.report` for the section "against the paper". Numbers are exactly as
printed (including the paper's oddities, see Notes); nothing here is computed by relnav.

Method keys follow relnav's method strings: ``"feature:<descriptor>+gcc+<filter>"`` for the
proposed pipeline (descriptors ``hods hod shot fpfh rops trisi``; filters ``hinf kalman
alphabeta sdre``) and ``icp-point icp-plane icp-x84 s4pcs sicp-point sicp-plane`` for the
competitors.

Notes
-----
- Appendix tables A1–A7 label the two rotation columns ``e^T_avg`` / ``e^R_max`` (A1–A4) or
  ``e^R_max`` / ``e^T_avg`` (A5–A7); in every table the first is the smaller, so they are read
  here as ``e_R_avg`` then ``e_R_max`` (degrees) **[interpretation]**. Some are negative in the
  paper (a signed quantity, see ``docs/ALGORITHMS.md`` §F.2).
- ``e^RT`` mixes m² and (presumably) deg² (§F.3); relnav's ``e_RT`` uses degrees as well.
- Table A1 prints 23620 ms for RoPS/αβ (every other RoPS row is ≈ 2 376 ms): kept as printed.
- Tables 5, 6 and B1 are "normalized": divided by the ground-truth path length (checked:
  Table 5 Real-FB ``e^RT`` 0.241 = 1.79 / 7.4 m from Table 3).
- Times are the paper's (MATLAB + C++/PCL via MEX, 2019 desktop), not comparable in absolute
  terms with relnav's.

References
----------
Kechagias-Stamatis, Aouf, Dubanchet, "Evaluating 3D local descriptors and recursive filtering
schemes for LIDAR based uncooperative relative space navigation", J. Field Robotics (Paper 1):
Appendix A, Tables 3–6 and B1.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from relnav.errors import InputError

__all__ = [
    "APPENDIX_COLUMNS",
    "PAPER_CLAIMS",
    "PAPER_DESCRIPTORS",
    "PAPER_FILTERS",
    "PAPER_COMPETITORS",
    "PAPER_SCENARIOS",
    "TOP_MODULES",
    "AblationRow",
    "PaperClaim",
    "appendix_table",
    "best_row",
    "paper_ablation",
    "paper_icp_iterations",
    "paper_path_length",
]

PAPER_SCENARIOS: tuple[str, ...] = (
    "real-fb",
    "real-curved",
    "sim-eoi",
    "sim-helical",
    "sim-voyager",
    "sim-orion",
    "sim-bennu",
)
"""The seven scenarios of Paper 1 §3, as relnav preset names."""

PAPER_DESCRIPTORS: tuple[str, ...] = ("hods", "fpfh", "shot", "hod", "rops", "trisi")
"""Descriptor rows in the order of the appendix tables."""

PAPER_FILTERS: tuple[str, ...] = ("hinf", "kalman", "alphabeta", "sdre")
"""Filter blocks in the order of the appendix tables."""

PAPER_COMPETITORS: tuple[str, ...] = (
    "icp-point",
    "icp-plane",
    "icp-x84",
    "s4pcs",
    "sicp-point",
    "sicp-plane",
)
"""Competitor rows in the order of the appendix tables."""

APPENDIX_COLUMNS: tuple[str, ...] = (
    "drift",
    "T_error_pct",
    "e_T_max",
    "e_T_avg",
    "e_x_max",
    "e_y_max",
    "e_z_max",
    "e_x_avg",
    "e_y_avg",
    "e_z_avg",
    "e_R_avg",
    "e_R_max",
    "e_RT",
    "time_ms",
)
"""Columns of Tables A1–A7 as relnav metric keys (m, %, m …, deg, deg, m²+deg², ms)."""

TOP_MODULES: dict[str, tuple[str, str, str, str]] = {
    "real-fb": ("hods", "alphabeta", "feature:hods+gcc+alphabeta", "low density, poor structure"),
    "real-curved": (
        "fpfh",
        "kalman",
        "feature:hods+gcc+alphabeta",
        "low density, high curvature, poor structure",
    ),
    "sim-eoi": ("fpfh", "kalman", "feature:hods+gcc+alphabeta", "high density, high curvature"),
    "sim-helical": (
        "hods",
        "kalman",
        "feature:hods+gcc+alphabeta",
        "very low density, high curvature, large 3-D translation",
    ),
    "sim-voyager": ("hods", "kalman", "feature:hods+gcc+sdre", "very low density, high curvature"),
    "sim-orion": (
        "hods",
        "kalman",
        "feature:shot+gcc+kalman",
        "very low density, high curvature, poor structure",
    ),
    "sim-bennu": (
        "hods",
        "alphabeta",
        "feature:hods+gcc+alphabeta",
        "very low density, high curvature",
    ),
}
"""Table 4: (top descriptor, top filter, top combination, scenario features) per scenario."""


@dataclass(frozen=True)
class PaperClaim:
    """A qualitative conclusion of Paper 1 that the report checks against our results.

    Attributes
    ----------
    key : str
        Identifier used by :mod:`relnav.bench.report`.
    text : str
        The claim, paraphrased.
    where : str
        Where the paper makes it.
    """

    key: str
    text: str
    where: str


PAPER_CLAIMS: tuple[PaperClaim, ...] = (
    PaperClaim(
        "hods_alphabeta_tradeoff",
        "HoD-S/αβ is the best accuracy–time trade-off (top combination in 5 of 7 scenarios)",
        "Table 4, §4.3",
    ),
    PaperClaim("gcc_beats_ransac", "GCC grouping beats RANSAC (lower e^RT)", "Table 5, §4.4"),
    PaperClaim(
        "filter_beats_icp_corr",
        "the recursive filter beats ICP on the same GCC correspondences (lower e^RT)",
        "Table 3, §4.2",
    ),
    PaperClaim("proposed_beats_clgv", "the proposed pipeline beats CLGV (lower e^RT)", "Table 6"),
    PaperClaim(
        "proposed_beats_competitors",
        "the best proposed combination is more accurate than the best competitor",
        "Fig. 18, §4.3",
    ),
    PaperClaim(
        "hods_fastest_descriptor",
        "HoD-S is the fastest descriptor (no LRF/LRA)",
        "§4.1, Fig. 14",
    ),
    PaperClaim("icp_faster", "ICP variants are faster than the proposed pipeline", "§4.3, Fig. 18"),
)
"""The conclusions checked in the report's "against the paper" section."""


@dataclass(frozen=True)
class AblationRow:
    """One scenario row of Table 3, 5, 6 or B1 (values as printed).

    ``a`` is the proposed / with-filter / GCC / 20-iteration value, ``b`` the alternative.
    Tables 5, 6 and B1 are normalised by the path length, Table 3 is not.
    """

    scenario: str
    method: str
    e_T_avg: tuple[float, float]
    e_R_avg: tuple[float, float]
    e_RT: tuple[float, float]
    time_ms: tuple[float, float]


def _parse_rows(text: str) -> list[list[str]]:
    return [line.split() for line in text.strip().splitlines() if line.strip()]


def _method_key(key: str) -> str:
    if "/" in key:
        d, f = key.split("/")
        return f"feature:{d}+gcc+{f}"
    return key


@cache
def _appendix() -> dict[str, dict[str, dict[str, float]]]:
    out: dict[str, dict[str, dict[str, float]]] = {}
    for scn, text in _APPENDIX_TEXT.items():
        rows = {}
        for parts in _parse_rows(text):
            if len(parts) != 1 + len(APPENDIX_COLUMNS):
                raise AssertionError(f"bad transcription row for {scn}: {parts}")
            rows[_method_key(parts[0])] = dict(
                zip(APPENDIX_COLUMNS, map(float, parts[1:]), strict=True)
            )
        out[scn] = rows
    return out


def _check_scenario(scenario: str) -> str:
    key = str(scenario).lower().replace("_", "-")
    if key not in PAPER_SCENARIOS:
        raise InputError(
            f"Paper 1 has no scenario {scenario!r}; scenarios: {', '.join(PAPER_SCENARIOS)}"
        )
    return key


def appendix_table(scenario: str) -> dict[str, dict[str, float]]:
    """Table A1–A7 of ``scenario``: ``{method: {column: value}}`` (:data:`APPENDIX_COLUMNS`).

    Raises
    ------
    InputError
        ``scenario`` is not one of :data:`PAPER_SCENARIOS`.
    """
    return {k: dict(v) for k, v in _appendix()[_check_scenario(scenario)].items()}


def paper_path_length(scenario: str) -> float:
    """Ground-truth path length of ``scenario`` implied by the appendix, m.

    The median over rows of ``100 · drift / T_error`` (rows with ``T_error`` ≥ 0.1 % only, to
    limit rounding error); e.g. ≈ 790 m for Sim-Voyager (the paper states 788 m).
    """
    vals = sorted(
        100.0 * r["drift"] / r["T_error_pct"]
        for r in _appendix()[_check_scenario(scenario)].values()
        if r["T_error_pct"] >= 0.1
    )
    n = len(vals)
    return 0.5 * (vals[(n - 1) // 2] + vals[n // 2])


def best_row(
    scenario: str, *, family: str = "proposed", metric: str = "e_RT"
) -> tuple[str, dict[str, float]]:
    """The paper's best row of ``scenario`` by ``metric`` (lowest; ``|value|`` for signed ones).

    Parameters
    ----------
    scenario : str
        A :data:`PAPER_SCENARIOS` name.
    family : {"proposed", "competitor", "all"}
        Rows considered.
    metric : str
        One of :data:`APPENDIX_COLUMNS`.

    Returns
    -------
    (method, row)
    """
    if metric not in APPENDIX_COLUMNS:
        raise InputError(f"unknown column {metric!r}; columns: {', '.join(APPENDIX_COLUMNS)}")
    if family not in ("proposed", "competitor", "all"):
        raise InputError(f"family must be proposed, competitor or all, got {family!r}")
    rows = _appendix()[_check_scenario(scenario)]
    cand = {
        k: v
        for k, v in rows.items()
        if family == "all" or (k.startswith("feature:") == (family == "proposed"))
    }
    best = min(cand, key=lambda k: (abs(cand[k][metric]), k))
    return best, dict(cand[best])


def _ablation(text: str) -> dict[str, AblationRow]:
    out = {}
    for p in _parse_rows(text):
        v = [float(x) for x in p[2:]]
        out[p[0]] = AblationRow(
            p[0], _method_key(p[1]), (v[0], v[1]), (v[2], v[3]), (v[4], v[5]), (v[6], v[7])
        )
    return out


def paper_ablation(table: str) -> dict[str, AblationRow]:
    """Table ``"3"`` (with/without filter), ``"5"`` (GCC/RANSAC) or ``"6"`` (proposed/CLGV).

    Returns ``{scenario: AblationRow}``; ``method`` is the paper's top combination.
    """
    texts = {"3": _TABLE3_TEXT, "5": _TABLE5_TEXT, "6": _TABLE6_TEXT}
    if str(table) not in texts:
        raise InputError(f"no ablation table {table!r}; choose 3, 5 or 6")
    return _ablation(texts[str(table)])


def paper_icp_iterations() -> dict[tuple[str, str], AblationRow]:
    """Table B1: ``{(scenario, icp variant): AblationRow}`` (20 vs 1000 iterations, normalised).

    The paper prints 10¹², 3×10¹¹ … for diverged ICP-plane runs; they are kept as floats.
    """
    out = {}
    for p in _parse_rows(_TABLE_B1_TEXT):
        v = [float(x) for x in p[2:]]
        out[(p[0], p[1])] = AblationRow(
            p[0], p[1], (v[0], v[1]), (v[2], v[3]), (v[4], v[5]), (v[6], v[7])
        )
    return out


# ---------------------------------------------------------------------------------------------
# transcriptions (one row per method: the 14 APPENDIX_COLUMNS values as printed)
# ---------------------------------------------------------------------------------------------

_APPENDIX_TEXT: dict[str, str] = {
    # Table A1: real-fb
    "real-fb": """
hods/hinf 0.16 2.11 0.17 0.09 0.05 0.13 0.09 0.05 0.03 0.05 9.12 13.58 9.91 560
fpfh/hinf 3.56 48.02 3.56 2.32 0.91 3.19 1.28 0.62 1.91 0.76 9.11 13.57 13.38 687
shot/hinf 0.58 7.77 0.59 0.23 0.56 0.15 0.09 0.12 0.09 0.10 8.61 12.77 9.89 1794
hod/hinf 0.15 2.00 0.36 0.17 0.34 0.07 0.01 0.12 0.04 0.03 9.12 13.57 10.05 950
rops/hinf 0.84 11.39 0.85 0.25 0.19 0.68 0.48 0.05 0.15 0.13 9.13 13.57 10.26 2376
trisi/hinf 0.26 3.56 3.13 1.69 3.13 0.01 0.01 1.39 0.03 0.04 3.35 4.55 6.32 1536
hods/kalman 0.84 11.29 1.29 0.79 1.12 0.08 0.64 0.50 0.03 0.41 2.34 4.90 4.48 557
fpfh/kalman 2.41 32.49 2.82 1.78 0.70 2.37 1.36 0.56 1.24 0.73 2.48 4.55 6.04 687
shot/kalman 0.58 7.84 0.59 0.23 0.57 0.16 0.06 0.12 0.10 0.11 0.27 0.51 1.56 1794
hod/kalman 0.26 3.52 0.35 0.21 0.30 0.06 0.16 0.12 0.04 0.12 0.91 1.83 2.09 946
rops/kalman 1.64 22.09 1.64 0.81 0.64 0.65 1.37 0.29 0.13 0.53 2.60 4.66 4.45 2375
trisi/kalman 0.26 3.57 3.13 1.69 3.13 0.01 0.01 1.39 0.03 0.04 0.05 0.07 3.02 1536
hods/alphabeta 0.16 2.20 0.18 0.10 0.11 0.07 0.13 0.05 0.04 0.05 0.99 1.34 1.79 518
fpfh/alphabeta 3.58 48.21 3.58 2.33 0.87 3.23 1.26 0.60 1.93 0.77 0.60 0.81 4.87 679
shot/alphabeta 0.56 7.54 0.57 0.23 0.54 0.17 0.08 0.12 0.10 0.11 0.26 0.35 1.57 1784
hod/alphabeta 0.15 2.00 0.38 0.18 0.36 0.07 0.01 0.13 0.04 0.03 0.99 1.36 1.94 903
rops/alphabeta 0.86 11.53 0.86 0.26 0.15 0.70 0.48 0.04 0.16 0.13 0.66 0.96 1.75 23620
trisi/alphabeta 0.26 3.53 3.13 1.69 3.13 0.01 0.01 1.40 0.03 0.04 0.06 0.08 3.03 1535
hods/sdre 0.85 11.41 0.86 0.40 0.45 0.54 0.49 0.18 0.23 0.16 9.12 13.58 10.85 521
fpfh/sdre 4.19 56.46 4.19 2.54 1.31 3.61 1.69 0.82 2.12 0.63 9.11 13.57 13.74 684
shot/sdre 1.13 15.28 1.14 0.46 0.92 0.52 0.44 0.17 0.28 0.13 8.61 12.77 10.24 1752
hod/sdre 0.85 11.43 0.85 0.38 0.48 0.53 0.47 0.14 0.20 0.18 9.12 13.57 10.71 907
rops/sdre 1.23 16.63 1.24 0.53 0.50 1.04 0.42 0.22 0.35 0.17 9.13 13.57 11.07 2376
trisi/sdre 0.27 3.57 3.10 1.67 3.10 0.02 0.03 1.37 0.02 0.04 3.35 4.55 6.28 1536
icp-point 0.44 5.90 1.41 0.64 1.30 0.50 0.22 0.43 0.15 0.13 84.49 133.01 86.32 5
icp-plane 1.90 25.61 1.91 0.97 1.79 0.07 0.67 0.61 0.40 0.35 -171.1 -111.87 191.71 9
icp-x84 8.75 117.97 11.36 9.57 8.69 4.94 4.56 6.65 3.78 4.24 -165.4 -121.96 206.69 40
s4pcs 1.26 16.98 1.91 1.09 0.10 1.89 0.19 0.16 0.73 0.45 77.01 141.53 79.53 1225
sicp-point 0.13 1.70 3.52 1.97 3.51 0.20 0.11 1.64 0.08 0.07 0.01 0.01 3.42 145.76
sicp-plane 0.13 1.70 3.52 1.97 3.51 0.20 0.11 1.64 0.08 0.07 0.01 0.01 3.42 150.16
    """,
    # Table A2: real-curved
    "real-curved": """
hods/hinf 0.27 2.15 0.28 0.16 0.20 0.04 0.20 0.08 0.07 0.08 12.22 17.95 13.51 481
fpfh/hinf 1.19 9.60 1.60 1.01 0.29 0.62 1.43 0.22 0.53 0.71 11.99 17.90 14.60 690
shot/hinf 0.72 5.86 0.93 0.71 0.80 0.45 0.11 0.57 0.34 0.04 11.05 16.72 13.55 1698
hod/hinf 0.06 0.51 0.47 0.23 0.42 0.22 0.03 0.16 0.10 0.05 12.00 17.96 13.42 817
rops/hinf 0.91 7.35 0.91 0.37 0.17 0.05 0.89 0.16 0.06 0.26 12.27 18.18 14.08 2373
trisi/hinf 0.51 4.12 3.45 1.93 3.43 0.37 0.03 1.50 0.49 0.03 4.27 6.10 7.83 2452
hods/kalman 0.40 3.23 0.53 0.31 0.29 0.05 0.30 0.25 0.09 0.09 14.85 22.70 16.66 480
fpfh/kalman 1.20 9.68 1.60 1.02 0.30 0.62 1.43 0.22 0.54 0.72 1.92 3.62 4.53 690
shot/kalman 0.71 5.78 0.93 0.71 0.80 0.45 0.10 0.57 0.33 0.04 0.61 1.03 3.10 1697
hod/kalman 0.06 0.50 0.48 0.24 0.42 0.22 0.03 0.16 0.11 0.05 0.98 1.90 2.41 816
rops/kalman 0.36 2.90 1.01 0.65 0.42 0.39 0.56 0.18 0.05 0.51 13.57 20.16 15.35 2372
trisi/kalman 0.51 4.11 3.45 1.93 3.43 0.36 0.03 1.50 0.49 0.03 0.21 0.25 3.77 2452
hods/alphabeta 0.25 2.03 0.27 0.16 0.17 0.05 0.20 0.09 0.08 0.08 1.44 1.81 2.75 464
fpfh/alphabeta 1.21 9.75 1.60 1.02 0.30 0.62 1.43 0.23 0.54 0.72 0.57 0.85 3.21 683
shot/alphabeta 0.72 5.84 0.94 0.72 0.81 0.45 0.10 0.58 0.33 0.04 0.43 0.60 2.93 1691
hod/alphabeta 0.05 0.41 0.49 0.24 0.43 0.22 0.03 0.17 0.11 0.05 1.21 1.47 2.65 809
rops/alphabeta 0.91 7.35 0.91 0.38 0.19 0.06 0.89 0.18 0.06 0.25 1.15 1.59 2.99 2357
trisi/alphabeta 0.51 4.11 3.45 1.93 3.43 0.36 0.03 1.50 0.49 0.03 0.14 0.16 3.70 2451
hods/sdre 0.74 5.99 0.77 0.41 0.49 0.34 0.49 0.16 0.22 0.22 12.22 17.95 14.14 466
fpfh/sdre 1.55 12.50 1.56 1.02 0.24 0.68 1.37 0.17 0.68 0.57 11.99 17.90 14.54 685
shot/sdre 0.46 3.74 0.79 0.56 0.68 0.34 0.22 0.44 0.21 0.13 11.05 16.72 13.40 1675
hod/sdre 0.56 4.54 0.66 0.39 0.43 0.40 0.29 0.19 0.25 0.14 12.00 17.96 13.92 812
rops/sdre 1.24 10.05 1.24 0.50 0.12 0.35 1.19 0.06 0.13 0.37 12.27 18.18 13.96 2360
trisi/sdre 0.46 3.72 3.43 1.91 3.41 0.35 0.05 1.48 0.48 0.04 4.27 6.10 7.84 2453
icp-point 2.70 21.81 2.78 1.68 1.68 2.07 0.53 0.66 1.14 0.16 104 -179.13 107.90 6
icp-plane 1.90 25.61 1.91 0.97 1.79 0.07 0.67 0.61 0.40 0.35 -171 -111.87 191.71 9
icp-x84 7.08 57.23 7.46 4.24 6.30 3.66 1.59 2.48 2.07 1.17 135 -142.43 140.29 53
s4pcs 4.60 37.18 4.60 2.89 3.52 2.53 1.54 1.47 1.73 0.81 141 -124.33 146.51 1219
sicp-point 0.13 1.70 3.52 1.97 3.51 0.20 0.11 1.64 0.08 0.07 0.01 0.01 3.42 137
sicp-plane 0.13 1.70 3.52 1.97 3.51 0.20 0.11 1.64 0.08 0.07 0.01 0.01 3.42 145
    """,
    # Table A3: sim-eoi
    "sim-eoi": """
hods/hinf 1.16 0.40 1.19 0.69 0.92 0.53 0.50 0.48 0.21 0.20 8.81 10.88 15.86 28157
fpfh/hinf 2.56 0.88 2.59 1.49 2.40 0.94 0.18 1.24 0.36 0.22 7.56 10.71 17.18 6525
shot/hinf 1.93 0.66 1.94 1.30 1.87 0.46 0.19 1.13 0.18 0.09 2.89 3.95 10.56 13701
hod/hinf 1.16 0.40 1.28 0.81 0.91 0.72 0.55 0.48 0.39 0.28 8.83 10.97 17.47 34832
rops/hinf 2.37 0.81 3.16 1.87 2.82 0.77 1.18 1.56 0.27 0.39 7.91 10.33 18.45 40647
trisi/hinf 1.90 0.65 1.95 1.08 1.68 0.43 0.27 0.84 0.29 0.09 8.98 11.16 16.80 38306
hods/kalman 28.14 9.68 38.48 25.49 2.28 29.11 25.07 9.63 13.67 14.27 127.37 97.55 178.64 28144
fpfh/kalman 14.83 5.10 14.98 11.69 13.40 3.27 4.59 9.64 2.16 3.42 109.41 154.76 136.54 6518
shot/kalman 18.85 6.48 37.37 25.98 10.37 24.73 25.63 10.63 11.36 16.25 105.31 164.46 148.07 13870
hod/kalman 15.88 5.46 29.03 21.60 8.80 11.59 25.11 4.24 12.64 14.14 79.02 117.81 125.87 34817
rops/kalman 20.36 7.00 39.97 28.72 8.13 29.34 23.98 10.17 13.88 18.76 156.53 200.72 202.61 40637
trisi/kalman 17.64 6.07 32.87 21.86 1.49 20.78 25.18 6.91 6.92 16.38 50.72 66.26 90.25 38296
hods/alphabeta 1.24 0.43 1.26 0.70 1.02 0.44 0.24 0.55 0.18 0.09 2.91 3.98 9.23 27954
fpfh/alphabeta 2.61 0.90 2.63 1.49 2.47 0.89 0.11 1.26 0.34 0.10 2.77 3.88 11.59 6424
shot/alphabeta 1.93 0.66 1.94 1.30 1.87 0.46 0.19 1.13 0.18 0.09 2.89 3.95 10.56 13701
hod/alphabeta 1.22 0.42 1.27 0.81 1.00 0.63 0.30 0.55 0.38 0.15 2.89 3.92 10.80 34610
rops/alphabeta 2.56 0.88 3.25 1.96 2.88 0.76 1.30 1.60 0.27 0.51 2.89 4.02 13.90 40502
trisi/alphabeta 2.04 0.70 2.08 1.16 2.04 0.35 0.19 0.90 0.30 0.13 2.73 3.66 11.10 38160
hods/sdre 1.44 0.50 1.46 0.86 1.17 0.27 0.76 0.63 0.13 0.34 8.81 10.88 16.56 27990
fpfh/sdre 2.79 0.96 2.81 1.65 2.70 0.64 0.48 1.39 0.24 0.35 7.56 10.71 17.45 6425
shot/sdre 2.21 0.76 2.21 1.49 1.88 0.73 0.57 1.23 0.32 0.32 7.96 10.29 18.06 13702
hod/sdre 1.40 0.48 1.49 0.94 1.16 0.46 0.80 0.62 0.25 0.43 8.83 10.97 17.72 34725
rops/sdre 2.63 0.91 3.21 2.02 2.98 0.62 1.02 1.70 0.35 0.30 7.91 10.33 18.65 40502
trisi/sdre 2.28 0.78 2.31 1.31 2.16 0.60 0.39 0.97 0.44 0.18 8.98 11.16 18.17 38161
icp-point 50.32 17.31 62.20 39.09 29.20 1.53 54.76 12.62 3.77 29.92 -164.3 -42.15 249.55 30.50
icp-plane 42.71 14.69 57.96 36.50 28.71 0.08 49.43 10.99 0.45 29.10 -167.5 -30.44 235.93 31.38
icp-x84 2.79 0.96 70.47 45.93 16.94 39.69 52.85 11.13 27.50 21.97 -165.6 -22.33 257.89 49.36
s4pcs 151.14 51.99 151.14 103.35 46.02 79.36 114.71 43.40 45.31 60.85 -155.6 32.60 342.80 1147
sicp-point 0.04 0.01 20.08 11.44 0.37 0.05 20.06 0.24 0.04 9.05 0.01 0.01 17.49 276.68
sicp-plane 0.04 0.01 20.08 11.44 0.37 0.05 20.06 0.24 0.04 9.05 0.01 0.01 17.49 327.62
    """,
    # Table A4: sim-helical
    "sim-helical": """
hods/hinf 1.85 0.90 2.09 1.61 1.79 0.42 1.00 1.28 0.17 0.74 0.08 0.16 12.55 137
fpfh/hinf 2.22 1.08 2.90 2.07 1.77 0.07 2.30 1.04 0.22 1.65 0.08 0.16 15.81 620
shot/hinf 5.89 2.86 5.92 2.17 3.63 4.33 1.64 1.67 0.37 0.74 0.08 0.15 13.69 1094
hod/hinf 6.27 3.04 6.27 3.29 5.25 1.50 3.08 2.03 1.27 1.04 0.08 0.14 17.55 997
rops/hinf 2.16 1.05 2.45 1.83 1.37 0.33 1.74 1.20 0.14 1.28 0.08 0.16 14.88 1164
trisi/hinf 12.74 6.18 12.74 8.26 7.40 7.24 7.24 2.69 4.86 2.82 0.07 0.13 26.49 1042
hods/kalman 2.03 0.98 2.47 1.59 1.79 0.12 1.70 1.22 0.23 0.77 0.01 0.01 13.13 134
fpfh/kalman 32.38 15.71 33.74 14.92 10.05 5.48 31.74 2.63 1.12 8.52 32.61 -179.99 58.38 619
shot/kalman 5.87 2.85 5.90 2.16 3.58 4.38 1.57 1.64 0.37 0.79 0.01 0.01 13.71 1092
hod/kalman 6.37 3.09 6.37 3.29 5.21 1.55 3.31 2.01 1.26 1.10 0.01 0.01 17.70 995
rops/kalman 9.36 4.54 10.03 6.12 6.94 0.14 7.24 3.70 0.19 3.36 0.20 0.24 23.89 1161
trisi/kalman 12.84 6.23 12.84 8.28 7.42 7.20 7.37 2.70 4.85 2.86 0.01 0.01 26.52 1041
hods/alphabeta 1.86 0.90 2.09 1.61 1.79 0.39 1.01 1.28 0.17 0.75 0.01 0.01 12.53 112
fpfh/alphabeta 2.27 1.10 2.91 2.08 1.77 0.10 2.30 1.04 0.24 1.66 0.01 0.01 15.87 607
shot/alphabeta 5.92 2.87 5.96 2.17 3.64 4.38 1.61 1.67 0.37 0.74 0.01 0.01 13.61 1074
hod/alphabeta 6.28 3.05 6.28 3.28 5.26 1.55 3.06 2.03 1.25 1.03 0.01 0.01 17.45 979
rops/alphabeta 2.20 1.07 2.49 1.85 1.37 0.35 1.76 1.20 0.16 1.29 0.01 0.01 14.97 1140
trisi/alphabeta 12.73 6.18 12.73 8.25 7.41 7.20 7.23 2.70 4.85 2.81 0.01 0.01 26.43 1024
hods/sdre 1.81 0.88 2.08 1.60 1.74 0.47 1.04 1.24 0.19 0.77 0.08 0.16 12.64 116
fpfh/sdre 2.29 1.11 2.91 2.08 1.73 0.03 2.34 1.01 0.19 1.68 0.08 0.16 15.75 609
shot/sdre 5.78 2.81 5.82 2.14 3.57 4.27 1.58 1.64 0.38 0.75 0.08 0.15 13.69 1077
hod/sdre 6.18 3.00 6.18 3.27 5.19 1.44 3.02 2.00 1.29 1.03 0.08 0.14 17.46 981
rops/sdre 2.20 1.07 2.48 1.83 1.15 0.09 2.18 1.16 0.13 1.32 0.08 0.16 14.82 1143
trisi/sdre 12.68 6.15 12.68 8.25 7.35 7.29 7.19 2.66 4.87 2.80 0.07 0.13 26.40 1027
icp-point 2.92 1.42 3.15 1.96 2.07 0.44 2.34 1.39 0.26 1.15 11.71 20.83 26.85 18
icp-plane 22.70 11.02 27.08 11.36 22.61 10.36 4.70 5.99 3.35 2.06 58.66 -96.87 84.62 89
icp-x84 16615 8063 17277 9210 12253 8668 8333 1905. 2878 3333 -132 -15.79 8346 25
s4pcs 147.65 71.65 155.65 84.13 46.40 146.59 24.19 15.94 64.69 10.21 109 -169 207.98 1081
sicp-point 47.90 23.25 47.90 39.05 28.09 19.00 31.66 19.15 12.80 23.86 0.01 0.01 50.04 107
sicp-plane 49.32 23.93 49.32 40.37 29.40 19.40 32.86 20.21 12.96 24.82 0.01 0.01 51.00 105
    """,
    # Table A5: sim-voyager
    "sim-voyager": """
hods/hinf 16.59 2.10 28.76 14.27 10.68 18.79 18.97 5.12 7.50 7.54 0.14 0.27 40.91 66
fpfh/hinf 104 13.24 105 62.86 28.27 50.14 88.19 11.47 29.59 47.60 0.13 0.26 97.43 438
shot/hinf 33.35 4.23 38.02 18.05 9.55 36.17 6.80 4.84 12.11 2.63 0.13 0.25 42.38 599
hod/hinf 24.31 3.08 27.71 15.36 19.58 18.44 6.63 9.25 9.04 3.18 0.13 0.26 41.68 103
rops/hinf 21.66 2.75 31.10 16.00 12.20 19.09 14.14 5.68 10.79 5.79 0.14 0.27 43.15 398
trisi/hinf 22.87 2.90 39.56 22.20 12.54 29.45 23.24 7.13 13.09 12.63 0.08 0.16 46.39 336
hods/kalman 10.34 1.31 55.07 22.22 52.30 12.06 2.33 13.55 6.65 4.64 95.19 -162.41 140.12 66
fpfh/kalman 93.16 11.82 93.21 59.57 32.86 35.56 79.65 13.70 24.50 46.74 0.10 0.20 94.85 438
shot/kalman 34.55 4.38 39.12 18.30 8.69 37.61 6.37 4.43 12.13 2.46 0.18 0.40 45.20 598
hod/kalman 25.04 3.18 28.35 15.74 20.29 18.81 6.20 9.67 9.18 3.03 0.01 0.02 41.79 102
rops/kalman 21.99 2.79 28.41 17.71 19.10 12.94 15.49 8.05 5.87 11.90 24.21 92.37 71.60 397
trisi/kalman 22.50 2.85 38.94 22.09 12.59 29.27 22.39 7.14 13.07 12.61 1.19 2.98 47.58 335
hods/alphabeta 15.77 2.00 28.03 13.83 10.64 18.03 18.63 5.11 7.05 7.35 1.88 3.58 41.68 57
fpfh/alphabeta 104 13.24 105 62.86 28.27 50.14 88.19 11.47 29.59 47.60 0.13 0.26 97.43 438
shot/alphabeta 33.36 4.23 38.03 17.89 9.82 36.00 7.32 5.00 11.89 2.81 1.53 3.09 38.19 595
hod/alphabeta 24.29 3.08 27.49 15.18 20.09 17.70 6.21 9.44 8.67 3.04 2.23 4.51 43.13 91
rops/alphabeta 22.08 2.80 30.72 16.08 12.71 18.64 14.88 5.98 10.57 6.18 1.03 1.97 44.68 390
trisi/alphabeta 22.93 2.91 39.64 22.22 12.55 29.36 23.50 7.11 13.07 12.67 0.80 1.50 47.06 331
hods/sdre 16.41 2.08 28.67 14.20 10.77 18.70 18.88 5.12 7.45 7.49 0.14 0.27 40.78 57
fpfh/sdre 104 13.23 105 62.83 28.16 50.26 88.08 11.42 29.65 47.54 0.13 0.26 97.38 435
shot/sdre 33.21 4.21 37.87 17.98 9.44 36.06 6.69 4.79 12.06 2.61 0.13 0.25 41.23 595
hod/sdre 24.14 3.06 27.52 15.26 19.47 18.33 6.52 9.19 8.99 3.13 0.13 0.26 41.52 91
rops/sdre 21.46 2.72 30.98 15.91 12.09 18.98 14.03 5.63 10.74 5.74 0.14 0.27 42.99 391
trisi/sdre 22.85 2.90 39.50 22.18 12.60 29.39 23.18 7.16 13.08 12.62 0.08 0.16 46.42 332
icp-point 9.52 1.21 21.03 11.22 4.93 19.40 6.43 4.48 6.37 2.91 19.22 34.10 55.27 15
icp-plane 11.15 1.41 26.18 13.30 3.73 23.66 10.27 3.92 8.38 4.26 41.48 75.56 80.69 16
icp-x84 80.60 10.22 80.60 61.73 53.26 58.43 15.68 43.74 24.99 9.27 147.65 -160 234.32 17
s4pcs 39.98 5.07 50.32 38.59 26.07 30.43 30.39 20.14 18.90 18.91 1.65 1.65 52.48 136
sicp-point 28.94 3.67 38.45 29.50 21.24 14.80 28.40 14.82 12.27 16.18 0.01 0.01 46.33 171
sicp-plane 28.94 3.67 38.45 29.50 21.24 14.80 28.40 14.82 12.27 16.18 0.01 0.01 46.33 177
    """,
    # Table A6: sim-orion
    "sim-orion": """
hods/hinf 109 13.84 111 64.28 7.72 4.21 109 3.61 3.89 54.45 0.14 0.27 70.76 156
fpfh/hinf 12.22 1.55 14.74 8.72 8.50 3.27 9.86 5.06 1.97 5.12 0.14 0.27 30.19 720
shot/hinf 9.43 1.20 11.94 5.91 7.39 7.08 6.16 3.08 2.59 2.74 0.14 0.27 26.93 859
hod/hinf 118 14.97 138 78.47 79.15 81.10 78.99 48.37 33.68 32.72 0.03 0.06 101 169
rops/hinf 7.30 0.93 11.33 6.70 7.21 6.38 5.56 5.13 2.03 2.27 0.14 0.27 26.46 1514
trisi/hinf 77.47 9.83 85.93 50.77 65.86 39.21 38.37 38.10 16.16 16.04 0.06 0.12 67.97 1159
hods/kalman 29.37 3.73 37.06 25.17 19.83 6.74 28.52 11.48 5.03 18.05 50.37 -159 94.00 156
fpfh/kalman 11.88 1.51 14.59 8.70 7.58 3.41 10.38 4.63 2.02 5.34 0.01 0.01 29.85 719
shot/kalman 8.46 1.07 10.76 5.32 5.72 6.80 6.07 2.44 2.29 2.65 0.01 0.01 24.25 858
hod/kalman 118 14.98 138 78.50 79.24 81.09 78.99 48.42 33.68 32.72 0.01 0.01 101 169
rops/kalman 13.40 1.70 16.59 6.44 0.89 3.53 16.19 2.14 1.90 4.33 0.10 0.22 24.69 1513
trisi/kalman 77.59 9.84 86.05 50.82 66.00 39.19 38.42 38.15 16.16 16.05 0.01 0.01 67.95 1158
hods/alphabeta 109 13.91 111 64.50 7.66 4.07 110 3.59 3.90 54.62 0.05 0.10 70.84 146
fpfh/alphabeta 12.29 1.56 14.77 8.75 8.55 3.35 9.85 5.09 2.00 5.12 0.07 0.13 30.28 711
shot/alphabeta 9.55 1.21 11.98 5.96 7.39 7.09 6.21 3.10 2.63 2.79 0.11 0.22 26.99 845
hod/alphabeta 118 14.97 138 78.50 79.19 81.09 79.04 48.39 33.68 32.74 0.01 0.03 101 166
rops/alphabeta 7.24 0.92 11.40 6.72 7.23 6.39 5.61 5.15 2.01 2.28 0.09 0.19 26.46 1503
trisi/alphabeta 77.54 9.84 86.01 50.80 65.92 39.23 38.41 38.12 16.17 16.05 0.03 0.05 67.95 1154
hods/sdre 109 13.83 111 64.22 7.83 4.09 109 3.65 3.90 54.39 0.14 0.27 70.74 147
fpfh/sdre 12.12 1.54 14.59 8.66 8.39 3.38 9.74 5.00 2.02 5.08 0.14 0.27 30.24 712
shot/sdre 9.53 1.21 11.95 5.94 7.36 7.10 6.18 3.05 2.64 2.79 0.14 0.27 26.60 846
hod/sdre 118 14.97 138 78.46 79.18 81.07 78.97 48.39 33.67 32.71 0.03 0.06 101 168
rops/sdre 7.11 0.90 11.33 6.65 7.19 6.40 5.58 5.07 2.01 2.27 0.14 0.27 26.40 1504
trisi/sdre 77.50 9.83 85.93 50.78 65.91 39.16 38.32 38.12 16.15 16.03 0.06 0.12 68.01 1155
icp-point 13.90 1.76 16.75 9.38 6.71 11.50 8.08 4.63 5.09 3.41 -130 35.91 262.48 13
icp-plane 11.54 1.46 12.59 8.64 8.10 3.02 8.79 4.62 1.80 4.91 -123 65.04 267.53 50
icp-x84 88.92 11.28 127.39 66.46 89.92 1.62 90.21 26.43 21.73 37.32 -163 26.55 277.57 24
s4pcs 54.65 6.93 65.76 43.33 39.43 37.30 37.11 27.31 19.49 19.47 0.54 1.07 60.24 1641
sicp-point 29.98 3.80 46.69 32.92 20.57 28.57 30.31 15.04 17.15 16.66 0.01 0.01 48.12 125
sicp-plane 29.98 3.80 46.69 32.92 20.57 28.57 30.31 15.04 17.15 16.66 0.01 0.01 48.12 133
    """,
    # Table A7: sim-bennu
    "sim-bennu": """
hods/hinf 2.02 0.26 2.04 1.15 0.21 0.64 1.93 0.15 0.38 0.92 0.14 0.28 10.76 47
fpfh/hinf 3.41 0.43 5.59 3.67 0.21 4.31 3.43 0.52 1.97 2.22 0.14 0.27 18.12 440
shot/hinf 1.22 0.15 7.05 4.54 0.25 4.98 4.99 0.58 2.89 2.92 0.13 0.26 22.72 516
hod/hinf 77.69 9.85 104 56.85 40.82 67.82 67.71 27.89 27.51 27.46 0.03 0.06 69.37 53
rops/hinf 11.07 1.40 11.08 6.19 1.73 7.16 8.26 0.76 2.95 3.56 0.14 0.28 20.72 591
trisi/hinf 50.19 6.37 55.81 39.46 36.34 29.85 29.83 25.40 17.93 17.93 0.03 0.06 59.38 457
hods/kalman 8.67 1.10 29.09 16.80 9.38 24.27 12.99 3.68 11.23 6.43 0.02 0.08 40.24 46
fpfh/kalman 3.40 0.43 5.57 3.67 0.21 4.32 3.42 0.52 1.96 2.22 0.01 0.01 17.96 439
shot/kalman 1.20 0.15 7.06 4.54 0.25 4.98 4.99 0.57 2.89 2.92 0.01 0.01 22.57 516
hod/kalman 77.69 9.85 104 56.85 40.83 67.82 67.70 27.89 27.51 27.46 0.01 0.01 69.34 53
rops/kalman 11.07 1.40 11.08 6.19 1.74 7.15 8.27 0.76 2.95 3.56 0.01 0.01 20.59 590
trisi/kalman 50.19 6.37 55.82 39.46 36.34 29.86 29.83 25.40 17.93 17.93 0.01 0.01 59.35 456
hods/alphabeta 2.04 0.26 2.05 1.16 0.20 0.64 1.94 0.15 0.38 0.93 0.01 0.01 10.65 41
fpfh/alphabeta 3.42 0.43 5.59 3.67 0.21 4.32 3.42 0.52 1.97 2.23 0.01 0.01 17.96 437
shot/alphabeta 1.21 0.15 7.06 4.54 0.25 4.98 4.99 0.57 2.90 2.92 0.01 0.01 22.58 509
hod/alphabeta 77.71 9.86 104 56.85 40.84 67.83 67.71 27.90 27.52 27.46 0.01 0.01 69.35 51
rops/alphabeta 11.07 1.40 11.09 6.19 1.74 7.15 8.27 0.76 2.95 3.56 0.01 0.01 20.58 583
trisi/alphabeta 50.20 6.37 55.83 39.47 36.36 29.86 29.83 25.40 17.93 17.93 0.01 0.01 59.35 453
hods/sdre 1.97 0.25 1.98 1.12 0.33 0.76 1.80 0.21 0.44 0.86 0.14 0.28 11.14 42
fpfh/sdre 3.54 0.45 5.69 3.68 0.30 4.41 3.52 0.50 1.96 2.22 0.14 0.27 18.09 437
shot/sdre 1.40 0.18 6.92 4.51 0.34 4.89 4.89 0.62 2.88 2.91 0.13 0.26 22.83 509
hod/sdre 77.68 9.85 104 56.84 40.84 67.79 67.69 27.90 27.50 27.45 0.03 0.06 69.37 52
rops/sdre 10.88 1.38 10.90 6.09 1.61 7.03 8.15 0.71 2.91 3.50 0.14 0.28 20.46 584
trisi/sdre 50.21 6.37 55.80 39.47 36.37 29.83 29.81 25.41 17.93 17.93 0.03 0.06 59.39 453
icp-point 150 19.05 275.76 177.24 147.90 194.21 116.25 85.52 90.65 79.85 -143 38.05 458.55 13
icp-plane 39.90 5.06 52.43 38.27 25.85 32.17 32.21 19.93 18.58 18.62 0.01 0.01 50.07 82
icp-x84 219 27.86 532.12 330.03 281.96 349.77 238.77 160 138.63 152.07 -146 41.38 653.59 35
s4pcs 22.72 2.88 34.53 20.89 14.95 20.87 23.09 9.07 10.72 10.35 81.95 172.80 125.48 1137
sicp-point 39.90 5.06 52.43 38.27 25.85 32.17 32.21 19.93 18.58 18.62 0.01 0.01 50.07 99
sicp-plane 39.90 5.06 52.43 38.27 25.85 32.17 32.21 19.93 18.58 18.62 0.01 0.01 50.07 112
    """,
}
_TABLE3_TEXT = """
real-fb hods/alphabeta 0.10 11.58 0.99 -77.59 1.79 298.93 1753 1481
real-curved hods/alphabeta 0.16 2.05 1.44 137.10 2.75 140.36 816 801
sim-eoi hods/alphabeta 0.70 37.88 2.91 -163.74 9.23 246.67 27954 26362
sim-helical hods/alphabeta 1.61 10.36 0.01 18.56 12.53 45.06 112 66
sim-voyager hods/sdre 14.20 28.52 0.14 119.44 40.78 177.50 57 27
sim-orion shot/kalman 5.32 49.83 0.01 91.69 24.25 176.40 858 714
sim-bennu hods/alphabeta 1.16 147.22 0.01 164.89 10.65 365.75 41 27
"""
_TABLE5_TEXT = """
real-fb hods/alphabeta 0.013 0.543 0.133 11.690 0.241 12.421 1753 1442
real-curved hods/alphabeta 0.013 0.351 0.116 11.215 0.222 11.800 816 677
sim-eoi hods/alphabeta 0.002 0.190 0.010 0.550 0.032 0.761 27954 9896
sim-helical hods/alphabeta 0.008 0.518 0.001 -0.553 0.061 1.776 112 3102
sim-voyager hods/sdre 0.018 0.067 0.001 0.226 0.052 0.300 57 3128
sim-orion shot/kalman 0.007 0.058 0.001 -0.175 0.031 0.347 858 3857
sim-bennu hods/alphabeta 0.001 0.071 0.001 -0.190 0.014 0.348 41 3409
"""
_TABLE6_TEXT = """
real-fb hods/alphabeta 0.013 0.554 0.133 14.447 0.241 15.260 1753 1382
real-curved hods/alphabeta 0.013 0.328 0.116 7.183 0.222 7.653 816 645
sim-eoi hods/alphabeta 0.002 0.185 0.010 0.510 0.032 0.705 27954 39249
sim-helical hods/alphabeta 0.008 0.319 0.001 0.613 0.061 0.958 112 3016
sim-voyager hods/sdre 0.018 0.061 0.001 -0.140 0.052 0.378 57 3245
sim-orion shot/kalman 0.007 0.103 0.001 -0.204 0.031 0.379 858 4221
sim-bennu hods/alphabeta 0.001 0.087 0.001 -0.213 0.014 0.345 41 3482
"""
_TABLE_B1_TEXT = """
real-fb icp-point 0.086 0.086 11.402 11.402 11.649 11.649 5 6
real-fb icp-plane 0.131 0.131 -23.090 -23.090 25.872 25.872 9 9
real-fb icp-x84 1.291 6.126 -22.321 -16.821 27.893 38.699 41 983
real-fb sicp-point 0.266 0.131 0.001 -23.090 0.462 25.872 145 191
real-fb sicp-plane 0.266 0.105 0.001 0.313 0.462 0.602 150 305
real-curved icp-point 0.136 0.227 8.447 12.427 8.723 12.745 6 6
real-curved icp-plane 0.146 0.177 -13.567 12.922 15.792 13.225 10 28
real-curved icp-x84 0.343 11.547 10.971 -9.621 11.341 31.967 53 1058
real-curved sicp-point 0.159 0.176 0.001 12.933 0.276 13.234 137 28
real-curved sicp-plane 0.159 0.025 0.001 1.196 0.276 1.343 145 250
sim-eoi icp-point 0.134 0.135 -0.565 -0.565 0.858 0.859 30 30
sim-eoi icp-plane 0.126 0.126 -0.576 -0.576 0.811 0.811 31 51
sim-eoi icp-x84 0.158 1.004 -0.570 -0.445 0.887 2.223 49 1059
sim-eoi sicp-point 0.039 0.126 0.001 -0.576 0.060 0.811 276 51
sim-eoi sicp-plane 0.039 0.088 0.001 0.434 0.060 0.610 327 14702
sim-helical icp-point 0.041 0.019 0.057 0.339 0.192 0.422 8 10
sim-helical icp-plane 1e12 0.048 0.578 0.297 3e11 0.461 17 127
sim-helical icp-x84 11.933 3.500 -0.788 -0.657 18.400 5.940 36 417
sim-helical sicp-point 0.190 0.055 0.001 0.285 0.243 0.411 107 84
sim-helical sicp-plane 0.196 0.008 0.001 0.001 0.248 0.064 105 123
sim-voyager icp-point 0.038 0.083 0.209 0.220 0.296 0.344 7 10
sim-voyager icp-plane 7e5 0.025 0.174 0.126 6e5 0.189 8 19
sim-voyager icp-x84 0.358 0.362 0.215 -0.164 0.710 0.749 16 284
sim-voyager sicp-point 0.037 0.017 0.001 0.053 0.059 0.102 171 14
sim-voyager sicp-plane 0.037 0.028 0.001 0.120 0.059 0.176 177 307
sim-orion icp-point 0.012 0.065 -0.165 0.064 0.333 0.185 13 14
sim-orion icp-plane 761.035 0.045 0.192 0.062 1014.713 0.158 12 14
sim-orion icp-x84 0.084 0.963 -0.207 -0.176 0.352 1.701 24 407
sim-orion sicp-point 0.042 0.069 0.001 -0.223 0.061 0.354 125 15
sim-orion sicp-plane 0.042 0.069 0.001 0.004 0.061 0.122 133 52
sim-bennu icp-point 0.371 0.055 -0.199 0.212 0.731 0.300 11 16
sim-bennu icp-plane 3e14 0.143 -0.189 0.184 5e14 0.373 36 84
sim-bennu icp-x84 0.265 0.652 -0.014 -0.223 0.604 1.127 35 419
sim-bennu sicp-point 0.049 0.011 0.001 -0.157 0.064 0.339 99 55
sim-bennu sicp-plane 0.049 0.034 0.001 0.107 0.064 0.172 112 300
"""
