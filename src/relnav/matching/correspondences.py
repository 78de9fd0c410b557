"""The :class:`Correspondences` container shared by matching, grouping and estimation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Correspondences"]


@dataclass(frozen=True)
class Correspondences:
    """Putative point matches between a source and a target cloud.

    Attributes
    ----------
    src_idx : (M,) int64
        Indices into the source cloud (odometry: current scan ``k+1``).
    tgt_idx : (M,) int64
        Indices into the target cloud (odometry: previous scan ``k``).
    distance : (M,) float64
        Descriptor-space distance of each match (L2 on unit-normalised descriptors).
    """

    src_idx: np.ndarray
    tgt_idx: np.ndarray
    distance: np.ndarray

    def __post_init__(self) -> None:
        s = np.asarray(self.src_idx, dtype=np.int64).reshape(-1)
        t = np.asarray(self.tgt_idx, dtype=np.int64).reshape(-1)
        d = np.asarray(self.distance, dtype=np.float64).reshape(-1)
        if not (s.shape == t.shape == d.shape):
            raise ValueError("src_idx, tgt_idx and distance must have the same length")
        for name, arr in (("src_idx", s), ("tgt_idx", t), ("distance", d)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.src_idx.shape[0])

    @classmethod
    def empty(cls) -> Correspondences:
        """No correspondences."""
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))

    def subset(self, mask_or_idx: np.ndarray) -> Correspondences:
        """The correspondences selected by a boolean mask or an index array (order kept)."""
        return Correspondences(
            self.src_idx[mask_or_idx], self.tgt_idx[mask_or_idx], self.distance[mask_or_idx]
        )

    def sorted_by_distance(self) -> Correspondences:
        """Copy sorted by ascending descriptor distance (stable)."""
        order = np.argsort(self.distance, kind="stable")
        return self.subset(order)
