"""Contour-model reconstruction from fused frames and per-frame pose observations (§G.4 end).

Paper 2 §2.3 builds the target's outer contour model with the authors' earlier band-contour
method and multi-view ICP (Li et al., Appl. Opt. 60, 8069, 2021), which it does not specify.
**[interpretation]** (ALGORITHMS §G.4): a :class:`ContourModel` accumulates the fused, clustered
frames: each new frame is registered to the model (frame → model ICP), transformed into the
model frame, appended and the model voxel-downsampled; the registration gives the observation
``(D, Q)`` the tracker filters.

Frames (all right-handed, metres):

* ``S_k`` — the sensor (depth-camera) frame at frame ``k``; the fused clouds are given in it.
* ``M`` — the **model frame** = ``S_0``, the sensor frame of the first observed frame. The model
  points are stored in ``M`` and are fixed to the target (the model is a frozen copy of the
  target as it was at frame 0).
* ``B`` — the **body frame**: axes of ``M``, origin ``b`` = centroid of the first frame's cloud
  (in ``M``). It is rigidly attached to the target.

``observe(cloud_k)`` registers the frame to the model, ``T_model_frame = T_{M,S_k}``, and
returns ``Observation(position, quaternion, quality)``:

* ``position`` (3,) — origin of ``B`` in ``S_k``: ``D_k = T_{S_k,M} b`` (the target reference
  point seen from the sensor; ``= b`` at frame 0);
* ``quaternion`` (4,) — ``(x, y, z, w)``, ``w ≥ 0``, of ``R_{S_k,B} = R_{S_k,M}``: the target's
  attitude relative to its attitude at frame 0, expressed as the rotation from body to current
  sensor axes (identity at frame 0);
* ``quality`` — fraction in ``[0, 1]`` of the frame's (voxel-downsampled) points within
  ``quality_gate`` (3) voxels of the model after registration (1 at frame 0). ``0`` means no
  usable registration: the pose is then the motion-prior prediction, the frame is not added to
  the model, and a filter should skip the update.

Registration of frame ``k``: ICP (``registration``, default point-to-point, 50 iterations) of
the voxel-downsampled frame onto the model from the constant-velocity prediction
``T_{M,S_{k−1}} · (T_{M,S_{k−2}}⁻¹ T_{M,S_{k−1}})`` (or ``init`` when given). If its quality is
below ``min_fitness`` — and always at frame 1, when there is no velocity yet — the
rotation-invariant CGA registration (:class:`~relnav.fusion.cross_source.
CrossSourceRegistration`, used here same-source) provides a global start and ICP is re-run from
it; the better result (quality, then RMSE) is kept.

**Multi-view refinement** (``multiview=True``, off by default) **[interpretation]** of paper 2's
unspecified "multi-view ICP": the sequential scheme above writes each registration's error into
the model, where every later frame inherits it (docs/results/paper2/observer_bias.md). With
``multiview`` the model keeps every accepted frame (voxel-downsampled, in its own ``S_j``) and
its pose ``T_{M,S_j}``; after frame ``k`` has been registered as above, all poses but frame 0's
(which defines ``M``) are refined jointly, the model is rebuilt as the voxel-downsampled union of
the frames at the refined poses, and the observation of frame ``k`` is its refined pose (the
poses of earlier frames change, their emitted observations do not). ``multiview_method``:

* ``"graph"`` (default) — a pose graph: frame ``k`` is registered onto each stored frame within
  ``multiview_max_angle_deg`` (70°) of attitude (its neighbours and, on return, the first
  frames: loop closures); each pairwise result is an edge ``T_{S_j,S_k}`` weighted by its ICP
  information; with ``multiview_model_edges`` (default) the frame → model registration is kept
  as an edge from frame 0 too. Gauss–Newton over all edges collected so far, frame 0 fixed
  (the conventions of :class:`relnav.navigation.pose_graph.PoseGraph`, without its robust
  kernel; solved here because ``navigation`` sits above ``fusion``).
* ``"leave-one-out"`` — rounds (``multiview_rounds``) of re-registering every frame onto the
  union of all the others at their current poses (Gauss–Seidel, frame 0 fixed).

**[measured]** (``benchmarks/paper2/paper2_experiment.py --seeds 20 --model-option multiview=true``,
docs/results/paper2/multiview.md): neither scheme removes the observer's error. The graph closes
the loop about the spin axis (spin-attitude RMS 1.4 → 0.47°) and lowers the position RMS (10 /
10 / 2.3 → 7.5 / 8.1 / 1.0 mm; y bias −5.4 → −0.06 mm, x bias unchanged at −5.7 mm), but the
tilt gets worse (0.31 / 0.6 → 0.45 / 0.85°): **[interpretation]** pairwise edges between partial
views constrain it less than one registration onto the whole model. The tracker's NEES goes
49.7 → 21.8 and its NIS 14 → 9.8, both still outside their bands; the jackknife σ is still
≈ 3.5× too small. Leave-one-out rounds do not converge: more rounds give larger errors. Same
cost per sequence (≈ 19 s against 22 s for 16 frames). Off by default.

**Match sources** (sequential model): the model keeps, per point, the share each merged frame
contributed to it (voxel centroids average the shares like the points). After each accepted
frame ``last_sources`` is ``{history index: share}`` of the frame's matches (nearest model
point within the quality gate at the accepted pose; shares sum to 1): a merged frame's pose
error is written into its part of the model, and a registration inherits the errors of the
parts it matched (``TwistorUKF(merge_slots=…)``, docs/results/paper2/merge_states.md).
``None`` for the first frame, a rejected frame and with ``multiview``.

Uncertainty of the observation (``last_covariance`` after each accepted frame, ``(6, 6)`` of
``[δD (m, sensor frame), δθ (rad, body axes: Q_true = Q ⊗ exp(δθ))]``), ``covariance=``:

* ``"icp"`` — the registration's own ``σ² (JᵀJ)⁻¹`` (information matrix scaled by the residual
  variance) mapped to the observation. It treats every point residual as independent, which
  neighbouring residuals on one surface and the model's own errors are not: on li-rotating it
  is 10–50× smaller than the scatter of the observations.
* ``"jackknife"`` (default) **[interpretation]** — delete-a-group jackknife over
  ``jackknife_blocks`` spatial blocks of the frame (k-means on the points, seeded): the frame
  is re-registered without each block (warm start at the accepted pose) and the covariance of
  the ``K`` observations is ``(K − 1)/K Σ (δᵢ − δ̄)(δᵢ − δ̄)ᵀ``, plus the ``"icp"`` term as a
  floor. Blocks keep spatially correlated errors together, so what one region of the frame
  pulls into the pose shows up as spread. Uses only the measurements. With ``multiview`` the
  blocks are re-registered, from the refined pose, onto the union of the other frames.
* ``"none"`` — ``last_covariance = None`` (the filter's fixed noise).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.rotations import matrix_to_quat
from relnav.geometry.se3 import invert
from relnav.registration.result import RegistrationResult

__all__ = ["ContourModel", "FusedFrame", "Observation", "fuse_frame"]

log = logging.getLogger(__name__)


class Observation(NamedTuple):
    """A per-frame pose observation of the target (see the module docstring for frames).

    Attributes
    ----------
    position : (3,) float64
        Body-frame origin (target reference point) in the current sensor frame, metres.
    quaternion : (4,) float64
        ``(x, y, z, w)`` of ``R_sensor_body`` (``w ≥ 0``).
    quality : float
        Overlap with the model in ``[0, 1]``; ``0`` = no usable registration (prediction
        returned).
    """

    position: np.ndarray
    quaternion: np.ndarray
    quality: float


class FusedFrame(NamedTuple):
    """One fused frame (camera frame ``S_k``).

    Attributes
    ----------
    points : (K, 3) float64
        Camera points + registered (and, with clustering, projected) LIDAR points (m).
    registration : RegistrationResult
        ``T_target_source = T_camera_lidar`` of the cross-source registration.
    clustering : ClusterResult or None
        The plane clustering output (``None`` when disabled or the registration failed).
    """

    points: np.ndarray
    registration: RegistrationResult
    clustering: Any


def fuse_frame(
    camera_pts: np.ndarray,
    lidar_pts: np.ndarray,
    *,
    registration: Any = None,
    cluster: bool = True,
    init: np.ndarray | None = None,
    **cluster_options: Any,
) -> FusedFrame:
    """Paper 2's per-frame fusion: cross-source registration, then plane clustering (§G.2–G.4).

    Parameters
    ----------
    camera_pts : (M, 3) float64
        Depth-camera cloud, camera frame (m).
    lidar_pts : (N, 3) float64
        LIDAR cloud, LIDAR frame (m).
    registration : Registration, optional
        Default :class:`~relnav.fusion.cross_source.CrossSourceRegistration` (m = 15, seed 0).
    cluster : bool
        Snap the registered LIDAR points onto the camera's planes/lines
        (:func:`~relnav.fusion.clustering.cluster_and_project`).
    init : (4, 4) float64, optional
        Prior ``T_camera_lidar`` (e.g. the previous frame's, the rig calibration).
    **cluster_options
        Passed to ``cluster_and_project``.

    Returns
    -------
    FusedFrame
        When the registration is not ``ok`` the LIDAR points are left out (camera points only).
    """
    from relnav.fusion.clustering import cluster_and_project
    from relnav.fusion.cross_source import CrossSourceRegistration

    reg = registration if registration is not None else CrossSourceRegistration()
    C = np.asarray(camera_pts, dtype=np.float64).reshape(-1, 3)
    C = C[np.isfinite(C).all(axis=1)]
    res = reg.register(lidar_pts, C, init=init)
    if not res.ok:
        return FusedFrame(C.copy(), res, None)
    T = res.T_target_source
    L = np.asarray(lidar_pts, dtype=np.float64).reshape(-1, 3)
    L = L[np.isfinite(L).all(axis=1)]
    Lc = L @ T[:3, :3].T + T[:3, 3]
    if not cluster:
        return FusedFrame(np.vstack([C, Lc]), res, None)
    cl = cluster_and_project(C, Lc, **cluster_options)
    return FusedFrame(cl.fused_points, res, cl)


class ContourModel:
    """Multi-view contour model of the target built from fused frames.

    Parameters
    ----------
    voxel_size : float, optional
        Model voxel (m); default ``voxel_factor ×`` the first frame's resolution.
    voxel_factor : float
        See ``voxel_size``.
    registration : str or Registration, optional
        Frame → model method (``relnav.registration.get_registration`` name or object);
        default point-to-point ICP with 50 iterations.
    min_fitness : float
        Below this quality the global (CGA) start is tried; a final quality below
        ``reject_fitness`` gives ``quality = 0``.
    reject_fitness : float
        See ``min_fitness``.
    quality_gate : float
        Quality = fraction of the (downsampled) frame's points within ``quality_gate × voxel``
        of the model after registration.
    global_start : bool
        Allow the CGA global start (``False``: ICP from the prediction only).
    max_model_points : int
        When the model grows beyond this, the voxel is enlarged by √2 until it fits.
    seed : int
        Seed of the CGA start (recorded in :attr:`history`).
    covariance : {"jackknife", "icp", "none"}
        Observation covariance (module docstring).
    jackknife_blocks : int
        Spatial blocks of the jackknife (≥ 4).
    multiview : bool
        Keep every accepted frame (voxel-downsampled, in its sensor frame) with its pose and
        refine all poses but frame 0's after each new frame, then rebuild the model from the
        refined poses (module docstring, "Multi-view refinement"). Off by default.
    multiview_method : {"graph", "leave-one-out"}
        How the poses are refined (module docstring).
    multiview_rounds : int
        ``"leave-one-out"``: rounds at most per frame (≥ 1).
    multiview_tol : float
        ``"leave-one-out"``: stop when no frame moved more than this many voxels (RMS).
    multiview_max_angle_deg : float
        ``"graph"``: pair the new frame with the stored frames whose attitude is within this
        angle (deg) of its own.
    multiview_model_edges : bool
        ``"graph"``: keep each frame → model registration as an edge from frame 0.

    Examples
    --------
    >>> model = ContourModel()  # doctest: +SKIP
    >>> for cloud in fused_frames:  # doctest: +SKIP
    ...     position, quaternion, quality = model.observe(cloud)
    """

    def __init__(
        self,
        *,
        voxel_size: float | None = None,
        voxel_factor: float = 2.0,
        registration: Any = None,
        min_fitness: float = 0.6,
        reject_fitness: float = 0.3,
        global_start: bool = True,
        max_model_points: int = 60000,
        quality_gate: float = 3.0,
        seed: int = 0,
        covariance: str = "jackknife",
        jackknife_blocks: int = 10,
        multiview: bool = False,
        multiview_method: str = "graph",
        multiview_rounds: int = 2,
        multiview_tol: float = 0.05,
        multiview_max_angle_deg: float = 70.0,
        multiview_model_edges: bool = True,
    ) -> None:
        if voxel_size is not None and not (float(voxel_size) > 0):
            raise ConfigError(f"voxel_size must be > 0, got {voxel_size}")
        if not float(voxel_factor) > 0:
            raise ConfigError(f"voxel_factor must be > 0, got {voxel_factor}")
        if not 0 <= reject_fitness <= min_fitness <= 1:
            raise ConfigError("need 0 <= reject_fitness <= min_fitness <= 1")
        if int(max_model_points) < 100:
            raise ConfigError(f"max_model_points must be >= 100, got {max_model_points}")
        self.voxel_size = None if voxel_size is None else float(voxel_size)
        self.voxel_factor = float(voxel_factor)
        if registration is None or isinstance(registration, str):
            from relnav.registration import get_registration

            name = registration or "icp-point"
            self._reg = (
                get_registration(name, max_iter=50)
                if registration is None
                else get_registration(name)
            )
        else:
            self._reg = registration
        self.min_fitness = float(min_fitness)
        self.reject_fitness = float(reject_fitness)
        self.global_start = bool(global_start)
        self.max_model_points = int(max_model_points)
        if not float(quality_gate) > 0:
            raise ConfigError(f"quality_gate must be > 0, got {quality_gate}")
        self.quality_gate = float(quality_gate)
        self.seed = int(seed)
        if covariance not in ("jackknife", "icp", "none"):
            raise ConfigError(
                f"covariance must be 'jackknife', 'icp' or 'none', got {covariance!r}"
            )
        if int(jackknife_blocks) < 4:
            raise ConfigError(f"jackknife_blocks must be >= 4, got {jackknife_blocks}")
        self.covariance = covariance
        self.jackknife_blocks = int(jackknife_blocks)
        if not isinstance(multiview, (bool, np.bool_)):
            raise ConfigError(f"multiview must be a bool, got {multiview!r}")
        if int(multiview_rounds) < 1 or int(multiview_rounds) != multiview_rounds:
            raise ConfigError(f"multiview_rounds must be an integer >= 1, got {multiview_rounds}")
        if not float(multiview_tol) > 0:
            raise ConfigError(f"multiview_tol must be > 0, got {multiview_tol}")
        if multiview_method not in ("graph", "leave-one-out"):
            raise ConfigError(
                f"multiview_method must be 'graph' or 'leave-one-out', got {multiview_method!r}"
            )
        if not 0 < float(multiview_max_angle_deg) <= 180:
            raise ConfigError(
                f"multiview_max_angle_deg must be in (0, 180], got {multiview_max_angle_deg}"
            )
        self.multiview = bool(multiview)
        self.multiview_method = multiview_method
        self.multiview_max_angle_deg = float(multiview_max_angle_deg)
        self.multiview_model_edges = bool(multiview_model_edges)
        self.multiview_rounds = int(multiview_rounds)
        self.multiview_tol = float(multiview_tol)
        self.reset()

    def reset(self) -> None:
        """Forget the model and the pose history."""
        self._model = np.zeros((0, 3))
        # sequential model: share of each model point contributed by each merged frame
        # (rows sum to 1; columns = merged frames in order, see merged_frames)
        self._sources = np.zeros((0, 0))
        self._merged: list[int] = []  # history index of each merged frame
        self.last_sources: dict[int, float] | None = None
        self._poses: list[np.ndarray] = []  # T_model_frame of every accepted frame
        self._frames: list[np.ndarray] = []  # multiview: downsampled cloud of each, in S_k
        # multiview graph: (j, k) -> (Z = T_{S_j,S_k}, information (6, 6), right perturbation)
        self._edges: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._priors: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # k -> (T_{M,S_k}, info)
        self._body_origin: np.ndarray | None = None
        self._voxel: float | None = self.voxel_size
        self.history: list[dict[str, Any]] = []
        self.last_result: RegistrationResult | None = None
        self.last_covariance: np.ndarray | None = None
        self.T_model_frame: np.ndarray | None = None
        self._last_refined: RegistrationResult | None = None

    # ---- properties ---------------------------------------------------------------------

    @property
    def points(self) -> np.ndarray:
        """Model points ``(K, 3)`` in the model frame ``M`` (m)."""
        return self._model.copy()

    @property
    def n_frames(self) -> int:
        """Frames merged into the model."""
        return len(self._poses)

    @property
    def frame_poses(self) -> np.ndarray:
        """``T_model_frame`` ``(n_frames, 4, 4)`` of every accepted frame: as registered, or
        as last refined with ``multiview`` (frame 0's is the identity)."""
        return np.array(self._poses).reshape(-1, 4, 4)

    @property
    def body_origin(self) -> np.ndarray | None:
        """Origin ``b`` of the body frame in ``M`` (m), ``None`` before the first frame."""
        return None if self._body_origin is None else self._body_origin.copy()

    @property
    def voxel(self) -> float | None:
        """Current model voxel size (m)."""
        return self._voxel

    # ---- main ---------------------------------------------------------------------------

    def observe(self, frame_cloud: np.ndarray, *, init: np.ndarray | None = None) -> Observation:
        """Register a fused frame to the model, merge it, and return the pose observation.

        Parameters
        ----------
        frame_cloud : (N, 3) float64
            Fused (clustered) cloud of the current frame in the sensor frame ``S_k`` (m).
        init : (4, 4) float64, optional
            Guess of ``T_model_frame`` (e.g. from a filter's prediction).

        Returns
        -------
        Observation
            ``(position, quaternion, quality)``; see the module docstring.

        Raises
        ------
        InputError
            ``frame_cloud`` is not an ``(N, 3)`` finite array, or the first frame is empty.
        """
        P = np.asarray(frame_cloud, dtype=np.float64)
        if P.size == 0:
            P = np.zeros((0, 3))
        if P.ndim != 2 or P.shape[1] != 3:
            raise InputError(f"frame_cloud: expected an (N, 3) array, got shape {P.shape}")
        P = P[np.isfinite(P).all(axis=1)]
        if init is not None:
            init = np.asarray(init, dtype=np.float64)
            if init.shape != (4, 4) or not np.isfinite(init).all():
                raise InputError(f"init must be a finite 4x4 matrix, got shape {init.shape}")
        k = len(self.history)
        self.last_covariance = None
        self.last_sources = None
        if not self._poses:
            return self._first(P, k)
        pred = self._predict() if init is None else init
        if P.shape[0] < 10:
            return self._reject(pred, k, "frame has fewer than 10 points")
        src = self._downsample(P)
        tree = cKDTree(self._model)
        res = self._reg.register(src, self._model, init=pred)
        q = self._quality(src, res, tree)
        how = "prediction"
        need_global = self.global_start and (
            (len(self._poses) == 1 and init is None) or q < self.min_fitness
        )
        if need_global:
            g = self._global(src)
            if g is not None and g.ok:
                res2 = self._reg.register(src, self._model, init=g.T_target_source)
                q2 = self._quality(src, res2, tree)
                if q2 > q + 1e-9 or (
                    abs(q2 - q) <= 1e-9 and res2.ok and res2.inlier_rmse < res.inlier_rmse
                ):
                    res, q, how = res2, q2, "global"
        self.last_result = res
        if q < self.reject_fitness:
            return self._reject(pred, k, f"registration {res.status}, quality {q:.2f}")
        T = res.T_target_source
        entry: dict[str, Any] = {"frame": k, "accepted": True, "start": how}
        if self.multiview:
            t0 = time.perf_counter()
            self._frames.append(src)
            self._poses.append(T)
            if self.multiview_method == "graph":
                entry.update(self._refine_graph(T, res))
            else:
                entry.update(self._refine())
            T = self._poses[-1]
            target = self._union(exclude=len(self._poses) - 1)
            res = self._last_refined if self._last_refined is not None else res
            self.last_result = res
            q = self._quality_at(src, T, cKDTree(target))
            if self.covariance != "none":
                self.last_covariance = self._observation_covariance(src, T, res, target)
            self._model = self._union(exclude=None, grow=True)
            entry["multiview_seconds"] = time.perf_counter() - t0
        else:
            if self.covariance != "none":
                self.last_covariance = self._observation_covariance(src, T, res, self._model)
            self.last_sources = self._match_sources(src, T, tree)
            self._merge(P, T, k)
            self._poses.append(T)
        self.T_model_frame = T
        obs = self._observation(T, q)
        entry.update(quality=q, fitness=float(res.fitness), rmse=float(res.inlier_rmse),
                     model_points=len(self._model))  # fmt: skip
        self.history.append(entry)
        return obs

    # ---- internals ----------------------------------------------------------------------

    def _first(self, P: np.ndarray, k: int) -> Observation:
        if P.shape[0] < 10:
            raise InputError(f"first frame has {P.shape[0]} points; need at least 10")
        if self._voxel is None:
            tr = mean_resolution(P)
            self._voxel = self.voxel_factor * (tr if math.isfinite(tr) and tr > 0 else 1e-3)
        self._body_origin = P.mean(axis=0)
        T = np.eye(4)
        self._model = np.zeros((0, 3))
        self._poses.append(T)
        if self.multiview:
            self._frames.append(self._downsample(P))
            self._model = self._union(exclude=None, grow=True)
        else:
            self._merge(P, T, k)
        self.T_model_frame = T
        self.history.append(
            {"frame": k, "accepted": True, "quality": 1.0, "rmse": 0.0, "start": "first",
             "model_points": len(self._model), "seed": self.seed, "voxel": self._voxel}
        )  # fmt: skip
        return self._observation(T, 1.0)

    def _quality(self, src: np.ndarray, res: RegistrationResult, tree: cKDTree) -> float:
        """Fraction of frame points within ``quality_gate × voxel`` of the model."""
        if not res.ok:
            return 0.0
        return self._quality_at(src, res.T_target_source, tree)

    def _quality_at(self, src: np.ndarray, T: np.ndarray, tree: cKDTree) -> float:
        """Fraction of frame points within ``quality_gate × voxel`` of the model at ``T``."""
        assert self._voxel is not None
        d, _ = tree.query(src @ T[:3, :3].T + T[:3, 3], distance_upper_bound=self._gate())
        return float(np.mean(np.isfinite(d))) if d.size else 0.0

    def _gate(self) -> float:
        assert self._voxel is not None
        return self.quality_gate * self._voxel

    def _predict(self) -> np.ndarray:
        if len(self._poses) >= 2:
            a, b = self._poses[-2], self._poses[-1]
            return b @ (invert(a) @ b)
        return self._poses[-1].copy()

    def _reject(self, pred: np.ndarray, k: int, why: str) -> Observation:
        log.info("ContourModel frame %d rejected: %s", k, why)
        self.history.append({"frame": k, "accepted": False, "reason": why})
        obs = self._observation(pred, 0.0)
        return obs

    def _downsample(self, P: np.ndarray) -> np.ndarray:
        from relnav.features.keypoints import voxel_downsample

        assert self._voxel is not None
        return voxel_downsample(P, self._voxel)

    def _merge(self, P: np.ndarray, T_model_frame: np.ndarray, k: int) -> None:
        """Append frame ``k`` (history index) at ``T_model_frame`` and voxel-downsample the
        model; the per-point source shares follow the same voxel averaging."""
        from relnav.features.keypoints import voxel_downsample, voxel_groups

        assert self._voxel is not None
        Pm = P @ T_model_frame[:3, :3].T + T_model_frame[:3, 3]
        merged = np.vstack([self._model, Pm])
        n_old = self._model.shape[0]
        S = np.zeros((merged.shape[0], len(self._merged) + 1))
        S[:n_old, :-1] = self._sources
        S[n_old:, -1] = 1.0
        self._merged.append(k)
        model = voxel_downsample(merged, self._voxel)
        while model.shape[0] > self.max_model_points:
            self._voxel *= math.sqrt(2.0)
            model = voxel_downsample(merged, self._voxel)
        inv, M = voxel_groups(merged, self._voxel)
        counts = np.bincount(inv, minlength=M).astype(np.float64)
        self._sources = (
            np.stack([np.bincount(inv, weights=S[:, j], minlength=M) for j in range(S.shape[1])], 1)
            / counts[:, None]
        )
        self._model = model

    def _match_sources(self, src: np.ndarray, T: np.ndarray, tree: cKDTree) -> dict[int, float]:
        """Share of frame ``src``'s matches (nearest model point within the quality gate, at
        ``T``) contributed by each merged frame: ``{history index: share}`` (shares sum to 1;
        empty when nothing matches)."""
        _, idx = tree.query(src @ T[:3, :3].T + T[:3, 3], distance_upper_bound=self._gate())
        idx = idx[idx < self._model.shape[0]]
        if idx.size == 0 or self._sources.shape[0] != self._model.shape[0]:
            return {}
        w = self._sources[idx].mean(axis=0)
        return {j: float(x) for j, x in zip(self._merged, w, strict=True) if x > 0.0}

    def _union(self, exclude: int | None, *, grow: bool = False) -> np.ndarray:
        """Voxel-downsampled union of the stored frames at their poses, in ``M`` (multiview),
        without frame ``exclude``; ``grow``: enlarge the voxel until ``max_model_points``."""
        from relnav.features.keypoints import voxel_downsample

        assert self._voxel is not None
        parts = [
            F @ T[:3, :3].T + T[:3, 3]
            for j, (F, T) in enumerate(zip(self._frames, self._poses, strict=True))
            if j != exclude
        ]
        merged = np.vstack(parts) if parts else np.zeros((0, 3))
        model = voxel_downsample(merged, self._voxel)
        while grow and model.shape[0] > self.max_model_points:
            self._voxel *= math.sqrt(2.0)
            model = voxel_downsample(merged, self._voxel)
        return model

    def _refine(self) -> dict[str, Any]:
        """Multi-view refinement of every frame's pose but frame 0's (which defines ``M``).

        Rounds of leave-one-out registration: frames ``1 … n−2``, then the newest, each
        re-registered onto the union of all the other frames at their current poses (warm
        start at its own pose; updated in place, Gauss–Seidel). A registration that fails or
        whose quality falls below ``reject_fitness`` leaves the pose unchanged. Stops after
        ``multiview_rounds`` rounds or when no frame's points moved by more than
        ``multiview_tol`` voxels RMS.

        Returns
        -------
        dict
            ``refine_rounds`` (rounds run) and ``refine_shift`` (largest RMS displacement of a
            frame's points over the refinement, m), for :attr:`history`.
        """
        assert self._voxel is not None
        n = len(self._poses)
        self._last_refined = None
        before = [T.copy() for T in self._poses]
        rounds = 0
        for _ in range(self.multiview_rounds):
            rounds += 1
            moved = 0.0
            for j in [*range(1, n - 1), n - 1]:
                target = self._union(exclude=j)
                F = self._frames[j]
                res = self._reg.register(F, target, init=self._poses[j])
                if not res.ok or self._quality(F, res, cKDTree(target)) < self.reject_fitness:
                    continue
                moved = max(moved, _rms_shift(F, self._poses[j], res.T_target_source))
                self._poses[j] = res.T_target_source
                if j == n - 1:
                    self._last_refined = res
            if moved <= self.multiview_tol * self._voxel:
                break
        pairs = zip(self._frames, before, self._poses, strict=True)
        shift = max((_rms_shift(F, a, b) for F, a, b in pairs), default=0.0)
        return {"refine_rounds": rounds, "refine_shift": shift}

    def _refine_graph(self, T_seq: np.ndarray, res_seq: RegistrationResult) -> dict[str, Any]:
        """Multi-view refinement by a pose graph of pairwise frame registrations.

        The newest frame ``k`` is registered (``registration``, warm start at the current
        relative pose) onto every stored frame ``j`` whose attitude is within
        ``multiview_max_angle_deg`` of its own; each registration whose quality reaches
        ``reject_fitness`` is an edge ``Z_jk ≈ T_{S_j,S_k}`` with the inverse of its ICP
        covariance as information (moved to a right perturbation). The edges of all frames
        are kept; the graph (frame 0 fixed) is solved by Gauss–Newton (:func:`_solve_pose_graph`)
        from the current poses. With
        ``multiview_model_edges`` — and always for a frame without an accepted pairwise edge —
        the frame → model registration ``T_seq`` is kept as an edge from frame 0 (a prior on
        ``T_{M,S_k}``, information from its ICP covariance). The observation's ``"icp"``
        covariance term stays that of the frame → model registration.

        Returns
        -------
        dict
            ``refine_edges`` (edges added for the newest frame), ``refine_shift`` (largest RMS
            displacement of a frame's points, m) and ``refine_iterations``, for :attr:`history`.
        """
        from relnav.geometry.rotations import rotation_angle
        from relnav.geometry.se3 import adjoint

        assert self._voxel is not None
        n = len(self._poses)
        k = n - 1
        Fk = self._frames[k]
        added = 0
        for j in range(k):
            Z0 = invert(self._poses[j]) @ self._poses[k]
            if math.degrees(float(rotation_angle(Z0[:3, :3]))) > self.multiview_max_angle_deg:
                continue
            Fj = self._frames[j]
            r = self._reg.register(Fk, Fj, init=Z0)
            if not r.ok or r.covariance is None or not np.all(np.isfinite(r.covariance)):
                continue
            if self._quality(Fk, r, cKDTree(Fj)) < self.reject_fitness:
                continue
            Z = r.T_target_source
            A = adjoint(invert(Z))
            C = A @ r.covariance @ A.T
            try:
                info = np.linalg.inv(0.5 * (C + C.T))
            except np.linalg.LinAlgError:
                continue
            self._edges[(j, k)] = (Z, info)
            added += 1
        if added == 0 or self.multiview_model_edges:
            # the frame → model registration as an edge from frame 0 (= M)
            C = res_seq.covariance
            info = (
                np.linalg.pinv(adjoint(invert(T_seq)) @ C @ adjoint(invert(T_seq)).T)
                if C is not None and np.all(np.isfinite(C))
                else np.eye(6) / self._voxel**2
            )
            self._priors[k] = (T_seq, info)
        before = self._poses
        self._poses, iterations = _solve_pose_graph(self._poses, self._edges, self._priors)
        self._last_refined = None
        pairs = zip(self._frames, before, self._poses, strict=True)
        shift = max((_rms_shift(F, a, b) for F, a, b in pairs), default=0.0)
        return {"refine_edges": added, "refine_shift": shift, "refine_iterations": iterations}

    def _global(self, src: np.ndarray) -> RegistrationResult | None:
        from relnav.fusion.cross_source import CrossSourceRegistration

        try:
            return CrossSourceRegistration(m=15, seed=self.seed).register(src, self._model)
        except Exception as e:  # pragma: no cover - defensive: never break the tracker
            log.warning("ContourModel: global start failed: %s", e)
            return None

    def _observation_covariance(
        self, src: np.ndarray, T: np.ndarray, res: RegistrationResult, target: np.ndarray
    ) -> np.ndarray | None:
        """``(6, 6)`` covariance of the observation ``[δD, δθ]`` (module docstring)."""
        from scipy.spatial.transform import Rotation

        assert self._body_origin is not None
        b = self._body_origin
        T_fm = invert(T)
        C = np.zeros((6, 6))
        have = False
        if res.covariance is not None and np.all(np.isfinite(res.covariance)):
            # left perturbation ξ = [ρ, φ] of T_model_frame → δD = R_fm([b]× φ − ρ), δθ = −φ
            bx = np.array([[0.0, -b[2], b[1]], [b[2], 0.0, -b[0]], [-b[1], b[0], 0.0]])
            J = np.zeros((6, 6))
            J[0:3, 0:3] = -T_fm[:3, :3]
            J[0:3, 3:6] = T_fm[:3, :3] @ bx
            J[3:6, 3:6] = -np.eye(3)
            C += J @ res.covariance @ J.T
            have = True
        K = self.jackknife_blocks
        if self.covariance == "jackknife" and src.shape[0] >= 10 * K:
            from scipy.cluster.vq import kmeans2

            _, labels = kmeans2(src, K, minit="++", seed=self.seed + len(self.history))
            D0 = T_fm[:3, :3] @ b + T_fm[:3, 3]
            deltas = []
            for i in range(K):
                sub = src[labels != i]
                r = self._reg.register(sub, target, init=T)
                if not r.ok:
                    continue
                Ti = invert(r.T_target_source)
                dth = Rotation.from_matrix(T_fm[:3, :3].T @ Ti[:3, :3]).as_rotvec()
                deltas.append(np.r_[Ti[:3, :3] @ b + Ti[:3, 3] - D0, dth])
            n = len(deltas)
            if n >= 4:
                Dl = np.asarray(deltas)
                Dl = Dl - Dl.mean(axis=0)
                C += (n - 1) / n * (Dl.T @ Dl)
                have = True
        return 0.5 * (C + C.T) if have else None

    def _observation(self, T_model_frame: np.ndarray, quality: float) -> Observation:
        assert self._body_origin is not None
        T_frame_model = invert(T_model_frame)
        pos = T_frame_model[:3, :3] @ self._body_origin + T_frame_model[:3, 3]
        q = matrix_to_quat(T_frame_model[:3, :3])
        return Observation(pos, np.asarray(q, dtype=np.float64), float(quality))


def _rms_shift(F: np.ndarray, T_a: np.ndarray, T_b: np.ndarray) -> float:
    """RMS displacement (m) of the points ``F`` between the poses ``T_a`` and ``T_b``."""
    if F.shape[0] == 0:
        return 0.0
    D = F @ (T_b[:3, :3] - T_a[:3, :3]).T + (T_b[:3, 3] - T_a[:3, 3])
    return float(np.sqrt(np.mean(np.sum(D * D, axis=1))))


def _solve_pose_graph(
    poses: list[np.ndarray],
    edges: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    priors: dict[int, tuple[np.ndarray, np.ndarray]],
    *,
    max_iter: int = 20,
    tolerance: float = 1e-9,
) -> tuple[list[np.ndarray], int]:
    """Gauss–Newton on the frames' SE(3) pose graph, node 0 fixed
    (:class:`relnav.geometry.pose_graph_solver.PoseGraph`, no robust edges).

    ``edges``: ``(i, j) -> (Z, Ω)`` with ``Z ≈ X_i⁻¹ X_j`` and the information ``Ω`` (6, 6) of a
    right perturbation, twists ``[ρ (m), φ (rad)]``; ``priors``: ``j -> (T, Ω)`` with ``T ≈ X_j``.
    Returns the optimised poses (node 0 unchanged) and the iterations run; stops when the largest
    update component is below ``tolerance`` (m and rad).
    """
    from relnav.geometry.pose_graph_solver import PoseGraph

    g = PoseGraph()
    for T in poses:
        g.add_node(T)
    for (i, j), (Z, L) in edges.items():
        g.add_edge(i, j, Z, L)
    for j, (T, L) in priors.items():
        g.add_prior(j, T, L)
    if len(poses) < 2 or not g.edges:
        return [np.array(T, dtype=np.float64) for T in poses], 0
    res = g.optimize(
        fixed=(0,), kernel_start=1.0, kernel=1.0, max_iter=max_iter, tolerance=tolerance
    )
    return list(res.poses), res.iterations
