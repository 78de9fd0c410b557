"""Ablations in the layout of Paper 1's Tables 3, 5, 6 and B1."""

from __future__ import annotations

import math
from typing import Any

from relnav.bench.report._common import (
    _combos,
    _Ctx,
    _f,
    _md_table,
    _paper_combos,
    _variant,
    _write_csv,
)
from relnav.bench.report.aggregation import (
    _COMPETITORS,
    Aggregate,
)


def _variant_of(ctx: _Ctx, tab: str, scn: str, d: str, f: str) -> Aggregate | None:
    """The ablation variant of combination (descriptor ``d``, filter ``f``) for Table ``tab``:
    "3" the same GCC correspondences with ICP, "5" RANSAC instead of GCC, "6" CLGV."""
    if tab == "6":
        return _variant(ctx, scn, lambda i: i.family == "clgv" and i.default and i.descriptor == d)
    grouper, estimator = ("gcc", "icp") if tab == "3" else ("ransac", f)
    return _variant(
        ctx,
        scn,
        lambda i: (
            i.family == "feature"
            and i.default
            and i.descriptor == d
            and i.grouper == grouper
            and i.estimator == estimator
        ),
    )


def _ablation_pair(ctx: _Ctx, scn: str, other: Any) -> tuple[Aggregate, Aggregate] | None:
    """Our top combination among those whose variant ``other(d, f)`` is in the grid."""
    combos = _paper_combos(ctx, scn) or _combos(ctx, scn)
    pairs = []
    for (d, f), a in combos.items():
        b = other(scn, d, f)
        if b is not None and b.n_ok:
            pairs.append((a, b))
    if not pairs:
        return None
    return min(pairs, key=lambda p: (p[0].m("e_RT"), p[0].info.label))


def _section_ablations(ctx: _Ctx) -> dict[str, list[tuple[str, Aggregate, Aggregate]]]:
    specs = {
        "3": (
            "Table 3 layout: with vs without the recursive filter (ICP point-to-point on the "
            "same GCC correspondences)",
            "with filter",
            "without (ICP)",
            False,
            lambda s, d, f: _variant_of(ctx, "3", s, d, f),
        ),
        "5": (
            "Table 5 layout: GCC vs RANSAC grouping (normalised by the path length)",
            "GCC",
            "RANSAC",
            True,
            lambda s, d, f: _variant_of(ctx, "5", s, d, f),
        ),
        "6": (
            "Table 6 layout: proposed vs CLGV (normalised by the path length)",
            "proposed",
            "CLGV",
            True,
            lambda s, d, f: _variant_of(ctx, "6", s, d, f),
        ),
    }
    results: dict[str, list[tuple[str, Aggregate, Aggregate]]] = {}
    ctx.md += ["## Ablations", ""]
    any_table = False
    for tab, (title, la, lb, norm, other) in specs.items():
        rows, csv_rows, res = [], [], []
        for scn in ctx.scenarios:
            p = _ablation_pair(ctx, scn, other)
            if p is None:
                continue
            a, b = p
            res.append((scn, a, b))
            L = ctx.path_length(scn) if norm else 1.0
            vals = []
            for k in ("e_T_avg", "e_R_avg", "e_RT"):
                vals += [a.m(k) / L, b.m(k) / L]
            vals += [a.m("time_ms"), b.m("time_ms")]
            rows.append([scn, a.info.display, b.info.display] + [_f(v) for v in vals])
            csv_rows.append([scn, a.info.label, b.info.label, *vals])
        results[tab] = res
        if not rows:
            continue
        any_table = True
        pre = "normalised " if norm else ""
        head = ["scenario", "top combination", "variant"] + [
            f"{'' if k == 't ms' else pre}{k} ({x})"
            for k in ("e^T_avg", "e^R_avg", "e^RT", "t ms")
            for x in (la, lb)
        ]
        ctx.md += [f"### {title}", "", _md_table(head, rows), ""]
        ctx.tables.append(
            _write_csv(
                ctx.out / "tables" / f"ablation_table{tab}.csv",
                ["scenario", "method", "variant"]
                + [
                    f"{k}_{x}"
                    for k in ("e_T_avg", "e_R_avg", "e_RT", "time_ms")
                    for x in ("a", "b")
                ],
                csv_rows,
            )
        )
    # Table B1
    rows, csv_rows = [], []
    for scn in ctx.scenarios:
        L = ctx.path_length(scn)
        for m in _COMPETITORS:
            if m == "s4pcs":
                continue
            var = {
                a.info.iterations: a
                for a in ctx.find(scn, lambda i, m=m: i.method == m and i.family == "competitor")
            }
            if 20 in var and 1000 in var:
                a, b = var[20], var[1000]
                vals = [
                    a.m("e_T_avg") / L,
                    b.m("e_T_avg") / L,
                    a.m("e_R_avg") / L,
                    b.m("e_R_avg") / L,
                    a.m("e_RT") / L,
                    b.m("e_RT") / L,
                    a.m("time_ms"),
                    b.m("time_ms"),
                ]
                rows.append([scn, m] + [_f(v) for v in vals])
                csv_rows.append([scn, m, *vals])
    if rows:
        any_table = True
        head = ["scenario", "ICP variant"] + [
            f"{k} ({x})"
            for k in ("norm. e^T_avg", "norm. e^R_avg", "norm. e^RT", "t ms")
            for x in ("20 it.", "1000 it.")
        ]
        ctx.md += [
            "### Table B1 layout: ICP variants at 20 vs 1000 iterations",
            "",
            _md_table(head, rows),
            "",
        ]
        ctx.tables.append(
            _write_csv(
                ctx.out / "tables" / "ablation_tableB1.csv",
                [
                    "scenario",
                    "variant",
                    "e_T_avg_20",
                    "e_T_avg_1000",
                    "e_R_avg_20",
                    "e_R_avg_1000",
                    "e_RT_20",
                    "e_RT_1000",
                    "time_ms_20",
                    "time_ms_1000",
                ],
                csv_rows,
            )
        )
    if not any_table:
        ctx.md += [
            "The grid has none of the ablation variants (`+icp`, `+ransac+`, `clgv:`, "
            "ICP with `max_iter: 1000`).",
            "",
        ]
    else:
        ctx.md += [
            "The top combination of each ablation is our best (lowest e^RT) GCC "
            "combination among those whose variant is in the grid (the paper used its "
            "Table 4 top combination).",
            "",
        ]
    return results


def _all_pairs(ctx: _Ctx, tab: str) -> list[tuple[Aggregate, Aggregate]]:
    out = []
    for scn in ctx.scenarios:
        combos = _paper_combos(ctx, scn) or _combos(ctx, scn)
        for (d, f), a in combos.items():
            b = _variant_of(ctx, tab, scn, d, f)
            if b is not None and math.isfinite(b.m("e_RT")):
                out.append((a, b))
    return out
