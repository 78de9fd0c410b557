"""Atomic writes (temporary name, then rename): moved to :mod:`relnav.atomic`, re-exported here."""

from relnav.atomic import *  # noqa: F403
from relnav.atomic import __all__  # noqa: F401
