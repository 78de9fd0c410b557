"""Against the paper: our best values beside Paper 1's, and its qualitative conclusions checked."""

from __future__ import annotations

import math
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
    _write_csv,
)
from relnav.bench.report.ablations import _all_pairs
from relnav.bench.report.aggregation import (
    _ICP_FAST,
    classify_method,
)


def _verdict(k: int, n: int) -> str:
    if n == 0:
        return "not testable (variants missing)"
    if k == n:
        return f"**holds** ({k}/{n})"
    if 2 * k >= n:
        return f"**mostly holds** ({k}/{n})"
    if k > 0:
        return f"**mostly does not hold** ({k}/{n})"
    return f"**does not hold** (0/{n})"


def _section_paper(
    ctx: _Ctx, summary: dict[str, dict[str, Any]], abl: dict[str, list[Any]]
) -> list[str]:
    rows, csv_rows = [], []
    preset_of = {s.label: s.preset for s in ctx.grid.scenarios if s.preset in ref.PAPER_SCENARIOS}
    frames_of = {s.label: s.max_frames or s.frames for s in ctx.grid.scenarios}
    for scn in ctx.scenarios:
        p = preset_of.get(scn)
        if p is None or scn not in summary:
            continue
        v = summary[scn]
        b = v["best"]
        c = v["best_competitor"]
        top = ref.TOP_MODULES[p][2]
        tab = ref.appendix_table(p)
        pt = tab[top]
        pb_m, pb = ref.best_row(p)
        pc_m, pc = ref.best_row(p, family="competitor")
        nf = [a.m("n_frames") for a in ctx.scen_aggs(scn) if a.n_ok]
        rows.append(
            [
                scn,
                f"{float(np.nanmedian(nf)):.0f} ({'part' if frames_of.get(scn) else 'full'})",
                b.info.display if b else "—",
                _f(b.m("T_error_pct")) if b else "—",
                _f(b.m("e_RT")) if b else "—",
                _f(b.m("time_ms")) if b else "—",
                classify_method(top, top).display,
                _f(pt["T_error_pct"]),
                _f(pt["e_RT"]),
                _f(pt["time_ms"]),
                f"{classify_method(pb_m, pb_m).display}: {_f(pb['e_RT'])}",
                f"{c.info.label}: {_f(c.m('e_RT'))}" if c else "—",
                f"{pc_m}: {_f(pc['e_RT'])}",
            ]
        )
        csv_rows.append(
            [
                scn,
                b.info.label if b else "",
                b.m("T_error_pct") if b else math.nan,
                b.m("e_RT") if b else math.nan,
                b.m("time_ms") if b else math.nan,
                top,
                pt["T_error_pct"],
                pt["e_RT"],
                pt["time_ms"],
                pb_m,
                pb["e_RT"],
                c.info.label if c else "",
                c.m("e_RT") if c else math.nan,
                pc_m,
                pc["e_RT"],
            ]
        )
    if not rows:
        return []
    md = [
        "## Against the paper",
        "",
        "Our best GCC combination (lowest mean e^RT) beside Paper 1's top combination (Table 4) "
        "and its lowest-e^RT rows (Appendix A). Caveats: when our runs use only the first part of "
        "a scenario (`part`), T_error % and e^T grow with the path while e^RT (a per-frame mean) "
        "stays comparable; our targets are procedural stand-ins for the paper's CAD models and "
        "mock-up; the paper's times are MATLAB/C++ on a 2019 desktop, ours are Python/numba on "
        "one core of this machine.",
        "",
        _md_table(
            [
                "scenario",
                "frames (ours)",
                "ours: best",
                "T_err %",
                "e^RT",
                "t ms",
                "paper: top (T4)",
                "T_err %",
                "e^RT",
                "t ms",
                "paper: lowest e^RT",
                "ours: best competitor (e^RT)",
                "paper: best competitor (e^RT)",
            ],
            rows,
        ),
        "",
    ]
    ctx.tables.append(
        _write_csv(
            ctx.out / "tables" / "against_paper.csv",
            [
                "scenario",
                "ours_best",
                "ours_T_error_pct",
                "ours_e_RT",
                "ours_time_ms",
                "paper_top",
                "paper_top_T_error_pct",
                "paper_top_e_RT",
                "paper_top_time_ms",
                "paper_lowest_eRT_method",
                "paper_lowest_e_RT",
                "ours_best_competitor",
                "ours_best_competitor_e_RT",
                "paper_best_competitor",
                "paper_best_competitor_e_RT",
            ],
            csv_rows,
        )
    )
    # qualitative claims
    scns = [s for s in ctx.scenarios if s in summary]
    claims: list[tuple[str, str, str]] = []
    k = sum(
        1
        for s in scns
        if summary[s]["tradeoff"] is not None
        and summary[s]["tradeoff"].info.label == "feature:hods+gcc+alphabeta"
    )
    picks = ", ".join(
        f"{s}: {summary[s]['tradeoff'].info.display}"
        for s in scns
        if summary[s]["tradeoff"] is not None
    )
    n = sum(1 for s in scns if summary[s]["tradeoff"] is not None)
    claims.append(
        (
            "hods_alphabeta_tradeoff",
            _verdict(k, n),
            f"best trade-off per scenario: {picks or '—'} (paper: HoD-S/αβ in 5 of 7)",
        )
    )
    for key, tab, what in (
        ("gcc_beats_ransac", "5", "RANSAC"),
        ("filter_beats_icp_corr", "3", "ICP on correspondences"),
        ("proposed_beats_clgv", "6", "CLGV"),
    ):
        pairs = _all_pairs(ctx, tab)
        kk = sum(1 for a, b in pairs if a.m("e_RT") < b.m("e_RT"))
        tops = abl.get(tab, [])
        kt = sum(1 for _, a, b in tops if a.m("e_RT") < b.m("e_RT"))
        claims.append(
            (
                key,
                _verdict(kk, len(pairs)),
                f"lower e^RT than {what} in {kk} of {len(pairs)} (scenario, combination) "
                f"pairs; for the top combination in {kt} of {len(tops)} scenarios",
            )
        )
    kc = nc = 0
    for s in scns:
        b = summary[s]["best"]
        c = _best(_competitors(ctx, s, baselines=False))
        if b is not None and c is not None:
            nc += 1
            kc += b.m("e_RT") < c.m("e_RT")
    kb = nb = 0
    for s in scns:
        b = summary[s]["best"]
        c = _best(ctx.find(s, lambda i: i.family == "baseline" and i.default))
        if b is not None and c is not None:
            nb += 1
            kb += b.m("e_RT") < c.m("e_RT")
    claims.append(
        (
            "proposed_beats_competitors",
            _verdict(kc, nc),
            f"best proposed e^RT below the best of Paper 1's competitors in {kc} of {nc} "
            f"scenarios; below the best [baselines] method in {kb} of {nb}",
        )
    )
    kf = nf_ = 0
    for s in scns:
        combos = _combos(ctx, s)
        t = {
            d: np.nanmean([a.m("time_ms") for (dd, _), a in combos.items() if dd == d])
            for d in {d for d, _ in combos}
        }
        t = {d: v for d, v in t.items() if math.isfinite(v)}
        if len(t) > 1 and "hods" in t:
            nf_ += 1
            kf += min(t, key=t.get) == "hods"
    claims.append(
        (
            "hods_fastest_descriptor",
            _verdict(kf, nf_),
            f"HoD-S has the lowest mean time per frame in {kf} of {nf_} scenarios",
        )
    )
    ki = ni = 0
    for s in scns:
        b = summary[s]["best"]
        icp = [
            a.m("time_ms")
            for a in _competitors(ctx, s, baselines=False)
            if a.info.method in _ICP_FAST
        ]
        if b is not None and icp:
            ni += 1
            ki += min(icp) < b.m("time_ms")
    claims.append(
        (
            "icp_faster",
            _verdict(ki, ni),
            f"the fastest ICP variant is faster than our best combination in {ki} of "
            f"{ni} scenarios",
        )
    )
    text = {c.key: (c.text, c.where) for c in ref.PAPER_CLAIMS}
    md += ["### Paper 1's conclusions, checked here", ""]
    md += [
        _md_table(
            ["claim (where)", "verdict", "evidence"],
            [[f"{text[k][0]} ({text[k][1]})", v, e] for k, v, e in claims],
        ),
        "",
    ]
    ctx.md += md
    return [f"{text[k][0]}: {v}" for k, v, _ in claims]
