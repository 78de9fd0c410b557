"""Shared configuration helpers: YAML loading with clear errors, pydantic error formatting."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from relnav.atomic import read_text_file
from relnav.errors import ConfigError

__all__ = [
    "FINITE_OPTIONS",
    "OPTION_RANGES",
    "StrictModel",
    "check_options",
    "describe_range",
    "did_you_mean",
    "dump_yaml",
    "format_validation_error",
    "load_yaml",
    "option_parameters",
    "validate",
]


class StrictModel(BaseModel):
    """Base of every relnav config model: unknown keys are errors, values validated."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping; :class:`ConfigError` naming the file on any problem."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such file")
    try:
        data = yaml.safe_load(read_text_file(p, what="YAML", error=ConfigError))
    except yaml.YAMLError as e:
        raise ConfigError(f"{p}: invalid YAML: {e}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def dump_yaml(data: dict[str, Any], path: str | Path | None = None) -> str:
    """YAML text of ``data`` (keys in insertion order); also written (atomically) to ``path``."""
    text = yaml.safe_dump(data, sort_keys=False)
    if path is not None:
        from relnav.atomic import atomic_write_text

        atomic_write_text(path, text)
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


# --------------------------------------------------------------------------------------------
# keyword options of a class or function (``-O key=value``): names, types, ranges
# --------------------------------------------------------------------------------------------

_Range = tuple[float | None, bool, float | None, bool]
"""``(low, low_inclusive, high, high_inclusive)``; ``None`` = unbounded."""

OPTION_RANGES: dict[str, _Range] = {
    "max_iter": (1, True, None, False),
    "max_iterations": (1, True, None, False),
    "min_points": (1, True, None, False),
    "stop_window": (1, True, None, False),
    "normal_k": (3, True, None, False),
    "k": (1, True, None, False),
    "tau": (0, False, None, False),
    "radius_factor": (0, False, None, False),
    "normal_radius_factor": (0, False, None, False),
    "gate_factor": (0, False, None, False),
    "translation_tol_factor": (0, False, None, False),
    "max_correspondence_distance": (0, False, None, False),
    "translation_tol": (0, True, None, False),
    "rotation_tol": (0, True, None, False),
    "std_factor": (0, True, None, False),
    "x84_factor": (0, False, None, False),
    "relative_fitness": (0, True, None, False),
    "relative_rmse": (0, True, None, False),
    "degeneracy_ratio": (0, True, 1, False),
    "epsilon": (0, False, None, False),
    "epsilon_factor": (0, False, None, False),
    "voxel_size": (0, False, None, False),
    "gate_rotation_deg": (0, False, 180, True),
    "gate_translation": (0, False, None, False),
    # the registration adapters (relnav's navigator ranges its own options beside them:
    # relnav.navigation.options)
    "voxel_factor": (0, False, None, False),
    "kernel": (0, False, None, False),
    "kernel_start": (0, False, None, False),
    "tolerance": (0, False, None, False),
    "kernel_decay": (0, False, 1, True),
    "max_points": (6, True, None, False),
}
"""Accepted ranges of numeric options, by name, whatever the method (an option of that name
means the same thing everywhere in relnav). Every float option must also not be NaN."""

FINITE_OPTIONS: frozenset[str] = frozenset()
"""Options that must also be finite (where an infinity is no value); others, such as a
correspondence distance, may be ``inf`` (no limit). None at present: the navigator's orbit
inputs, the former members, are checked by their own model (``allow_inf_nan=False`` in
:class:`relnav.navigation.options.OrbitOptions`)."""


DID_YOU_MEAN_N = 3
"""Names a "did you mean" offers at most, nearest first."""

LIST_ALL_MAX = 15
"""An unknown option's message lists every accepted name only when there are at most this
many (a method has over a hundred: the nearest names are shown instead)."""


def close_names(word: str, choices: Any, n: int = DID_YOU_MEAN_N) -> list[str]:
    """The ``n`` names of ``choices`` nearest to ``word`` (difflib's ratio ≥ 0.6), nearest
    first."""
    import difflib

    return difflib.get_close_matches(str(word), [str(c) for c in choices], n=n, cutoff=0.6)


def did_you_mean(word: str, choices: Any) -> str:
    """``" (did you mean 'x', 'y' or 'z'?)"`` for the (at most 3) nearest of ``choices``,
    nearest first, or ``""``."""
    close = [repr(c) for c in close_names(word, choices)]
    if not close:
        return ""
    names = close[0] if len(close) == 1 else f"{', '.join(close[:-1])} or {close[-1]}"
    return f" (did you mean {names}?)"


def _accepted(word: str, choices: Any) -> str:
    """The tail of an unknown-name message: every name when they are few, else how many there
    are (and the first few alphabetically when none is near ``word``)."""
    names = sorted(str(c) for c in choices)
    if len(names) <= LIST_ALL_MAX:
        return f"accepted: {', '.join(names) or '(none)'}"
    if close_names(word, names):  # the did-you-mean already shows the nearest
        return f"{len(names)} options accepted"
    return f"{len(names)} options accepted, e.g. {', '.join(names[:DID_YOU_MEAN_N])}"


def describe_range(r: _Range) -> str:
    """``">= 0 and <= 1"``: a range ``(low, low_inclusive, high, high_inclusive)`` in words."""
    lo, lo_inc, hi, hi_inc = r
    parts = []
    if lo is not None:
        parts.append(f"{'>=' if lo_inc else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"{'<=' if hi_inc else '<'} {hi:g}")
    return " and ".join(parts)


def _in_range(v: float, r: _Range) -> bool:
    lo, lo_inc, hi, hi_inc = r
    if lo is not None and (v < lo or (v == lo and not lo_inc)):
        return False
    return not (hi is not None and (v > hi or (v == hi and not hi_inc)))


def option_parameters(target: Any) -> tuple[dict[str, Any], bool]:
    """Keyword options ``{name: annotation}`` of a class (its ``__init__``, following
    ``**kwargs`` up the MRO) or a function, and whether it still accepts any other key.

    Positional-only and ``*args`` parameters are skipped; ``Any`` stands for annotations
    that cannot be resolved.
    """
    import inspect
    import typing

    funcs: list[Any] = []
    if isinstance(target, type):
        funcs = [c.__dict__["__init__"] for c in target.__mro__ if "__init__" in c.__dict__]
        funcs = [f for f in funcs if f is not object.__init__]
    else:
        funcs = [target]
    params: dict[str, Any] = {}
    open_ = False
    for fn in funcs:
        try:
            sig = inspect.signature(fn)
        except (TypeError, ValueError):
            return params, True
        try:
            hints = typing.get_type_hints(fn)
        except Exception:  # unresolvable forward references: no type checks
            hints = {}
        var_kw = False
        for i, (name, p) in enumerate(sig.parameters.items()):
            if i == 0 and name in ("self", "cls") and isinstance(target, type):
                continue
            if p.kind is inspect.Parameter.VAR_KEYWORD:
                var_kw = True
            elif p.kind in (
                inspect.Parameter.KEYWORD_ONLY,
                inspect.Parameter.POSITIONAL_OR_KEYWORD,
            ):
                params.setdefault(name, hints.get(name, Any))
        if not var_kw:
            return params, False
        open_ = True
    return params, open_


def check_options(
    target: Any,
    options: dict[str, Any],
    *,
    where: str,
    skip: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Check keyword ``options`` for ``target`` (a class or function) before using them.

    Unknown keys (with a "did you mean"), values of the wrong type (``max_iter=2.5`` or
    ``"abc"`` for an int), NaN floats and values outside :data:`OPTION_RANGES` raise a one-line
    :class:`ConfigError` naming ``where``, the key and the accepted values.

    Returns
    -------
    dict
        The options with their values converted to the annotated types (``"1E0"`` → ``1.0``
        for a float); keys the signature does not name (``**kwargs``) unchanged.
    """
    from pydantic import TypeAdapter

    params, open_ = option_parameters(target)
    for key in skip:
        params.pop(key, None)
    out = dict(options)
    for key, value in options.items():
        if key not in params:
            if open_:
                continue
            raise ConfigError(
                f"{where}: unknown option {key!r}{did_you_mean(key, params)}; "
                f"{_accepted(key, params)}"
            )
        ann = params[key]
        if ann is not Any:
            try:
                adapter = TypeAdapter(ann, config={"arbitrary_types_allowed": True})
            except Exception:  # annotation pydantic cannot express (e.g. a Protocol)
                adapter = None
            if adapter is not None:
                try:
                    value = out[key] = adapter.validate_python(value)
                except ValidationError as e:
                    msg = e.errors()[0]["msg"] if e.errors() else str(e)
                    raise ConfigError(
                        f"{where}: option {key}={value!r}: {msg} (expected {_ann_name(ann)})"
                    ) from None
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if value != value:  # NaN
            raise ConfigError(f"{where}: option {key} is NaN")
        if key in FINITE_OPTIONS and not math.isfinite(value):
            raise ConfigError(f"{where}: option {key}={options[key]!r} is not finite")
        r = OPTION_RANGES.get(key)
        if r is not None and not _in_range(float(value), r):
            raise ConfigError(
                f"{where}: option {key}={options[key]!r} out of range (must be {describe_range(r)})"
            )
    return out


def _ann_name(ann: Any) -> str:
    name = getattr(ann, "__name__", None)
    return name if name and not getattr(ann, "__args__", None) else str(ann).replace("typing.", "")
