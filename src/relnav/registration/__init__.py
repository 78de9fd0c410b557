"""Registration methods (feature pipeline, ICP family, baselines) behind one interface."""

from relnav.registration.base import (
    PreparedRegistration,
    Registration,
    available_methods,
    get_registration,
    register_method,
)
from relnav.registration.result import RegistrationResult

__all__ = [
    "PreparedRegistration",
    "Registration",
    "RegistrationResult",
    "available_methods",
    "get_registration",
    "register_method",
]
