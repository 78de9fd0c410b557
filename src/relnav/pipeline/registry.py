"""The tracker registry: method names that are trackers of their own (``relnav``, the navigator).

A method name is either a registration method (``icp-point``, ``feature:hods+gcc+alphabeta`` …:
run frame to frame by :class:`relnav.odometry.Odometry`, registered in
:mod:`relnav.registration`) or a **registered tracker**: a name bound to a factory of
:class:`relnav.odometry.tracker.Tracker` objects with declared capabilities.
:func:`register_tracker` adds one (a plug-in tracker the same way as the built-in one)::

    from relnav.pipeline import register_tracker

    register_tracker("my-tracker", MyTracker, description="what it does")
    run_pipeline(seq, "my-tracker", out="runs/mine")

The same goes for registration methods defined above :mod:`relnav.registration`: paper 2's
``cga-sphere`` and ``cbd`` (:mod:`relnav.fusion`) register when their modules are imported, and
this module imports them.

Why the table is here, in the pipeline layer: the navigator sits *above* odometry
(:mod:`relnav.navigation` imports :mod:`relnav.odometry`), so odometry cannot name it without an
upward import (it did so through an import path in a string, hidden from the layer test). The
pipeline sits above both: it imports the navigator like any other module, registers it below,
and resolves method names for everything that runs a sequence (the CLI, the demo, the benchmark
worker, scripts). :mod:`relnav.odometry` keeps only the protocol (:mod:`relnav.odometry.tracker`)
and runs whatever tracker it is handed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

# paper 2's registration methods (cga-sphere, cbd) register in relnav.registration when their
# modules are imported: every command that runs a method comes through here
import relnav.fusion.cbd
import relnav.fusion.cross_source  # noqa: F401
from relnav.errors import ConfigError
from relnav.navigation.navigator import Navigator
from relnav.odometry.tracker import CAPABILITIES, TrackerEntry

__all__ = [
    "available_trackers",
    "builds_navigator",
    "register_tracker",
    "tracker_entry",
    "unregister_tracker",
]

_TRACKERS: dict[str, TrackerEntry] = {}


def register_tracker(
    name: str,
    factory: Callable[..., Any],
    *,
    capabilities: frozenset[str] | set[str] | None = None,
    description: str = "",
    replace: bool = False,
) -> TrackerEntry:
    """Register a tracker under a method name.

    Parameters
    ----------
    name : str
        Method name (case-insensitive; no ``:``, not a registration family's prefix).
    factory : callable
        ``factory(*, initial_pose, **options) -> Tracker`` (a class taking those arguments).
    capabilities : set of str, optional
        What its trackers offer besides ``register_frame`` (:data:`CAPABILITIES`). Default: the
        factory's own ``capabilities`` attribute; when both are given they must agree.
    description : str
        One line for ``relnav methods``.
    replace : bool
        Allow replacing an existing registration of ``name``.

    Returns
    -------
    TrackerEntry

    Raises
    ------
    ConfigError
        Bad name, name taken, unknown capability, or capabilities that contradict the class's.
    """
    from relnav.registration import available_methods

    key = str(name).strip().lower()
    if not key or ":" in key or any(c.isspace() for c in key):
        raise ConfigError(f"tracker name {name!r}: one word without ':' or spaces")
    if key in available_methods():
        raise ConfigError(f"tracker name {key!r} is a registration method family")
    if key in _TRACKERS and not replace:
        raise ConfigError(f"tracker {key!r} is already registered (replace=True replaces it)")
    own = getattr(factory, "capabilities", None)
    if capabilities is None:
        caps = frozenset(own or ())
    else:
        caps = frozenset(capabilities)
        if own is not None and frozenset(own) != caps:
            raise ConfigError(
                f"tracker {key!r}: capabilities {sorted(caps)} contradict its class's {sorted(own)}"
            )
    unknown = sorted(caps - set(CAPABILITIES))
    if unknown:
        raise ConfigError(f"tracker {key!r}: unknown capabilities {unknown}")
    entry = TrackerEntry(key, factory, caps, description)
    _TRACKERS[key] = entry
    return entry


def unregister_tracker(name: str) -> None:
    """Remove a registered tracker (tests, plug-ins replacing one); unknown names are ignored."""
    _TRACKERS.pop(str(name).strip().lower(), None)


def tracker_entry(name: str) -> TrackerEntry | None:
    """The registered tracker named ``name`` (case-insensitive), or ``None``."""
    return _TRACKERS.get(str(name).strip().lower())


def builds_navigator(entry: TrackerEntry | None) -> bool:
    """Whether ``entry`` builds relnav's navigator (:class:`~relnav.navigation.Navigator` or a
    subclass): its run folder has the revisit counts and the relative state."""
    factory = entry.factory if entry is not None else None
    return isinstance(factory, type) and issubclass(factory, Navigator)


def available_trackers() -> dict[str, TrackerEntry]:
    """Registered trackers by name (sorted)."""
    return dict(sorted(_TRACKERS.items()))


register_tracker(
    "relnav",
    Navigator,
    description="relnav's own navigator (the default): frame-to-model robust GICP on a voxel map "
    "of the target, constant-velocity filter of pose and velocity as the prior, flags from "
    "overlap, degeneracy and motion consistency",
)
