"""Named method presets: a short name for a method string plus its options.

``relnav odometry SEQ --method extended`` runs the demo's best configuration without spelling
out its options; ``relnav methods`` lists every preset with its expansion. A preset is used
wherever a method string is: :func:`resolve_method` turns a name (preset or method string) and
user options into the ``(method string, options)`` pair that :func:`relnav.pipeline.run_sequence`
takes. Options given by the user override the preset's (nested dicts are merged).

Method names besides the registration families are the registered trackers (``relnav``, the
navigator): this layer does not know them, :func:`relnav.pipeline.resolve_method` passes them
in (``trackers``).
"""

from __future__ import annotations

import copy
import difflib
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any

from relnav.errors import ConfigError

__all__ = [
    "METHOD_PRESETS",
    "PAPER1_COMPETITORS",
    "MethodPreset",
    "method_label",
    "resolve_method",
]

PAPER1_COMPETITORS = ("icp-point", "icp-plane", "icp-x84", "s4pcs", "sicp-point", "sicp-plane")
"""Paper 1's competitor schemes; ``paper1-<name>`` is each as the paper ran it."""


@dataclass(frozen=True)
class MethodPreset:
    """A named configuration: ``method`` string, ``options`` and a one-line description."""

    method: str
    options: dict[str, Any] = field(default_factory=dict)
    description: str = ""

    def expansion(self) -> str:
        """The command-line spelling, e.g. ``feature:hods+gcc+svd -O refine=icp-plane``."""
        return " ".join([self.method, *(f"-O {k}={v}" for k, v in _flatten(self.options))])


METHOD_PRESETS: dict[str, MethodPreset] = {
    "paper1": MethodPreset(
        "feature:hods+gcc+alphabeta",
        {"motion_prior": "identity"},
        "paper 1's pipeline as published: HoD-S descriptors, GCC grouping, adaptive αβ filter, "
        "one support radius from the new scan's resolution for both scans; a step without a "
        "usable GCC cluster keeps the filter's initialisation (the identity)",
    ),
    "paper1-own-radius": MethodPreset(
        "feature:hods+gcc+alphabeta",
        {"radius_from": "own", "motion_prior": "identity"},
        "paper 1's pipeline with relnav's radius per scan (reuses the previous scan's "
        "descriptors; not the paper's rule, docs/paper1-deviations.md)",
    ),
    "paper1-svd": MethodPreset(
        "feature:hods+gcc+svd",
        {"motion_prior": "identity"},
        "paper 1's HoD-S + GCC correspondences, SVD (Kabsch) instead of the adaptive filter",
    ),
    "extended": MethodPreset(
        "feature:hods+gcc+svd",
        {
            "grouper_options": {"seeds": "all"},
            "refine": "icp-plane",
            "gate_rotation_deg": 15.0,
            "radius_from": "own",
            "match_from": "source",
        },
        "HoD-S with relnav's extensions: GCC seeded from every correspondence, SVD, "
        "point-to-plane ICP refinement, 15° innovation gate, each scan's own support radius, "
        "source-to-target matching (the demo's 'extended')",
    ),
    "relnav-tumbling": MethodPreset(
        "relnav",
        {"map": {"surface": "quadric"}, "startup": {"reanchor_frame": 20}},
        "relnav's navigator for a turning target seen by a sparse flash: curved map patches and "
        "the start-up re-anchored on the map of frames 5-20 (docs/navigator.md)",
    ),
    **{
        f"paper1-{m}": MethodPreset(
            f"{m}:paper",
            {"motion_prior": "identity"},
            f"paper 1's competitor {m} as the paper ran it: absolute thresholds (m, rad), "
            "started from the identity (the bare method string is relnav's tuned setting: "
            "scale-aware thresholds, constant-velocity start)",
        )
        for m in PAPER1_COMPETITORS
    },
}
"""Preset name → :class:`MethodPreset`."""


def _flatten(d: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.extend(_flatten(v, key + "."))
        else:
            out.append((key, v))
    return out


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _known_names(trackers: Collection[str] = ()) -> list[str]:
    from relnav.registration import available_methods

    names = [*trackers, *METHOD_PRESETS]
    for prefix, meta in available_methods().items():
        names.append(prefix)
        names.extend(meta["examples"])
    return list(dict.fromkeys(names))


def resolve_method(
    name: str, options: dict[str, Any] | None = None, trackers: Collection[str] = ()
) -> tuple[str, dict[str, Any], str | None]:
    """Expand a preset name, or check a method string's family, before any work starts.

    Parameters
    ----------
    name : str
        A preset name (:data:`METHOD_PRESETS`), a registered tracker's name or a method string
        (``relnav methods``).
    options : dict, optional
        User options; they override a preset's options (nested dicts merged).
    trackers : collection of str
        The registered trackers' names (lower case; :func:`relnav.pipeline.resolve_method`
        gives them).

    Returns
    -------
    method : str
        The method string.
    options : dict
        The expanded options.
    preset : str or None
        The preset name when ``name`` was one.

    Raises
    ------
    ConfigError
        Unknown preset or method family, with the closest known names ("did you mean").
    """
    from relnav.registration import available_methods

    opts = dict(options or {})
    key = name.strip()
    if key in METHOD_PRESETS:
        p = METHOD_PRESETS[key]
        return p.method, _merge(p.options, opts), key
    prefix = key.partition(":")[0].strip().lower()
    if key.lower() in trackers:
        return key.lower(), opts, None
    if prefix not in available_methods():
        known = _known_names(trackers)
        close = difflib.get_close_matches(key.lower(), known, n=3, cutoff=0.6)
        if not close:
            close = difflib.get_close_matches(prefix, known, n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise ConfigError(
            f"unknown method {name!r}{hint} (`relnav methods` lists methods and presets)"
        )
    return key, opts, None


def method_label(method: str, options: dict[str, Any] | None = None) -> str:
    """A short label: the preset name when ``(method, options)`` is one, else the method string."""
    for name, p in METHOD_PRESETS.items():
        if p.method == method and p.options == (options or {}):
            return name
    return method
