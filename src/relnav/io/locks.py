"""An exclusive lock on a folder shared by several processes (POSIX ``flock``).

The lock is held on ``<folder>/.lock``; the operating system releases it when its holder exits,
even on ``SIGKILL``, so a killed run never leaves a stale lock behind.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from types import TracebackType

from relnav.errors import InputError

__all__ = ["FolderLock"]

log = logging.getLogger(__name__)


class FolderLock:
    """Exclusive lock on a folder (context manager).

    Parameters
    ----------
    folder : str or Path
        Folder to lock (created if needed).
    timeout : float or None
        Seconds to wait for another holder; ``None`` waits as long as needed, ``0`` fails at
        once. On timeout: :class:`relnav.errors.InputError` naming the holder's pid.
    what : str
        Name of the work, for messages.
    """

    def __init__(self, folder: str | Path, *, timeout: float | None = None, what: str = "run"):
        self.path = Path(folder) / ".lock"
        self.timeout = timeout
        self.what = what
        self._fd: int | None = None

    def holder(self) -> str:
        """The pid written by the current holder ("?" when unknown)."""
        try:
            return self.path.read_text().strip() or "?"
        except OSError:
            return "?"

    def acquire(self) -> None:
        """Take the lock, waiting as configured."""
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        t0 = time.monotonic()
        warned = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                waited = time.monotonic() - t0
                if self.timeout is not None and waited >= self.timeout:
                    os.close(fd)
                    raise InputError(
                        f"{self.path.parent}: another {self.what} (pid {self.holder()}) is using "
                        "this folder"
                    ) from None
                if not warned:
                    log.warning(
                        "%s: waiting for another %s (pid %s) to finish",
                        self.path.parent,
                        self.what,
                        self.holder(),
                    )
                    warned = True
                time.sleep(0.2)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd

    def release(self) -> None:
        """Release the lock (idempotent)."""
        import fcntl

        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()
