"""Paper 2: cross-source fusion (CGA point-to-sphere), plane clustering, contour model, and the
chain that tracks a target from them (its filters are in :mod:`relnav.filtering`).

Entry points are re-exported lazily (``import relnav.fusion`` stays cheap)::

    from relnav.fusion import cross_source_register, track_sequence
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "cross_source_register": "relnav.fusion.cross_source",
    "CrossSourceRegistration": "relnav.fusion.cross_source",
    "cluster_and_project": "relnav.fusion.clustering",
    "ContourModel": "relnav.fusion.reconstruction",
    "fuse_frame": "relnav.fusion.reconstruction",
    "CBDRegistration": "relnav.fusion.cbd",
    "track_sequence": "relnav.fusion.tracker",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'relnav.fusion' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)
