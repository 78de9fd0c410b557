"""Paper 1's ICP baselines: point-to-point, point-to-plane and X84 ICP (ALGORITHMS §C.1–C.3).

Method strings (spec ``paper`` / ``scale`` picks the threshold preset, see below):

============ =================================================================================
``icp-point`` Point-to-point ICP (Besl & McKay 1992), closed-form rigid fit per iteration,
              distance gate + standard-deviation outlier rule; ``max_iter = 20`` (paper 1).
``icp-plane`` Point-to-plane ICP (Chen & Medioni 1992), linearised 6×6 solve, target normals
              by PCA (k = 10); ``max_iter = 1000`` (paper 1).
``icp-x84``   Point-to-point ICP with Hampel's X84 rule (Fusiello et al. 2002):
              inlier iff ``|d − median(d)| ≤ 5.2·MAD``; ``max_iter = 20`` (paper 1).
============ =================================================================================

The algorithm, its thresholds (scale-aware by default, ``:paper`` for paper 1's absolute values),
the Open3D-compatible mode and the result fields are those of
:class:`relnav.geometry.icp_solver.ICPSolver` (see that module); :class:`ICP` is that solver
returning :class:`~relnav.registration.result.RegistrationResult`. The KD-tree, the numba
kernels and the cloud preparation live in :mod:`relnav.geometry` (``kdtree``, ``eigen``,
``icp_kernels``, ``prepared_cloud``) and are re-exported here under their former names.
"""

from __future__ import annotations

# the former names, re-exported (navigation/, super4pcs, the adapters and the tests use them)
from relnav.geometry.eigen import jacobi_eigh as _jacobi_eigh  # noqa: F401
from relnav.geometry.icp_kernels import (  # noqa: F401
    horn_rotation,
    information_ratio,
    kabsch_pairs,
    point_information,
    reject_nb,
    reject_outliers,
    rodrigues_nb,
    transform_nb,
)
from relnav.geometry.icp_solver import (  # noqa: F401
    PAPER_GATE,
    PAPER_ROTATION_TOL,
    PAPER_TRANSLATION_TOL,
    ICPSolver,
    failed_result,
    total_time,
)
from relnav.geometry.kdtree import KDTree, kd_build, kd_query  # noqa: F401
from relnav.geometry.prepared_cloud import PreparedCloud, check_init, prepare_cloud
from relnav.registration.base import register_variants

__all__ = [
    "ICP",
    "KDTree",
    "PAPER_GATE",
    "PAPER_ROTATION_TOL",
    "PAPER_TRANSLATION_TOL",
    "PreparedCloud",
    "check_init",
    "information_ratio",
    "prepare_cloud",
    "reject_outliers",
]


class ICP(ICPSolver):
    """Paper 1's ICP baselines as registration methods: :class:`ICPSolver` under its method
    names (same parameters, same :class:`RegistrationResult`)."""


register_variants(
    ICP,
    {
        "icp-point": (
            "point",
            "Point-to-point ICP (Besl & McKay), std-dev outlier rule, 20 iterations "
            "(paper 1 baseline)",
        ),
        "icp-plane": (
            "plane",
            "Point-to-plane ICP (Chen & Medioni), PCA normals k=10, 1000 iterations "
            "(paper 1 baseline)",
        ),
        "icp-x84": (
            "x84",
            "Point-to-point ICP with X84 (median ± 5.2·MAD) outlier rejection, 20 iterations "
            "(paper 1)",
        ),
    },
)
