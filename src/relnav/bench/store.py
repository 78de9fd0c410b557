"""SQLite results store of a benchmark: one row per job, committed as each job finishes.

A benchmark folder holds ``results.sqlite`` with two tables:

``jobs``
    One row per (scenario, nuisance, method, seed) job, keyed by ``job_id`` (a hash of
    everything that determines the result, see :func:`relnav.bench.benchmark.job_id`): grid
    hash, scenario, method, seed, nuisance, status (``ok`` / ``failed``), error, every metric of
    :data:`relnav.eval.metrics.METRIC_KEYS` as a column, per-stage mean times (ms), points per
    scan, package version, host/worker and timestamps. Each :meth:`ResultsStore.put` is its
    own committed transaction (WAL journal), so a killed run loses at most the job in flight.
``meta``
    Key/value pairs (e.g. the schema version).

Only the process that drives the benchmark writes to the store (workers return rows), so
there is never more than one writer. Columns added to :data:`COLUMNS` later are added to old
stores on open (``ALTER TABLE``), so an old folder stays readable and resumable.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import sqlite3
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from relnav.errors import InputError
from relnav.eval.metrics import METRIC_KEYS
from relnav.odometry.runner import DIAGNOSTIC_STAGES

__all__ = ["COLUMNS", "SCHEMA_VERSION", "STAGE_COLUMNS", "ResultsStore"]

log = logging.getLogger(__name__)

SCHEMA_VERSION = 1

STAGE_COLUMNS: tuple[str, ...] = (
    *(f"t_{s}_ms" for s in DIAGNOSTIC_STAGES),
    "t_other_ms",
    "t_frame_ms",
)
"""Per-stage mean times per registered frame (ms), from ``diagnostics.csv``."""

_ID_COLUMNS: tuple[tuple[str, str], ...] = (
    ("job_id", "TEXT PRIMARY KEY"),
    ("grid_hash", "TEXT"),
    ("grid_name", "TEXT"),
    ("scenario", "TEXT"),
    ("scenario_kind", "TEXT"),
    ("scenario_spec", "TEXT"),
    ("nuisance", "TEXT"),
    ("nuisance_params", "TEXT"),
    ("method", "TEXT"),
    ("method_label", "TEXT"),
    ("method_options", "TEXT"),
    ("seed", "INTEGER"),
    ("status", "TEXT"),
    ("error", "TEXT"),
)
_INFO_COLUMNS: tuple[tuple[str, str], ...] = (
    ("n_flagged", "INTEGER"),
    ("mean_points", "REAL"),
    ("estimate_path", "TEXT"),
    ("sequence_path", "TEXT"),
    ("relnav_version", "TEXT"),
    ("host", "TEXT"),
    ("worker", "TEXT"),
    ("started_at", "TEXT"),
    ("finished_at", "TEXT"),
    ("wall_s", "REAL"),
    ("metrics_json", "TEXT"),
)

COLUMNS: tuple[tuple[str, str], ...] = (
    _ID_COLUMNS
    + tuple((k, "TEXT" if k == "align" else "REAL") for k in METRIC_KEYS)
    + tuple((k, "REAL") for k in STAGE_COLUMNS)
    + _INFO_COLUMNS
)
"""``(name, SQL type)`` of every column of the ``jobs`` table, in order."""

_NAMES = tuple(c for c, _ in COLUMNS)
_TYPES = dict(COLUMNS)


def _sql_value(name: str, v: Any) -> Any:
    if v is None:
        return None
    t = _TYPES[name]
    if t == "REAL":
        try:
            f = float(v)
        except (TypeError, ValueError):
            return None
        return f if math.isfinite(f) else None
    if t == "INTEGER":
        return int(v)
    if isinstance(v, dict | list | tuple):
        return json.dumps(v, sort_keys=True)
    return str(v)


class ResultsStore:
    """The ``results.sqlite`` of a benchmark folder.

    Parameters
    ----------
    path : str or Path
        Database file (created with its parent folder when missing).
    readonly : bool
        Open an existing store for reading only (:class:`InputError` when it does not exist).

    Examples
    --------
    >>> store = ResultsStore("bench/results.sqlite")  # doctest: +SKIP
    >>> store.finished_ids()  # doctest: +SKIP
    """

    def __init__(self, path: str | Path, *, readonly: bool = False) -> None:
        self.path = Path(path)
        if readonly and not self.path.is_file():
            raise InputError(f"{self.path}: no results store (run `relnav benchmark` first)")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            if readonly:
                self._con = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
            else:
                self._con = sqlite3.connect(self.path, timeout=30.0)
                self._con.execute("PRAGMA journal_mode=WAL")
                self._con.execute("PRAGMA synchronous=NORMAL")
                self._create()
        except sqlite3.DatabaseError as e:
            raise InputError(f"{self.path}: not a usable SQLite results store: {e}") from None
        self._con.row_factory = sqlite3.Row

    # ------------------------------------------------------------------ schema
    def _create(self) -> None:
        cols = ", ".join(f'"{n}" {t}' for n, t in COLUMNS)
        with self._con:
            self._con.execute(f"CREATE TABLE IF NOT EXISTS jobs ({cols})")
            self._con.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT)")
            have = {r[1] for r in self._con.execute("PRAGMA table_info(jobs)")}
            for n, t in COLUMNS:
                if n not in have:
                    log.info("%s: adding column %s", self.path, n)
                    self._con.execute(f'ALTER TABLE jobs ADD COLUMN "{n}" {t}')
            self._con.execute(
                "INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
            )

    # ------------------------------------------------------------------ writing
    def put(self, row: dict[str, Any]) -> None:
        """Insert or replace one job row and commit.

        Keys that are not columns are kept in ``metrics_json`` (merged with any given there).

        Raises
        ------
        InputError
            ``row`` has no ``job_id``.
        """
        if not row.get("job_id"):
            raise InputError("results store: a row needs a job_id")
        extra = {k: v for k, v in row.items() if k not in _TYPES}
        if row.get("metrics_json"):
            base = row["metrics_json"]
            extra = {**(json.loads(base) if isinstance(base, str) else dict(base)), **extra}
        values = {n: _sql_value(n, row.get(n)) for n in _NAMES}
        values["metrics_json"] = json.dumps(_jsonable(extra), sort_keys=True) if extra else None
        names = ", ".join(f'"{n}"' for n in _NAMES)
        marks = ", ".join("?" for _ in _NAMES)
        with self._con:
            self._con.execute(
                f"INSERT OR REPLACE INTO jobs ({names}) VALUES ({marks})",
                [values[n] for n in _NAMES],
            )

    def set_meta(self, key: str, value: str) -> None:
        """Store a key/value pair in ``meta`` (committed)."""
        with self._con:
            self._con.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))

    def delete(self, job_ids: Iterable[str]) -> int:
        """Delete the given jobs; returns how many rows went."""
        ids = list(job_ids)
        with self._con:
            cur = self._con.executemany("DELETE FROM jobs WHERE job_id = ?", [(i,) for i in ids])
        return cur.rowcount

    # ------------------------------------------------------------------ reading
    def meta(self, key: str) -> str | None:
        """A ``meta`` value, or ``None``."""
        r = self._con.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if r is None else str(r[0])

    def finished_ids(self, statuses: Sequence[str] = ("ok", "failed")) -> set[str]:
        """Job ids whose row has one of ``statuses``."""
        marks = ", ".join("?" for _ in statuses)
        cur = self._con.execute(
            f"SELECT job_id FROM jobs WHERE status IN ({marks})", tuple(statuses)
        )
        return {r[0] for r in cur}

    def rows(
        self, job_ids: Iterable[str] | None = None, *, status: str | None = None
    ) -> list[dict[str, Any]]:
        """Rows as dictionaries (NULL → ``nan`` for metric columns), optionally filtered.

        ``metrics_json`` is decoded and merged into each row (columns take precedence).
        """
        sql = "SELECT * FROM jobs"
        args: list[Any] = []
        if status is not None:
            sql += " WHERE status = ?"
            args.append(status)
        sql += " ORDER BY scenario, nuisance, method_label, seed"
        wanted = None if job_ids is None else set(job_ids)
        out = []
        for r in self._con.execute(sql, args):
            d = dict(r)
            if wanted is not None and d["job_id"] not in wanted:
                continue
            extra = json.loads(d["metrics_json"]) if d.get("metrics_json") else {}
            for k, v in extra.items():
                d.setdefault(k, v)
            for n, t in COLUMNS:
                if t == "REAL" and d.get(n) is None:
                    d[n] = float("nan")
            out.append(d)
        return out

    def __len__(self) -> int:
        return int(self._con.execute("SELECT COUNT(*) FROM jobs").fetchone()[0])

    def to_csv(self, path: str | Path, job_ids: Iterable[str] | None = None) -> Path:
        """Write the (selected) rows as CSV, every column; returns the path."""
        rows = self.rows(job_ids)
        from relnav.atomic import atomic_open

        p = Path(path)
        with atomic_open(p, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(_NAMES), extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
        return p

    def close(self) -> None:
        """Close the connection."""
        self._con.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if hasattr(x, "item"):
        return x.item()
    return x
