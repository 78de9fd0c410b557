"""Reading text files (times, trajectories, calibration, YAML) with one clear error on bad bytes.

Every text file relnav reads goes through :func:`read_text_file`: a file whose bytes are not
valid in its encoding (a binary file renamed, a Latin-1 export, a truncated multi-byte
character) raises the project's error naming the file and the byte offset, never a
``UnicodeDecodeError`` traceback.
"""

from __future__ import annotations

from pathlib import Path

from relnav.errors import InputError, RelnavError

__all__ = ["decode_text", "read_text_file"]


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
