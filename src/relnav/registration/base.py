"""The :class:`Registration` protocol, method strings and the method registry.

A registration method aligns a *source* cloud onto a *target* cloud and returns a
:class:`~relnav.registration.result.RegistrationResult` with ``T_target_source``
(``target ≈ T @ source``). Methods are named by strings: a family prefix, optionally followed by
``:`` and a family-specific spec, e.g. ``"feature:hods+gcc+alphabeta"`` or ``"icp-point"``.

Methods that can reuse per-cloud work between calls (descriptors of the previous scan in odometry)
implement the optional :class:`PreparedRegistration` protocol: ``prepare(points)`` returns an
opaque object that ``register_prepared(source_prep, target_prep, init=...)`` consumes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from relnav.config import check_options, did_you_mean
from relnav.errors import ConfigError
from relnav.registration.result import RegistrationResult

__all__ = [
    "PreparedRegistration",
    "Registration",
    "available_methods",
    "get_registration",
    "register_method",
    "register_variants",
]


@runtime_checkable
class Registration(Protocol):
    """Anything with ``name`` and ``register(source, target, *, init=None)``."""

    name: str

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult: ...


@runtime_checkable
class PreparedRegistration(Registration, Protocol):
    """A registration that can precompute per-cloud data once and reuse it."""

    def prepare(self, points: np.ndarray) -> Any: ...

    def register_prepared(
        self, source: Any, target: Any, *, init: np.ndarray | None = None
    ) -> RegistrationResult: ...


# prefix -> (factory(spec, **options) -> Registration, description, needs_extra)
_REGISTRY: dict[str, tuple[Callable[..., Registration], str, str | None]] = {}
_EXAMPLES: dict[str, list[str]] = {}


def register_method(
    prefix: str, description: str, *, extra: str | None = None, examples: list[str] | None = None
) -> Callable[[Callable[..., Registration]], Callable[..., Registration]]:
    """Register a factory ``factory(spec: str | None, **options)`` for the method ``prefix``.

    ``extra`` names the optional-dependency extra the method needs (e.g. ``"baselines"``).
    """

    def deco(factory: Callable[..., Registration]) -> Callable[..., Registration]:
        _REGISTRY[prefix] = (factory, description, extra)
        _EXAMPLES[prefix] = examples or [prefix]
        return factory

    return deco


def register_variants(cls: type, variants: dict[str, tuple[str, str]]) -> None:
    """Register ``cls(variant, **options)`` under each method prefix of ``variants``.

    ``variants`` maps a prefix to ``(variant, description)``; a method spec ``paper`` or
    ``scale`` sets ``thresholds`` (``"icp-point:paper"``), examples are ``prefix`` and
    ``prefix:paper``. The factories' return annotation is ``cls``, so :func:`get_registration`
    checks the options against ``cls``'s signature.
    """
    for prefix, (variant, description) in variants.items():
        register_method(prefix, description, examples=[prefix, f"{prefix}:paper"])(
            _threshold_factory(cls, prefix, variant)
        )


def register_fixed(
    cls: type, methods: dict[str, tuple[str, dict[str, Any]]], *, extra: str | None = None
) -> None:
    """Register ``cls(**fixed, **options)`` under each method prefix of ``methods``.

    ``methods`` maps a prefix to ``(description, fixed)``: the keyword arguments that make the
    method (e.g. ``{"variant": "plane"}``). The method takes no ``:`` spec, and an option that
    repeats a fixed argument is a :class:`ConfigError`. The factories' return annotation is
    ``cls``, so :func:`get_registration` checks the options against ``cls``'s signature.
    """
    for prefix, (description, fixed) in methods.items():
        register_method(prefix, description, extra=extra)(_fixed_factory(cls, prefix, fixed))


def _fixed_factory(cls: type, prefix: str, fixed: dict[str, Any]) -> Callable[..., Registration]:
    def factory(spec: str | None, **options: Any) -> Registration:
        if spec:
            raise ConfigError(f"method {prefix!r} takes no ':' spec, got {spec!r}")
        clash = sorted(set(fixed) & set(options))
        if clash:
            raise ConfigError(f"method {prefix!r} sets {clash[0]!r} itself; it is not an option")
        return cls(**fixed, **options)

    return _factory_of(cls, prefix, factory)


def _factory_of(
    cls: type, prefix: str, factory: Callable[..., Registration]
) -> Callable[..., Registration]:
    """Name ``factory`` after ``prefix`` and annotate it as returning ``cls`` (the option check
    of :func:`get_registration` reads that annotation)."""
    factory.__annotations__ = {**factory.__annotations__, "return": cls}
    factory.__name__ = factory.__qualname__ = f"_make_{prefix.replace('-', '_')}"
    return factory


def _threshold_factory(cls: type, prefix: str, variant: str) -> Callable[..., Registration]:
    def factory(spec: str | None, **options: Any) -> Registration:
        if spec:
            s = spec.strip().lower()
            if s not in ("paper", "scale"):
                raise ConfigError(f"{prefix}: spec must be 'paper' or 'scale', got {spec!r}")
            options = {**options, "thresholds": s}
        return cls(variant, **options)

    return _factory_of(cls, prefix, factory)


METHOD_MODULES: tuple[str, ...] = (
    "relnav.registration.feature",
    "relnav.registration.clgv",
    "relnav.registration.icp",
    "relnav.registration.sparse_icp",
    "relnav.registration.super4pcs",
    "relnav.registration.external",
    "relnav.registration.kiss_matcher",
)
"""This package's modules whose import registers method families (loaded on first use, so that
``import relnav.registration`` stays cheap). Packages above this one register their own methods
when they are imported (paper 2's ``cga-sphere`` and ``cbd`` in :mod:`relnav.fusion`);
:mod:`relnav.pipeline.registry`, which every command that runs a method goes through, imports
them, so that no module here names a package above it."""


def _load_all() -> None:
    import importlib

    for name in METHOD_MODULES:
        importlib.import_module(name)


def available_methods() -> dict[str, dict[str, Any]]:
    """Registered method families: ``{prefix: {"description", "extra", "examples"}}``."""
    _load_all()
    return {
        k: {"description": v[1], "extra": v[2], "examples": _EXAMPLES[k]}
        for k, v in sorted(_REGISTRY.items())
    }


def get_registration(method: str, **options: Any) -> Registration:
    """Build the registration named by ``method`` (e.g. ``"feature:hods+gcc+alphabeta"``).

    Raises
    ------
    ConfigError
        Unknown method family or bad spec/options.
    """
    _load_all()
    prefix, sep, spec = method.partition(":")
    prefix = prefix.strip().lower()
    if prefix not in _REGISTRY:
        raise ConfigError(
            f"unknown method {method!r}{did_you_mean(prefix, _REGISTRY)}; families: "
            f"{', '.join(sorted(_REGISTRY))} (see `relnav methods`)"
        )
    if sep and not spec.strip():
        raise ConfigError(
            f"method {method!r}: empty spec after ':'; e.g. {', '.join(_EXAMPLES[prefix])}"
        )
    factory = _REGISTRY[prefix][0]
    built = _built_class(factory)
    if built is not None:
        options = check_options(built, options, where=f"method {method!r}")
    try:
        return factory(spec.strip() or None, **options)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"bad options for method {method!r}: {e}") from None


def _built_class(factory: Callable[..., Registration]) -> type | None:
    """The class a factory returns (its return annotation), whose options are checked."""
    import typing

    try:
        ret = typing.get_type_hints(factory).get("return")
    except Exception:  # unresolvable annotation: the factory checks its own options
        return None
    return ret if isinstance(ret, type) else None
