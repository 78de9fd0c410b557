"""Paper 1's published results, transcribed from its Appendix A and Tables 3–6 and B1.

The numbers are data, ``paper1_tables.txt`` next to this module (parsed on first use);
this module reads them and adds the paper's top modules and claims. Used by
:mod:`relnav.bench.report` for the section "against the paper". Numbers are exactly as
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
from importlib import resources

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

TABLES_FILE = "paper1_tables.txt"
"""The transcribed tables (data file in this package)."""

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
    for scn in PAPER_SCENARIOS:
        text = _table_text(f"appendix {scn}")
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
    if str(table) not in ("3", "5", "6"):
        raise InputError(f"no ablation table {table!r}; choose 3, 5 or 6")
    return _ablation(_table_text(f"table {table}"))


def paper_icp_iterations() -> dict[tuple[str, str], AblationRow]:
    """Table B1: ``{(scenario, icp variant): AblationRow}`` (20 vs 1000 iterations, normalised).

    The paper prints 10¹², 3×10¹¹ … for diverged ICP-plane runs; they are kept as floats.
    """
    out = {}
    for p in _parse_rows(_table_text("table B1")):
        v = [float(x) for x in p[2:]]
        out[(p[0], p[1])] = AblationRow(
            p[0], p[1], (v[0], v[1]), (v[2], v[3]), (v[4], v[5]), (v[6], v[7])
        )
    return out


# ---------------------------------------------------------------------------------------------
# transcriptions: paper1_tables.txt (data, next to this module)
# ---------------------------------------------------------------------------------------------


@cache
def _sections() -> dict[str, str]:
    """``{section: rows}`` of ``paper1_tables.txt`` (``[appendix <scenario>]``, ``[table N]``)."""
    text = resources.files("relnav.bench").joinpath(TABLES_FILE).read_text(encoding="utf-8")
    out: dict[str, list[str]] = {}
    rows: list[str] = []
    for line in text.splitlines():
        s = line.split("#", 1)[0].strip()
        if s.startswith("[") and s.endswith("]"):
            rows = out.setdefault(s[1:-1].strip(), [])
        elif s:
            rows.append(s)
    return {k: "\n".join(v) for k, v in out.items()}


def _table_text(name: str) -> str:
    return _sections()[name]


PART_NAMES: dict[str, str] = {
    "hods": "HoD-S",
    "hod": "HoD",
    "shot": "SHOT",
    "fpfh": "FPFH",
    "rops": "RoPS",
    "trisi": "TriSI",
    "hinf": "H∞",
    "kalman": "Kalman",
    "alphabeta": "αβ",
    "sdre": "SDRE",
}
"""The paper's names of the descriptors and filters, by relnav's method-string parts."""
