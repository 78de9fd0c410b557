"""Descriptor matching and correspondence grouping (NN, GCC, RANSAC, CLGV).

Source = current scan ``k+1`` (PCL "scene"), target = previous scan ``k`` (PCL "model");
``Correspondences.src_idx`` index the source cloud, ``tgt_idx`` the target cloud.
"""

from relnav.matching.clgv import ClgvResult, clgv_select, clgv_vote
from relnav.matching.correspondences import Correspondences
from relnav.matching.gcc import consistency_bitset, geometric_consistency_grouping
from relnav.matching.grouping import (
    ClgvGrouper,
    GccGrouper,
    Grouper,
    NoGrouper,
    RansacGrouper,
    available_groupers,
    get_grouper,
    register_grouper,
)
from relnav.matching.nn import match_descriptors, normalize_descriptors
from relnav.matching.ransac import RansacResult, ransac_correspondences, ransac_search

__all__ = [
    "ClgvGrouper",
    "ClgvResult",
    "Correspondences",
    "GccGrouper",
    "Grouper",
    "NoGrouper",
    "RansacGrouper",
    "RansacResult",
    "available_groupers",
    "clgv_select",
    "clgv_vote",
    "consistency_bitset",
    "geometric_consistency_grouping",
    "get_grouper",
    "match_descriptors",
    "normalize_descriptors",
    "ransac_correspondences",
    "ransac_search",
    "register_grouper",
]
