"""Files at the foundation: atomic output, and text input decoded with one clear error.

Output: write to a temporary name in the same folder, then rename. A later run trusts a file
only by its final name; a process killed mid-write leaves at most a ``.<name>.<pid>.tmp`` file
behind, which no reader opens (and which the next write replaces).

Input: every text file relnav reads (times, trajectories, calibration, YAML) goes through
:func:`read_text_file`; bytes that are not valid in the file's encoding raise the project's
error naming the file and the byte offset, never a ``UnicodeDecodeError`` traceback
(re-exported by :mod:`relnav.io.text`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from relnav.errors import InputError, RelnavError

__all__ = [
    "atomic_open",
    "atomic_write_text",
    "decode_text",
    "read_text_file",
    "remove_stale_temps",
    "temp_name",
]


def temp_name(path: str | Path) -> Path:
    """The temporary sibling of ``path`` used while it is being written."""
    p = Path(path)
    return p.with_name(f".{p.name}.{os.getpid()}.tmp")


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: object) -> Iterator[IO]:
    """Open a temporary sibling of ``path`` for writing; on a clean exit flush, fsync and
    rename it to ``path`` (atomic on POSIX), on an exception delete it.

    Parameters
    ----------
    path : str or Path
        Final file name; parent folders are created.
    mode : str
        ``"w"`` (text) or ``"wb"``.
    **kwargs
        Passed to :func:`open` (``newline``, ``encoding``...).
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_name(p)
    f = open(tmp, mode, **kwargs)
    try:
        yield f
        f.flush()
        os.fsync(f.fileno())
        f.close()
        os.replace(tmp, p)
    except BaseException:
        f.close()
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_open`); returns the path."""
    with atomic_open(path, "w", encoding=encoding) as f:
        f.write(text)
    return Path(path)


def remove_stale_temps(path: str | Path) -> int:
    """Delete temporary siblings of ``path`` left by processes that no longer run (killed
    mid-write); returns how many were removed."""
    p = Path(path)
    n = 0
    for tmp in p.parent.glob(f".{p.name}.*.tmp"):
        pid_text = tmp.name[len(p.name) + 2 : -len(".tmp")]
        if not pid_text.isdigit() or _alive(int(pid_text)):
            continue
        tmp.unlink(missing_ok=True)
        n += 1
    return n


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def decode_text(
    raw: bytes,
    source: str | Path,
    *,
    encoding: str = "utf-8-sig",
    what: str = "text",
    error: type[RelnavError] = InputError,
) -> str:
    """Decode ``raw`` (the bytes of ``source``) as ``encoding``.

    Parameters
    ----------
    raw : bytes
        File content.
    source : str or Path
        Named in the error message.
    encoding : str
        Codec (default UTF-8, a leading byte-order mark ignored).
    what : str
        What the file should hold, for the message (``"timestamps"``, ``"YAML"``…).
    error : RelnavError subclass
        Raised on undecodable bytes (default :class:`~relnav.errors.InputError`).

    Returns
    -------
    str
        The text.
    """
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as e:
        bad = raw[e.start : min(e.end, e.start + 4)]
        raise error(
            f"{source}: not a {what} file in {e.encoding.upper().replace('-SIG', '')}: "
            f"undecodable byte(s) 0x{bad.hex()} at byte offset {e.start} ({e.reason})"
        ) from None


def read_text_file(
    path: str | Path,
    *,
    encoding: str = "utf-8-sig",
    what: str = "text",
    error: type[RelnavError] = InputError,
) -> str:
    """The text of ``path``; :class:`~relnav.errors.InputError` (or ``error``) naming the file on
    a missing/unreadable file or undecodable bytes (with the byte offset). See
    :func:`decode_text` for the parameters."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise error(f"{p}: no such file") from None
    except IsADirectoryError:
        raise error(f"{p}: is a folder, expected a {what} file") from None
    except OSError as e:
        raise error(f"{p}: cannot read ({e.strerror or e})") from None
    return decode_text(raw, p, encoding=encoding, what=what, error=error)
