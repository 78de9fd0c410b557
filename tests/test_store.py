"""Results store: round trip, NULL/NaN handling, resumability queries, schema migration."""

from __future__ import annotations

import math
import sqlite3

import pytest

from relnav.bench.store import COLUMNS, ResultsStore
from relnav.errors import InputError
from relnav.eval.metrics import METRIC_KEYS


def _row(job_id: str, status: str = "ok", **kw: object) -> dict:
    r = {
        "job_id": job_id,
        "scenario": "sim-bennu",
        "nuisance": "clean",
        "method": "icp-point",
        "method_label": "icp-point",
        "method_options": {"max_iter": 20},
        "seed": 3,
        "status": status,
        "error": "" if status == "ok" else "ValueError: boom",
        "e_RT": 1.5,
        "drift": float("nan"),
        "time_ms": 12.0,
        "n_matched": 7.0,  # not a column: goes to metrics_json
    }
    r.update(kw)
    return r


def test_round_trip_and_nan(tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as st:
        st.put(_row("a"))
        rows = st.rows()
    assert len(rows) == 1
    r = rows[0]
    assert r["e_RT"] == 1.5 and r["time_ms"] == 12.0 and r["seed"] == 3
    assert math.isnan(r["drift"])  # NaN stored as NULL, read back as NaN
    assert math.isnan(r["e_T_avg"])  # absent metric
    assert r["n_matched"] == 7.0  # extra key kept in metrics_json
    assert r["method_options"] == '{"max_iter": 20}'


def test_every_metric_is_a_column():
    names = {c for c, _ in COLUMNS}
    assert set(METRIC_KEYS) <= names
    assert {"job_id", "grid_hash", "status", "error", "relnav_version", "started_at"} <= names


def test_replace_and_finished_ids(tmp_path):
    st = ResultsStore(tmp_path / "r.sqlite")
    st.put(_row("a"))
    st.put(_row("b", status="failed"))
    assert st.finished_ids() == {"a", "b"}
    assert st.finished_ids(("ok",)) == {"a"}
    st.put(_row("b", e_RT=2.0))  # rerun replaces the row
    assert len(st) == 2
    assert {r["job_id"]: r["e_RT"] for r in st.rows()} == {"a": 1.5, "b": 2.0}
    assert [r["job_id"] for r in st.rows(["b"])] == ["b"]
    assert st.delete(["a"]) == 1 and len(st) == 1
    st.close()


def test_rows_survive_a_new_connection(tmp_path):
    p = tmp_path / "r.sqlite"
    st = ResultsStore(p)
    st.put(_row("a"))  # committed immediately, no close
    other = ResultsStore(p, readonly=True)
    assert other.finished_ids() == {"a"}
    other.close()
    st.close()


def test_missing_and_corrupt_store(tmp_path):
    with pytest.raises(InputError, match="no results store"):
        ResultsStore(tmp_path / "none.sqlite", readonly=True)
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(InputError, match="SQLite"):
        ResultsStore(bad)
    with pytest.raises(InputError, match="job_id"):
        ResultsStore(tmp_path / "ok.sqlite").put({"scenario": "x"})


def test_old_store_gains_new_columns(tmp_path):
    p = tmp_path / "old.sqlite"
    con = sqlite3.connect(p)
    con.execute("CREATE TABLE jobs (job_id TEXT PRIMARY KEY, status TEXT, e_RT REAL)")
    con.execute("INSERT INTO jobs VALUES ('x', 'ok', 3.0)")
    con.commit()
    con.close()
    with ResultsStore(p) as st:
        r = st.rows()[0]
        assert r["e_RT"] == 3.0 and math.isnan(r["drift"])
        st.put(_row("y"))
        assert st.finished_ids() == {"x", "y"}


def test_to_csv(tmp_path):
    with ResultsStore(tmp_path / "r.sqlite") as st:
        st.put(_row("a"))
        st.put(_row("b", status="failed"))
        p = st.to_csv(tmp_path / "t" / "jobs.csv", ["a"])
    lines = p.read_text().splitlines()
    assert len(lines) == 2 and lines[0].startswith("job_id,")
