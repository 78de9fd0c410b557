"""Side-by-side of a benchmark store with paper 1's tables (issue 9), as Markdown.

Per scenario: the best proposed combination (T_error %, e^RT, ms per frame), HoD-S/αβ and the
best competitor, ours beside the paper's; then paper 1's conclusions, each marked holds / does
not hold with the counts. Reads ``OUT/results.sqlite`` of ``relnav benchmark`` (any grid with the
proposed pipeline and the competitors; ``--suffix`` picks scenario twins such as
``sim-voyager-resample``).

Run: ``python benchmarks/paper1/paper1_side_by_side.py bench/paper1-fidelity-quick``
"""

from __future__ import annotations

import argparse
import sqlite3
from collections import defaultdict
from pathlib import Path

import numpy as np

from relnav.bench.paper1_reference import (
    PAPER_COMPETITORS,
    PAPER_DESCRIPTORS,
    PAPER_FILTERS,
    PART_NAMES,
    appendix_table,
)

NAMES = PART_NAMES
KEYS = ("T_error_pct", "e_RT", "time_ms")


def pretty(m: str) -> str:
    if m.startswith("feature:"):
        d, _, f = m[8:].split("+")
        return f"{NAMES.get(d, d)}/{NAMES.get(f, f)}"
    return m


def load(path: Path) -> dict[str, dict[str, dict[str, float]]]:
    con = sqlite3.connect(f"file:{path / 'results.sqlite'}?mode=ro", uri=True)
    out: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    q = "select scenario, method_label, T_error_pct, e_RT, time_ms from jobs where status='ok'"
    for sc, m, te, ert, ms in con.execute(q):
        out[sc][m].append((te, ert, ms))
    res: dict[str, dict[str, dict[str, float]]] = {}
    for sc, ms in out.items():
        res[sc] = {m: dict(zip(KEYS, np.mean(v, axis=0), strict=True)) for m, v in ms.items()}
    return res


def proposed(rows: dict) -> dict:
    return {m: r for m, r in rows.items() if m.startswith("feature:") and "+gcc+" in m
            and m.rsplit("+", 1)[1] in PAPER_FILTERS}  # fmt: skip


def competitors(rows: dict) -> dict:
    return {m: r for m, r in rows.items() if m in PAPER_COMPETITORS}


def best(rows: dict, key: str = "T_error_pct") -> tuple[str, dict] | None:
    return min(rows.items(), key=lambda kv: kv[1][key]) if rows else None


def filter_spread(
    ours_all: dict, scenarios: list[str], suffix: str = ""
) -> dict[str, dict[str, float]]:
    """Per scenario and descriptor: max ÷ min T_error over the paper's four filters."""
    out: dict[str, dict[str, float]] = {}
    for s in scenarios:
        rows = ours_all[s + suffix]
        ratios = {}
        for d in PAPER_DESCRIPTORS:
            v = [rows[f"feature:{d}+gcc+{f}"]["T_error_pct"] for f in PAPER_FILTERS
                 if f"feature:{d}+gcc+{f}" in rows]  # fmt: skip
            if len(v) == len(PAPER_FILTERS):
                ratios[d] = max(v) / max(min(v), 1e-12)
        out[s] = ratios
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", type=Path)
    ap.add_argument("--suffix", default="")
    a = ap.parse_args()
    ours_all = load(a.store)
    scen = [s for s in ("real-fb", "real-curved", "sim-eoi", "sim-helical", "sim-voyager",
                        "sim-orion", "sim-bennu") if s + a.suffix in ours_all]  # fmt: skip
    print("| scenario | best proposed: ours | paper | HoD-S/αβ: ours | paper "
          "| best competitor: ours | paper |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")

    def cell(mr: tuple[str, dict] | None) -> str:
        if mr is None:
            return "—"
        m, r = mr
        return f"{pretty(m)} {r['T_error_pct']:.2f} % / {r['e_RT']:.3g} / {r['time_ms']:.0f} ms"

    checks: dict[str, list[bool]] = defaultdict(list)
    for s in scen:
        ours, paper = ours_all[s + a.suffix], appendix_table(s)
        bp, bc = best(proposed(ours)), best(competitors(ours))
        hk = "feature:hods+gcc+alphabeta"
        h = cell((hk, ours[hk])) if hk in ours else "—"
        print(
            f"| {s} | {cell(bp)} | {cell(best(proposed(paper)))} | {h} "
            f"| {cell((hk, paper[hk]))} | {cell(bc)} | {cell(best(competitors(paper)))} |"
        )
        # conclusions
        prop = proposed(ours)
        by_desc = {}
        for d in PAPER_DESCRIPTORS:
            v = [r["T_error_pct"] for m, r in prop.items() if f":{d}+" in m]
            if v:
                by_desc[d] = float(np.median(v))
        if by_desc:
            checks["HoD-S the best descriptor (median T_error over filters)"].append(
                min(by_desc, key=by_desc.get) == "hods"
            )
        by_filt = {}
        for f in PAPER_FILTERS:
            v = [r["e_RT"] for m, r in prop.items() if m.endswith("+" + f)]
            if v:
                by_filt[f] = float(np.median(v))
        if by_filt:
            checks["Kalman the best filter (median e^RT over descriptors)"].append(
                min(by_filt, key=by_filt.get) == "kalman"
            )
        for d in PAPER_DESCRIPTORS:
            g, r = ours.get(f"feature:{d}+gcc+alphabeta"), ours.get(f"feature:{d}+ransac+alphabeta")
            if g and r:
                checks["GCC beats RANSAC (e^RT, αβ, per descriptor)"].append(g["e_RT"] < r["e_RT"])
            i = ours.get(f"feature:{d}+gcc+icp")
            if i:
                for f in PAPER_FILTERS:
                    fr = ours.get(f"feature:{d}+gcc+{f}")
                    if fr:
                        checks["filter beats ICP on the same correspondences (e^RT)"].append(
                            fr["e_RT"] < i["e_RT"]
                        )
        if s in ("sim-voyager", "sim-bennu") and bp and bc:
            checks["proposed beats the best competitor on Sim-Voyager and Sim-Bennu"].append(
                bp[1]["T_error_pct"] < bc[1]["T_error_pct"]
            )
    print()
    spread = filter_spread(ours_all, scen, a.suffix)
    print("Four filters' T_error within 2× of each other (max ÷ min over H∞, Kalman, αβ, SDRE, per")
    print(
        "descriptor; issue 9 asks ≥ 80 % of descriptors per scenario, the paper is within 1.6×):\n"
    )
    print("| scenario | descriptors within 2× | largest ratio |")
    print("|---|---|---|")
    for s, ratios in spread.items():
        if not ratios:
            continue
        n = sum(r <= 2.0 for r in ratios.values())
        worst = max(ratios, key=ratios.get)
        print(f"| {s} | {n} of {len(ratios)} | {NAMES[worst]} {ratios[worst]:.2f} |")
    print()
    for k, v in checks.items():
        n = sum(v)
        print(f"- {k}: {n} of {len(v)} — {'holds' if n > len(v) / 2 else 'does not hold'}")


if __name__ == "__main__":
    main()
