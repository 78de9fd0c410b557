"""The options of relnav's navigator (:class:`NavigatorConfig`, ``-O section.key=value``).

The options come in sections (:data:`SECTIONS`): ``map``, ``solver``, ``prior``, ``startup``,
``integrity``, ``reloc``, ``loops``, ``symmetry`` and ``orbit``, each a model whose fields carry
their range and one line of meaning. On the command line an option is ``-O reloc.gate=5``; in
Python ``Navigator(reloc={"gate": 5})`` or ``Navigator(**{"reloc.gate": 5})``. The flat names of
earlier releases (``reloc_gate``, ``init_window``, …) are still accepted, with a deprecation
message (:data:`LEGACY_NAMES`). What each option does at length, and the measurements that chose
its default, are in ``docs/navigator.md``, "Options". The navigator itself is
:class:`relnav.navigation.navigator.Navigator`.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, Literal

from pydantic import ConfigDict, Field, ValidationError, field_validator

from relnav.config import StrictModel, describe_range, did_you_mean, format_validation_error
from relnav.errors import ConfigError

__all__ = [
    "LEGACY_NAMES",
    "MERGED_STATUSES",
    "SECTIONS",
    "NavigatorConfig",
    "in_map",
    "loop_closer_options",
    "navigator_config",
    "range_text",
    "MapOptions",
    "SolverOptions",
    "PriorOptions",
    "StartupOptions",
    "IntegrityOptions",
    "RelocOptions",
    "LoopOptions",
    "SymmetryOptions",
    "OrbitOptions",
]

MERGED_STATUSES = ("ok", "first", "flagged")
"""Statuses of the navigator's frames whose pose is the registration's and whose scan went into
the map (``flagged``: an ``ok`` step labelled by ``integrity.flag_probability``)."""


def in_map(step: Any) -> bool:
    """Did the frame's scan go into the navigator's map?

    Its status is one of :data:`MERGED_STATUSES`, or the scan was merged and an integrity
    check relabelled the step afterwards (``degenerate`` over an alert limit): the
    ``merged`` attribute of a :class:`relnav.navigation.state.StateRecord` or the
    ``result.info["merged"]`` of an :class:`relnav.odometry.OdometryStep`.
    """
    if step.status in MERGED_STATUSES:
        return True
    merged = getattr(step, "merged", None)
    if merged is None:
        result = getattr(step, "result", None)
        merged = result is not None and result.info.get("merged")
    return bool(merged)


class _Section(StrictModel):
    """A section of :class:`NavigatorConfig`: unknown keys and NaN values are errors."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    @field_validator("*")
    @classmethod
    def _not_nan(cls, value: Any) -> Any:
        if isinstance(value, float) and math.isnan(value):
            raise ValueError("NaN is not a value")
        return value


class MapOptions(_Section):
    """``map``: The map: voxels, patches and what of each scan goes in."""

    voxel_factor: float = Field(
        0.3, gt=0, description="Map voxel edge, × the first scan's point spacing s₀."
    )
    max_voxel_weight: float = Field(
        20.0,
        ge=1,
        description="Observations after which a voxel forgets geometrically (the map follows "
        "corrections).",
    )
    max_voxels: int = Field(
        200_000,
        ge=1,
        description="Bound on the map's size (the least recently seen voxels dropped).",
    )
    k_neighbors: int = Field(10, ge=3, description="Map points per patch (normal estimation).")
    inplane_sigma: float = Field(
        3.0, gt=0, description="In-plane 1σ of a map point's information, × s₀."
    )
    noise_floor: float = Field(
        0.03, gt=0, description="Smallest 1σ of a map patch along its normal, × s₀."
    )
    nonplanar_gain: float = Field(
        0.0, ge=0, description="Weight of a patch's non-planar directions (0: planes only)."
    )
    surface: Literal["plane", "quadric"] = Field(
        "plane", description="Surface model of the map's patches."
    )
    curvature_sigma: float = Field(
        0.3, gt=0, description="Prior 1σ of a quadric patch's curvatures, 1/m."
    )
    quadric_reach: float = Field(
        1.8,
        ge=0,
        description="A quadric patch whose neighbours reach farther than this (× s₀) stays a "
        "plane.",
    )
    patch_point: Literal["mean", "plane"] = Field(
        "plane",
        description="A plane patch's residuals from the plane through its neighbours' centroid "
        "(within ``patch_point_reach``), or from the voxel's mean (before session 32).",
    )
    patch_point_reach: float = Field(
        1.2,
        ge=0,
        description="A plane patch whose neighbours reach farther than this (× s₀) keeps its "
        "mean as its point.",
    )
    max_points: int = Field(
        4000,
        ge=6,
        description="Point budget of the registration (a seeded random subset in scan order "
        "beyond it).",
    )
    max_map_points: int = Field(
        1500, ge=6, description="Points of an accepted scan inserted into the map (an even subset)."
    )


class SolverOptions(_Section):
    """``solver``: The registration of a scan onto the map and its acceptance."""

    kernel: float = Field(
        3.0, gt=0, description="Geman–McClure scale on the Mahalanobis distance to the map (σ)."
    )
    kernel_start: float = Field(
        100.0, gt=0, description="Graduated non-convexity: the kernel's first scale (σ)."
    )
    kernel_decay: float = Field(
        0.6,
        gt=0,
        le=1,
        description="Graduated non-convexity: the scale's factor per iteration down to ``kernel``.",
    )
    max_iter: int = Field(30, ge=1, description="Gauss–Newton iterations per registration.")
    tolerance: float = Field(
        1e-4, gt=0, description="Convergence: a step below this × the voxel (rotation × range)."
    )
    min_points: int = Field(
        6,
        ge=1,
        description="Fewest finite scan points, and scan points near the map, for a step (else "
        "failed).",
    )
    min_overlap: float = Field(
        0.3,
        ge=0,
        le=1,
        description="Smallest fraction of the scan near the map for a step (else failed).",
    )
    chi2_gate: float = Field(
        100.0,
        gt=0,
        description="Largest χ² (6 dof) of the correction against the motion model for an ok step.",
    )
    recover_rms_ratio: float = Field(
        1.5,
        gt=0,
        description="A weak-prior answer is kept if its robust RMS is at most this × the first "
        "one's.",
    )
    recover_unmatched: Literal["never", "with_attitude", "always"] = Field(
        "with_attitude",
        description="A scan with too few points near the map under the motion model's gate is "
        "registered again under the weak prior (kept when usable and not degenerate): never, "
        "only when the prediction took the measured attitude (the prior then keeps its "
        "rotation and the filter widens in translation only), or always.",
    )
    min_degeneracy: float = Field(
        1e-6,
        ge=0,
        lt=1,
        description="Smallest eigenvalue ratio of the scan's information (else degenerate).",
    )
    information: Literal["full", "normal"] = Field(
        "full",
        description="The scan's information: the solver's full one or along the normals only.",
    )
    repeat_refine: float = Field(
        0.1,
        ge=0,
        description="Point-to-point 1σ (× s₀) of the refinement on repeated points (0: off).",
    )
    threads: int = Field(
        1,
        ge=0,
        description="Threads for a frame's independent registrations (the extra starts under "
        "jitter; 0: the usable cores). Same answers for any number.",
    )
    repeat_max_points: int = Field(
        16000, ge=0, description="Points of the full scan used by that refinement (0: all)."
    )
    repeat_fraction: float = Field(
        0.5,
        ge=0,
        le=1,
        description="Fraction of the scan on the previous scan's rays to keep that refinement.",
    )


class PriorOptions(_Section):
    """``prior``: The motion model: the constant-velocity filter, its noise, jitter and smoother."""

    sigma_acc_t: float = Field(
        0.2, gt=0, description="White-acceleration 1σ in translation per frame, × s₀."
    )
    sigma_acc_r_deg: float = Field(
        0.2, gt=0, le=180, description="White-acceleration 1σ in rotation per frame, deg."
    )
    sigma_first_t: float = Field(
        5.0, gt=0, description="The first step's weak prior in translation, × the scan's lever arm."
    )
    sigma_first_r_deg: float = Field(
        30.0, gt=0, le=180, description="The first step's weak prior in rotation, deg."
    )
    adaptive_noise: bool = Field(
        True, description="Scale the process noise by the recent normalised corrections."
    )
    jitter_rate: float = Field(
        0.2,
        ge=0,
        le=1,
        description="Learning rate of the attitude jitter from the rotation corrections (0: off).",
    )
    jitter_after_frames: int = Field(
        3,
        ge=0,
        description="Frames of the map before the jitter is learned (10: before session 31, "
        "with the flags).",
    )
    jitter_max_deg: float = Field(
        5.0, ge=0, le=90, description="Largest learned attitude jitter 1σ per axis, deg."
    )
    jitter_scan_margin: float = Field(
        9.0,
        ge=0,
        description="A correction counts as jitter beyond this × the scan's own rotation variance.",
    )
    jitter_starts: int = Field(
        2,
        ge=0,
        description="Extra registrations from rotated starts once jitter is learned (0: off).",
    )
    jitter_start_min_deg: float = Field(
        0.3, ge=0, le=90, description="Learned jitter 1σ from which the extra starts run, deg."
    )
    jitter_choice: Literal["objective", "rms"] = Field(
        "objective",
        description="Keep the answer (the prediction's or an extra start's) of lowest objective, "
        "the robust cost plus χ² against the motion model's prior, or of lowest robust RMS "
        "(before session 31).",
    )
    jitter_screen: int = Field(
        3,
        ge=1,
        description="Screen the extra starts on every n-th scan point, then register the best "
        "on the whole scan (1: every start on the whole scan).",
    )
    jitter_screen_keep: int = Field(
        2, ge=1, description="Screened extra starts registered on the whole scan."
    )
    smooth_lag: int = Field(
        20, ge=0, description="Fixed-lag smoother's lag, frames (0: no smoothed trajectory)."
    )


class StartupOptions(_Section):
    """``startup``: The first frames: the multi-view refinement, re-anchoring and the second "
    "pass."""

    window: int = Field(
        10, ge=0, description="Frames refined together once tracked (0: off; else at least 3)."
    )
    premap_range: bool = Field(
        True,
        description="Before the map starts (scans too sparse to start it), place the sensor from "
        "each scan's centroid: its range along the first line of sight, or its whole bearing "
        "with the attitude input (off: keep the initial pose).",
    )
    map_min_points: int = Field(
        0,
        ge=0,
        description="Points a scan needs to start the map (0: solver.min_points); sparser scans "
        "before it are placed by premap_range.",
    )
    rounds: int = Field(10, ge=1, description="Largest number of rounds of that refinement.")
    gate: float = Field(
        3.0, gt=0, description="Pair gate of the refinement, × s₀ (at least two voxels)."
    )
    repeat: int = Field(
        0, ge=0, description="A second refinement at this frame (0: none; more than ``window``)."
    )
    solver: Literal["loo", "joint"] = Field(
        "joint", description="Joint Levenberg–Marquardt over all poses, or leave-one-out."
    )
    prior: Literal["weak", "motion", "velocity"] = Field(
        "motion",
        description="Terms besides the scans: a weak prior, constant velocity, or the filter's "
        "velocity.",
    )
    prior_scale: float = Field(1.0, gt=0, description="Scale of the constant-velocity terms' 1σ.")
    inplane_sigma: float = Field(
        3.0, gt=0, description="In-plane 1σ of the refinement's pairs, × s₀."
    )
    velocity: Literal["refined", "keep"] = Field(
        "keep",
        description="The filter's velocity after a refinement: its own, or the refined steps'.",
    )
    check: bool = Field(
        True,
        description="Keep a joint refinement only if it is surer of the last pose than the filter.",
    )
    reanchor_frame: int = Field(
        0, ge=0, description="Re-register the first scan on the later map at this frame (0: off)."
    )
    reanchor_skip: int = Field(
        5, ge=1, description="The later map starts this many frames after the first."
    )
    reanchor_gate: float = Field(
        22.46, gt=0, description="χ²₆ gate of the re-anchoring's two tests (22.46: 0.999)."
    )
    bootstrap_frames: int = Field(
        0,
        ge=0,
        description="Track the first frames again from the velocity they revealed (0: off).",
    )


class IntegrityOptions(_Section):
    """``integrity``: Each step's judgement from its covariance and its disagreements."""

    alert_limit_t: float = Field(
        0.0, ge=0, description="Alert limit of the translation protection level, m (0: none)."
    )
    alert_limit_r_deg: float = Field(
        0.0,
        ge=0,
        le=180,
        description="Alert limit of the rotation protection level, deg (0: none).",
    )
    protection_k: float = Field(
        3.0, gt=0, description="Protection level: this × the step's largest 1σ."
    )
    flag_probability: float = Field(
        0.5,
        ge=0,
        lt=1,
        description="Flag a step whose error exceeds the flag limits with more than this "
        "probability (0: off).",
    )
    flag_limit_t: float = Field(0.5, gt=0, description="Flag limit in translation, m.")
    flag_limit_r_deg: float = Field(5.0, gt=0, le=180, description="Flag limit in rotation, deg.")
    flag_chi2: float = Field(
        0.0, ge=0, description="Flag a step whose correction's χ² exceeds this (0: off)."
    )
    flag_min_fitness: float = Field(
        0.8, ge=0, le=1, description="Flag a step whose fitness is below this."
    )
    flag_recovered: bool = Field(True, description="Flag a step kept under the weak prior.")
    ambiguity_rms: float = Field(
        1.02,
        ge=0,
        description="Flag a step when another start's answer fits within this RMS ratio and "
        "lies beyond the flag limits (0: off).",
    )
    flag_after_frames: int = Field(
        10,
        ge=0,
        description="Frames of the map before the disagreement flags start.",
    )
    stability_check: bool = Field(
        False,
        description="Register again from a start along the weakest direction; unstable → "
        "degenerate.",
    )
    stability_k: float = Field(2.0, ge=0, description="That start's displacement, σ.")
    stability_cap: float = Field(
        4.0, gt=0, description="Largest displacement of the second start, map voxels."
    )
    stability_gate: float = Field(
        3.0, gt=0, description="Answers farther apart than this (σ) are unstable."
    )
    stability_pose: Literal["prediction", "fit"] = Field(
        "fit", description="An unstable step keeps the prediction or its better-fitting answer."
    )
    stability_kernel: float = Field(
        1.0, gt=0, description="Kernel scale factor of the second registration."
    )
    stability_mode: Literal["start", "prior"] = Field(
        "start", description="Displace the start only, or the prior too."
    )
    stability_flag: Literal["sigma", "limits"] = Field(
        "sigma",
        description="Unstable when the answers are over stability_gate σ apart, or only when "
        "they are also farther apart than the flag limits.",
    )
    stability_when: Literal["always", "jitter"] = Field(
        "always",
        description="Check every step, or only while the learned attitude jitter is at least "
        "prior.jitter_start_min_deg.",
    )


class RelocOptions(_Section):
    """``reloc``: Loss detection and global relocalisation against the map."""

    enabled: bool = Field(True, description="Detect losses and suspect jumps and relocalise.")
    lost_after: int = Field(
        3, ge=1, description="Frames in a row not ok after which the navigator is lost."
    )
    every: int = Field(1, ge=1, description="While lost, try every this many frames.")
    method: Literal["clique", "gcc"] = Field(
        "clique",
        description="Consistent matches by maximum clique or by geometric-consistency grouping.",
    )
    descriptor: str = Field("fpfh", description="Descriptor of the scan and the map.")
    radius: float = Field(6.0, gt=0, description="Descriptor support radius, × s₀.")
    tau: float = Field(
        1.0, gt=0, description="Descriptor-distance gate of the nearest-neighbour matching."
    )
    epsilon: float = Field(2.0, gt=0, description="Geometric-consistency tolerance, × s₀.")
    gate: float = Field(4.0, gt=0, description="Pair gate of the verifying registration, × s₀.")
    candidates: int = Field(3, ge=1, description="Candidate poses verified.")
    max_map_points: int = Field(2000, ge=6, description="Keypoints of the map's description.")
    max_scan_points: int = Field(400, ge=6, description="Keypoints of the scan's description.")
    rms_ratio: float = Field(
        1.5, gt=0, description="A candidate's robust RMS at most this × the recent steps'."
    )
    chi2: float = Field(100.0, gt=0, description="A step's χ² beyond this is a jump to confirm.")
    suspect_ratio: float = Field(
        2.5, gt=0, description="A step's robust RMS beyond this × the recent ones' is suspect."
    )
    overlap_ratio: float = Field(
        0.9, ge=0, le=1, description="A step's overlap below this × the recent ones' is suspect."
    )
    max_doubt: int = Field(8, ge=0, description="Suspect steps flagged in a row at most.")
    min_support: int = Field(6, ge=3, description="Fewest consistent matches of a candidate.")
    ambiguity: float = Field(
        0.3,
        ge=0,
        le=1,
        description="Another pose fitting within this fraction makes a relocalisation ambiguous.",
    )
    velocity: Literal["keep", "zero", "widen"] = Field(
        "keep", description="The filter's velocity after a relocalisation."
    )


class LoopOptions(_Section):
    """``loops``: Keyframes, the pose graph and the online revisit test."""

    enabled: bool = Field(
        False,
        description="Revisits and pose-graph optimisation at the end of the run (online poses "
        "unchanged).",
    )
    keyframe_every: int = Field(5, ge=1, description="Accepted frames between keyframes.")
    keyframe_window: int = Field(
        5,
        ge=0,
        description="A keyframe's submap merges the accepted frames within this many frames of it.",
    )
    min_separation: int = Field(
        10,
        ge=1,
        description="A revisit closes only on keyframes at least this many keyframes older.",
    )
    max_distance: float = Field(
        0.15,
        gt=0,
        description="Largest distance between a revisit's two sensor positions, fraction of "
        "the range.",
    )
    max_angle_deg: float = Field(
        15.0, gt=0, le=180, description="Largest view-angle difference of a revisit, deg."
    )
    min_overlap: float = Field(
        0.5, ge=0, le=1, description="Smallest overlap of a loop registration."
    )
    max_rms: float = Field(3.0, gt=0, description="Largest robust RMS of a loop registration (σ).")
    chi2_gate: float = Field(50.0, gt=0, description="χ² gate of a loop edge against the chain.")
    kernel: float = Field(5.0, gt=0, description="Robust kernel of the pose graph's edges (σ).")
    info_scale: float = Field(1.0, gt=0, description="Scale of the loop edges' information.")
    prior_scale: float = Field(
        0.0,
        ge=0,
        description="Weight of the filter's pose covariance on the graph's nodes (0: none).",
    )
    revisit_alarm_chi2: float = Field(
        16.81,
        ge=0,
        description="χ² (6 dof) of a revisit beyond which the map is inconsistent (0: off).",
    )


class SymmetryOptions(_Section):
    """``symmetry``: The map's axis of rotational symmetry."""

    max_ratio: float = Field(
        0.0, ge=0, description="Symmetry ratio below which the map has an axis (0: no test)."
    )
    min_arc_deg: float = Field(
        180.0, gt=0, le=360, description="Smallest arc of the map about the axis, deg."
    )
    max_axial: float = Field(
        0.6, ge=0, le=1, description="Largest fraction of normals along the axis."
    )
    gain: float = Field(
        0.0, ge=0, description="Stiffening of the prior along the symmetric rotation."
    )
    every: int = Field(5, ge=1, description="Test every this many accepted frames.")
    irls: int = Field(0, ge=0, description="Robust reweighting rounds of the axis fit.")


class OrbitOptions(_Section):
    """``orbit``: The target's free relative orbit (a mission input) and its azimuth test."""

    mean_motion: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="The target orbit's mean motion, rad/s (0: unknown; low Earth orbit ≈ "
        "1.13e-3).",
    )
    max_symmetry: float = Field(
        0.05,
        gt=0,
        allow_inf_nan=False,
        description="Largest symmetry ratio of the map for the test.",
    )
    max_misfit: float = Field(
        0.005,
        gt=0,
        allow_inf_nan=False,
        description="Largest RMS misfit of the orbit, × the sensor's distance from the axis.",
    )
    min_excess: float = Field(
        3.0,
        ge=1,
        allow_inf_nan=False,
        description="How many times larger the free fit's misfit must be.",
    )


SECTIONS: dict[str, type[_Section]] = {
    "map": MapOptions,
    "solver": SolverOptions,
    "prior": PriorOptions,
    "startup": StartupOptions,
    "integrity": IntegrityOptions,
    "reloc": RelocOptions,
    "loops": LoopOptions,
    "symmetry": SymmetryOptions,
    "orbit": OrbitOptions,
}
"""The sections of :class:`NavigatorConfig`, by name."""

LEGACY_NAMES: dict[str, str] = {
    "voxel_factor": "map.voxel_factor",
    "max_voxel_weight": "map.max_voxel_weight",
    "max_voxels": "map.max_voxels",
    "k_neighbors": "map.k_neighbors",
    "inplane_sigma": "map.inplane_sigma",
    "noise_floor": "map.noise_floor",
    "nonplanar_gain": "map.nonplanar_gain",
    "surface": "map.surface",
    "curvature_sigma": "map.curvature_sigma",
    "quadric_reach": "map.quadric_reach",
    "max_points": "map.max_points",
    "max_map_points": "map.max_map_points",
    "kernel": "solver.kernel",
    "kernel_start": "solver.kernel_start",
    "kernel_decay": "solver.kernel_decay",
    "max_iter": "solver.max_iter",
    "tolerance": "solver.tolerance",
    "min_points": "solver.min_points",
    "min_overlap": "solver.min_overlap",
    "chi2_gate": "solver.chi2_gate",
    "recover_rms_ratio": "solver.recover_rms_ratio",
    "min_degeneracy": "solver.min_degeneracy",
    "information": "solver.information",
    "repeat_refine": "solver.repeat_refine",
    "repeat_max_points": "solver.repeat_max_points",
    "repeat_fraction": "solver.repeat_fraction",
    "sigma_acc_t": "prior.sigma_acc_t",
    "sigma_acc_r_deg": "prior.sigma_acc_r_deg",
    "sigma_first_t": "prior.sigma_first_t",
    "sigma_first_r_deg": "prior.sigma_first_r_deg",
    "adaptive_noise": "prior.adaptive_noise",
    "jitter_rate": "prior.jitter_rate",
    "jitter_max_deg": "prior.jitter_max_deg",
    "jitter_scan_margin": "prior.jitter_scan_margin",
    "jitter_starts": "prior.jitter_starts",
    "jitter_start_min_deg": "prior.jitter_start_min_deg",
    "smooth_lag": "prior.smooth_lag",
    "init_window": "startup.window",
    "init_rounds": "startup.rounds",
    "init_gate": "startup.gate",
    "init_repeat": "startup.repeat",
    "init_solver": "startup.solver",
    "init_prior": "startup.prior",
    "init_prior_scale": "startup.prior_scale",
    "init_inplane_sigma": "startup.inplane_sigma",
    "init_velocity": "startup.velocity",
    "init_check": "startup.check",
    "reanchor_frame": "startup.reanchor_frame",
    "reanchor_skip": "startup.reanchor_skip",
    "reanchor_gate": "startup.reanchor_gate",
    "bootstrap_frames": "startup.bootstrap_frames",
    "alert_limit_t": "integrity.alert_limit_t",
    "alert_limit_r_deg": "integrity.alert_limit_r_deg",
    "protection_k": "integrity.protection_k",
    "flag_probability": "integrity.flag_probability",
    "flag_limit_t": "integrity.flag_limit_t",
    "flag_limit_r_deg": "integrity.flag_limit_r_deg",
    "flag_chi2": "integrity.flag_chi2",
    "flag_min_fitness": "integrity.flag_min_fitness",
    "flag_recovered": "integrity.flag_recovered",
    "flag_after_frames": "integrity.flag_after_frames",
    "stability_check": "integrity.stability_check",
    "stability_k": "integrity.stability_k",
    "stability_cap": "integrity.stability_cap",
    "stability_gate": "integrity.stability_gate",
    "stability_pose": "integrity.stability_pose",
    "stability_kernel": "integrity.stability_kernel",
    "stability_mode": "integrity.stability_mode",
    "relocalise": "reloc.enabled",
    "lost_after": "reloc.lost_after",
    "reloc_every": "reloc.every",
    "reloc_method": "reloc.method",
    "reloc_descriptor": "reloc.descriptor",
    "reloc_radius": "reloc.radius",
    "reloc_tau": "reloc.tau",
    "reloc_epsilon": "reloc.epsilon",
    "reloc_gate": "reloc.gate",
    "reloc_candidates": "reloc.candidates",
    "reloc_max_map_points": "reloc.max_map_points",
    "reloc_max_scan_points": "reloc.max_scan_points",
    "reloc_rms_ratio": "reloc.rms_ratio",
    "reloc_chi2": "reloc.chi2",
    "reloc_suspect_ratio": "reloc.suspect_ratio",
    "reloc_overlap_ratio": "reloc.overlap_ratio",
    "reloc_max_doubt": "reloc.max_doubt",
    "reloc_min_support": "reloc.min_support",
    "reloc_ambiguity": "reloc.ambiguity",
    "reloc_velocity": "reloc.velocity",
    "loop_closure": "loops.enabled",
    "keyframe_every": "loops.keyframe_every",
    "keyframe_window": "loops.keyframe_window",
    "loop_min_separation": "loops.min_separation",
    "loop_max_distance": "loops.max_distance",
    "loop_max_angle_deg": "loops.max_angle_deg",
    "loop_min_overlap": "loops.min_overlap",
    "loop_max_rms": "loops.max_rms",
    "loop_chi2_gate": "loops.chi2_gate",
    "loop_kernel": "loops.kernel",
    "loop_info_scale": "loops.info_scale",
    "loop_prior_scale": "loops.prior_scale",
    "revisit_alarm_chi2": "loops.revisit_alarm_chi2",
    "symmetry_max_ratio": "symmetry.max_ratio",
    "symmetry_min_arc_deg": "symmetry.min_arc_deg",
    "symmetry_max_axial": "symmetry.max_axial",
    "symmetry_gain": "symmetry.gain",
    "symmetry_every": "symmetry.every",
    "symmetry_irls": "symmetry.irls",
    "orbit_mean_motion": "orbit.mean_motion",
    "orbit_max_symmetry": "orbit.max_symmetry",
    "orbit_max_misfit": "orbit.max_misfit",
    "orbit_min_excess": "orbit.min_excess",
}
"""The flat option names of earlier releases → their ``section.key``: still accepted, with a
deprecation message, for one release."""


class NavigatorConfig(StrictModel):
    """Options of :class:`~relnav.navigation.navigator.Navigator`, in sections.

    Build it with :func:`navigator_config` from ``-O``-style options (dotted keys, nested
    mappings or the flat names of earlier releases), or directly with nested mappings:
    ``NavigatorConfig(reloc={"gate": 5})``. Each field's range and meaning are in its section's
    model (:data:`SECTIONS`); the measurements behind the defaults in ``docs/navigator.md``.
    """

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=True)

    map: MapOptions = Field(default_factory=MapOptions)
    solver: SolverOptions = Field(default_factory=SolverOptions)
    prior: PriorOptions = Field(default_factory=PriorOptions)
    startup: StartupOptions = Field(default_factory=StartupOptions)
    integrity: IntegrityOptions = Field(default_factory=IntegrityOptions)
    reloc: RelocOptions = Field(default_factory=RelocOptions)
    loops: LoopOptions = Field(default_factory=LoopOptions)
    symmetry: SymmetryOptions = Field(default_factory=SymmetryOptions)
    orbit: OrbitOptions = Field(default_factory=OrbitOptions)


def _nest(options: dict[str, Any], where: str) -> dict[str, dict[str, Any]]:
    """``-O``-style options → ``{section: {key: value}}``; flat names of earlier releases are
    translated with a deprecation message; an unknown name is a :class:`ConfigError` with the
    nearest names."""
    nested: dict[str, dict[str, Any]] = {}
    known = [f"{s}.{k}" for s, m in SECTIONS.items() for k in m.model_fields]
    flat: list[tuple[str, Any]] = []
    for key, value in options.items():  # a section's mapping → its dotted keys, in order
        if key in SECTIONS and isinstance(value, dict):
            flat += [(f"{key}.{k}", v) for k, v in value.items()]
        else:
            flat.append((key, value))
    for key, value in flat:
        dotted = key
        if key in LEGACY_NAMES:
            dotted = LEGACY_NAMES[key]
            warnings.warn(
                f"{where}: option {key!r} is now {dotted!r} (the flat name is accepted for one "
                "more release)",
                FutureWarning,
                stacklevel=4,
            )
        section, _, name = dotted.partition(".")
        if section not in SECTIONS or name not in SECTIONS[section].model_fields:
            raise ConfigError(
                f"{where}: unknown option {key!r}{did_you_mean(key, known)}"
                f"; options are section.key with the sections {', '.join(SECTIONS)}"
            )
        nested.setdefault(section, {})[name] = value
    return nested


def navigator_config(options: dict[str, Any] | None = None, *, where: str = "method 'relnav'"):
    """A :class:`NavigatorConfig` from ``-O``-style options.

    Parameters
    ----------
    options : dict, optional
        ``{"reloc.gate": 5}``, ``{"reloc": {"gate": 5}}`` or a flat name of an earlier release
        (``{"reloc_gate": 5}``, with a :class:`FutureWarning`).
    where : str
        What the error messages name.

    Raises
    ------
    ConfigError
        An unknown option (with the nearest names), a value of the wrong type or out of its
        range (one line naming ``section.key``).
    """
    nested = _nest(dict(options or {}), where)
    try:
        return NavigatorConfig.model_validate(nested)
    except ValidationError as e:
        raise ConfigError(_one_line(e, where)) from None


def _one_line(err: ValidationError, where: str) -> str:
    """The first problem of a validation error in the house style of ``-O`` options:
    ``where: option section.key=value out of range (must be >= 0 and <= 1)``, ``… is NaN``, or
    ``…: <pydantic's message> (expected <type>)``."""
    e = err.errors()[0]
    loc = [str(x) for x in e["loc"]]
    if len(loc) != 2 or loc[0] not in SECTIONS or loc[1] not in SECTIONS[loc[0]].model_fields:
        return format_validation_error(err, where)
    field = SECTIONS[loc[0]].model_fields[loc[1]]
    name, value = ".".join(loc), e.get("input")
    if isinstance(value, float) and math.isnan(value):
        return f"{where}: option {name} is NaN"
    if e["type"] in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        return f"{where}: option {name}={value!r} out of range (must be {range_text(field)})"
    if e["type"] == "finite_number":
        return f"{where}: option {name}={value!r} is not finite"
    kind = getattr(field.annotation, "__name__", None) or str(field.annotation)
    expected = "" if "Literal" in str(field.annotation) else f" (expected {kind})"
    return f"{where}: option {name}={value!r}: {e['msg']}{expected}"


def range_text(field: Any) -> str:
    """``">= 0 and <= 1"`` from a field's bounds (:func:`relnav.config.describe_range`)."""
    bounds = {
        attr: getattr(m, attr)
        for m in field.metadata
        for attr in ("gt", "ge", "lt", "le")
        if getattr(m, attr, None) is not None
    }
    low = bounds.get("ge", bounds.get("gt"))
    high = bounds.get("le", bounds.get("lt"))
    return describe_range((low, "ge" in bounds, high, "le" in bounds))


def loop_closer_options(c: NavigatorConfig) -> dict[str, Any]:
    """The :class:`~relnav.navigation.pose_graph.LoopCloser` keywords of a navigator's
    configuration (keyframes, revisit tests, registration, pose graph)."""
    lo, so = c.loops, c.solver
    return {
        "every": lo.keyframe_every,
        "window": lo.keyframe_window,
        "min_separation": lo.min_separation,
        "max_distance": lo.max_distance,
        "max_angle_deg": lo.max_angle_deg,
        "min_overlap": lo.min_overlap,
        "max_rms": lo.max_rms,
        "chi2_gate": lo.chi2_gate,
        "min_degeneracy": so.min_degeneracy,
        "kernel": so.kernel,
        "kernel_start": so.kernel_start,
        "kernel_decay": so.kernel_decay,
        "max_iter": so.max_iter,
        "tolerance": so.tolerance,
        "graph_kernel": lo.kernel,
        "info_scale": lo.info_scale,
        "prior_scale": lo.prior_scale,
    }
