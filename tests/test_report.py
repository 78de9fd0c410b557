"""Benchmark report: normalisation, classification, aggregation, the written report, paper data."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from relnav.bench import paper1_reference as ref
from relnav.bench.benchmark import load_grid, run_benchmark
from relnav.bench.report import aggregate, classify_method, normalised_ert, write_report
from relnav.bench.store import ResultsStore
from relnav.errors import InputError

GRID = {
    "name": "report-test",
    "scenarios": [{"preset": "sim-bennu", "max_frames": 3}],
    "methods": [
        "feature:{hods,fpfh}+gcc+{alphabeta,kalman}",
        "feature:hods+gcc+icp",
        "feature:{hods,fpfh}+ransac+alphabeta",
        "clgv:hods",
        "icp-point",
        {"method": "icp-point", "label": "icp-point@1000", "options": {"max_iter": 1000}},
        {"method": "icp-point", "label": "broken", "options": {"bogus": True}},
    ],
    "seeds": [0, 1],
    "warmup_frames": 0,
}


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report") / "b"
    run_benchmark(load_grid(GRID), out, workers=0)
    write_report(out)
    return out


def test_normalised_ert_known_answer():
    ert = {
        ("a", "f1"): 1.0,
        ("b", "f1"): 2.0,
        ("c", "f1"): 100.0,  # worst descriptor: dropped
        ("a", "f2"): 4.0,
        ("b", "f2"): 2.0,
        ("c", "f2"): 50.0,
    }
    per_d, per_f, dropped = normalised_ert(ert, 10.0, constant=1000.0)
    assert dropped == "c"
    # descriptor a: (1/2 + 4/4) / 2 / 10 m * 1000 = 75; b: (2/2 + 2/4) / 2 * 100 = 75
    assert per_d == pytest.approx({"a": 75.0, "b": 75.0})
    # filter f1: a 1/4, b 2/2 -> mean 0.625 -> 62.5 ; f2: a 4/4, b 2/2 -> 100
    assert per_f == pytest.approx({"f1": 62.5, "f2": 100.0})
    per_d2, _, dropped2 = normalised_ert(ert, 10.0, discard_worst=False)
    assert dropped2 is None and per_d2["c"] == pytest.approx(100.0)
    assert normalised_ert({}, 10.0) == ({}, {}, None)


def test_classify_method():
    i = classify_method("feature:hods+gcc+alphabeta", "feature:hods+gcc+alphabeta")
    assert (i.family, i.descriptor, i.grouper, i.estimator, i.default) == (
        "feature",
        "hods",
        "gcc",
        "alphabeta",
        True,
    )
    assert i.display == "HoD-S/αβ"
    assert classify_method("x", "feature:shot+ransac+kalman").display == "SHOT/Kalman (RANSAC)"
    assert classify_method("clgv:fpfh", "clgv:fpfh").display == "CLGV (FPFH)"
    assert classify_method("icp-plane", "icp-plane").iterations == 1000
    p = classify_method("icp-point@1000", "icp-point", {"max_iter": 1000})
    assert (p.family, p.iterations, p.default) == ("competitor", 1000, False)
    assert classify_method("kiss-icp", "kiss-icp").family == "baseline"


def test_aggregate_mean_and_std(bench):
    with ResultsStore(bench / "results.sqlite") as st:
        rows = st.rows()
    aggs = aggregate(rows)
    a = aggs[("sim-bennu", "clean", "icp-point")]
    vals = [r["e_RT"] for r in rows if r["method_label"] == "icp-point"]
    assert a.n_ok == a.n_runs == 2
    assert a.m("e_RT") == pytest.approx(np.mean(vals))
    assert a.std["e_RT"] == pytest.approx(np.std(vals, ddof=1))
    broken = aggs[("sim-bennu", "clean", "broken")]
    assert broken.n_ok == 0 and broken.n_runs == 2 and "bogus" in broken.errors[0]


def test_report_files_and_sections(bench):
    md = (bench / "report.md").read_text()
    for heading in (
        "## What was run",
        "## Per-scenario results (Appendix-A layout)",
        "adaptive αβ recursive filtering",
        "competitor schemes",
        "## Cross-scenario comparison (Paper 1 §4)",
        "Top module per scenario (Table 4 layout)",
        "Table 3 layout",
        "Table 5 layout",
        "Table 6 layout",
        "Table B1 layout",
        "## Against the paper",
        "Paper 1's conclusions, checked here",
        "## Failed jobs",
    ):
        assert heading in md, heading
    for name in (
        "appendix_sim-bennu",
        "all_results",
        "jobs",
        "against_paper",
        "top_modules",
        "ablation_table3",
        "ablation_table5",
        "ablation_table6",
        "ablation_tableB1",
    ):
        assert (bench / "tables" / f"{name}.csv").is_file(), name
    for name in (
        "traj_sim-bennu",
        "errors_sim-bennu",
        "normalised_eRT_vs_time",
        "time_vs_points",
        "normalised_eRT_per_filter",
    ):
        p = bench / "figures" / f"{name}.png"
        assert p.is_file() and 10_000 < p.stat().st_size < 1_000_000, name
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_appendix_csv_is_the_mean_over_seeds(bench):
    with ResultsStore(bench / "results.sqlite") as st:
        rows = st.rows()
    with (bench / "tables" / "appendix_sim-bennu.csv").open() as f:
        table = {r["method"]: r for r in csv.DictReader(f)}
    for m in ("feature:fpfh+gcc+kalman", "icp-point"):
        vals = [r for r in rows if r["method_label"] == m]
        for k in ("e_RT", "drift", "e_x_max", "e_R_avg"):
            assert float(table[m][k]) == pytest.approx(np.mean([r[k] for r in vals]), rel=1e-12)
        assert table[m]["n_ok"] == "2"
    # the ablation variants stay out of the Appendix-A blocks
    assert "feature:hods+ransac+alphabeta" not in table and "icp-point@1000" not in table


def test_ablation_table_pairs_the_top_combination(bench):
    with (bench / "tables" / "ablation_table5.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    assert row["variant"] == row["method"].replace("+gcc+", "+ransac+")
    with (bench / "tables" / "appendix_sim-bennu.csv").open() as f:
        app = {r["method"]: float(r["e_RT"]) for r in csv.DictReader(f)}
    # the chosen combination is the best GCC+alphabeta one (only alphabeta has RANSAC variants)
    best = min((k for k in app if k.endswith("+gcc+alphabeta")), key=app.get)
    assert row["method"] == best


def test_report_errors(tmp_path):
    with pytest.raises(InputError, match=r"grid\.yaml"):
        write_report(tmp_path)


# ------------------------------------------------------------------ paper reference


def test_paper_reference_tables():
    assert set(ref.PAPER_SCENARIOS) == set(ref.TOP_MODULES)
    for s in ref.PAPER_SCENARIOS:
        tab = ref.appendix_table(s)
        assert len(tab) == 30
        assert ref.TOP_MODULES[s][2] in tab
    # path lengths implied by drift / T_error match the paper's scenario descriptions
    for s, L in {
        "real-fb": 7.4,
        "real-curved": 12.4,
        "sim-eoi": 290.0,
        "sim-helical": 206.0,
        "sim-voyager": 788.0,
    }.items():
        assert ref.paper_path_length(s) == pytest.approx(L, rel=0.02)
    a1 = ref.appendix_table("real-fb")["feature:hods+gcc+hinf"]
    # ALGORITHMS.md F.1 check: the norm of the axis maxima is e_T_max (0.166 ~ 0.17)
    assert math.hypot(a1["e_x_max"], a1["e_y_max"], a1["e_z_max"]) == pytest.approx(
        a1["e_T_max"], abs=0.01
    )
    m, row = ref.best_row("sim-bennu")
    assert m == "feature:hods+gcc+alphabeta" and row["e_RT"] == 10.65
    assert ref.best_row("real-fb", family="competitor")[0] == "sicp-plane"
    t5 = ref.paper_ablation("5")
    assert t5["sim-orion"].method == "feature:shot+gcc+kalman"
    assert t5["real-fb"].e_RT == (0.241, 12.421)
    # Table 5 is Table 3 divided by the path length
    t3 = ref.paper_ablation("3")
    assert t3["real-fb"].e_RT[0] / ref.paper_path_length("real-fb") == pytest.approx(
        t5["real-fb"].e_RT[0], rel=0.02
    )
    b1 = ref.paper_icp_iterations()
    assert len(b1) == 35 and b1[("sim-bennu", "icp-plane")].e_RT[0] == 5e14
    with pytest.raises(InputError):
        ref.appendix_table("sim-mars")


def test_export_report_compresses_figures(bench, tmp_path):
    from relnav.bench.report import export_report

    md = export_report(bench, tmp_path / "docs")
    text = md.read_text()
    assert "Tables (in the benchmark folder)" in text
    pngs = sorted((tmp_path / "docs" / "figures").glob("*.png"))
    assert pngs and all(f"figures/{p.name}" in text for p in pngs)
    src = sum((bench / "figures" / p.name).stat().st_size for p in pngs)
    assert sum(p.stat().st_size for p in pngs) < 0.7 * src


def test_cli_benchmark_and_report(tmp_path):
    import typer
    import yaml
    from typer.testing import CliRunner

    from relnav.cli.benchmark import register

    app = typer.Typer()
    register(app)
    grid = tmp_path / "g.yaml"
    grid.write_text(yaml.safe_dump({**GRID, "methods": ["icp-point", "icp-x84"], "seeds": 1}))
    out = tmp_path / "out"
    r = CliRunner().invoke(
        app,
        [
            "benchmark",
            str(grid),
            "--out",
            str(out),
            "--workers",
            "0",
            "--max-frames",
            "2",
            "--method",
            "icp-p*",
            "--dry-run",
        ],
    )
    assert r.exit_code == 0, r.output
    assert "1 jobs" in r.output and not (out / "results.sqlite").exists()
    r = CliRunner().invoke(
        app, ["benchmark", str(grid), "--out", str(out), "--workers", "0", "--max-frames", "2"]
    )
    assert r.exit_code == 0, r.output
    assert "2 ok, 0 failed" in r.output and (out / "report.md").is_file()
    r = CliRunner().invoke(
        app,
        [
            "benchmark",
            str(grid),
            "--out",
            str(out),
            "--workers",
            "0",
            "--max-frames",
            "2",
            "--no-report",
        ],
    )
    assert "2 already finished" in r.output
    r = CliRunner().invoke(app, ["report", str(out), "--export", str(tmp_path / "exp")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "exp" / "report.md").is_file()
