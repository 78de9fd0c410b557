"""Helpers shared by the CLI commands: key=value options, progress bars, tables."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import yaml
from rich.console import Console, ConsoleDimensions
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from relnav.errors import ConfigError

PIPE_WIDTH = 1000
"""Columns of the CLI's output when stdout is not a terminal and ``COLUMNS`` is not set: a
table piped to a file or another program is written at its full width, never cut to 80
columns with ``…``."""


class CliConsole(Console):
    """A rich console that is :data:`PIPE_WIDTH` wide when its output is not a terminal (and
    neither ``COLUMNS`` nor an explicit width says otherwise); a terminal's own width else."""

    @property
    def size(self) -> ConsoleDimensions:
        """The console's (width, height); see the class."""
        dims = super().size
        if (
            self._width is None
            and not self.is_terminal
            and not self._environ.get("COLUMNS", "").isdigit()
        ):
            return ConsoleDimensions(PIPE_WIDTH, dims.height)
        return dims

    @size.setter
    def size(self, new_size: tuple[int, int]) -> None:
        self._width, self._height = new_size


console = CliConsole()


def parse_options(
    items: Iterable[str] | None, *, flag: str = "option", nested: bool = True
) -> dict[str, Any]:
    """Parse repeated ``key=value`` command-line options.

    Parameters
    ----------
    items : iterable of str or None
        The options as typed, e.g. ``["a=1", "b.c=true"]``.
    flag : str
        How the error message names an option (``"option"``, ``"--param"``).
    nested : bool
        True: values parsed as YAML and dotted keys nested, ``{"a": 1, "b": {"c": True}}``.
        False: a flat ``{key: raw string}`` (dotted keys kept whole, values left for the
        consumer to parse, e.g. :func:`relnav.sim.scenario.apply_overrides`).

    Raises
    ------
    ConfigError
        An item without ``=`` or key, or (nested) a key that is both a value and a section.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"{flag} {item!r} is not of the form key=value")
        if not nested:
            out[key.strip()] = raw
            continue
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError:
            value = raw
        value = _number(value)
        node = out
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{flag} {item!r} conflicts with another option")
        node[parts[-1]] = value
    return out


def _number(value: Any) -> Any:
    """A string YAML 1.1 leaves unparsed but Python reads as a number (``1E0``, ``nan``,
    ``inf``, ``1_000``) → that number; anything else unchanged."""
    if not isinstance(value, str):
        return value
    s = value.strip()
    try:
        return int(s)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return value


def consistency_meaning(label: str, mean: float, band: tuple[float, float]) -> str | None:
    """One line saying what a mean NIS/NEES outside its 95 % band means, or None inside it.

    Parameters
    ----------
    label : str
        ``"NIS"`` (innovations against their predicted covariance) or ``"NEES"`` (errors
        against the ground truth and the filter's covariance).
    mean, band : float, (float, float)
        The mean statistic and its two-sided 95 % band (χ² of that many values).
    """
    lo, hi = band
    what = "innovations" if label == "NIS" else "errors against the ground truth"
    if mean > hi:
        return (
            f"mean {label} {mean:.3g} above its 95 % band [{lo:.2f}, {hi:.2f}]: the {what} are "
            "larger than the filter's covariance says (overconfident: noise set too low or a "
            "motion the model does not have)"
        )
    if mean < lo:
        return (
            f"mean {label} {mean:.3g} below its 95 % band [{lo:.2f}, {hi:.2f}]: the {what} are "
            "smaller than the filter's covariance says (cautious: noise set too high)"
        )
    return None


def progress_bar() -> Progress:
    """A rich progress bar writing to the CLI console."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    )
