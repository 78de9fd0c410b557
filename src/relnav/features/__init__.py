"""3D local descriptors (HoD, HoD-S, SHOT, FPFH, RoPS, TriSI, spin image) and keypoints."""

from relnav.features.base import (
    MIN_SUPPORT,
    DescriptorSpec,
    available_descriptors,
    compute,
    get_descriptor,
    register_descriptor,
)
from relnav.features.keypoints import select_keypoints, voxel_downsample

__all__ = [
    "MIN_SUPPORT",
    "DescriptorSpec",
    "available_descriptors",
    "compute",
    "get_descriptor",
    "register_descriptor",
    "select_keypoints",
    "voxel_downsample",
]
