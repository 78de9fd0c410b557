"""Helpers shared by the CLI commands: key=value options, progress bars, tables."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import yaml
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from relnav.errors import ConfigError

console = Console()


def parse_options(items: Iterable[str] | None) -> dict[str, Any]:
    """``["a=1", "b.c=true"]`` → ``{"a": 1, "b": {"c": True}}`` (values parsed as YAML)."""
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"option {item!r} is not of the form key=value")
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
                raise ConfigError(f"option {item!r} conflicts with another option")
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
