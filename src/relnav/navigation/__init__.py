"""relnav's own navigator: frame-to-model tracking of a space target (method ``relnav``)."""

from relnav.navigation.navigator import Navigator, NavigatorConfig
from relnav.navigation.voxel_map import VoxelMap

__all__ = ["Navigator", "NavigatorConfig", "VoxelMap"]
