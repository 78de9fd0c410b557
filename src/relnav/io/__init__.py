"""File I/O: point clouds, meshes, trajectories (TUM/KITTI), sequence folders, recordings.

:func:`open_sequence` opens any input odometry accepts: a sequence folder, a KITTI folder, a
plain folder of scans, or a ROS 1/ROS 2/MCAP recording (:class:`BagSequence`, extra ``[ros]``).

Every reader raises :class:`relnav.errors.InputError` naming the file when something is wrong;
warnings (e.g. dropped NaN points) go to the ``relnav.io`` logger.
"""

from relnav.io.bags import BagSequence
from relnav.io.meshes import MESH_EXTENSIONS, read_mesh, write_mesh
from relnav.io.pointclouds import (
    POINT_READ_EXTENSIONS,
    POINT_WRITE_EXTENSIONS,
    lzf_decompress,
    read_points,
    read_scan,
    write_points,
    write_scan,
)
from relnav.io.sequences import (
    ScanSequence,
    SequenceLayout,
    SequenceWriter,
    sequence_layout,
    write_sequence,
)
from relnav.io.sources import FileSequence, open_sequence
from relnav.io.trajectories import read_kitti, read_trajectory, read_tum, write_kitti, write_tum

__all__ = [
    "MESH_EXTENSIONS",
    "POINT_READ_EXTENSIONS",
    "POINT_WRITE_EXTENSIONS",
    "BagSequence",
    "FileSequence",
    "ScanSequence",
    "SequenceLayout",
    "SequenceWriter",
    "lzf_decompress",
    "open_sequence",
    "read_kitti",
    "read_mesh",
    "read_points",
    "read_scan",
    "read_trajectory",
    "read_tum",
    "sequence_layout",
    "write_kitti",
    "write_mesh",
    "write_points",
    "write_scan",
    "write_sequence",
    "write_tum",
]
