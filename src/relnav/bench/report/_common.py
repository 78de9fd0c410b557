"""What every report section shares: cell formatting, markdown/CSV tables, the report context
and the selectors of its method blocks (GCC combinations, competitors, variants)."""

from __future__ import annotations

import csv
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.benchmark import (
    GridSpec,
)
from relnav.bench.report.aggregation import (
    _FILTER_ORDER,
    _PAPER_FILTERS,
    Aggregate,
)

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# formatting helpers
# --------------------------------------------------------------------------------------------


def _f(x: float) -> str:
    if not math.isfinite(x):
        return "—"
    ax = abs(x)
    if ax >= 1e5:
        return f"{x:.2e}"
    if ax >= 100:
        return f"{x:.0f}"
    if ax >= 10:
        return f"{x:.1f}"
    if ax >= 0.01 or ax == 0:
        return f"{x:.2f}"
    return f"{x:.1e}"


def _pm(a: Aggregate, key: str) -> str:
    m, s = a.m(key), a.std.get(key, float("nan"))
    return _f(m) if not math.isfinite(s) else f"{_f(m)} ± {_f(s)}"


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def _write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow(["" if isinstance(v, float) and not math.isfinite(v) else v for v in r])
    return path


def _order(x: str, order: Sequence[str]) -> tuple[int, str]:
    return (order.index(x) if x in order else len(order), x)


def _slug(s: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in s)


# --------------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------------


@dataclass
class _Ctx:
    out: Path
    grid: GridSpec
    aggs: dict[tuple[str, str, str], Aggregate]
    scenarios: list[str]
    clean: str = "clean"
    md: list[str] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)

    def scen_aggs(self, scenario: str, nuisance: str | None = None) -> list[Aggregate]:
        nz = self.clean if nuisance is None else nuisance
        return [a for (s, n, _), a in self.aggs.items() if s == scenario and n == nz]

    def find(self, scenario: str, pred: Any) -> list[Aggregate]:
        return [a for a in self.scen_aggs(scenario) if a.n_ok and pred(a.info)]

    def path_length(self, scenario: str) -> float:
        v = [a.m("path_length") for a in self.scen_aggs(scenario) if a.n_ok]
        v = [x for x in v if math.isfinite(x)]
        return float(np.median(v)) if v else float("nan")

    def mean_points(self, scenario: str) -> float:
        v = [a.m("mean_points") for a in self.scen_aggs(scenario) if a.n_ok]
        v = [x for x in v if math.isfinite(x)]
        return float(np.median(v)) if v else float("nan")


def _combos(ctx: _Ctx, scenario: str, grouper: str = "gcc") -> dict[tuple[str, str], Aggregate]:
    out = {}
    for a in ctx.find(
        scenario,
        lambda i: (
            i.family == "feature"
            and i.grouper == grouper
            and i.default
            and i.estimator in _FILTER_ORDER
        ),
    ):
        out[(a.info.descriptor, a.info.estimator)] = a
    return out


def _paper_combos(ctx: _Ctx, scenario: str) -> dict[tuple[str, str], Aggregate]:
    return {k: v for k, v in _combos(ctx, scenario).items() if k[1] in _PAPER_FILTERS}


def _competitors(ctx: _Ctx, scenario: str, *, baselines: bool = True) -> list[Aggregate]:
    fams = ("competitor", "baseline") if baselines else ("competitor",)
    return ctx.find(scenario, lambda i: i.family in fams and i.default)


def _best(aggs: Iterable[Aggregate], key: str = "e_RT") -> Aggregate | None:
    c = [a for a in aggs if math.isfinite(a.m(key))]
    return min(c, key=lambda a: (a.m(key), a.info.label)) if c else None


def _tradeoff(combos: dict[tuple[str, str], Aggregate], tol: float) -> Aggregate | None:
    best = _best(combos.values())
    if best is None:
        return None
    lim = best.m("e_RT") * (1.0 + tol)
    ok = [a for a in combos.values() if a.m("e_RT") <= lim and math.isfinite(a.m("time_ms"))]
    return min(ok, key=lambda a: (a.m("time_ms"), a.info.label)) if ok else best


def _load_traj(ctx: _Ctx, a: Aggregate, seed: int) -> tuple[np.ndarray, np.ndarray] | None:
    from relnav.eval.metrics import match_trajectories
    from relnav.io.trajectories import read_tum

    row = next((r for r in a.rows if int(r["seed"]) == seed), None)
    if row is None or not row.get("estimate_path") or not row.get("sequence_path"):
        return None
    est = ctx.out / row["estimate_path"]
    seq = Path(row["sequence_path"])
    seq = seq if seq.is_absolute() else ctx.out / seq
    gt = seq / "gt_T_target_sensor.tum"
    if not est.is_file() or not gt.is_file():
        log.warning("missing files for %s seed %d (%s, %s)", a.info.label, seed, est, gt)
        return None
    te, pe = read_tum(est)
    tg, pg = read_tum(gt)
    m = match_trajectories(te, pe, tg, pg)
    return m.est_poses, m.gt_poses


def _variant(ctx: _Ctx, scn: str, pred: Any) -> Aggregate | None:
    c = ctx.find(scn, pred)
    return c[0] if c else None
