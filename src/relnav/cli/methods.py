"""``relnav methods``: list every registration method, the named presets and the building blocks."""

from __future__ import annotations

import importlib.util

import typer
from rich.markup import escape

from relnav.cli._common import console

_EXTRA_MODULES = {"baselines": ("open3d", "kiss_icp", "small_gicp", "kiss_matcher")}
# the module a method of an extra actually imports (method prefix -> module)
_METHOD_MODULES = {
    "o3d-": "open3d",
    "kiss-icp": "kiss_icp",
    "small-gicp": "small_gicp",
    "kiss-matcher": "kiss_matcher",
}


def _extra_available(extra: str | None, method: str = "") -> bool:
    if extra is None:
        return True
    mods = [m for p, m in _METHOD_MODULES.items() if method.startswith(p)]
    mods = mods or list(_EXTRA_MODULES.get(extra, ()))
    return all(importlib.util.find_spec(m) is not None for m in mods)


def methods() -> None:
    """List registration methods, named presets, descriptors, groupers and estimators."""
    from rich.table import Table

    from relnav.estimation import available_estimators
    from relnav.features import available_descriptors
    from relnav.matching.grouping import available_groupers
    from relnav.odometry.presets import METHOD_PRESETS
    from relnav.pipeline import available_trackers  # also registers paper 2's methods
    from relnav.registration import available_methods

    t = Table(title="registration methods (use with `relnav odometry --method`)")
    for col in ("method", "description", "available"):
        t.add_column(col)
    for name, entry in available_trackers().items():
        t.add_row(name, escape(entry.description), "yes")
    for name, meta in available_methods().items():
        extra = meta["extra"]
        if extra is None:
            avail = "yes"
        elif _extra_available(extra, name):
            avail = escape(f"yes [{extra}]")
        else:
            hint = escape(f"needs pip install 'relnav[{extra}]'")
            avail = f"[yellow]{hint}[/]"
        t.add_row(escape(", ".join(meta["examples"])), escape(meta["description"]), avail)
    console.print(t)
    from relnav.odometry.budget import DEFAULT_BUDGET_TARGET, DEFAULT_POINT_BUDGET
    from relnav.odometry.odometry import DEFAULT_DENSE_KEYPOINTS

    console.print(
        escape(
            f"Point budget: pairwise methods without a [baselines] tag get scans above "
            f"{DEFAULT_POINT_BUDGET} points reduced to a seeded random {DEFAULT_BUDGET_TARGET} "
            "(-O point_budget=N, budget_target=M, budget_sampler=voxel; point_budget=None keeps "
            "every point); the navigator keeps map.max_points; the peers use their own range-based "
            "downsampling on scans above 5000 points. Dense mode (beyond paper 1, reduced scans "
            f"only): feature pipelines describe a seeded random {DEFAULT_DENSE_KEYPOINTS} points "
            "of a reduced scan and their step is refined by point-to-plane ICP, the step check's "
            "referee (-O dense_refine=off, dense_keypoints=None)."
        )
    )
    presets = Table(title="method presets (use the name with `relnav odometry --method`)")
    for col in ("preset", "expands to", "description"):
        presets.add_column(col)
    for name, p in METHOD_PRESETS.items():
        presets.add_row(name, escape(p.expansion().replace(" -O ", "\n-O ")), escape(p.description))
    console.print(presets)
    parts = Table(title="parts of feature:<descriptor>+<grouper>+<estimator>")
    for col in ("kind", "name", "description"):
        parts.add_column(col)
    for name, spec in available_descriptors().items():
        parts.add_row(
            "descriptor", name, f"{spec.description} (D={spec.dim}, r={spec.radius_factor:g}·Tr)"
        )
    for name, desc in available_groupers().items():
        parts.add_row("grouper", name, desc)
    for name, desc in available_estimators().items():
        parts.add_row("estimator", name, desc)
    console.print(parts)
    console.print(navigator_options_table())


def navigator_options_table() -> object:
    """relnav's options, section by section: ``-O section.key=value``, default, range and
    meaning (the fields of :data:`relnav.navigation.options.SECTIONS`)."""
    from rich.table import Table

    from relnav.navigation.options import SECTIONS, range_text

    table = Table(
        title="relnav's options (-O section.key=value; at length in docs/navigator.md, Options)"
    )
    for col in ("option", "default", "range", "meaning"):
        table.add_column(col)
    for section, model in SECTIONS.items():
        for key, field in model.model_fields.items():
            table.add_row(
                f"{section}.{key}",
                escape(repr(field.default)),
                escape(range_text(field)),
                escape(field.description or ""),
            )
    return table


def register(app: typer.Typer) -> None:
    """Register ``relnav methods``."""
    app.command("methods")(methods)
