"""External baselines behind the relnav :class:`~relnav.registration.base.Registration` interface.

Method strings (optional extra ``[baselines]``: ``open3d-cpu``, ``kiss-icp``, ``small_gicp``):

==================== ===========================================================================
``o3d-fpfh-ransac``  Open3D global registration: voxel downsampling, normals, FPFH, RANSAC on
                     FPFH matches (seeded), then point-to-plane ICP refinement (``init`` ignored).
``o3d-icp-point``    Open3D point-to-point ICP from ``init``.
``o3d-icp-plane``    Open3D point-to-plane ICP from ``init`` (target normals by Open3D PCA).
``kiss-icp``         KISS-ICP (Vizzo et al. 2023) fed frame by frame; stateful, see below.
``small-gicp``       small_gicp ``align`` (spec: ``gicp`` default, ``icp``, ``plane_icp``,
                     ``vgicp``), e.g. ``small-gicp:vgicp``.
==================== ===========================================================================

The libraries are imported lazily when a method is constructed; a missing one raises
:class:`~relnav.errors.ConfigError` naming the ``[baselines]`` extra.

**Scale-aware parameters.** The libraries' defaults are tuned for cars and rooms (KISS-ICP: 1 m
voxels at 100 m range; small_gicp: 0.25 m downsampling, 1 m gate). Space targets span 1 m to
800 m, so every length is derived from the source resolution ``Tr`` (mean nearest-neighbour
distance, :func:`relnav.geometry.neighbors.mean_resolution`; KISS-ICP uses the target's ``Tr``
when it builds its pipeline) and from the clouds' ranges. Every factor is an option, and the
values actually used are recorded in ``result.info``.

**Dense scans** (more than ``dense_points`` points, default 5 000 as the point budget of relnav's
own methods: real sensors, not paper 1's clouds, which all have fewer): KISS-ICP and small_gicp
then use their own recommended, range-based downsampling, which is what makes them fast on such
scans — KISS-ICP's voxel ``max_range / 100`` (its default when no voxel is given), small_gicp's
``0.25 m`` downsampling and ``1 m`` gate of its 100 m-range examples scaled to the scan
(``max range / 400`` and ``4 ×`` that) **[interpretation]**. ``info["settings"]`` says which
(``"sparse"``: ``Tr``-based, ``"dense"``: range-based); ``relnav methods`` lists the rule.

**KISS-ICP statefulness.** KISS-ICP registers each new frame against a local voxel map of the
previous frames, with a constant-velocity prediction and an adaptive correspondence threshold.
Odometry calls ``register(source=scan k+1, target=scan k)`` in order, so the adapter keeps one
pipeline alive while the calls are consecutive — the ``target`` of a call is the cloud that was
the ``source`` of the previous call (same content, checked by a hash of the float64 bytes) — and
registers only the new source. Otherwise (first call, out-of-order pair, the source leaving the
configured range, ``stateful=False`` or a library error) it rebuilds a fresh pipeline from the
target, registers the target as its first frame (empty map: pose = identity) and then the source.
The result is the relative step between the two frames, ``T_target_source =
inv(pose_k) @ pose_{k+1}`` (KISS-ICP's ``last_delta``). A given ``init`` replaces KISS-ICP's own
constant-velocity prediction for that frame (``last_delta = init`` before ``register_frame``); with
``init=None`` KISS-ICP's own prediction is used (identity for a fresh pipeline). Deskewing is
off (relnav scans carry no per-point times).

**Result fields** (all methods, recomputed by relnav at the final estimate): ``fitness`` =
fraction of the source points (small_gicp: its downsampled source) with a target point within
the method's final gate (``info["gate"]``: the ICP gate; the refinement gate for
``o3d-fpfh-ransac``; ``3σ`` of KISS-ICP's adaptive threshold; small_gicp's
``max_correspondence_distance``) — Open3D's definition, divided by the SOURCE count;
``inlier_rmse`` = RMS distance of those pairs (m); ``n_inliers`` = their count;
``n_correspondences`` = putative pairs (the downsampled source points, each with one FPFH match,
for ``o3d-fpfh-ransac``; otherwise ``n_inliers``). ``covariance`` is the covariance of the twist
``δ = [ρ (m), φ (rad)]`` of a LEFT perturbation ``T_true = exp_se3(δ) · T`` (target frame, about
its origin), as relnav's own ICP: for small_gicp it is built from its Hessian ``H`` (see
:class:`SmallGICPRegistration`); for the others it is the Gauss–Newton covariance
``σ² (JᵀJ)⁻¹`` of the final nearest-neighbour pairs (point-to-plane rows ``[nᵀ, (p×n)ᵀ]`` when
the method used target normals, point-to-point blocks ``[I, −[p]×]`` otherwise) with ``σ²`` the
residual variance. ``info["degeneracy_ratio"]`` is ``λmin/λmax`` of that information matrix
re-expressed about the cloud centroid with the rotation block scaled by the cloud radius
(:func:`information_degeneracy`); below the ``degeneracy_ratio`` option (1e-9) the status is
``degenerate``. Empty, tiny, coincident or collinear clouds, a bad ``init``, fewer than 3 inliers
after alignment, or an exception inside the library give a ``degenerate``/``failed`` result with a
``message`` — never an exception.
"""

from __future__ import annotations

from relnav.registration.external_base import (  # noqa: F401
    DENSE_POINTS,
    _dense_points,
    _evaluate,
    _ExternalBase,
    _fingerprint,
    _Fit,
    _flag,
    _information,
    _is_dense,
    _max_range,
    _positive,
    _total,
    information_degeneracy,
    require,
    twist_covariance_from_hessian,
)
from relnav.registration.kiss_icp_adapter import KissFrame, KissICPRegistration
from relnav.registration.open3d_adapter import Open3DFPFHRansac, Open3DICP
from relnav.registration.small_gicp_adapter import SmallGICPRegistration

__all__ = [
    "KissICPRegistration",
    "KissFrame",
    "Open3DFPFHRansac",
    "Open3DICP",
    "SmallGICPRegistration",
    "require",
    "information_degeneracy",
    "twist_covariance_from_hessian",
]
