"""A run's output folder: one writer at a time, no stale files, a killed run recognised.

:class:`RunFolder` is what ``relnav odometry`` holds on its ``--out``:

- an exclusive lock (:class:`relnav.io.locks.FolderLock` on ``OUT/.lock``): a second run into
  the same folder is refused at once (:class:`~relnav.errors.OutputError`) instead of mixing
  its files with the first one's;
- a marker ``OUT/.incomplete`` written when the run starts and removed only after its last
  file (``run.json``) is in place. A run killed (``SIGKILL``, power loss) or starved of disk at
  any moment leaves the marker; the next run into the folder says so and removes the partial
  outputs before writing its own;
- :meth:`RunFolder.finish` removes the previous run's outputs that the new run did not write
  (e.g. ``metrics.json`` and ``errors.png`` of an earlier run with ground truth), so the folder
  describes one run only.

Every ``OSError`` met while writing becomes one :class:`~relnav.errors.OutputError` line naming
the path and the reason (:func:`output_error`).
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any

from relnav.errors import InputError, OutputError

__all__ = ["INCOMPLETE_MARKER", "RUN_OUTPUTS", "RunFolder", "output_error"]

log = logging.getLogger(__name__)

INCOMPLETE_MARKER = ".incomplete"
"""Present in an output folder while a run writes it (and after a run that did not finish)."""

RUN_OUTPUTS = (
    "estimate.tum",
    "estimate_causal.tum",
    "diagnostics.csv",
    "metrics.json",
    "errors.png",
    "estimate_kitti.txt",
    "times.txt",
    "state.csv",
    "state.png",
    "state_errors.png",
    "live.rrd",
    "run.json",
)
"""Files ``relnav odometry`` may write (removed after a run that did not finish)."""


def output_error(e: OSError, path: str | Path | None = None) -> OutputError:
    """One line for an ``OSError`` met while writing: the path and the reason."""
    where = e.filename if e.filename is not None else path
    if where is not None:  # a temporary sibling (.name.pid.tmp) is reported by its final name
        q = Path(os.fsdecode(where))
        parts = q.name.split(".")
        if len(parts) >= 4 and parts[0] == "" and parts[-1] == "tmp" and parts[-2].isdigit():
            where = q.with_name(".".join(parts[1:-2]))
    reason = e.strerror or str(e) or type(e).__name__
    return OutputError(f"{where}: cannot write: {reason}")


class RunFolder:
    """The output folder of one run (context manager; see the module docstring).

    Parameters
    ----------
    folder : str or Path
        Output folder (created).
    what : str
        The run's name in messages (``"odometry run"``).
    protect : iterable of Path
        Files never removed (the run's inputs, when the output folder holds them).
    """

    def __init__(
        self, folder: str | Path, *, what: str = "odometry run", protect: Iterable[Path] = ()
    ) -> None:
        from relnav.io.locks import FolderLock

        self.folder = Path(folder)
        self.what = what
        self._protect = {_resolved(p) for p in protect}
        self._lock = FolderLock(self.folder, timeout=0, what=what)
        self.previous: list[str] = []
        self.was_incomplete = False
        self.removed: list[str] = []

    @property
    def marker(self) -> Path:
        """``OUT/.incomplete``."""
        return self.folder / INCOMPLETE_MARKER

    def __enter__(self) -> RunFolder:
        try:
            if self.folder.exists() and not self.folder.is_dir():
                raise OutputError(f"{self.folder}: exists and is not a folder")
            self.folder.mkdir(parents=True, exist_ok=True)
            try:
                self._lock.acquire()
            except InputError as e:
                raise OutputError(str(e)) from None
            try:
                self._start()
            except BaseException:
                self._lock.release()
                raise
        except OSError as e:
            raise output_error(e, self.folder) from None
        return self

    def _start(self) -> None:
        from relnav.atomic import atomic_write_text
        from relnav.io.runinfo import read_run_info

        info = read_run_info(self.folder) or {}
        listed = [str(x) for x in info.get("outputs", []) if isinstance(x, str)]
        self.previous = [n for n in listed if self._is_output(n)]
        if self.marker.exists():
            self.was_incomplete = True
            started = _marker_text(self.marker)
            partial = sorted({*self.previous, *(n for n in RUN_OUTPUTS if self._is_output(n))})
            for name in partial:
                self._remove(name)
            log.warning(
                "%s: the previous %s into this folder did not finish (%s): its %d partial "
                "output(s) were removed",
                self.folder,
                self.what,
                started,
                len(partial),
            )
            self.previous = []
        for stale in self.folder.glob(".*.tmp"):  # temporaries of killed writers
            stale.unlink(missing_ok=True)
        doc = {
            "pid": os.getpid(),
            "started_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "what": self.what,
        }
        atomic_write_text(self.marker, json.dumps(doc) + "\n")

    def _is_output(self, name: str) -> bool:
        p = self.folder / name
        return (
            "/" not in name
            and name not in ("", ".", "..", INCOMPLETE_MARKER, ".lock")
            and p.is_file()
            and _resolved(p) not in self._protect
        )

    def _remove(self, name: str) -> None:
        (self.folder / name).unlink(missing_ok=True)
        self.removed.append(name)

    def finish(self, written: Iterable[str]) -> list[str]:
        """The run wrote ``written`` (names in the folder, ``run.json`` last): remove the
        previous run's outputs it did not write, then the ``.incomplete`` marker. Returns the
        removed names."""
        keep = set(written)
        try:
            for name in self.previous:
                if name not in keep and self._is_output(name):
                    self._remove(name)
            self.marker.unlink(missing_ok=True)
        except OSError as e:
            raise output_error(e, self.folder) from None
        return [n for n in self.removed if n not in keep]

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._lock.release()


def _resolved(p: Path) -> Path:
    try:
        return Path(p).resolve()
    except OSError:  # pragma: no cover - a path the OS cannot resolve
        return Path(p)


def _marker_text(marker: Path) -> str:
    try:
        doc: dict[str, Any] = json.loads(marker.read_text(encoding="utf-8"))
        return f"pid {doc.get('pid', '?')}, started {doc.get('started_utc', '?')}"
    except (OSError, ValueError, AttributeError):
        return "killed while writing"
