"""Triangle-mesh files (PLY, OBJ, STL, GLB/GLTF, OFF...) through trimesh.

A file holding a scene (several meshes with node transforms, typical of GLB/GLTF and multi-part
OBJ) is flattened into one :class:`trimesh.Trimesh` with every node transform applied. Mesh
coordinates are returned in the file's units (relnav expects metres; rescaling is the caller's
choice, see ``relnav.sim``).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import trimesh

from relnav.errors import InputError

__all__ = ["MESH_EXTENSIONS", "read_mesh", "write_mesh"]

logger = logging.getLogger("relnav.io")

MESH_EXTENSIONS: tuple[str, ...] = (".ply", ".obj", ".stl", ".glb", ".gltf", ".off")
"""Extensions :func:`read_mesh` / :func:`write_mesh` accept (lower case)."""


def read_mesh(path: str | Path, *, process: bool = True) -> trimesh.Trimesh:
    """Read a triangle mesh.

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.obj``, ``.stl``, ``.glb``, ``.gltf`` or ``.off`` file.
    process : bool
        Let trimesh merge duplicate vertices and drop degenerate faces (its default). Pass
        ``False`` to keep the file's vertex order exactly.

    Returns
    -------
    trimesh.Trimesh
        One mesh; a scene is concatenated with its node transforms applied.

    Raises
    ------
    InputError
        Missing file, unknown extension, unreadable content, or no triangles (e.g. a PLY point
        cloud).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in MESH_EXTENSIONS:
        raise InputError(
            f"{p}: unknown mesh extension {p.suffix!r}; supported: {', '.join(MESH_EXTENSIONS)}"
        )
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    try:
        scene = trimesh.load_scene(str(p), file_type=ext[1:], process=process)
    except Exception as e:  # trimesh raises many exception types on bad files
        raise InputError(f"{p}: cannot read mesh ({type(e).__name__}: {e})") from None
    meshes = [g for g in scene.geometry.values() if isinstance(g, trimesh.Trimesh)]
    if not meshes or all(len(m.faces) == 0 for m in meshes):
        raise InputError(f"{p}: the file has no triangle faces (a point cloud or empty mesh?)")
    if len(scene.geometry) == 1 and len(scene.graph.nodes_geometry) == 1:
        node = scene.graph.nodes_geometry[0]
        T, _ = scene.graph.get(node)
        mesh = meshes[0].copy()
        if not np.allclose(T, np.eye(4)):
            mesh.apply_transform(T)
    else:
        mesh = scene.to_mesh()
    if len(mesh.faces) == 0:
        raise InputError(f"{p}: the file has no triangle faces")
    logger.debug("%s: %d vertices, %d faces", p, len(mesh.vertices), len(mesh.faces))
    return mesh


def write_mesh(path: str | Path, mesh: trimesh.Trimesh) -> Path:
    """Write a mesh; the format follows the extension (see :data:`MESH_EXTENSIONS`).

    Returns
    -------
    Path
        The path written (parent folders are created).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in MESH_EXTENSIONS:
        raise InputError(
            f"{p}: unknown mesh extension {p.suffix!r}; supported: {', '.join(MESH_EXTENSIONS)}"
        )
    if not isinstance(mesh, trimesh.Trimesh):
        raise InputError(f"{p}: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0:
        raise InputError(f"{p}: refusing to write a mesh without faces")
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        mesh.export(str(p), file_type=ext[1:])
    except Exception as e:
        raise InputError(f"{p}: cannot write mesh ({type(e).__name__}: {e})") from None
    return p
