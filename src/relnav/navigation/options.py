"""The options of relnav's navigator (:class:`NavigatorConfig`, ``-O key=value``).

Every option is documented with what it does and, where it was chosen on the navigation suite
(``benchmarks/nav_suite.py``), with the measurements that chose it. The navigator itself is
:class:`relnav.navigation.navigator.Navigator`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["MERGED_STATUSES", "NavigatorConfig", "in_map", "loop_closer_options"]

MERGED_STATUSES = ("ok", "first", "flagged")
"""Statuses of the navigator's frames whose pose is the registration's and whose scan went into
the map (``flagged``: an ``ok`` step labelled by ``flag_probability``, see
:class:`NavigatorConfig`)."""


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


@dataclass
class NavigatorConfig:
    """Options of :class:`Navigator` (``-O key=value`` on the command line).

    The **[measured]** figures below were taken with the defaults of their time: those made
    before the multi-view start became the default (``init_window=10``, ``init_velocity="keep"``;
    every one except ``init_window``'s own) are reproduced with ``-O init_window=0``.

    Attributes
    ----------
    voxel_factor : float
        Map voxel edge in multiples of the first scan's median point spacing ``s₀``.
    max_voxel_weight : float
        Observations after which a voxel forgets geometrically (map adapts to corrections).
    max_voxels : int
        Bound on the map size (least recently seen voxels dropped).
    kernel : float
        Geman–McClure scale on the Mahalanobis distance to a voxel (σ units).
    kernel_start, kernel_decay : float
        Graduated non-convexity: the scale starts at ``kernel_start`` and is multiplied by
        ``kernel_decay`` each iteration until it reaches ``kernel``.
    max_iter : int
        Gauss–Newton iterations per frame.
    tolerance : float
        Stop when an update moves the pose by less than this × the map voxel (translation) and
        rotates it by less than that length at the scan's median range. 1e-3 measured on the
        suite: 15 % faster on 128×128 scans, but worse on the sparsest sequences; kept at 1e-4.
    min_points : int
        Scans with fewer finite points are ``failed``.
    max_points : int
        Point budget of the registration: larger scans are reduced to a seeded random subset
        (in scan order) of this size (:func:`relnav.odometry.budget.reduce_to_budget`, seed
        ``[0, frame]``). **[interpretation, measured]** An even subset of a raster scan (every
        k-th pixel) repeats from frame to frame and aliases with the image rows; a random draw
        does not. RPE translation, random vs even (first 10 frames of the ``dense-*`` presets;
        first 80 of sim-eoi, seed 0): Kinect 221k points 7.3 vs 40.7 mm, flash at 30k 8.7 vs
        18.4 mm, at 121k 13.0 vs 9.8 mm (worse), sim-eoi (3 200 points) 10.0 vs 10.9 mm.
        **[measured]** 1 500 → 4 000 (every point of sim-eoi's 3 500-point scans; chosen on
        the suite once the navigator's frame was 37–52 % faster): APE sim-eoi 0.014 → 0.008 m,
        sim-eoi-resample 0.068 → 0.032 m (17.5 → 26.8 and 14.8 → 24.5 ms per frame against
        KISS-ICP's ≈ 58 and 250 ms), the 15 other suite sequences and the 4 held-out ones
        identical to the printed digits.
    max_map_points : int
        Point budget of the map update (an evenly spaced subset of the registered points).
    min_overlap : float
        Smallest fraction of scan points with a map voxel within the gate for an ``ok`` step.
    chi2_gate : float
        Largest χ² (6 dof) of the correction against the motion model's uncertainty for an
        ``ok`` step.
    recover_rms_ratio : float
        A step inconsistent with the motion model is registered again under the first frame's
        weak prior and accepted if its robust residual is at most this times the first one's
        (the model, not the scan, was wrong: a manoeuvre or an over-confident velocity).
    bootstrap_frames : int
        After this many frames, track them again from the velocity they revealed (once; 0 =
        off, the default; needs ``init_window=0``): the first step has no motion prior (see
        :meth:`Navigator._bootstrap`). Measured on the suite with 5: better on sim-bennu,
        sim-eoi and orion-inclined-64's wrong steps, worse on iridium-helical-64, so off.
    init_window : int
        Multi-view refinement of the first frames (default 10; 0 = off; else at least 3): once
        this many frames are tracked their poses are refined together, the first one fixed,
        then the map is rebuilt and the filter goes on from the refined last pose
        (:mod:`relnav.navigation.startup.multiview` has the method and the suite's measurements).
    init_rounds, init_gate, init_solver, init_prior, init_prior_scale, init_inplane_sigma :
        Rounds at most; pair gate (× ``s₀``); ``joint`` or ``loo`` solver; ``motion``,
        ``velocity`` or ``weak`` prior and the factor on its 1σ; the joint refinement's
        in-plane 1σ (× ``s₀``) — see :func:`relnav.navigation.startup.multiview.refine_window`.
    init_velocity, init_check, init_repeat :
        The filter's velocity afterwards: its own (``keep``, the default) or the mean of the
        refined last steps (``refined``: the suite's dense presets are lost for some windows,
        see :mod:`relnav.navigation.startup.multiview`); keep a joint refinement only if it is more
        certain of the last pose than the filter; refine once more over the first
        ``init_repeat`` frames (0 = off; more than ``init_window``).
    reanchor_frame, reanchor_skip, reanchor_gate :
        **[interpretation, measured]** Re-anchoring of the start-up
        (:mod:`relnav.navigation.startup.anchor`; 0 = off, the default): once ``reanchor_frame``
        frames are tracked, the first scan is registered onto a map of the frames from
        ``reanchor_skip`` on, and the track is turned in the target frame so that the first scan
        sits where that denser map puts it, unless the correction is inconsistent with the start-up
        steps' covariance plus the registration's own, or does not fit significantly better (both
        χ²₆ tests at ``reanchor_gate``, default 22.46, the 0.999 quantile). Part of the
        ``relnav-tumbling`` method preset with ``surface="quadric"``: navigator APE over 20 noise
        seeds, median, voyager-tumble-64 8.55 → 0.63 m, comet-tumble-64 (made after it was frozen)
        0.15 → 0.06 m (``docs/navigator.md``, "Re-anchoring the start-up").
    smooth_lag : int
        Fixed-lag Rauch–Tung–Striebel smoothing of the trajectory over this many frames
        (:meth:`Navigator.finalize`; the per-frame online poses are unchanged); 0 = off.
    adaptive_noise : bool
        Scale the motion model's process noise by its recent normalised corrections.
    jitter_rate, jitter_max_deg, jitter_scan_margin : float
        The chaser's attitude jitter learned from the rotation innovations (EMA rate; 0 = off),
        its largest 1σ per axis per step (degrees) and how many times the scan's own rotation
        variance an innovation must exceed to count: white rotation noise of the pose, not of
        the velocity (:meth:`~relnav.navigation.motion.ConstantVelocityFilter.adapt_jitter`),
        learned from the ``flag_after_frames``-th frame of the map on (before, the corrections
        are the model learning the velocity: sim-orion-resample learned 1.5° at frame 4), and
        not with the chaser's attitude input (the jitter is measured there: envisat-jitter2
        with the input 0.15–0.33 m APE without learning, 0.82 m with it and the extra starts).
    jitter_starts, jitter_start_min_deg : int, float
        When the learned jitter's 1σ reaches ``jitter_start_min_deg`` (degrees), each scan is
        registered again from the prediction turned ±1 … ``jitter_starts`` σ about each sensor
        axis, the best-fitting answer kept (:mod:`relnav.navigation.multistart`; 0 = off); not
        while the map has a symmetry axis (its cost is flat about it).
    min_degeneracy : float
        Smallest ratio of the extreme eigenvalues of the scan's lever-arm-normalised
        information for an ``ok`` step (below: ``degenerate``, the model keeps the pose).
    sigma_acc_t, sigma_acc_r_deg : float
        Motion model's white acceleration: 1σ change of the per-frame motion from one frame to
        the next, translation in multiples of ``s₀``, rotation in degrees.
    sigma_first_t, sigma_first_r_deg : float
        1σ of the unknown motion over the first frame period: translation in multiples of the
        first scan's RMS radius, rotation in degrees.
    noise_floor : float
        Smallest 1σ of a map patch along its normal, multiples of ``s₀``.
    alert_limit_t, alert_limit_r_deg : float
        Integrity monitoring (0 = off, the default): a step whose protection level exceeds
        the alert limit (m, degrees) is flagged ``degenerate`` with the reason, its pose kept
        (the scans do not determine that step to the required accuracy). The protection
        level is ``protection_k`` × the largest 1σ of the step's translation (rotation) from
        the filter's step covariance (recorded for every step as ``step_sigma_t``,
        ``step_sigma_r_deg`` and the whole 6×6 ``step_covariance``, body frame).
    protection_k : float
        Multiplier of the step's 1σ in the protection level.
    flag_probability : float
        Honest step flags (0 = off): an ``ok`` step whose probability of being off by more than
        ``flag_limit_t`` metres or ``flag_limit_r_deg`` degrees exceeds this, under the filter's
        step covariance (a zero-mean Gaussian, body frame;
        :func:`relnav.navigation.integrity.exceedance_probability`), gets the status
        ``flagged``: its pose, the filter and the map are those of an ``ok`` step (the flag
        changes no pose), and the probability is recorded as ``info["exceed_probability"]``.
        **[measured]** Per-step signals against the suite's wrong steps (ground truth for
        scoring only; ``nav_suite.py --out /work/nav --methods relnav``; 64 wrong of 2033
        steps): this probability has AUC 0.73 pooled; iridium-helical-64's start-up steps 1–7
        have probabilities 0.87–1 (its 12–30-point scans do not fix the step: 1σ 1.3–4.1 m),
        the other wrong steps 0–0.5 — their covariances are over-confident (step NEES 3–20 on
        orion-inclined-64, 18–930 on sim-orion-resample, whose registrations are stable,
        biased optima about the capsule's axis). Flagged at 0.5 / 0.7 / **0.8** / 0.9: wrong
        11 / 7 / **7** / 4 of 64, right 47 / 11 / **3** / 0 of 1969 (iridium-helical-64 43 /
        9 / 1 / 0 of 138, envisat-tumble-64 2 / 2 / 2 / 0 of 199, orion-inclined-64 2 / 0 / 0
        / 0); 0.8 was the default then (it flags at most 1 % of any suite sequence's right
        steps). Held out (``--holdout``, not used to choose): 0 of capsule-ellipse-128's 249
        wrong steps (confident: probabilities ≤ 0.29), 7 of 597 right steps
        (voyager-helical-64's first 7 of 149, 1σ 1–8 m). **0.5 is the default** since the
        orbit input (``orbit_mean_motion``): given the target's orbit (the suite's mission
        input) the navigator corrects orion-inclined-64's and sim-orion-resample's confident
        wrong steps, and the suite's remaining wrong steps are iridium-helical-64's, whose
        covariances are honest. ``python benchmarks/nav_option_sweep.py --out bench/nav -O
        orbit_mean_motion=0 -O flag_probability=0.8`` (6 perturbed runs): wrong steps flagged
        11/11, 34/40, 34/34, 11/11, 41/42 and 10/10 per run (without the orbit at 0.8: 6–9 of
        50–93), right ones 16–50 of about 2 000 (at most 2.5 %; iridium-helical-64's 182 of its
        ~760 over the six runs). Held out: voyager-helical-64 flags 237 of its ~890 right steps
        over six runs (27 %: on 15–54-point scans the steps' 1σ is near the 0.5 m limit),
        aura-tumble-64 12, the capsule none of its wrong ones. 0.5 is the decision "more likely
        wrong than right". No other evidence-only signal tried
        (posterior σ per axis and along the scan's weakest direction, the prior's σ, the velocity's
        σ, residual RMS, overlap, information eigenvalues, the innovation against the motion model
        and its CUSUM along the weakest direction, the smoother's revision, the frame index) reaches
        a useful recall at < 5 % false flags pooled and on every sequence (best: the scaled
        information's eigenvalue ratio, 55 % at 5 % pooled, a property of whole sequences: it
        flags 61 of iridium-helical-64's 138 right steps and all 26 of sim-orion-resample's).
    flag_limit_t, flag_limit_r_deg : float
        The step error (m, degrees) the flags guard against (the suite's definition of a wrong
        step). Absolute, not scaled with the target: a mission sets its own.
    flag_chi2, flag_min_fitness, flag_recovered, flag_after_frames : float, float, bool, int
        Evidence that the motion model and the scan disagree, which the step's covariance (the
        model's and the scan's own) cannot show: from the ``flag_after_frames``-th frame of the
        map on (before, the model is still learning the motion), an ``ok`` step is also
        ``flagged`` when (``flag_recovered``) the model's prior was rejected and the step
        registered again under the weak prior, when under ``flag_min_fitness`` of the scan's
        points fit the map within 3σ (0 = off), or when its correction's χ² against the model's
        prior exceeds ``flag_chi2`` (0 = off, the default: a precise scan through a manoeuvre
        the model did not expect is right; sim-voyager's frames 44–55 have χ² 33–80).
        Labels only: poses unchanged. **[measured, not held out]** chosen on the stress group
        (``nav_suite.py --stress``) and the suite: envisat-jitter1 wrong steps flagged 0 → 21
        of 49 (right 3 of 61), envisat-jitter2 35 → 74 of 93; the suite's right steps +0–1
        per sequence (``docs/navigator.md``, "Motion that is not smooth").
    stability_check, stability_k : bool, float
        Stability check (off by default): the scan is registered a second time from the
        first answer displaced by ``stability_k`` σ along the weakest direction of the answer's
        information (scan + prior; rotations scaled by the scan's lever arm), the displacement
        capped at ``stability_cap`` map voxels. When the two answers differ by more than
        ``stability_gate`` in that information's metric (Mahalanobis distance), the step is
        not determined by the scan: it is flagged ``degenerate`` and the map is not updated.
        Recorded per step: ``stability_distance`` (σ) and ``stability_shift`` (m, rad).
        **Off: measured on the suite, it does not find the wrong steps.** The 64 wrong steps of
        the default (iridium-helical-64 11, orion-inclined-64 14, sim-orion-resample 33,
        sim-bennu-resample 6) are stable: registered again from 2σ (or 8 voxels, along the
        scan-only weakest direction), with the kernel schedule ×0.67 or ×1.5, or with the
        prior's centre shifted 2σ, they end at the same answer (median distance < 1e-3 σ;
        AUC wrong vs right 0.19–0.78). ``python benchmarks/nav_suite.py --out /work/nav
        --methods relnav -O stability_check=true [...]``, default gate 3: with
        ``stability_pose=fit`` 0 of the 64 flagged, 19 of 1949 right steps flagged (1.0 %),
        iridium-helical-64 APE 13.5 → 23.2 m (wrong 11 → 31, 13 of the new ones flagged),
        sim-voyager-resample 0.111 → 0.124 m, the rest within 5 %; with
        ``stability_pose=prediction`` 0 of the 64 flagged and 48 right steps flagged (2.5 %),
        sim-eoi-resample lost (APE 0.032 → 13.0 m, 27 wrong), iridium 11 → 24 wrong; gate 10
        flags 1 step in all; ``stability_mode=prior`` (gate 2.5) flags 133 right steps (7 %)
        and worsens 9 sequences. Cost 0.1–0.9 ms per 64×64 frame (one extra solve, usually a
        few iterations).
    stability_cap : float
        Largest displacement of the second start, multiples of the map voxel.
    stability_gate : float
        Mahalanobis distance between the two answers above which the step is flagged.
    stability_kernel : float
        Scale of the second registration's kernel schedule (``kernel`` and ``kernel_start``).
    stability_mode : {"start", "prior"}
        ``start``: only the second start is displaced; ``prior``: the prior's centre is
        displaced with it (how much of the prior the answer follows).
    stability_pose : {"prediction", "fit"}
        Pose of a flagged unstable step: the motion model's prediction (the filter skips the
        measurement) or the better-fitting of the two answers (lower robust RMS; the filter is
        updated with it, the map is not). ``fit``: fewer sequences worse on the suite (2, not
        4; keeping the prediction loses sim-eoi-resample).
    relocalise : bool
        Global re-localisation against the map with paper 1's descriptor pipeline when the
        navigator is lost or makes a suspect jump (:mod:`relnav.navigation.relocalize`).
    lost_after : int
        Consecutive frames that are not ``ok`` after which the navigator is lost.
    reloc_every : int
        While lost, try to relocalise every this many frames.
    reloc_method : {"clique", "gcc"}
        Consistent matches by maximum clique or by paper 1's geometric consistency grouping.
    reloc_descriptor : str
        Descriptor of the map and the scan (``fpfh``, ``hods``, ``shot``, …).
    reloc_radius : float
        Descriptor support radius, multiples of ``s₀``. **[measured]** Method, descriptor and
        radius were chosen with ``benchmarks/nav_relocalize.py --probe`` (each third scan of
        the last 40 % of a sequence located on the map of the first 60 %, from the pose 10
        frames earlier; right = within 0.5 m / 5° of the navigator's own pose). Right scans
        of 30 on eros-ellipse-64 / aura-ellipse-64, wrong ones in brackets: FPFH 6 s₀ clique
        16 / 7 (0), FPFH 6 s₀ GCC 14 / 2 (0), FPFH 4 s₀ 14 / 3 (1), 8 s₀ 11 / 5 (0), 10 s₀
        7 / 4 (2), SHOT 6 s₀ 12 / 9 (1), SHOT 10 s₀ 14 / 10 (0), HoD-S 6 s₀ 5 / 1 (0),
        12 s₀ 4 / 3 (0); none of 24 on envisat-tumble-64 (50 points per scan) or on
        orion-inclined-64 (a body of revolution) with any of them, and none wrong there.
    reloc_tau : float
        Descriptor-distance gate of the nearest-neighbour matching.
    reloc_epsilon : float
        Consistency tolerance of the pairwise distances, multiples of ``s₀``.
    reloc_gate : float
        Pair gate of the verifying registration, multiples of ``s₀``.
    reloc_candidates : int
        Candidate poses verified per attempt (disjoint consistent sets, largest first).
    reloc_max_map_points, reloc_max_scan_points : int
        Described map points (the map voxelised at ``s₀``) and scan points, at most.
    reloc_rms_ratio : float
        A relocalised pose must fit with a robust RMS at most this × the recent ``ok`` steps'
        median; an ``ok`` step above it that is also a jump (see ``reloc_chi2``) is suspect.
    reloc_chi2 : float
        A step is a jump when it was recovered under the weak prior or its correction's χ²
        against the motion model exceeds this (6 dof), or it follows a frame that was not
        ``ok``. 25 flagged a right step of sim-orion (χ² 30–67 there on right steps), so the
        navigator's own ``chi2_gate``.
    reloc_suspect_ratio : float
        An ``ok`` step whose robust RMS exceeds this × the recent median is suspect even
        without a jump. Measured: kidnaps 2.9–3.1×, right steps up to 2.3× (a 9-point scan of
        iridium-helical-64).
    reloc_max_doubt : int
        Suspect steps flagged in a row at most; then the navigator's own judgement stands
        again until its next ``ok`` step. **[measured]** 20 frames removed at 3 places of
        eros-ellipse-64 and aura-ellipse-64: 3 → tracks back after 2 of 6 kidnaps, 8 → 5 of 6
        (the relocaliser needs a few scans of a new view).
    reloc_overlap_ratio : float
        An ``ok`` step whose overlap is below this × the recent median is suspect too
        (measured: the overlap of every right step of the suite's 17 sequences is at least 0.99
        × the recent median; kidnapped steps 0.55–0.80).
    reloc_min_support : int
        Fewest consistent matches that make a candidate pose.
    reloc_ambiguity : float
        A relocalisation is refused when a quarter/half turn of the scan converges to another
        pose whose fitness is at least ``1 −`` this times the best one's and whose RMS is at
        most ``1 +`` this times its RMS (a near-symmetric target; see
        :meth:`relnav.navigation.relocalize.Relocalizer._ambiguous`). **[measured]** With
        ``--probe`` (108 scans of four sequences, see ``reloc_radius``): off 26 right / 7 wrong,
        0.1 25 / 2, 0.3 23 / 0, 0.5 19 / 0.
    reloc_velocity : {"keep", "zero", "widen"}
        The motion filter's velocity after a relocalisation: kept with its 1σ widened by
        10 × the white acceleration, zeroed with the first frame's 1σ, or kept with the first
        frame's 1σ (:meth:`relnav.navigation.relocalize.Relocalizer._reset_motion`).
    information : {"full", "normal"}
        The scan's information passed to the filter, the degeneracy test and the covariances:
        the solver's own (``full``, default: the map patches' normals and their weak in-plane
        pull), or from the normals only (``normal``,
        :func:`~relnav.navigation.gicp.normal_information`). Measured on the suite (APE m,
        wrong steps; full → normal): orion-inclined-64 8.09/14 → 4.40/5, aura-ellipse-64
        0.40 → 0.58, envisat-tumble-64 0.81 → 1.04, iridium-helical-64 13.5/11 → 28.9/42
        (12–30 points per scan: the filter then trusts the weak prior less than the in-plane
        pull), others equal — so ``full`` stays the default.
    inplane_sigma : float
        1σ of a map patch along its own plane, multiples of ``s₀`` (weak: point-to-plane).
    nonplanar_gain : float
        ``γ`` of the map patches' information (0 = off, the default): a patch whose
        neighbourhood is not a plane (an edge, a corner, a rim, a small detail; eigenvalues
        ``λ₀ ≤ λ₁`` of its neighbourhood's covariance) has its variance along the normal
        inflated to ``λ₀ (1 + γ λ₀/λ₁) + σ_n²`` (``plane_information`` in
        :mod:`relnav.navigation.voxel_map`), so that the directions only such patches
        constrain come from the motion model. **[measured]**
        (``benchmarks/nav_weak_directions.py``) The suite's wrong steps are errors along the
        weakest eigen-direction of the scan's information (body frame, rotations scaled by the
        scan's lever arm), which under-estimate the motion there:
        orion-inclined-64's 14 (steps 107–124) are 0.9–1.2° about Orion's symmetry axis with
        the 0.5–0.6 m translation it implies, 96–100 % in that direction, online step NEES
        3–20 (over-confident); iridium-helical-64's 11 (steps 1–7, 20–23) are 0.6–0.9° about
        the target's x axis, 38–100 % (median 87 %) in it, NEES 0.1–3 (a start-up velocity
        error the smoother spreads). Along that direction the scan's information is 0.97
        (orion) and 0.52 (iridium) of the motion prior's (median over frames), 0.80 and 0.31
        with γ = 100. On the suite (``nav_suite.py --methods relnav -O nonplanar_gain=100``;
        APE m / wrong steps, off → on): iridium-helical-64 13.50/11 → 2.80/0,
        orion-inclined-64 8.09/14 → 4.38/0, eros-ellipse-64 0.59 → 0.53,
        asteroid-helical-128 0.81 → 0.71, but aura-ellipse-64 0.40 → 0.97,
        envisat-tumble-64 0.81 → 1.10, voyager-ellipse-128 2.07/0 → 2.52/10, sim-eoi 0.05 →
        0.17, sim-eoi-resample 0.07 → 2.51, sim-voyager 0.05 → 0.64/1, sim-voyager-resample
        0.11 → 3.77/7, sim-orion 0.54 → 1.62/2, sim-orion-resample 31.9/33 → 72.1/59,
        sim-bennu 0.82 → 1.26/1, sim-bennu-resample 10.0/6 → 16.7/17; no wrong step is
        flagged either way. Single runs of those two sequences are one draw: under 12 neutral
        perturbations of the solver (``--perturb 12``: ``kernel`` 2.9–3.1, ``kernel_decay``
        0.58–0.62, ``max_iter`` 31–33) the unchanged navigator gives orion APE 4.6–14.2 m,
        0–25 wrong steps; the medians go iridium 17.5 m/39.5 → 2.9/0, orion 7.35/11 →
        5.2/7.5, and aura-ellipse-64's (6 perturbations) 0.44 → 1.00. Held-out sequences
        (``--holdout``, not used to choose): comet-ellipse-64 0.47 → 0.43, voyager-helical-64
        14.82/0 → 7.21/4, aura-tumble-64 0.64 → 0.83, capsule-ellipse-128 52.4 → 54.2 (249/249
        wrong either way). Hence off by default
        (γ = 10: iridium 1.65/0, orion 3.92/13, aura 0.94, envisat 1.15; γ = 30: iridium
        4.67/0, orion 3.90/0, aura 0.91, envisat 1.63).
    surface : {"plane", "quadric"}
        The map patches' shape in the registration: the plane through each map point
        (default), or the second-order surface fitted to its ``k_neighbors``
        (:func:`relnav.navigation.voxel_map.quadric_surface`), which removes the pull of a
        curved surface's sample positions (a scan point between two samples is off the
        plane of either by ``d²/2R``). **[measured]** (``docs/navigator.md``, "Curved map
        patches": ``python benchmarks/nav_option_sweep.py --out bench/nav -O
        surface=quadric``, 6 neutral perturbations per sequence) Median APE better on 11 of
        the 17 suite sequences (iridium-helical-64 17.8 → 4.7 m, voyager-ellipse-128 1.19 →
        0.70 m, eros-ellipse-64 0.46 → 0.27 m), worse on 3 (envisat-tumble-64 0.92 → 1.59 m);
        but the suite's wrong steps per run stay 50–84 (50–93 with planes), fewer of them are
        flagged (0–4 against 6–9), and the time per frame grows 5–30 %, which takes the
        presets' whole run to 3.1× KISS-ICP's. Hence off by default.
    curvature_sigma : float
        Prior 1σ of a quadric patch's curvatures, 1/m (0.3: radii of a few metres and more
        are curvatures, tighter bends of a sparse map are mostly noise).
    quadric_reach : float
        A patch whose ``k_neighbors`` reach farther than this (multiples of ``s₀``) stays a
        plane with ``surface="quadric"``: on a sparse map (the first scans, a thin part) the
        neighbours are too far apart for their curvature to be the surface's. **[measured]**
        Without it the held-out voyager-helical-64 goes 14.8 → 73.3 m and sim-orion-resample
        31.1 → 73.3 m; it was added after seeing that held-out failure. 1.8 s₀: the
        compromise on the suite's median APE among 1.2, 1.8 and 2.4 s₀ (``docs/navigator.md``).
    k_neighbors : int
        Map points per patch (normal estimation).
    symmetry_max_ratio : float
        Near-symmetric targets (0 = off, the default): every ``symmetry_every`` accepted frames
        the map (voxel means and normals) is tested for an axis of rotational symmetry
        (:func:`relnav.navigation.symmetry.symmetry_axis`: mean squared normal displacement
        over mean squared displacement under a rotation about the best axis at most this,
        the map covering at least ``symmetry_min_arc_deg`` about it, at most
        ``symmetry_max_axial`` of its normals within 25° of it). While one is found, the
        rotation about it (with the translation it implies at the scan's lever arm) is taken
        from the motion model: the direction is marginalised out of the scan's information
        passed to the filter, and the prior's information along it is multiplied by
        ``1 + symmetry_gain`` inside the solver. **[measured]** On the suite
        (``nav_suite.py --methods relnav -O symmetry_max_ratio=0.009``; APE m / wrong steps,
        off → on): orion-inclined-64 8.09/14 → 2.31/5 (active on 194 of 200 frames), sim-bennu-
        resample 9.99/6 → 11.21/7, asteroid-helical-128 0.812 → 0.833, the 14 others
        identical; no wrong step flagged either way. Orion is chaotic: under 6 neutral
        perturbations (``nav_weak_directions.py --only orion-inclined-64 --perturb 6``) APE
        8.09 14.20 4.82 9.00 11.39 7.17 (median 8.54 m, wrong median 13.5) → 2.31 5.68 23.82
        2.22 5.11 3.35 (median 4.23 m, wrong median 5.0; one run worse than any of the
        baseline's). The test cannot tell a target the registration fails on from one it
        tracks: the map's ratio is 3.9–8.7e-3 on orion-inclined-64 but 7–16e-3 on sim-bennu
        (tracked, 0 wrong) and 6.6–13e-3 on sim-bennu-resample; at 0.03 it fires on sim-orion,
        sim-bennu and asteroid-helical-128 too, which it then breaks (sim-bennu 0.14 → 2.82 m,
        17 wrong; sim-orion-resample 31.9/33 → 56.0/59). On sim-orion-resample the motion
        model does not know the rotation about the axis either (the first frames' velocity
        along it comes from the same biased registrations), so handing it over makes every
        step wrong. ``symmetry_gain`` 3 and 30 (ratio 0.009): orion 5.89/8 and 9.02/9, others
        as with 0; the robust test (``symmetry_irls=3``) at 0.0025: orion 8.72/3,
        sim-orion 0.076 → 3.04/4, sim-orion-resample 58.5/59, sim-bennu-resample 7.71/34.
        Held-out (``--holdout``, ratio 0.009, not used to choose): comet-ellipse-64 0.473,
        voyager-helical-64 14.821, aura-tumble-64 0.635, capsule-ellipse-128 52.416/249 wrong,
        all identical to off (capsule's map, wrong from the first steps, has ratio 0.11: never
        declared symmetric). Hence off by default. **[interpretation]** With
        ``symmetry_gain = 0`` the pose along the rotation is still the registration's (which
        has the prior inside its least squares); only the filter's covariance along it stops
        shrinking, so the next priors keep the motion model's uncertainty there. A flag on the
        registration's correction along the rotation (``info["symmetry_shift_sigma"]``, in
        prior σ) does not separate the steps: orion-inclined-64's 5 wrong steps 0.05–0.46σ,
        its right ones median 0.12σ, 95th percentile 0.49σ, max 2.05σ; none added.
    symmetry_min_arc_deg, symmetry_max_axial : float
        Guards of that test against partial maps and flat plates.
    symmetry_gain : float
        Stiffening of the prior along the symmetric rotation inside the solver (0 = only the
        filter's information is changed).
    symmetry_every : int
        Accepted frames between two symmetry tests of the map.
    symmetry_irls : int
        Reweighted passes of the symmetry test (0: plain least squares; see
        :func:`~relnav.navigation.symmetry.symmetry_axis`). Reweighting separates synthetic
        shapes better (capsule 5e-4 against an irregular blob's 1.8e-2, plain 9.7e-3 against
        1.8e-2) but not the suite's maps (robust ratio orion-inclined-64 1.6–2.4e-3,
        sim-bennu-resample 1.6–2.5e-3, asteroid-helical-128 1.5–3.7e-3).
    repeat_refine : float
        Repeated surface points (0 = off): 1σ (× ``s₀``) of a point-to-point refinement of
        each registration, kept when the scan repeats the previous scan's surface points
        (:mod:`relnav.navigation.repeated`, with the suite's figures: sim-orion APE 0.54 →
        0.08 m, sim-bennu 0.82 → 0.14 m, flash and ``-resample`` sequences unchanged).
    repeat_fraction : float
        Smallest fraction of the scan on the previous scan's rays for that (measured: fresh
        samples ≤ 0.08, repeated points ≥ 0.63).
    repeat_max_points : int
        At most this many of the scan's points (an even subset; 0 = all) in that refinement and
        its evidence: dense scans (sim-eoi at 89 000 points) spent ~90 % of the frame there.
    loop_closure : bool
        Revisits and pose-graph optimisation (:mod:`relnav.navigation.pose_graph`), in
        :meth:`Navigator.finalize` on the smoothed trajectory (the online poses are unchanged):
        keyframes with small submaps, loop edges registered onto old keyframes' submaps, and
        the keyframes' pose graph; every accepted scan (its map subset) is kept until then.
        **[measured]** Off by default: on the suite it halves the APE on eros-ellipse-64 and
        voyager-ellipse-128 but multiplies it by 2.5 on aura-ellipse-64 (and 1.05 on
        envisat-tumble-64); about 1.2 ms per frame, in ``finalize`` (see the module).
    keyframe_every : int
        Accepted frames between keyframes.
    keyframe_window : int
        A keyframe's submap merges the accepted frames within this many frames of it (both
        sides; relative poses from the final trajectory), in its sensor frame.
    loop_min_separation : int
        A revisit closes only on keyframes at least this many keyframes older.
    loop_max_distance : float
        Largest distance between the two sensor positions of a revisit, fraction of the range.
    loop_max_angle_deg : float
        Largest angle between the two viewing directions of a revisit, degrees.
    loop_min_overlap : float
        Smallest overlap of a loop registration for the edge to be kept.
    loop_max_rms : float
        Largest robust residual (σ units) of a loop registration for the edge to be kept.
    loop_chi2_gate : float
        Largest χ² (6 dof) of the loop correction against the odometry's covariance between
        the two keyframes for the edge to be kept.
    loop_kernel : float
        Geman–McClure scale of the loop edges in the pose graph (Mahalanobis units).
    loop_info_scale : float
        Factor on a loop registration's information in the pose graph.
    loop_prior_scale : float
        Factor on the information of a prior on each keyframe at its tracked pose (the
        filter's pose covariance; 0 = none).
    revisit_alarm_chi2 : float
        Online test of the map at revisits (:mod:`relnav.navigation.revisit_check`; 0 = off):
        keyframes are made while tracking (``keyframe_every``, past ``keyframe_window``
        frames), a revisit is registered as a loop edge would be, and when its χ² (6 dof)
        against the chain exceeds this value the map is called inconsistent: every later
        ``ok`` step is ``flagged`` until a revisit agrees again. Default: the χ² 99 % point.
    orbit_mean_motion : float
        The target orbit's mean motion ``n``, rad/s (0 = unknown, the default; low Earth orbit
        ≈ 1.13e-3). A mission input, not a tuning: when given, :meth:`Navigator.finalize` tests
        whether the trajectory is a free relative orbit about a body of revolution and, if the
        navigator's azimuth about its axis disagrees with that orbit, takes the azimuth from the
        orbit (:mod:`relnav.navigation.orbit`; the online poses are unchanged).
    orbit_max_symmetry, orbit_max_misfit, orbit_min_excess : float
        The three tests of that correction (:func:`relnav.navigation.orbit.correct_azimuth`):
        the map's symmetry ratio about its axis, the orbit's RMS misfit to the radius and height
        about it (fraction of the sensor's median distance from the axis's centre), and how many
        times larger the misfit of the orbit fitted to the whole positions must be.
        **[measured]** chosen on the suite (``docs/navigator.md``, "A free relative orbit").
    """

    voxel_factor: float = 0.3
    inplane_sigma: float = 3.0
    nonplanar_gain: float = 0.0
    surface: Literal["plane", "quadric"] = "plane"
    curvature_sigma: float = 0.3
    quadric_reach: float = 1.8
    symmetry_max_ratio: float = 0.0
    symmetry_min_arc_deg: float = 180.0
    symmetry_max_axial: float = 0.6
    symmetry_gain: float = 0.0
    symmetry_every: int = 5
    symmetry_irls: int = 0
    k_neighbors: int = 10
    repeat_refine: float = 0.1
    repeat_max_points: int = 16000
    repeat_fraction: float = 0.5
    max_voxel_weight: float = 20.0
    max_voxels: int = 200_000
    kernel: float = 3.0
    kernel_start: float = 100.0
    kernel_decay: float = 0.6
    max_iter: int = 30
    tolerance: float = 1e-4
    min_points: int = 6
    max_points: int = 4000
    max_map_points: int = 1500
    min_overlap: float = 0.3
    chi2_gate: float = 100.0
    recover_rms_ratio: float = 1.5
    adaptive_noise: bool = True
    jitter_rate: float = 0.2
    jitter_max_deg: float = 5.0
    jitter_scan_margin: float = 9.0
    jitter_starts: int = 2
    jitter_start_min_deg: float = 0.3
    smooth_lag: int = 20
    bootstrap_frames: int = 0
    init_window: int = 10
    init_rounds: int = 10
    init_gate: float = 3.0
    init_repeat: int = 0
    reanchor_frame: int = 0
    reanchor_skip: int = 5
    reanchor_gate: float = 22.46
    init_solver: Literal["loo", "joint"] = "joint"
    init_prior: Literal["weak", "motion", "velocity"] = "motion"
    init_prior_scale: float = 1.0
    init_inplane_sigma: float = 3.0
    init_velocity: Literal["refined", "keep"] = "keep"
    init_check: bool = True
    min_degeneracy: float = 1e-6
    sigma_acc_t: float = 0.2
    sigma_acc_r_deg: float = 0.2
    sigma_first_t: float = 5.0
    sigma_first_r_deg: float = 30.0
    noise_floor: float = 0.03
    alert_limit_t: float = 0.0
    alert_limit_r_deg: float = 0.0
    protection_k: float = 3.0
    flag_probability: float = 0.5
    flag_limit_t: float = 0.5
    flag_limit_r_deg: float = 5.0
    flag_chi2: float = 0.0
    flag_min_fitness: float = 0.8
    flag_recovered: bool = True
    flag_after_frames: int = 10
    stability_check: bool = False
    stability_k: float = 2.0
    stability_cap: float = 4.0
    stability_gate: float = 3.0
    stability_pose: Literal["prediction", "fit"] = "fit"
    stability_kernel: float = 1.0
    stability_mode: Literal["start", "prior"] = "start"
    information: Literal["full", "normal"] = "full"
    loop_closure: bool = False
    keyframe_every: int = 5
    keyframe_window: int = 5
    loop_min_separation: int = 10
    loop_max_distance: float = 0.15
    loop_max_angle_deg: float = 15.0
    loop_min_overlap: float = 0.5
    loop_max_rms: float = 3.0
    loop_chi2_gate: float = 50.0
    loop_kernel: float = 5.0
    loop_info_scale: float = 1.0
    loop_prior_scale: float = 0.0
    revisit_alarm_chi2: float = 16.81
    relocalise: bool = True
    lost_after: int = 3
    reloc_every: int = 1
    reloc_method: Literal["clique", "gcc"] = "clique"
    reloc_descriptor: str = "fpfh"
    reloc_radius: float = 6.0
    reloc_tau: float = 1.0
    reloc_epsilon: float = 2.0
    reloc_gate: float = 4.0
    reloc_candidates: int = 3
    reloc_max_map_points: int = 2000
    reloc_max_scan_points: int = 400
    reloc_rms_ratio: float = 1.5
    reloc_chi2: float = 100.0
    reloc_suspect_ratio: float = 2.5
    reloc_overlap_ratio: float = 0.9
    reloc_max_doubt: int = 8
    reloc_min_support: int = 6
    reloc_ambiguity: float = 0.3
    reloc_velocity: Literal["keep", "zero", "widen"] = "keep"
    orbit_mean_motion: float = 0.0
    orbit_max_symmetry: float = 0.05
    orbit_max_misfit: float = 0.005
    orbit_min_excess: float = 3.0


def loop_closer_options(c: NavigatorConfig) -> dict[str, Any]:
    """The :class:`~relnav.navigation.pose_graph.LoopCloser` keywords of a navigator's
    configuration (keyframes, revisit tests, registration, pose graph)."""
    return {
        "every": c.keyframe_every,
        "window": c.keyframe_window,
        "min_separation": c.loop_min_separation,
        "max_distance": c.loop_max_distance,
        "max_angle_deg": c.loop_max_angle_deg,
        "min_overlap": c.loop_min_overlap,
        "max_rms": c.loop_max_rms,
        "chi2_gate": c.loop_chi2_gate,
        "min_degeneracy": c.min_degeneracy,
        "kernel": c.kernel,
        "kernel_start": c.kernel_start,
        "kernel_decay": c.kernel_decay,
        "max_iter": c.max_iter,
        "tolerance": c.tolerance,
        "graph_kernel": c.loop_kernel,
        "info_scale": c.loop_info_scale,
        "prior_scale": c.loop_prior_scale,
    }
