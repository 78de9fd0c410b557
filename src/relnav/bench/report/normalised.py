"""Cross-scenario comparison (Paper 1 §4): normalised e^RT per descriptor and per filter, the
Table-4-style top module per scenario, Figs. 14–16."""

from __future__ import annotations

import logging
import math
from collections import defaultdict
from typing import Any

import numpy as np

from relnav.bench import paper1_reference as ref
from relnav.bench.report._common import (
    _best,
    _combos,
    _competitors,
    _Ctx,
    _f,
    _md_table,
    _order,
    _paper_combos,
    _tradeoff,
    _write_csv,
)
from relnav.bench.report.aggregation import (
    _DESC_ORDER,
    _FILTER_ORDER,
    DESCRIPTOR_NAMES,
    FILTER_NAMES,
)
from relnav.errors import InputError

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# normalised e^RT (Paper 1 §4)
# --------------------------------------------------------------------------------------------


def normalised_ert(
    ert: dict[tuple[str, str], float],
    path_length: float,
    *,
    constant: float = 1000.0,
    discard_worst: bool = True,
) -> tuple[dict[str, float], dict[str, float], str | None]:
    """Paper 1 §4 normalised ``e^RT`` of one scenario, per descriptor and per filter.

    Parameters
    ----------
    ert : dict (descriptor, filter) → e^RT
        Mean e^RT of each combination (m² + deg²).
    path_length : float
        Ground-truth path length, m.
    constant : float
        Multiplier for log plots.
    discard_worst : bool
        Drop the descriptor with the largest mean e^RT first.

    Returns
    -------
    per_descriptor : dict
        Descriptor → mean over filters of ``e^RT(d, f) / max_d' e^RT(d', f) / L · C``.
    per_filter : dict
        Filter → mean over descriptors of ``e^RT(d, f) / max_f' e^RT(d, f') / L · C``.
    discarded : str or None
        The dropped descriptor.
    """
    vals = {k: v for k, v in ert.items() if math.isfinite(v)}
    if not vals or not (path_length > 0):
        return {}, {}, None
    descs = sorted({d for d, _ in vals})
    filters = sorted({f for _, f in vals})
    discarded = None
    if discard_worst and len(descs) > 2:
        worst = max(descs, key=lambda d: np.mean([v for (dd, _), v in vals.items() if dd == d]))
        discarded = worst
        vals = {k: v for k, v in vals.items() if k[0] != worst}
        descs = [d for d in descs if d != worst]
    scale = constant / path_length
    per_d: dict[str, float] = {}
    for d in descs:
        xs = []
        for f in filters:
            col = [v for (dd, ff), v in vals.items() if ff == f]
            if (d, f) in vals and max(col) > 0:
                xs.append(vals[(d, f)] / max(col) * scale)
        if xs:
            per_d[d] = float(np.mean(xs))
    per_f: dict[str, float] = {}
    for f in filters:
        xs = []
        for d in descs:
            row = [v for (dd, ff), v in vals.items() if dd == d]
            if (d, f) in vals and max(row) > 0:
                xs.append(vals[(d, f)] / max(row) * scale)
        if xs:
            per_f[f] = float(np.mean(xs))
    return per_d, per_f, discarded


def _section_normalised(ctx: _Ctx) -> dict[str, dict[str, Any]]:
    opts = ctx.grid.report
    summary: dict[str, dict[str, Any]] = {}
    d_rows, f_rows, pts14 = [], [], []
    fig16: dict[str, dict[str, float]] = {}
    for scn in ctx.scenarios:
        combos = _paper_combos(ctx, scn) or _combos(ctx, scn)
        if not combos:
            continue
        ert = {k: a.m("e_RT") for k, a in combos.items()}
        per_d, per_f, dropped = normalised_ert(
            ert,
            ctx.path_length(scn),
            constant=opts.normalisation_constant,
            discard_worst=opts.discard_worst_descriptor,
        )
        best = _best(combos.values())
        trade = _tradeoff(combos, opts.tradeoff_tolerance)
        comp = _best(_competitors(ctx, scn))
        summary[scn] = {
            "per_descriptor": per_d,
            "per_filter": per_f,
            "discarded": dropped,
            "top_descriptor": min(per_d, key=per_d.get) if per_d else None,
            "top_filter": min(per_f, key=per_f.get) if per_f else None,
            "best": best,
            "tradeoff": trade,
            "best_competitor": comp,
        }
        for d in sorted(per_d, key=lambda d: _order(d, _DESC_ORDER)):
            v = per_d[d]
            t = np.nanmean([a.m("time_ms") for (dd, _), a in combos.items() if dd == d])
            pts14.append((scn, DESCRIPTOR_NAMES.get(d, d), float(t), v))
            d_rows.append([scn, d, v, float(t)])
        ordered_f = sorted(per_f, key=lambda f: _order(f, _FILTER_ORDER))
        for f in ordered_f:
            f_rows.append([scn, f, per_f[f]])
        fig16[scn] = {FILTER_NAMES.get(f, f): per_f[f] for f in ordered_f}
    if not summary:
        return summary
    C = opts.normalisation_constant
    descs = [d for d in _DESC_ORDER if any(d in s["per_descriptor"] for s in summary.values())]
    filts = [f for f in _FILTER_ORDER if any(f in s["per_filter"] for s in summary.values())]
    ctx.md += [
        "## Cross-scenario comparison (Paper 1 §4)",
        "",
        f"Normalised e^RT × {C:g} (per metre of path; lower is better). Per scenario the least "
        "accurate descriptor is "
        + ("dropped (shown as —)" if opts.discard_worst_descriptor else "kept")
        + "; descriptor scores are averaged over filters, filter scores over descriptors.",
        "",
        "### Per descriptor (Fig. 14 data)",
        "",
        _md_table(
            ["scenario", *[DESCRIPTOR_NAMES.get(d, d) for d in descs]],
            [
                [s] + [_f(v["per_descriptor"].get(d, math.nan)) for d in descs]
                for s, v in summary.items()
            ],
        ),
        "",
        "### Per filter (Fig. 16 data)",
        "",
        _md_table(
            ["scenario", *[FILTER_NAMES.get(f, f) for f in filts]],
            [
                [s] + [_f(v["per_filter"].get(f, math.nan)) for f in filts]
                for s, v in summary.items()
            ],
        ),
        "",
    ]
    ctx.tables.append(
        _write_csv(
            ctx.out / "tables" / "normalised_eRT_descriptor.csv",
            ["scenario", "descriptor", "normalised_eRT", "time_ms"],
            d_rows,
        )
    )
    ctx.tables.append(
        _write_csv(
            ctx.out / "tables" / "normalised_eRT_filter.csv",
            ["scenario", "filter", "normalised_eRT"],
            f_rows,
        )
    )
    # Table 4
    t4 = []
    for s, v in summary.items():
        b, t, c = v["best"], v["tradeoff"], v["best_competitor"]
        t4.append(
            [
                s,
                DESCRIPTOR_NAMES.get(v["top_descriptor"] or "", "—"),
                FILTER_NAMES.get(v["top_filter"] or "", "—"),
                f"{b.info.display} ({_f(b.m('e_RT'))}, {_f(b.m('time_ms'))} ms)" if b else "—",
                f"{t.info.display} ({_f(t.m('e_RT'))}, {_f(t.m('time_ms'))} ms)" if t else "—",
                f"{c.info.label} ({_f(c.m('e_RT'))}, {_f(c.m('time_ms'))} ms)" if c else "—",
                ref.TOP_MODULES[s][3] if s in ref.TOP_MODULES else f"{_f(ctx.mean_points(s))} pts",
            ]
        )
    ctx.md += [
        "### Top module per scenario (Table 4 layout)",
        "",
        f"Top combination = lowest mean e^RT; best trade-off = the fastest combination within "
        f"{100 * opts.tradeoff_tolerance:g} % of that e^RT. In brackets: e^RT and time per frame.",
        "",
        _md_table(
            [
                "scenario",
                "top descriptor",
                "top filter",
                "top combination",
                "best trade-off",
                "best competitor",
                "scenario features",
            ],
            t4,
        ),
        "",
    ]
    ctx.tables.append(
        _write_csv(
            ctx.out / "tables" / "top_modules.csv",
            [
                "scenario",
                "top_descriptor",
                "top_filter",
                "top_combination",
                "best_tradeoff",
                "best_competitor",
            ],
            [
                [
                    s,
                    v["top_descriptor"],
                    v["top_filter"],
                    v["best"].info.label if v["best"] else "",
                    v["tradeoff"].info.label if v["tradeoff"] else "",
                    v["best_competitor"].info.label if v["best_competitor"] else "",
                ]
                for s, v in summary.items()
            ],
        )
    )
    from relnav.bench.report.plots import (
        plot_filter_scores,
        plot_normalised_ert_vs_time,
        plot_time_vs_points,
    )

    figs = []
    try:
        figs.append(
            plot_normalised_ert_vs_time(
                ctx.out / "figures" / "normalised_eRT_vs_time.png", pts14, constant=C
            )
        )
    except InputError as e:
        log.warning("Fig. 14 skipped: %s", e)
    series: dict[str, list[tuple[float, float, str]]] = defaultdict(list)
    for scn in ctx.scenarios:
        combos = _combos(ctx, scn)
        npts = ctx.mean_points(scn)
        for d in _DESC_ORDER:
            ts = [a.m("time_ms") for (dd, _), a in combos.items() if dd == d]
            if ts:
                series[DESCRIPTOR_NAMES[d]].append((npts, float(np.nanmean(ts)), scn))
        for a in _competitors(ctx, scn, baselines=False):
            series[a.info.label].append((npts, a.m("time_ms"), scn))
    try:
        figs.append(
            plot_time_vs_points(
                ctx.out / "figures" / "time_vs_points.png",
                series,
                title="Mean time per frame vs points per scan (descriptors: mean over filters)",
            )
        )
    except InputError as e:
        log.warning("Fig. 15 skipped: %s", e)
    if any(fig16.values()):
        try:
            figs.append(
                plot_filter_scores(
                    ctx.out / "figures" / "normalised_eRT_per_filter.png",
                    fig16,
                    ylabel=f"normalised e^RT × {C:g} [1/m]",
                )
            )
        except InputError as e:
            log.warning("Fig. 16 skipped: %s", e)
    ctx.figures += figs
    ctx.md += [f"![{p.stem}](figures/{p.name})\n" for p in figs]
    return summary


def _section_normalised_placeholder(ctx: _Ctx) -> dict[str, Any]:
    """Compute the §4 section first (the appendix figures need nothing from it) and keep its
    markdown aside so that it follows the per-scenario tables in the report."""
    md_before = list(ctx.md)
    ctx.md = []
    summary: dict[str, Any] = _section_normalised(ctx)
    summary["__md__"] = ctx.md
    ctx.md = md_before
    return summary
