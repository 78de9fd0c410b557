"""Shared configuration helpers: YAML loading with clear errors, pydantic error formatting."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from relnav.errors import ConfigError

__all__ = ["StrictModel", "dump_yaml", "format_validation_error", "load_yaml", "validate"]


class StrictModel(BaseModel):
    """Base of every relnav config model: unknown keys are errors, values validated."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping; :class:`ConfigError` naming the file on any problem."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such file")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ConfigError(f"{p}: invalid YAML: {e}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def dump_yaml(data: dict[str, Any], path: str | Path | None = None) -> str:
    """YAML text of ``data`` (keys in insertion order); also written to ``path`` if given."""
    text = yaml.safe_dump(data, sort_keys=False)
    if path is not None:
        Path(path).write_text(text)
    return text


def format_validation_error(err: ValidationError, source: str = "config") -> str:
    """One line per problem: ``source: a.b.c: message``."""
    lines = []
    for e in err.errors():
        loc = ".".join(str(x) for x in e["loc"]) or "(root)"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        lines.append(f"{source}: {loc}: {msg}")
    return "; ".join(lines)


def validate(model: type[BaseModel], data: dict[str, Any], source: str = "config") -> Any:
    """``model.model_validate(data)`` raising :class:`ConfigError` with a readable message."""
    try:
        return model.model_validate(data)
    except ValidationError as e:
        raise ConfigError(format_validation_error(e, source)) from None
