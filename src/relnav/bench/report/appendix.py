"""Per-scenario Appendix-A tables, their trajectory/error figures, and ``all_results.csv``."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from relnav.bench.report._common import (
    _best,
    _combos,
    _competitors,
    _Ctx,
    _f,
    _load_traj,
    _md_table,
    _order,
    _paper_combos,
    _pm,
    _slug,
    _write_csv,
)
from relnav.bench.report.aggregation import (
    _BASELINES,
    _COMPETITORS,
    _DESC_ORDER,
    _EXTRA_KEYS,
    _FILTER_ORDER,
    _PAPER_FILTERS,
    APPENDIX_COLUMNS,
    DESCRIPTOR_NAMES,
    FILTER_NAMES,
    Aggregate,
)
from relnav.errors import InputError

log = logging.getLogger(__name__)


def _appendix_rows(ctx: _Ctx, scenario: str) -> list[tuple[str, list[Aggregate]]]:
    combos = _combos(ctx, scenario)
    blocks: list[tuple[str, list[Aggregate]]] = []
    descs = [d for d in _DESC_ORDER if any(k[0] == d for k in combos)]
    descs += sorted({k[0] for k in combos} - set(descs))
    for f in _FILTER_ORDER:
        rows = [combos[(d, f)] for d in descs if (d, f) in combos]
        if rows:
            blocks.append(
                (
                    f"adaptive {FILTER_NAMES[f]} recursive filtering"
                    if f in _PAPER_FILTERS
                    else f"{FILTER_NAMES[f]} estimator",
                    rows,
                )
            )
    comp = {a.info.method: a for a in _competitors(ctx, scenario)}
    order = [m for m in (*_COMPETITORS, *_BASELINES) if m in comp]
    order += sorted(set(comp) - set(order))
    if order:
        blocks.append(("competitor schemes", [comp[m] for m in order]))
    return blocks


def _section_appendix(ctx: _Ctx) -> None:
    ctx.md += ["## Per-scenario results (Appendix-A layout)", ""]
    header = ["method", *[h for _, h in APPENDIX_COLUMNS], "ok", "flagged"]
    for scn in ctx.scenarios:
        blocks = _appendix_rows(ctx, scn)
        if not blocks:
            continue
        L, npts = ctx.path_length(scn), ctx.mean_points(scn)
        ctx.md += [
            f"### {scn}",
            "",
            f"Path length {_f(L)} m, {_f(npts)} points per scan on average.",
            "",
        ]
        md_rows, csv_rows = [], []
        for title, aggs in blocks:
            md_rows.append([f"**{title}**"] + [""] * (len(header) - 1))
            best = {
                k: min((a.m(k) for a in aggs if math.isfinite(a.m(k))), default=math.nan)
                for k, _ in APPENDIX_COLUMNS
            }
            for a in aggs:
                cells = []
                for k, _ in APPENDIX_COLUMNS:
                    c = _pm(a, k)
                    if len(aggs) > 1 and math.isfinite(best[k]) and a.m(k) == best[k]:
                        c = f"**{c}**"
                    cells.append(c)
                name = (
                    DESCRIPTOR_NAMES.get(a.info.descriptor or "", "")
                    if a.info.family == "feature"
                    else a.info.label
                )
                md_rows.append([name, *cells, f"{a.n_ok}/{a.n_runs}", _f(a.m("n_flagged"))])
                csv_rows.append(
                    [title, a.info.label, a.n_ok, a.n_runs]
                    + [v for k, _ in APPENDIX_COLUMNS for v in (a.m(k), a.std[k])]
                    + [a.m("n_flagged"), a.m("mean_points"), a.m("path_length")]
                )
        ctx.md += [_md_table(header, md_rows), ""]
        ctx.tables.append(
            _write_csv(
                ctx.out / "tables" / f"appendix_{_slug(scn)}.csv",
                ["block", "method", "n_ok", "n_runs"]
                + [x for k, _ in APPENDIX_COLUMNS for x in (k, f"{k}_std")]
                + ["n_flagged", "mean_points", "path_length"],
                csv_rows,
            )
        )
        for fig in _scenario_figures(ctx, scn):
            ctx.md += [f"![{fig.stem}](figures/{fig.name})", ""]


_MAX_COMPETITOR_LINES = 5


def _nan_last(v: float) -> float:
    return v if v is not None and math.isfinite(v) else math.inf


def _scenario_figures(ctx: _Ctx, scn: str) -> list[Path]:
    from relnav.bench.report.plots import plot_axis_errors, plot_trajectory_panels
    from relnav.eval.metrics import pose_errors

    seed = ctx.grid.report.plot_seed
    seed = ctx.grid.seeds[0] if seed is None else seed
    combos = _paper_combos(ctx, scn) or _combos(ctx, scn)
    per_filter = {}
    for f in _FILTER_ORDER:
        b = _best([a for (d, ff), a in combos.items() if ff == f and seed in a.seeds])
        if b is not None:
            per_filter[b.info.display] = b
    comps = sorted(
        (a for a in _competitors(ctx, scn) if seed in a.seeds),
        key=lambda a: _order(a.info.method, (*_COMPETITORS, *_BASELINES)),
    )
    best_all = _best(per_filter.values())
    out: list[Path] = []
    gt = None
    traj_f, traj_c, errs = {}, {}, {}
    for name, a in per_filter.items():
        t = _load_traj(ctx, a, seed)
        if t is not None:
            traj_f[name], gt = t[0][:, :3, 3], t[1]
            pe = pose_errors(t[0], t[1])
            errs[name] = (pe.delta, pe.rot_deg)
    if best_all is not None:
        t = _load_traj(ctx, best_all, seed)
        if t is not None:
            traj_c[f"best proposed: {best_all.info.display}"] = t[0][:, :3, 3]
    # readable at a glance: the best few competitors by e^RT, not every one on top of another
    shown = sorted(comps, key=lambda a: _nan_last(a.m("e_RT")))[:_MAX_COMPETITOR_LINES]
    for a in comps:
        t = _load_traj(ctx, a, seed)
        if t is not None:
            gt = t[1] if gt is None else gt
            if a in shown:
                traj_c[a.info.label] = t[0][:, :3, 3]
    best_c = _best(comps)
    if best_c is not None:
        t = _load_traj(ctx, best_c, seed)
        if t is not None and t[1].shape == (gt.shape if gt is not None else t[1].shape):
            pe = pose_errors(t[0], t[1])
            errs[f"best competitor: {best_c.info.label}"] = (pe.delta, pe.rot_deg)
    if gt is None:
        return out
    groups = []
    if traj_f:
        groups.append(("best combination per filter", traj_f))
    if traj_c:
        n_more = len(comps) - len(shown)
        more = f" (best {len(shown)} of {len(comps)} by e^RT)" if n_more > 0 else ""
        groups.append((f"competitors{more}", traj_c))
    try:
        out.append(
            plot_trajectory_panels(
                ctx.out / "figures" / f"traj_{_slug(scn)}.png",
                gt[:, :3, 3],
                groups,
                title=f"{scn}: estimated vs ground-truth sensor positions "
                f"(target frame, seed {seed})",
            )
        )
        errs = {k: v for k, v in errs.items() if len(v[1]) == len(gt)}
        if errs:
            out.append(
                plot_axis_errors(
                    ctx.out / "figures" / f"errors_{_slug(scn)}.png",
                    np.arange(len(gt)),
                    errs,
                    title=f"{scn}: per-axis error (GT − estimate) and rotation error, seed {seed}",
                )
            )
    except InputError as e:
        log.warning("figures for %s skipped: %s", scn, e)
    ctx.figures += out
    return out


def _write_all_results(ctx: _Ctx) -> None:
    keys = [k for k, _ in APPENDIX_COLUMNS] + list(_EXTRA_KEYS)
    rows = []
    for (scn, nz, lab), a in sorted(ctx.aggs.items()):
        rows.append(
            [
                scn,
                nz,
                lab,
                a.info.family,
                a.info.descriptor or "",
                a.info.grouper or "",
                a.info.estimator or "",
                a.n_ok,
                a.n_runs,
            ]
            + [v for k in keys for v in (a.m(k), a.std.get(k, math.nan))]
        )
    ctx.tables.append(
        _write_csv(
            ctx.out / "tables" / "all_results.csv",
            [
                "scenario",
                "nuisance",
                "method",
                "family",
                "descriptor",
                "grouper",
                "estimator",
                "n_ok",
                "n_runs",
            ]
            + [x for k in keys for x in (k, f"{k}_std")],
            rows,
        )
    )
