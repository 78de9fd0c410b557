"""Robustness (nuisance sweeps) and the failed jobs."""

from __future__ import annotations

import logging
import math
from collections import defaultdict

from relnav.bench.report._common import (
    _Ctx,
    _f,
    _md_table,
    _slug,
    _write_csv,
)
from relnav.errors import InputError

log = logging.getLogger(__name__)


_SWEEP_UNITS = {
    "range_sigma_m": "range noise σ [m]",
    "outlier_fraction": "outliers [fraction of points]",
    "keep_fraction": "points kept [fraction]",
    "occlusion_fraction": "occluded [fraction of points]",
    "occlusion_half_angle_deg": "occlusion cone half-angle [deg]",
}
_NEUTRAL = {
    "range_sigma_m": 0.0,
    "outlier_fraction": 0.0,
    "keep_fraction": 1.0,
    "occlusion_fraction": 0.0,
    "occlusion_half_angle_deg": 0.0,
}


def _section_robustness(ctx: _Ctx) -> None:
    from relnav.bench.report.plots import plot_nuisance_curves

    if not ctx.grid.sweeps:
        return
    ctx.md += [
        "## Robustness (nuisance sweeps)",
        "",
        "Each sweep varies one nuisance applied to the simulated scans (seeded, see "
        "`relnav.sim.nuisance`); the clean runs are the neutral point. Mean ± std over "
        "seeds.",
        "",
    ]
    for sw in ctx.grid.sweeps:
        curves: dict[str, dict[str, list[tuple[float, float, float]]]] = {}
        tcurves: dict[str, dict[str, list[tuple[float, float, float]]]] = {}
        csv_rows = []
        levels = [(v, lv) for v, lv in zip(sw.values, sw.levels(), strict=True)]
        if not any(lv.is_identity for _, lv in levels):
            levels.insert(0, (_NEUTRAL[sw.parameter], ctx.grid.nuisance_levels()[0]))
        for scn in ctx.scenarios:
            curves[scn], tcurves[scn] = defaultdict(list), defaultdict(list)
            for v, lv in levels:
                for a in ctx.scen_aggs(scn, lv.label):
                    if not a.n_ok:
                        continue
                    x = _NEUTRAL[sw.parameter] if lv.is_identity else float(v)
                    curves[scn][a.info.label].append((x, a.m("e_RT"), a.std["e_RT"]))
                    tcurves[scn][a.info.label].append((x, a.m("T_error_pct"), a.std["T_error_pct"]))
                    csv_rows.append(
                        [
                            scn,
                            a.info.label,
                            x,
                            a.n_ok,
                            a.m("e_RT"),
                            a.std["e_RT"],
                            a.m("T_error_pct"),
                            a.std["T_error_pct"],
                            a.m("e_T_avg"),
                            a.m("e_R_avg"),
                            a.m("time_ms"),
                        ]
                    )
        ctx.tables.append(
            _write_csv(
                ctx.out / "tables" / f"robustness_{_slug(sw.label)}.csv",
                [
                    "scenario",
                    "method",
                    sw.parameter,
                    "n_ok",
                    "e_RT",
                    "e_RT_std",
                    "T_error_pct",
                    "T_error_pct_std",
                    "e_T_avg",
                    "e_R_avg",
                    "time_ms",
                ],
                csv_rows,
            )
        )
        ctx.md += [f"### {sw.label}", ""]
        for what, cv, ylab in (
            ("eRT", curves, "e^RT [m² + deg²]"),
            ("Terror", tcurves, "T_error [%]"),
        ):
            try:
                p = plot_nuisance_curves(
                    ctx.out / "figures" / f"robustness_{_slug(sw.label)}_{what}.png",
                    {s: dict(c) for s, c in cv.items()},
                    xlabel=_SWEEP_UNITS[sw.parameter],
                    ylabel=ylab,
                    title=f"{ylab.split(' [')[0]} vs {_SWEEP_UNITS[sw.parameter]}",
                )
                ctx.figures.append(p)
                ctx.md += [f"![{p.stem}](figures/{p.name})", ""]
            except InputError as e:
                log.warning("robustness figure %s skipped: %s", sw.label, e)
        # compact table: e^RT per level
        meths = sorted({m for c in curves.values() for m in c})
        xs = sorted({x for c in curves.values() for pts in c.values() for x, _, _ in pts})
        trows = []
        for scn in ctx.scenarios:
            for m in meths:
                d = {x: y for x, y, _ in curves[scn].get(m, [])}
                if d:
                    trows.append([scn, m] + [_f(d.get(x, math.nan)) for x in xs])
        if trows:
            ctx.md += [_md_table(["scenario", "method"] + [f"e^RT @ {x:g}" for x in xs], trows), ""]


def _section_failures(ctx: _Ctx) -> None:
    failed = [a for a in ctx.aggs.values() if a.errors]
    if not failed:
        return
    by_method: dict[str, list[str]] = defaultdict(list)
    for a in failed:
        for e in a.errors:
            by_method[a.info.label].append(f"{a.scenario}/{a.nuisance}: {e}")
    rows = []
    for m, errs in sorted(by_method.items()):
        first = errs[0].replace("|", "\\|").replace("\n", " ")
        rows.append([m, str(len(errs)), first[:160]])
    ctx.md += [
        "## Failed jobs",
        "",
        "Jobs recorded as failed (or without ground truth); the rest of the grid ran on.",
        "",
        _md_table(["method", "jobs", "first error"], rows),
        "",
    ]
