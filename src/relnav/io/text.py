"""Reading text files with one clear error on bad bytes: :func:`read_text_file` and
:func:`decode_text` (defined in :mod:`relnav.atomic`, at the foundation, so that
:mod:`relnav.config` uses them too).

A file whose bytes are not valid in its encoding (a binary file renamed, a Latin-1 export, a
truncated multi-byte character) raises :class:`relnav.errors.InputError` (or the error asked
for) naming the file and the byte offset.
"""

from relnav.atomic import decode_text, read_text_file

__all__ = ["decode_text", "read_text_file"]
