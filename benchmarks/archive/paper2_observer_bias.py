"""Where the contour observer's error on li-rotating comes from, stage by stage (issue 15).

Diagnosis only: the truth is used to feed stages and to measure errors, never by the library.
For each stage the :class:`~relnav.fusion.reconstruction.ContourModel` observes one simulated
li-rotating sequence (``benchmarks/paper2/paper2_experiment.py`` layout) with every registration
started AT THE TRUE POSE, and the observation error is measured directly in the sensor frame
``S_k`` (the model frame ``M`` is ``S_0`` exactly, so the true observation is
``T_{S_k,M} b``; no alignment is fitted). Stages (``--stages``, comma-separated):

* ``camera`` — the camera cloud alone;
* ``camera-true-merges`` — the same, but every frame is merged into the model at its TRUE pose
  (the error is then that of one frame → model registration, none inherited);
* ``camera-true-merges-no-back`` — and the frame points whose nearest model point was seen
  from the other side of the surface (thin two-sided structures) are dropped;
* ``camera-true-merges-overlap`` — true merges, and the frame points farther than
  ``OVERLAP_VOXELS`` voxels from the model at the true pose (surfaces not modelled yet) dropped;
* ``camera-no-back`` — the same exclusion with the normal merges; ``clustered-cga-no-back``
  the same on the observer's chain;
* ``camera-no-back-merge`` — frames with more than ``BACK_MERGE_LIMIT`` back-face matches are
  observed but not merged (a remedy tried: far worse, the model then lacks the sides those
  frames first showed); ``clustered-cga-no-back-merge`` the same on the observer's chain;
* ``fused-true-extrinsic`` — camera + LIDAR moved by the true ``T_camera_lidar``, no clustering;
* ``clustered-true-extrinsic`` — plus paper 2's plane clustering;
* ``clustered-cga-extrinsic`` — the observer's own chain (CGA cross-source registration),
  still with the true registration start; ``clustered-cga-own-start`` the same from the
  model's own constant-velocity prediction (and its CGA global start at frame 1), as without a
  filter.

``--noiseless SEQ2`` (the same seed simulated without depth noise) registers each frame once
onto a model merged at the true poses, with model and frame each noisy or noiseless: which
side's noise moves the one-registration error. ``--trace STAGE`` prints that stage's
per-frame error on the first sequence in the sensor frame and in the model (body) axes: an
error inherited through the merges is constant in body axes and turns with the target in the
sensor frame. ``--per-frame`` prints per frame the fraction of the frame's points whose
nearest model point (the model built at the true poses) is a back face, and the error of one
registration onto that model.

Run: ``python benchmarks/archive/paper2_observer_bias.py SEQ [SEQ ...] [--stages a,b]
[--trace STAGE]
[--per-frame] [--noiseless SEQ2]``
with SEQ a sequence folder (``--work DIR`` of paper2_experiment.py, e.g.
``DIR/seq000_sensors.0.overrides.quantize-false_sensors.0.overrides.sigma_coeff-0``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from relnav.fusion.clustering import cluster_and_project, shape_factors
from relnav.fusion.cross_source import cross_source_register
from relnav.fusion.reconstruction import ContourModel
from relnav.geometry.rotations import quat_to_matrix
from relnav.geometry.se3 import invert, transform_points
from relnav.io.sequences import ScanSequence

STAGES = {
    "camera": dict(cloud="camera"),
    "camera-true-merges": dict(cloud="camera", true_merge=True),
    "camera-true-merges-no-back": dict(cloud="camera", true_merge=True, no_back=True),
    "camera-true-merges-overlap": dict(cloud="camera", true_merge=True, overlap=True),
    "camera-no-back": dict(cloud="camera", no_back=True),
    "camera-no-back-merge": dict(cloud="camera", skip_back_merge=True),
    "clustered-cga-no-back": dict(cloud="clustered", cga=True, no_back=True),
    "clustered-cga-no-back-merge": dict(cloud="clustered", cga=True, skip_back_merge=True),
    "fused-true-extrinsic": dict(cloud="fused"),
    "clustered-true-extrinsic": dict(cloud="clustered"),
    "clustered-cga-extrinsic": dict(cloud="clustered", cga=True),
    "clustered-cga-own-start": dict(cloud="clustered", cga=True, own_start=True),
}


OVERLAP_VOXELS = 2.0
"""``camera-true-merges-overlap``: frame points farther than this many voxels from the model
(at the true pose) — surfaces the model does not hold yet — are dropped."""
BACK_MERGE_LIMIT = 0.2
"""``camera-no-back-merge``: frames with more back-face matches than this are not merged."""


def back_facing(
    frame_pts: np.ndarray, sensor_origin: np.ndarray, store: np.ndarray, store_origin: np.ndarray
) -> np.ndarray:
    """Mask of frame points whose nearest stored point was seen from the other side.

    Parameters
    ----------
    frame_pts : (N, 3) float64
        Frame points in the model frame (m).
    sensor_origin : (3,) float64
        The frame's sensor origin in the model frame (m).
    store, store_origin : (M, 3) float64
        Model points (m) and the sensor origin of the frame that contributed each (m).

    Returns
    -------
    (N,) bool
        ``True`` where the frame's PCA normal (k = 10) puts its own sensor and the stored
        point's sensor on opposite sides by more than 5 cm.
    """
    n = shape_factors(frame_pts, k=10).normals
    ok = np.all(np.isfinite(n), axis=1)
    n = np.nan_to_num(n)
    _, i = cKDTree(store).query(frame_pts)
    s_now = np.einsum("ij,ij->i", sensor_origin - frame_pts, n)
    s_then = np.einsum("ij,ij->i", store_origin[i] - store[i], n)
    return (
        ok & (np.sign(s_now) != np.sign(s_then)) & (np.abs(s_now) > 0.05) & (np.abs(s_then) > 0.05)
    )


class _DiagnosticModel(ContourModel):
    """ContourModel that can merge at the true pose and drop back-face points (truth-fed)."""

    def __init__(
        self,
        *,
        true_merge: bool,
        no_back: bool,
        seed: int,
        skip_back_merge: bool = False,
        overlap: bool = False,
    ) -> None:
        super().__init__(seed=seed)
        self.overlap = overlap
        self.true_merge = true_merge
        self.no_back = no_back
        self.skip_back_merge = skip_back_merge
        self.T_true = np.eye(4)
        self._store: tuple[np.ndarray, np.ndarray] | None = None

    def _merge(self, P: np.ndarray, T_model_frame: np.ndarray) -> None:
        T = self.T_true if self.true_merge else T_model_frame
        if self.skip_back_merge and self._store is not None:
            Q = transform_points(self.T_true, self._downsample(P))
            if np.mean(back_facing(Q, self.T_true[:3, 3], *self._store)) > BACK_MERGE_LIMIT:
                return  # the frame is observed but not merged
        Pm = transform_points(T, P)
        O = np.tile(T[:3, 3], (len(P), 1))
        if self._store is None:
            self._store = (Pm, O)
        else:
            self._store = (np.vstack([self._store[0], Pm]), np.vstack([self._store[1], O]))
        super()._merge(P, T)

    def _downsample(self, P: np.ndarray) -> np.ndarray:
        Q = super()._downsample(P)
        if self.no_back and self._store is not None:
            Qm = transform_points(self.T_true, Q)
            Q = Q[~back_facing(Qm, self.T_true[:3, 3], *self._store)]
        if self.overlap and self._store is not None and self._voxel is not None:
            d, _ = cKDTree(self._model).query(transform_points(self.T_true, Q))
            Q = Q[d <= OVERLAP_VOXELS * self._voxel]
        return Q


def run_stage(seq: Path, stage: str, seed: int) -> np.ndarray:
    """Observation errors ``(K - 1, 6)``: ``[δD (m, sensor frame), δθ (rad)]`` of frames 1…K−1."""
    opts = STAGES[stage]
    cam = ScanSequence(seq)
    lid = ScanSequence(seq, sensor="lidar")
    gc, gl = cam.gt_poses, lid.gt_poses
    model = _DiagnosticModel(
        true_merge=bool(opts.get("true_merge")),
        no_back=bool(opts.get("no_back")),
        skip_back_merge=bool(opts.get("skip_back_merge")),
        overlap=bool(opts.get("overlap")),
        seed=seed,
    )
    errs = []
    for k in range(len(cam)):
        C = cam[k].points
        cloud = C
        if opts["cloud"] != "camera":
            T_cl = invert(gc[k]) @ gl[k]
            if opts.get("cga"):
                res = cross_source_register(C, lid[k].points, m=15, seed=seed + k)
                if not res.ok:
                    errs.append(np.full(6, np.nan))
                    continue
                T_cl = res.T_target_source
            Lc = transform_points(T_cl, lid[k].points)
            if opts["cloud"] == "clustered":
                cloud = cluster_and_project(C, Lc).fused_points
            else:
                cloud = np.vstack([C, Lc])
        T_M_S = invert(gc[0]) @ gc[k]
        model.T_true = T_M_S
        start = None if k == 0 or opts.get("own_start") else T_M_S
        pos, q, _ = model.observe(cloud, init=start)
        b = model.body_origin
        T_S_M = invert(T_M_S)
        D_true = T_S_M[:3, :3] @ b + T_S_M[:3, 3]
        dth = Rotation.from_matrix(T_S_M[:3, :3].T @ quat_to_matrix(q)).as_rotvec()
        errs.append(np.r_[pos - D_true, dth])
    return np.asarray(errs)[1:]


def per_frame_back_faces(seq: Path) -> list[tuple[int, float, np.ndarray]]:
    """Per frame: back-face fraction against the true-pose model, error of one registration."""
    from relnav.features.keypoints import voxel_downsample
    from relnav.geometry.neighbors import mean_resolution
    from relnav.registration import get_registration

    cam = ScanSequence(seq)
    g = cam.gt_poses
    T = [invert(g[0]) @ g[k] for k in range(len(cam))]
    vox = 2.0 * mean_resolution(cam[0].points)
    out = []
    for k in range(1, len(cam)):
        parts = [transform_points(T[j], cam[j].points) for j in range(k)]
        store = np.vstack(parts)
        origins = np.concatenate([np.tile(T[j][:3, 3], (len(p), 1)) for j, p in enumerate(parts)])
        back = back_facing(transform_points(T[k], cam[k].points), T[k][:3, 3], store, origins)
        model = voxel_downsample(store, vox)
        src = voxel_downsample(cam[k].points, vox)
        r = get_registration("icp-point", max_iter=50).register(src, model, init=T[k])
        T_est_S = invert(r.T_target_source)
        b = store.mean(axis=0)  # any body point: the observation error of that reference
        e = (T_est_S[:3, :3] @ b + T_est_S[:3, 3]) - (
            invert(T[k])[:3, :3] @ b + invert(T[k])[:3, 3]
        )
        out.append((k, float(back.mean()), e))
    return out


def noise_split(noisy: Path, clean: Path) -> list[tuple[str, str, np.ndarray]]:
    """One registration per frame onto a model merged at the true poses, with the model and the
    frame each taken from the noisy or the noiseless sequence (same geometry and poses).

    Returns ``(model, frame, errors (K - 1, 3))`` per combination; errors of the reference point
    ``b`` = the noisy first frame's centroid, sensor frame, m.
    """
    from relnav.features.keypoints import voxel_downsample
    from relnav.geometry.neighbors import mean_resolution
    from relnav.registration import get_registration

    seqs = {"noisy": ScanSequence(noisy), "noiseless": ScanSequence(clean)}
    g = seqs["noisy"].gt_poses
    T = [invert(g[0]) @ g[k] for k in range(len(g))]
    vox = 2.0 * mean_resolution(seqs["noisy"][0].points)
    b = seqs["noisy"][0].points.mean(axis=0)
    out = []
    for m_name, m_seq in seqs.items():
        for f_name, f_seq in seqs.items():
            errs = []
            model = np.zeros((0, 3))
            for k in range(len(g)):
                if k > 0:
                    src = voxel_downsample(f_seq[k].points, vox)
                    r = get_registration("icp-point", max_iter=50).register(src, model, init=T[k])
                    Te, Tt = invert(r.T_target_source), invert(T[k])
                    errs.append((Te[:3, :3] @ b + Te[:3, 3]) - (Tt[:3, :3] @ b + Tt[:3, 3]))
                Pm = transform_points(T[k], m_seq[k].points)
                model = voxel_downsample(np.vstack([model, Pm]), vox)
            out.append((m_name, f_name, np.asarray(errs)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seqs", type=Path, nargs="+")
    ap.add_argument("--stages", default=",".join(STAGES), help="comma-separated, '' = none")
    ap.add_argument("--per-frame", action="store_true", help="also the per-frame back faces")
    ap.add_argument("--trace", default=None, help="per-frame errors of this stage")
    ap.add_argument(
        "--noiseless", type=Path, default=None, help="noiseless twin of the first SEQ: noise split"
    )
    args = ap.parse_args()
    mm = lambda v: ", ".join(f"{1e3 * x:+.2f}" for x in v)  # noqa: E731
    print("| stage | mean error x, y, z (mm, sensor) | RMS x, y, z (mm) | mean attitude (deg) |")
    print("|---|---|---|---|")
    for stage in filter(None, args.stages.split(",")):
        t0 = time.perf_counter()
        E = np.vstack([run_stage(s, stage, int(s.name[3:6])) for s in args.seqs])
        att = ", ".join(f"{x:+.3f}" for x in np.degrees(np.nanmean(E[:, 3:], axis=0)))
        print(
            f"| {stage} | {mm(np.nanmean(E[:, :3], axis=0))} | "
            f"{mm(np.sqrt(np.nanmean(E[:, :3] ** 2, axis=0)))} | {att} |"
            f" <!-- {time.perf_counter() - t0:.0f} s -->",
            flush=True,
        )
    if args.trace:
        seq = args.seqs[0]
        E = run_stage(seq, args.trace, int(seq.name[3:6]))
        g = ScanSequence(seq).gt_poses
        print(f"\n{args.trace}, {seq.name}")
        print("\n| frame | error x, y, z (mm, sensor) | error in body (model) axes (mm) |")
        print("|---|---|---|")
        for k in range(1, len(g)):
            R_S_M = (invert(g[k]) @ g[0])[:3, :3]
            print(f"| {k} | {mm(E[k - 1, :3])} | {mm(R_S_M.T @ E[k - 1, :3])} |")
    if args.noiseless is not None:
        print("\n| model | frame | mean error x, y, z (mm, sensor) | RMS x, y, z (mm) |")
        print("|---|---|---|---|")
        for m_name, f_name, E in noise_split(args.seqs[0], args.noiseless):
            rms = np.sqrt(np.mean(E**2, axis=0))
            print(f"| {m_name} | {f_name} | {mm(E.mean(axis=0))} | {mm(rms)} |", flush=True)
    if args.per_frame:
        print("\n| frame | back-face nearest neighbours | one-registration error x, y, z (mm) |")
        print("|---|---|---|")
        for k, f, e in per_frame_back_faces(args.seqs[0]):
            print(f"| {k} | {f:.1%} | {mm(e)} |", flush=True)


if __name__ == "__main__":
    main()
