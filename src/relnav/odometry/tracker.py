"""The per-frame tracker protocol: :class:`Tracker`, its capabilities, :class:`TrackerEntry`.

A tracker turns scans into poses one frame at a time: ``register_frame(scan) -> OdometryStep``.
:class:`relnav.odometry.Odometry` (pairwise registration with any method) and relnav's navigator
(:class:`relnav.navigation.Navigator`) are trackers. Anything else a run may ask of a tracker is
an optional **capability**, declared by the tracker's class in ``capabilities`` (a frozenset of
the names in :data:`CAPABILITIES`) instead of being guessed from its attributes:

``skip_frame``
    ``skip_frame(reason) -> OdometryStep``: a frame whose scan could not be read is flagged
    ``failed`` and the run goes on (without it such a frame ends the run).
``smoother``
    ``finalize() -> (N, 4, 4)``: after the last frame the tracker returns its poses of every frame
    again, using later frames (a smoother); the run keeps them as its estimate and the per-frame
    poses as its causal trajectory.
``final_report``
    ``final_report() -> dict``: what the tracker decided once per run (``run.json``'s
    ``options.finalize``).
``step_check``
    ``step_checker``: a :class:`relnav.odometry.step_check.StepChecker` or ``None``; its mode is
    recorded in the run's options.

Trackers are found by name in the registry of :mod:`relnav.pipeline.registry` (a layer above this
one, so that the navigator, which sits above odometry, registers there with a plain import). A
registered name is a :class:`TrackerEntry`: the name, a factory and the capabilities.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from relnav.errors import ConfigError

__all__ = ["CAPABILITIES", "Tracker", "TrackerEntry", "capabilities_of"]

CAPABILITIES: dict[str, str] = {
    "skip_frame": "skip_frame",
    "smoother": "finalize",
    "final_report": "final_report",
    "step_check": "step_checker",
}
"""Capability name → the attribute a tracker declaring it provides."""


@runtime_checkable
class Tracker(Protocol):
    """A per-frame tracker: ``register_frame(scan) -> OdometryStep`` (``scan``: a
    :class:`relnav.scan.Scan` or an ``(N, 3)`` array, sensor frame, m); the optional
    ``capabilities`` class attribute names what else it offers (:data:`CAPABILITIES`)."""

    def register_frame(self, scan: Any) -> Any:
        """Register one scan; returns its :class:`relnav.odometry.OdometryStep`."""
        ...


def capabilities_of(tracker: Any) -> frozenset[str]:
    """The capabilities ``tracker`` declares (empty when it declares none).

    Raises
    ------
    ConfigError
        An unknown capability name, or a declared capability whose attribute is missing.
    """
    declared = getattr(type(tracker), "capabilities", frozenset())
    caps = frozenset(declared)
    unknown = sorted(caps - set(CAPABILITIES))
    if unknown:
        raise ConfigError(
            f"{type(tracker).__name__} declares unknown capabilities {unknown}; "
            f"known: {sorted(CAPABILITIES)}"
        )
    missing = [c for c in sorted(caps) if not hasattr(tracker, CAPABILITIES[c])]
    if missing:
        raise ConfigError(
            f"{type(tracker).__name__} declares {missing} but has no "
            f"{', '.join(CAPABILITIES[c] for c in missing)}"
        )
    return caps


@dataclass(frozen=True)
class TrackerEntry:
    """A registered tracker: ``factory(initial_pose=T0, **options)`` builds it.

    Attributes
    ----------
    name : str
        The method name (``relnav``), lower case.
    factory : callable
        ``factory(*, initial_pose, **options) -> Tracker``; ``initial_pose`` is the first
        frame's ``T_world_sensor`` (4, 4) or ``None`` (identity).
    capabilities : frozenset of str
        What the trackers it builds declare (:data:`CAPABILITIES`).
    description : str
        One line for ``relnav methods``.
    """

    name: str
    factory: Callable[..., Any]
    capabilities: frozenset[str] = frozenset()
    description: str = ""

    def build(self, *, initial_pose: Any = None, **options: Any) -> Any:
        """A fresh tracker (``initial_pose``: (4, 4) or ``None``)."""
        return self.factory(initial_pose=initial_pose, **options)
