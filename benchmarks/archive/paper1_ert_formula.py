"""Which formula reproduces paper 1's e^RT from its own table columns? (issue 39, item 3)

Paper 1's eq. 31 defines ``e^RT = (1/N) Σ_k (trans(R*_GT ∘ R*_k)² + rot(R*_GT ∘ R*_k)²)``, a
per-step (relative) quantity, while Tables A1–A7 print only whole-run statistics (drift,
T_error, e^T max/avg, per-axis max/avg, e^R avg/max). This script searches, over all 210 rows of
Tables A1–A7 (``src/relnav/bench/paper1_tables.txt``):

1. every single column and every sum of two columns under ``x``, ``x²``, ``√x`` (no fitted
   constant), and every least-squares fit ``a·g(c1) + b·g(c2)`` (two fitted constants);
2. the bounds any reading based on the *absolute* pose errors must satisfy (Jensen): a mean of
   squares is at least ``e^T_avg² + e^R_avg²``, an RMS at least ``√(e^T_avg² + e^R_avg²)`` and at
   most ``√(e^T_max² + e^R_max²)``, a mean of sums between ``e^T_avg + e^R_avg`` and
   ``e^T_max + e^R_max`` (e^R in degrees, or radians);
3. per scenario, the best single-scale fit of a few candidates (a constant per scenario).

and prints how many rows each reproduces within 5 %. Run: ``python
benchmarks/archive/paper1_ert_formula.py`` (a second; no simulation).
"""

from __future__ import annotations

import itertools

import numpy as np

from relnav.bench.paper1_reference import APPENDIX_COLUMNS, PAPER_SCENARIOS, appendix_table

COLS = list(APPENDIX_COLUMNS[: APPENDIX_COLUMNS.index("e_RT")])  # what e^RT may come from
G = {"x": lambda v: v, "x²": lambda v: v**2, "√x": lambda v: np.sqrt(np.abs(v))}


def load() -> tuple[list[str], np.ndarray, dict[str, np.ndarray]]:
    """Scenario per row, the printed e^RT, and the candidate columns."""
    rows = [(s, r) for s in PAPER_SCENARIOS for r in appendix_table(s).values()]  # 7 × 30 rows
    y = np.array([r["e_RT"] for _, r in rows])
    X = {c: np.array([r[c] for _, r in rows]) for c in COLS}
    X["|e_R_avg|"] = np.abs(X.pop("e_R_avg"))
    X["|e_R_max|"] = np.abs(X.pop("e_R_max"))
    X["Σ axis avg"] = X["e_x_avg"] + X["e_y_avg"] + X["e_z_avg"]
    X["‖axis avg‖"] = np.sqrt(X["e_x_avg"] ** 2 + X["e_y_avg"] ** 2 + X["e_z_avg"] ** 2)
    X["‖axis max‖"] = np.sqrt(X["e_x_max"] ** 2 + X["e_y_max"] ** 2 + X["e_z_max"] ** 2)
    return [s for s, _ in rows], y, X


def score(f: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(share of rows within 5 %, median |log(f / y)|) over the rows where both are > 0."""
    ok = np.isfinite(f) & (f > 0) & (y > 0)
    lr = np.abs(np.log(f[ok] / y[ok]))
    return float(np.mean(lr < np.log(1.05))), float(np.median(lr))


def main() -> None:
    scen, y, X = load()
    names = list(X)
    cands: list[tuple[tuple[float, float], str]] = []
    for a in names:
        for ga, g in G.items():
            cands.append((score(g(X[a]), y), f"{ga}[{a}]"))
    for a, b in itertools.combinations(names, 2):
        for (ga, g), (gb, h) in itertools.product(G.items(), G.items()):
            cands.append((score(g(X[a]) + h(X[b]), y), f"{ga}[{a}] + {gb}[{b}]"))
            A = np.c_[g(X[a]), h(X[b])]
            coef = np.linalg.lstsq(A, y, rcond=None)[0]
            cands.append(
                (score(A @ coef, y), f"{coef[0]:.3g}·{ga}[{a}] + {coef[1]:.3g}·{gb}[{b}] (fitted)")
            )
    cands.sort(key=lambda t: (-t[0][0], t[0][1]))
    print(f"{len(y)} rows (Tables A1–A7). Best formulas of the printed columns:")
    print(f"{'within 5 %':>10} {'median ×':>9}  formula")
    for (share, med), name in cands[:8]:
        print(f"{100 * share:9.1f}% {np.exp(med):9.2f}  {name}")
    eTa, eTm = X["e_T_avg"], X["e_T_max"]
    print("\nBounds a reading on the absolute errors must satisfy (share of rows that do):")
    for unit, ra, rm in (
        ("deg", X["|e_R_avg|"], X["|e_R_max|"]),
        ("rad", np.radians(X["|e_R_avg|"]), np.radians(X["|e_R_max|"])),
    ):
        tol = 1.005  # the printed values' rounding
        ms = np.mean(y * tol >= eTa**2 + ra**2)
        lo, hi = np.sqrt(eTa**2 + ra**2), np.sqrt(eTm**2 + rm**2)
        rms = np.mean((y * tol >= lo) & (y <= hi * tol))
        sm = np.mean((y * tol >= eTa + ra) & (y <= (eTm + rm) * tol))
        print(
            f"  e^R in {unit}: mean of squares ≥ e^T_avg²+e^R_avg² on {100 * ms:.0f} %; "
            f"RMS within its bounds on {100 * rms:.0f} %; mean of sums within its bounds on "
            f"{100 * sm:.0f} %"
        )
    print("\nPer scenario, one fitted constant k (e^RT ≈ k·f): median deviation")
    s_arr = np.array(scen)
    for s in PAPER_SCENARIOS:
        i = s_arr == s
        out = []
        for name, f in (
            ("e^T_max+|e^R_avg|", eTm + X["|e_R_avg|"]),
            ("e^T_avg+|e^R_avg|", eTa + X["|e_R_avg|"]),
            ("√(e^T_max²+e^R_max²)", np.sqrt(eTm**2 + X["|e_R_max|"] ** 2)),
        ):
            k = float(np.median(y[i] / f[i]))
            out.append((float(np.median(np.abs(np.log(k * f[i] / y[i])))), name, k))
        med, name, k = min(out)
        print(f"  {s:12} best {name} with k={k:.2f}: median ×{np.exp(med):.2f}")


if __name__ == "__main__":
    main()
