"""The :class:`RegistrationResult` every registration method returns (defined in
:mod:`relnav.geometry.registration_result`, below the ICP solver that both estimation and
registration use)."""

from relnav.geometry.registration_result import RegistrationResult, RegistrationStatus

__all__ = ["RegistrationResult", "RegistrationStatus"]
