"""Benchmark grid runner: grid parsing, job identity, resume, failures, evaluate parity, Dask."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from relnav.bench.benchmark import (
    GridSpec,
    expand_jobs,
    expand_methods,
    job_id,
    load_grid,
    run_benchmark,
)
from relnav.bench.store import ResultsStore
from relnav.errors import ConfigError
from relnav.eval.metrics import METRIC_KEYS

TINY = {
    "name": "tiny",
    "scenarios": [{"preset": "sim-bennu", "max_frames": 3}],
    "methods": [
        "icp-point",
        "feature:hods+gcc+alphabeta",
        # a method that fails every job (bad option) must be recorded, not stop the grid
        {"method": "icp-point", "label": "broken", "options": {"no_such_option": 1}},
    ],
    "seeds": [0, 1],
    "warmup_frames": 0,
}
ACCURACY_KEYS = [k for k in METRIC_KEYS if k != "time_ms"]


def _same_metrics(a: dict, b: dict) -> bool:
    return all(a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])) for k in ACCURACY_KEYS)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict]]:
    out = tmp_path_factory.mktemp("bench") / "tiny"
    s = run_benchmark(load_grid(TINY), out, workers=0)
    assert (s.n_jobs, s.n_ok, s.n_failed) == (6, 4, 2)
    with ResultsStore(out / "results.sqlite") as st:
        rows = st.rows()
    return out, rows


# ------------------------------------------------------------------ grid


def test_brace_expansion():
    assert expand_methods("feature:{hods, shot}+{gcc,ransac}+svd") == [
        "feature:hods+gcc+svd",
        "feature:hods+ransac+svd",
        "feature:shot+gcc+svd",
        "feature:shot+ransac+svd",
    ]
    assert expand_methods("icp-point") == ["icp-point"]
    with pytest.raises(ConfigError, match="empty"):
        expand_methods("feature:{}+gcc+svd")


def test_grid_parsing_and_narrowing():
    g = load_grid(
        {
            "scenarios": ["sim-bennu", {"preset": "real-fb", "max_frames": 50}],
            "methods": ["feature:{hods,shot}+gcc+alphabeta", "icp-point"],
            "seeds": 4,
        }
    )
    assert [s.label for s in g.scenarios] == ["sim-bennu", "real-fb"]
    assert [m.name for m in g.methods][:2] == [
        "feature:hods+gcc+alphabeta",
        "feature:shot+gcc+alphabeta",
    ]
    assert g.seeds == [0, 1, 2, 3]
    n = load_grid(g, seeds=2, max_frames=20, methods=["feature:*"], scenarios=["real*"])
    assert n.seeds == [0, 1] and [m.name for m in n.methods] == [
        "feature:hods+gcc+alphabeta",
        "feature:shot+gcc+alphabeta",
    ]
    assert [(s.label, s.max_frames) for s in n.scenarios] == [("real-fb", 20)]
    assert n.grid_hash() != g.grid_hash()


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        ({"scenarios": [{"preset": "a", "sequence": "b"}], "methods": ["icp-point"]}, "exactly"),
        ({"scenarios": ["sim-bennu", "sim-bennu"], "methods": ["icp-point"]}, "duplicate"),
        ({"scenarios": ["sim-bennu"], "methods": []}, "methods"),
        ({"scenarios": ["sim-bennu"], "methods": ["icp-point"], "seeds": 0}, "seeds"),
        ({"scenarios": ["sim-bennu"], "methods": ["icp-point"], "colour": 1}, "unknown key"),
    ],
)
def test_bad_grids(bad, match):
    with pytest.raises(ConfigError, match=match):
        load_grid(bad)


def test_unknown_method_family_is_a_config_error():
    with pytest.raises(ConfigError, match="grid method 'warp-drive': unknown method"):
        expand_jobs(load_grid({"scenarios": ["sim-bennu"], "methods": ["warp-drive"]}))


def test_grid_accepts_the_navigator_and_presets():
    grid = load_grid({"scenarios": ["sim-bennu"], "methods": ["relnav", "extended"]})
    jobs = expand_jobs(grid)
    assert {j.method for j in jobs} == {"relnav", "feature:hods+gcc+svd"}
    ext = next(j for j in jobs if j.method.startswith("feature"))
    assert ext.options["refine"] == "icp-plane"


def test_job_ids_are_content_hashes():
    spec = {"preset": "sim-bennu", "frames": None, "max_frames": 3, "options": {}}
    a = job_id(spec, 0, {}, "icp-point", {})
    assert a == job_id(dict(reversed(spec.items())), 0, {}, "icp-point", {})
    assert a != job_id(spec, 1, {}, "icp-point", {})
    assert a != job_id(spec, 0, {"range_sigma_m": 0.1}, "icp-point", {})
    assert a != job_id(spec, 0, {}, "icp-point", {"max_iter": 1000})
    jobs = expand_jobs(load_grid(TINY))
    assert len(jobs) == 6 and len({j.job_id for j in jobs}) == 6
    # the same scenario/seed share one sequence folder across methods
    assert len({j.sequence_rel for j in jobs}) == 2


def test_sweeps_expand_to_levels():
    g = load_grid(
        {
            "scenarios": ["sim-bennu"],
            "methods": ["icp-point"],
            "sweeps": [
                {"parameter": "range_sigma_m", "values": [0.0, 0.01]},
                {
                    "parameter": "occlusion_fraction",
                    "values": [0.2],
                    "fixed": {"occlusion": "cone"},
                },
            ],
        }
    )
    labels = [lv.label for lv in g.nuisance_levels()]
    assert labels == ["clean", "range_sigma_m=0.01", "occlusion=cone,occlusion_fraction=0.2"]
    assert len(expand_jobs(g)) == 3


# ------------------------------------------------------------------ running


def test_jobs_ok_and_failures_recorded(tiny_run):
    out, rows = tiny_run
    by = {(r["method_label"], r["seed"]): r for r in rows}
    assert {r["status"] for r in rows if r["method_label"] == "broken"} == {"failed"}
    assert "no_such_option" in by[("broken", 0)]["error"]
    for m in ("icp-point", "feature:hods+gcc+alphabeta"):
        for seed in (0, 1):
            r = by[(m, seed)]
            assert r["status"] == "ok" and r["n_frames"] == 3
            assert math.isfinite(r["e_RT"]) and r["time_ms"] > 0
            assert r["relnav_version"] and r["grid_hash"] and r["finished_at"]
            assert (out / r["estimate_path"]).is_file()
            assert r["mean_points"] > 50
    # seeds change the data (sensor noise / jitter), so the metrics differ
    assert by[("icp-point", 0)]["e_RT"] != by[("icp-point", 1)]["e_RT"]
    assert (out / "grid.yaml").is_file() and (out / "runs.jsonl").is_file()


def test_store_metrics_equal_relnav_evaluate(tiny_run):
    from relnav.cli.evaluate import register

    out, rows = tiny_run
    app = typer.Typer()
    register(app)
    app.command("noop")(lambda: None)  # keep the subcommand form
    r = next(r for r in rows if r["method_label"] == "feature:hods+gcc+alphabeta")
    gt = out / r["sequence_path"] / "gt_T_target_sensor.tum"
    js = out / "m.json"
    res = CliRunner().invoke(
        app, ["evaluate", str(out / r["estimate_path"]), str(gt), "--json", str(js)]
    )
    assert res.exit_code == 0, res.output
    ev = json.loads(js.read_text())
    for k in ACCURACY_KEYS:
        v = ev[k]
        assert (v is None and math.isnan(r[k])) or v == r[k], k


def test_resume_skips_finished_and_force_reruns(tiny_run, tmp_path):
    out, rows = tiny_run
    before = {r["job_id"]: r["finished_at"] for r in rows}
    s = run_benchmark(load_grid(TINY), out, workers=0)
    assert (s.n_skipped, s.n_ok, s.n_failed) == (6, 0, 0)
    s = run_benchmark(load_grid(TINY), out, workers=0, retry_failed=True)
    assert (s.n_skipped, s.n_failed) == (4, 2)
    with ResultsStore(out / "results.sqlite") as st:
        after = {r["job_id"]: r["finished_at"] for r in st.rows() if r["status"] == "ok"}
    assert all(after[k] == before[k] for k in after)


def test_killed_run_resumes_without_redoing(tmp_path):
    out = tmp_path / "b"
    grid = load_grid({**TINY, "seeds": [0]})
    done = []

    def kill_after_two(i, n, row):
        done.append(row["job_id"])
        if len(done) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_benchmark(grid, out, workers=0, progress=kill_after_two)
    with ResultsStore(out / "results.sqlite") as st:
        assert st.finished_ids() == set(done)
    s = run_benchmark(grid, out, workers=0)
    assert (s.n_jobs, s.n_skipped, s.n_ok + s.n_failed) == (3, 2, 1)
    s = run_benchmark(grid, out, workers=0, force=True)
    assert s.n_skipped == 0 and s.n_ok + s.n_failed == 3


def test_same_job_same_metrics_in_another_folder(tiny_run, tmp_path):
    _, rows = tiny_run
    grid = load_grid({**TINY, "seeds": [1], "methods": ["feature:hods+gcc+alphabeta"]})
    run_benchmark(grid, tmp_path / "again", workers=0)
    with ResultsStore(tmp_path / "again" / "results.sqlite") as st:
        (b,) = st.rows()
    a = next(r for r in rows if r["job_id"] == b["job_id"])
    assert _same_metrics(a, b)


def test_sequence_folder_scenario(tiny_run, tmp_path):
    out, rows = tiny_run
    seq = out / next(r["sequence_path"] for r in rows if r["seed"] == 0 and r["status"] == "ok")
    grid = GridSpec.model_validate(
        {
            "scenarios": [{"sequence": str(seq), "name": "mine", "max_frames": 2}],
            "methods": ["icp-point"],
            "seeds": [0, 1],  # the clean level of a recorded sequence runs once
            "nuisances": [{"keep_fraction": 0.5}],
            "warmup_frames": 0,
        }
    )
    jobs = expand_jobs(grid)
    assert [(j.seed, j.nuisance_label) for j in jobs] == [
        (0, "clean"),
        (0, "keep_fraction=0.5"),
        (1, "keep_fraction=0.5"),
    ]
    s = run_benchmark(grid, tmp_path / "seq", workers=0)
    assert s.n_ok == 3
    with ResultsStore(tmp_path / "seq" / "results.sqlite") as st:
        r = {(x["seed"], x["nuisance"]): x for x in st.rows()}
    assert r[(0, "clean")]["n_frames"] == 2
    assert r[(0, "keep_fraction=0.5")]["mean_points"] < 0.6 * r[(0, "clean")]["mean_points"]


def test_scheduler_gives_the_same_metrics(tiny_run, tmp_path):
    """Jobs run by separate worker processes (through a scheduler address) = in-process run."""
    distributed = pytest.importorskip("distributed")
    _, rows = tiny_run
    grid = load_grid({**TINY, "methods": TINY["methods"][:2]})
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        s = run_benchmark(grid, tmp_path / "d", scheduler=cluster.scheduler_address)
    assert (s.n_ok, s.n_failed, s.n_workers) == (4, 0, 2)
    with ResultsStore(tmp_path / "d" / "results.sqlite") as st:
        remote = {r["job_id"]: r for r in st.rows()}
    assert {r["worker"].split(":")[0] for r in remote.values()} == {"tcp"}
    local = {r["job_id"]: r for r in rows}
    assert set(remote) <= set(local)
    assert all(_same_metrics(local[k], remote[k]) for k in remote)
