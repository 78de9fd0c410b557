"""Descriptor matching and correspondence grouping (NN, GCC, RANSAC, CLGV)."""

from relnav.matching.correspondences import Correspondences

__all__ = ["Correspondences"]
