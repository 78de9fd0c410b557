"""Online test of the navigator's map at revisits (option ``loops.revisit_alarm_chi2``).

The navigator tracks against its own map, so once the map is inconsistent — a start-up that
under-rotated, a roll that crept in mid-run — every later scan fits it, every step looks right and
the pose is metres off without a flag. A revisit can tell: when the sensor comes back near a
keyframe it has passed (same place and viewing direction in the target frame, at least
``loops.min_separation`` keyframes earlier), the new keyframe's submap registered onto the old one's
measures their relative pose independently of the chain of steps between them. Its disagreement with
the chain, weighed by the chain's composed step covariances plus the registration's own (χ², 6 dof),
is the test; an alarm is raised when it exceeds ``loops.revisit_alarm_chi2`` and every later ``ok``
step is ``flagged`` until a revisit agrees again. A revisit whose registration lacks the evidence
(overlap, residual, a non-degenerate information: the loop edge's gates but the χ²) neither raises
nor clears the alarm.

This is :class:`~relnav.navigation.pose_graph.LoopCloser`'s revisit test run while tracking
(its registration, gates and χ²), on keyframes built from the past frames only, at the poses
the navigator holds when the keyframe is made. It corrects nothing.

**[interpretation]** The alarm threshold is the χ² (6 dof) 99 % point, 16.81: a test size,
not a value fitted on runs. The chain covariance treats the steps as independent, which a
navigator tracking a map is not (its error does not grow as a random walk): the test is
conservative between distant keyframes.

**[measured]** (``relnav-tumbling``, 20 random phases of each tumbling sequence, the loop
registrations examined offline): the revisits' measured disagreements match the true ones
(aura phase 14: 17.5 m against 14.8 m; envisat phase 12: 20.6 m against 19.7 m); the χ² of the
revisits on runs that keep the track stays under 10.1, on lost runs it reaches 16–1 416.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
from numba import njit

from relnav.geometry.eigen import matmul, matmul_t
from relnav.geometry.lie import adjoint_nb, log_se3
from relnav.geometry.se3 import adjoint, invert
from relnav.navigation.pose_graph import (
    Keyframe,
    LoopCloser,
    LoopEdge,
    merge_submap,
    revisit_candidate,
)
from relnav.odometry.odometry import OdometryStep

__all__ = ["RevisitCheck", "chain_covariance"]


@njit(cache=True)
def _add_moved(S: np.ndarray, T: np.ndarray, C: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``S + Ad(T) C Ad(T)ᵀ`` (6×6): a step's covariance moved to the target frame, added."""
    A = adjoint_nb(T)
    return S + matmul_t(matmul(A, C), A)


def chain_covariance(S_old: np.ndarray, S_new: np.ndarray, T_new: np.ndarray) -> np.ndarray:
    """Covariance (6×6, right perturbation of ``T_old⁻¹ T_new``) of the steps between two
    frames from the running sums ``S`` of the steps' covariances moved to the target frame
    (``Σ Ad(T_e) C_e Ad(T_e)ᵀ`` over the steps up to each frame; equal to
    :func:`~relnav.navigation.pose_graph.compose_step_covariances` of the same steps)."""
    A = adjoint(invert(T_new))
    C = A @ (S_new - S_old) @ A.T
    return 0.5 * (C + C.T)


class RevisitCheck:
    """Keyframes made while tracking and the χ² test of each revisit (see the module doc).

    Parameters
    ----------
    closer : LoopCloser
        Supplies the keyframe spacing and window, the revisit tests, the registration and its
        gates (its own keyframes are not used).
    alarm_chi2 : float
        χ² (6 dof) of a supported revisit above which the map is called inconsistent.
    """

    def __init__(self, closer: LoopCloser, alarm_chi2: float) -> None:
        self.closer = closer
        self.alarm_chi2 = float(alarm_chi2)
        self._recent: deque[tuple[int, np.ndarray]] = deque(maxlen=closer.window + 1)
        self._S = np.zeros((6, 6))
        self._merged = 0
        self._frames: list[int] = []  # keyframes' frames
        self._points: list[np.ndarray] = []  # their submaps, own sensor frame (m)
        self._sums: list[np.ndarray] = []  # running covariance sum at each keyframe
        self._centroids = np.zeros((0, 3))  # submaps' centroids, own sensor frame (m)
        self.checks: list[LoopEdge] = []
        self.check_frames: list[tuple[int, int]] = []  # (old, new) frame of each check
        # standing alarm: (old frame, new frame, χ², disagreement m, disagreement °)
        self.alarm: tuple[int, int, float, float, float] | None = None

    def observe(
        self,
        frame: int,
        merged: bool,
        points: np.ndarray | None,
        step_covariance: np.ndarray | None,
        pose_of: Callable[[int], np.ndarray],
    ) -> LoopEdge | None:
        """Record one frame (its scan in the sensor frame, m, and its step's covariance) and,
        when it makes a keyframe that revisits an old one, test the revisit.

        ``pose_of(f)`` gives frame ``f``'s current pose ``T_target_sensor`` (4×4). Returns the
        revisit's edge (``chi2``, ``supported``) or None when there was no test.
        """
        C = step_covariance
        if C is None or not np.all(np.isfinite(C)):
            C = self.closer.fallback_covariance
        T = pose_of(frame)
        self._S = _add_moved(self._S, np.ascontiguousarray(T), np.ascontiguousarray(C))
        if not merged or points is None or len(points) < 3:
            return None
        self._recent.append((frame, np.asarray(points, dtype=np.float64)))
        n, self._merged = self._merged, self._merged + 1
        if n % self.closer.every:
            return None
        scans = [(pose_of(g), Pg) for g, Pg in self._recent if frame - g <= self.closer.window]
        Q = merge_submap(T, scans, self.closer.max_points)
        self._frames.append(frame)
        self._points.append(Q)
        self._sums.append(self._S.copy())
        self._centroids = np.vstack([self._centroids, Q.mean(0)])
        return self._test(pose_of)

    def _test(self, pose_of: Callable[[int], np.ndarray]) -> LoopEdge | None:
        """The newest keyframe against the old keyframe it revisits, if any."""
        c = self.closer
        if len(self._frames) <= c.min_separation:
            return None
        poses = [pose_of(f) for f in self._frames]
        positions = np.array([T[:3, 3] for T in poses])
        centroids = np.einsum("kij,kj->ki", np.array(poses)[:, :3, :3], self._centroids)
        centroids += positions
        j = revisit_candidate(positions, centroids, c.min_separation, c.max_distance, c.max_angle)
        if j is None:
            return None
        k = len(self._frames) - 1
        C_chain = chain_covariance(self._sums[j], self._sums[k], poses[k])
        old, new = (
            Keyframe(self._frames[i], poses[i], self._points[i], centroids[i]) for i in (j, k)
        )
        edge = c.measure(j, k, old, new, C_chain, {})
        self.checks.append(edge)
        self.check_frames.append((self._frames[j], self._frames[k]))
        if self.failed(edge):
            xi = log_se3(invert(invert(poses[j]) @ poses[k]) @ edge.Z)
            gap = (float(np.linalg.norm(xi[:3])), math.degrees(float(np.linalg.norm(xi[3:]))))
            self.alarm = (self._frames[j], self._frames[k], edge.chi2, *gap)
        elif edge.supported and math.isfinite(edge.chi2):  # an agreeing revisit clears it
            self.alarm = None
        return edge

    def failed(self, edge: LoopEdge) -> bool:
        """Whether a tested revisit raises the alarm: supported, with a finite χ² over the
        threshold."""
        return bool(edge.supported and math.isfinite(edge.chi2) and edge.chi2 > self.alarm_chi2)

    def label(self, step: OdometryStep, edge: LoopEdge | None) -> None:
        """Record the frame's test on its result (info ``revisit_chi2`` when a revisit was
        tested) and, while the alarm stands, turn an ``ok`` step into ``flagged`` (info
        ``revisit_alarm``, the alarm in its message, after the reason of a step flagged
        already)."""
        if step.result is None:
            return
        if edge is not None:
            step.result.info["revisit_chi2"] = edge.chi2
        if self.alarm is not None and step.status in ("ok", "flagged"):
            flagged = step.status == "flagged"  # already, for another reason: both are said
            step.status = step.result.status = "flagged"
            alarm = self.describe_alarm()
            step.result.message = f"{step.result.message}; {alarm}" if flagged else alarm
            step.result.info["revisit_alarm"] = True

    def summary(self) -> list[dict[str, float | int | bool]]:
        """Every revisit tested, for the run's record: frames, χ², whether the registration had
        the evidence and whether it raised the alarm."""
        return [
            {
                "old_frame": old,
                "new_frame": new,
                "chi2": round(float(e.chi2), 3) if math.isfinite(e.chi2) else None,
                "supported": bool(e.supported),
                "alarm": self.failed(e),
            }
            for (old, new), e in zip(self.check_frames, self.checks, strict=True)
        ]

    def describe_alarm(self) -> str:
        """The standing alarm in words (empty when there is none)."""
        if self.alarm is None:
            return ""
        old, new, chi2, gap_m, gap_deg = self.alarm
        return (
            f"map inconsistent since frame {new}: its revisit of frame {old} is {gap_m:.2g} m, "
            f"{gap_deg:.2g}° off the tracked chain (χ² {chi2:.1f} > {self.alarm_chi2:g}, 6 dof)"
        )
