"""3D local descriptors (HoD, HoD-S, SHOT, FPFH, RoPS, TriSI, spin image) and keypoints."""

from relnav.features.base import (
    MIN_SUPPORT,
    DescriptorSpec,
    available_descriptors,
    compute,
    get_descriptor,
    register_descriptor,
)

__all__ = [
    "MIN_SUPPORT",
    "DescriptorSpec",
    "available_descriptors",
    "compute",
    "get_descriptor",
    "register_descriptor",
]
