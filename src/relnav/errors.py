"""Exceptions raised by relnav.

Every error a user can cause (bad file, bad config, impossible request) derives from
:class:`RelnavError`, so the CLI can print one clear line instead of a traceback.
"""

from __future__ import annotations

__all__ = ["ConfigError", "EstimationError", "InputError", "OutputError", "RelnavError"]


class RelnavError(Exception):
    """Base class of every error relnav raises on purpose."""


class InputError(RelnavError):
    """A file or array given to relnav is missing, corrupt, or of the wrong shape/format."""


class ConfigError(RelnavError):
    """A configuration (YAML scenario, method string, option) is invalid."""


class EstimationError(RelnavError):
    """An estimation could not be carried out (e.g. not enough matched poses to evaluate)."""


class OutputError(RelnavError):
    """An output cannot be written: a read-only or full file system, or an output folder in use
    by another run. The message names the path and the reason."""
