"""The navigator's start-up window: its first frames refined together (:class:`StartupWindow`)."""

from relnav.navigation.startup.window import StartupCorrection, StartupWindow

__all__ = ["StartupCorrection", "StartupWindow"]
