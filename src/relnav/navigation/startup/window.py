"""The navigator's start-up window (:class:`StartupWindow`): the first frames refined together.

The first frames of a map are tracked onto a map of a few sparse scans under a motion prior whose
velocity is not yet known; their errors stay in the map. The start-up window keeps those frames
(:class:`~.multiview.WindowFrame`) and, at the frames its options name, corrects them: the
multi-view refinement of ``startup.window`` (and ``startup.repeat``) frames
(:func:`~.multiview.refine_window`) and the re-anchoring of the first scan at
``startup.reanchor_frame`` (:func:`~.anchor.reanchor`). A correction is returned to the navigator as
a :class:`StartupCorrection`, which the navigator applies to its own map, motion filter and
trajectory: the window never writes the navigator's state.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.lie import log_se3
from relnav.geometry.rotations import angle_between_rotations
from relnav.geometry.se3 import invert
from relnav.navigation.options import in_map
from relnav.navigation.solver import median_range
from relnav.navigation.startup.anchor import reanchor
from relnav.navigation.startup.multiview import WindowFrame, refine_window
from relnav.navigation.voxel_map import even_subset

if TYPE_CHECKING:
    from relnav.navigation.motion import ConstantVelocityFilter
    from relnav.navigation.options import NavigatorConfig
    from relnav.navigation.solver import MapSolver
    from relnav.odometry.odometry import OdometryStep

__all__ = ["StartupCorrection", "StartupWindow", "adopt_window", "check_window_options"]


@dataclass
class StartupCorrection:
    """What a start-up correction changes in the navigator (:meth:`Navigator._apply_startup`).

    Attributes
    ----------
    map_frames : list of ((M, 3) float64, (4, 4) float64, int)
        The map's new content: each frame in the map with its map points (sensor frame, m), its
        corrected pose ``T_target_sensor`` and its index.
    earlier_poses : list of (4, 4) float64
        The corrected poses of the window's frames before the last (the trajectory's).
    pose : (4, 4) float64
        The last frame's corrected pose: the motion filter goes on from it.
    velocity : (6,) float64 or None
        The motion filter's new body velocity ``[m/s ×3, rad/s ×3]``, or None to keep its own.
    gauge_turn : (4, 4) float64 or None
        The turn of the target frame applied to the earlier frames (re-anchoring), else None.
    """

    map_frames: list[tuple[np.ndarray, np.ndarray, int]]
    earlier_poses: list[np.ndarray]
    pose: np.ndarray
    velocity: np.ndarray | None = None
    gauge_turn: np.ndarray | None = None


class StartupWindow:
    """The first frames of the navigator's map and their corrections (see the module doc).

    Parameters
    ----------
    config : NavigatorConfig
        The navigator's options (its ``startup`` section, and the map's and the solver's);
        inconsistent ``startup`` options raise :class:`~relnav.errors.ConfigError`.

    Attributes
    ----------
    refinements : list of dict
        Each correction tried (``"kind"``: ``"multi-view"`` or ``"reanchor"``), accepted or
        not and why, for the run's record.
    """

    def __init__(self, config: NavigatorConfig) -> None:
        check_window_options(config)
        c = self.config = config
        self.frames: list[WindowFrame] | None = (
            [] if c.startup.window > 0 or c.startup.reanchor_frame > 0 else None
        )
        self.due = sorted({c.startup.window, c.startup.repeat, c.startup.reanchor_frame} - {0})
        self.refinements: list[dict[str, Any]] = []

    @property
    def open(self) -> bool:
        """Whether the window still records frames (a correction is still due)."""
        return self.frames is not None

    def observe(
        self,
        frame: int,
        t: float,
        pose: np.ndarray,
        P: np.ndarray | None,
        out: OdometryStep,
        age: int,
        solver: MapSolver,
        motion: ConstantVelocityFilter,
    ) -> StartupCorrection | None:
        """Record a tracked frame and correct the window when a correction is due.

        Parameters
        ----------
        frame : int
            The frame's index.
        t : float
            Its time, s.
        pose : (4, 4) float64
            Its tracked pose ``T_target_sensor``.
        P : (N, 3) float64 or None
            Its registration points (sensor frame, m); None for a skipped frame.
        out : OdometryStep
            Its step (in the map or not; ``info["gauge_turn"]`` is added on re-anchoring).
        age : int
            Frames since the map started, this one included.
        solver, motion :
            The navigator's registration onto its map and its motion filter (read only).

        Returns
        -------
        StartupCorrection or None
            The correction for the navigator to apply, None when there is none.
        """
        if self.frames is None:
            return None
        c = self.config
        # in the map: the first frame and every step merged into it (an integrity label such as
        # ``degenerate`` over the alert limit does not take a merged scan out of the map)
        ok = P is not None and in_map(out)
        f = WindowFrame(frame, float(t), pose.copy(), ok)
        if out.result is not None:
            f.step_cov = out.result.info.get("step_covariance")
        if ok:
            assert P is not None
            f.P = P
            f.Pm = even_subset(P, c.map.max_map_points)
            f.rng = max(median_range(P), 1.0)
        self.frames.append(f)
        if age not in self.due:
            return None
        frames = self.frames
        correction = None
        if age in (c.startup.window, c.startup.repeat):
            correction = self._refine(frames, solver, motion)
        if age == c.startup.reanchor_frame:
            correction = self._reanchor(frames, solver, motion)
            if correction is not None and out.result is not None:
                out.result.info["gauge_turn"] = correction.gauge_turn  # earlier poses: G T now
        if age >= self.due[-1]:
            self.frames = None
        return correction

    def _refine(
        self, frames: list[WindowFrame], solver: MapSolver, motion: ConstantVelocityFilter
    ) -> StartupCorrection | None:
        """The multi-view refinement, recorded; its correction when accepted."""
        t_start = time.perf_counter()
        rounds, accepted, before = refine_window(frames, solver, motion)
        record: dict[str, Any] = {"kind": "multi-view", "frames": len(frames), "rounds": rounds}
        if not accepted:
            self.refinements.append(
                record | {"accepted": False, "time_s": time.perf_counter() - t_start}
            )
            return None
        correction, stats = adopt_window(frames, before, self.config, motion)
        self.refinements.append(
            record | {"time_s": time.perf_counter() - t_start, "accepted": True, **stats}
        )
        return correction

    def _reanchor(
        self, frames: list[WindowFrame], solver: MapSolver, motion: ConstantVelocityFilter
    ) -> StartupCorrection | None:
        """The re-anchoring, recorded; its correction (with its gauge turn) when accepted."""
        t_start = time.perf_counter()
        record, turn = reanchor(frames, solver)
        if turn is None:
            self.refinements.append(record)
            return None
        G, before, angle = turn
        correction, stats = adopt_window(frames, before, self.config, motion)
        correction.gauge_turn = G
        self.refinements.append(
            record
            | stats
            | {"accepted": True, "rotation_deg": angle, "time_s": time.perf_counter() - t_start}
        )
        return correction


def check_window_options(c: NavigatorConfig) -> None:
    """Raise :class:`~relnav.errors.ConfigError` for inconsistent ``startup`` options."""
    st = c.startup
    if st.window in (1, 2):
        raise ConfigError(
            f"method 'relnav': option startup.window={st.window} must be 0 (off) or at "
            "least 3 (an anchor and two frames)"
        )
    if st.repeat and (st.window == 0 or st.repeat <= st.window):
        raise ConfigError(
            f"method 'relnav': option startup.repeat={st.repeat} must be 0 or more than "
            f"startup.window ({st.window})"
        )
    if st.reanchor_frame and (
        st.reanchor_skip < 1
        or st.reanchor_frame < st.reanchor_skip + 2
        or st.reanchor_frame in (st.window, st.repeat)
        or st.bootstrap_frames
    ):
        raise ConfigError(
            f"method 'relnav': option startup.reanchor_frame={st.reanchor_frame} must be 0 "
            f"(off) or at least startup.reanchor_skip + 2 ({st.reanchor_skip} + 2), differ from "
            "startup.window and startup.repeat, and exclude startup.bootstrap_frames"
        )
    if st.window and st.bootstrap_frames:
        raise ConfigError(
            "method 'relnav': options startup.window and startup.bootstrap_frames exclude each "
            "other (set startup.window=0 to use startup.bootstrap_frames)"
        )


def adopt_window(
    frames: list[WindowFrame],
    before: list[np.ndarray],
    config: NavigatorConfig,
    motion: ConstantVelocityFilter,
) -> tuple[StartupCorrection, dict[str, float]]:
    """The correction that makes the window's new poses the navigator's (after
    :func:`~.multiview.refine_window` or :func:`~.anchor.reanchor`): frames outside the map
    follow the last accepted frame's change; the map is to be rebuilt from the new poses, the
    filter to go on from the last one (its velocity its own, or with
    ``startup.velocity="refined"`` the mean of the refined last steps) and the smoother to restart
    at the last frame; :meth:`~relnav.navigation.navigator.Navigator.finalize` returns the new
    poses for the window's other frames. ``before``: the poses before the change; ``motion``
    is read, not written. Returns the correction, and the largest rotation of a pose (deg) and
    the χ² of the last pose's and the velocity's change against the filter's covariance.
    """
    c = config
    used = [f for f in frames if f.ok]
    # frames outside the map follow the last accepted frame's correction
    corr = np.eye(4)
    for f, T0 in zip(frames, before, strict=True):
        if f.ok:
            corr = f.pose @ invert(T0)
        else:
            f.pose = corr @ f.pose
    steps = [
        log_se3(invert(a.pose) @ b.pose) / (b.t - a.t)
        for a, b in itertools.pairwise(used)
        if b.frame == a.frame + 1 and b.t > a.t
    ]
    mot = motion
    xi_last = log_se3(invert(before[-1]) @ frames[-1].pose)
    try:
        chi2_p = float(xi_last @ np.linalg.solve(mot.P[:6, :6], xi_last))
    except np.linalg.LinAlgError:
        chi2_p = float("nan")
    chi2_v = float("nan")
    velocity = None
    if steps:
        v_new = np.mean(steps[-max(2, len(steps) // 2) :], axis=0)
        dv = v_new - mot.velocity
        try:
            chi2_v = float(dv @ np.linalg.solve(mot.P[6:, 6:], dv))
        except np.linalg.LinAlgError:
            pass
        if c.startup.velocity == "refined":
            velocity = v_new
    correction = StartupCorrection(
        map_frames=[(f.Pm, f.pose.copy(), f.frame) for f in used],
        earlier_poses=[f.pose.copy() for f in frames[:-1]],
        pose=frames[-1].pose.copy(),
        velocity=velocity,
    )
    shift = [
        math.degrees(angle_between_rotations(T0[:3, :3], f.pose[:3, :3]))
        for f, T0 in zip(frames, before, strict=True)
    ]
    stats = {"max_rotation_deg": max(shift), "velocity_chi2": chi2_v, "pose_chi2": chi2_p}
    return correction, stats
