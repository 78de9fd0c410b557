"""File I/O: point clouds, meshes, trajectories (TUM/KITTI) and sequence folders."""
