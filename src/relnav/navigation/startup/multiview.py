"""Multi-view refinement of the navigator's first frames (``startup.window``).

**[interpretation]** On the suite's orbits and on the tumbling target the navigator's error is
mostly a near-constant rotation of the whole map about the target, set in the first frames:
each early step is registered onto a map of only a few sparse scans, under a motion prior whose
velocity is not known yet, and such a step is weak in the target's aspect (a rotation about the
target against a lateral translation). Once ``startup.window`` frames are tracked, their poses
(the first one fixed: the anchor) are refined from all of them at once, the map is rebuilt from
the refined poses and the motion filter goes on from the refined last pose, with its own
velocity (``startup.velocity="keep"``) or the refined last steps' (``"refined"``)
(:func:`refine_window`). Two solvers:

* ``joint`` (default): Levenberg–Marquardt over all the window's poses; every map point paired
  with the nearest point of another frame, both poses in the residual, plane information from
  the union of the frames, constant-velocity terms on consecutive triples
  (:func:`_joint_system`); kept only if it is more certain of the last pose than the filter
  (``startup.check``, :func:`_joint_is_surer`).
* ``loo``: each frame in turn registered onto the voxel map of the others (leave-one-out,
  Gauss–Seidel sweeps) with the navigator's own solver.

**[measured]** The default is ``startup.window=10`` with ``startup.velocity="keep"`` (the filter
keeps its own velocity; the window's poses and the map are replaced). Off → on, ``python
benchmarks/nav/nav_suite.py --out OUT --methods relnav [-O startup.window=0]`` (APE m, wrong steps):
eros-ellipse-64 0.59 → 0.42, voyager-ellipse-128 2.07 → 1.21, asteroid-helical-128 0.81 → 0.16,
sim-helical-resample 0.343 → 0.254, sim-voyager-resample 0.111 → 0.091, sim-bennu-resample 9.99 / 6
→ 1.32 / 0, orion-inclined-64 8.09 / 14 → 8.03 / 7, sim-orion-resample 31.9 / 33 → 31.1 / 32; worse
on aura-ellipse-64 0.40 → 0.57; refused by the check and unchanged on the other 8
(envisat-tumble-64, iridium-helical-64 and the dense presets). Held out (never used to choose):
comet-ellipse-64 0.47 → 0.13, capsule-ellipse-128 52.4 → 51.9, voyager-helical-64 and aura-tumble-64
refused. Under 6 neutral perturbations of the solver (``benchmarks/nav/nav_weak_directions.py
--perturb 6``) the medians go eros 0.58 → 0.46, voyager-ellipse-128 2.08 → 1.19,
asteroid-helical-128 0.81 → 0.18, aura-ellipse-64 0.44 → 0.57; under 12, orion-inclined-64 7.35 m /
11 wrong → 7.11 / 13 (chaotic either way) and iridium-helical-64 17.5 → 17.2 m. Over windows of 6,
8, 10, 12 and 15 frames no sequence is lost as with the former setting below (sim-bennu-resample
2.06 / 7.18 / 1.32 / 2.03 / 0.99 m, sim-helical-resample 0.25–0.30 m, asteroid-helical-128 0.13–0.54
m; orion-inclined-64 2.9 / 13.3 / 8.0 / 6.8 / 9.6 m, chaotic as without; with 12 frames
iridium-helical-64 8.1 m but 30 wrong steps). With ``startup.velocity="refined"`` (the filter
restarting from the mean of the refined last steps, the former setting) the dense presets break for
some windows: 8 frames lose sim-orion (0.08 → 73.7 m: the restarted velocity is 40 χ² off the
filter's, the next step is inconsistent with it, the re-registration under the weak prior is
accepted and the widened filter lets the capsule slide 11.5 m), 12 frames sim-eoi (0.008 → 2.3 m,
velocity 302 χ² off); the refinement's own pose corrections are 20–5 000 χ² of the filter's
covariance on the runs it helps too, so no consistency gate tells the cases apart. Without the
check, envisat-tumble-64 is worse on 17 of 20 noise seeds (median APE 1.44 → 3.08 m): started at the
true poses the refinement drifts 0.27° per frame away from them (its 50-point scans of a box
themselves favour a slower rotation, which constant-velocity terms cannot see); with the check all
20 are refused. The ``loo`` solver converges slowly and was worse (iridium-helical-64 13.5 → 54.6
m). Cost: one refinement (or refused attempt) of 0.03–0.20 s at 64×64 and 128×128, 0.05–0.15 s on
the presets and 0.40 s on sim-eoi's 4 000-point scans, all in the window's last frame (the pair
system in numba and closed form, :func:`_pair_system`; the pairs found among the plane neighbours,
:func:`_window_pairs`, and reused while the graduated kernel shrinks: the same poses as the first
version's 0.3–3.6 s): the median time per frame is unchanged, the mean over a run is 1.6–2.5 ms on
the flash sequences (8.1 ms on asteroid-helical-128) and 3.4–6.4 ms on the 60-frame presets (34 ms
on sim-eoi); over a whole run 1.0–2.2× KISS-ICP's time on the flash sequences, up to 2.9× on the
presets (``nav_suite.py``'s second time ratio).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from relnav.geometry.kdtree import kd_build_select, kd_knn, kd_knn_within
from relnav.geometry.lie import exp_se3, exp_se3_nb, log_se3, log_se3_nb
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import adjoint, invert
from relnav.navigation.gicp import left_information, solve_scan_to_map
from relnav.navigation.voxel_map import plane_information

if TYPE_CHECKING:
    from relnav.navigation.motion import ConstantVelocityFilter
    from relnav.navigation.solver import MapSolver

PairMemo = dict[bytes, tuple[np.ndarray, ...]]
"""The window's pairs at the last poses evaluated (:func:`_window_pairs`), by pose bytes: the
graduated kernel changes the weights, not the pairs."""

__all__ = ["WindowFrame", "refine_window"]

log = logging.getLogger(__name__)


@dataclass
class WindowFrame:
    """One frame of the multi-view refinement's window (:func:`refine_window`).

    Attributes
    ----------
    frame : int
        Frame index.
    t : float
        Time, s.
    pose : (4, 4) float64
        ``T_target_sensor`` (tracked, then refined).
    ok : bool
        The frame is in the map (the first frame or an ``ok`` step).
    P, Pm : (N, 3), (M, 3) float64
        Registration points and the map subset, sensor frame, m (empty when not ``ok``).
    rng : float
        Median range of the scan, m.
    step_cov : (6, 6) float64 or None
        Covariance of the step that led to the frame (body frame; None for the first frame).
    """

    frame: int
    t: float
    pose: np.ndarray
    ok: bool
    P: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    Pm: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rng: float = 1.0
    step_cov: np.ndarray | None = None


def _joint_refine(
    solver: MapSolver,
    motion: ConstantVelocityFilter,
    used: list[WindowFrame],
    gate: float,
    sa: np.ndarray,
    memo: PairMemo,
) -> int:
    """Levenberg–Marquardt over the poses of ``used`` but the first (the anchor), with the
    solver's graduated kernel (``solver.kernel_start`` × ``solver.kernel_decay`` per round down to
    ``solver.kernel``); returns the rounds run.

    A step is kept only if it lowers the joint cost at the same kernel (the pairs found
    again at the new poses); otherwise the poses are restored and the damping grows ×10
    (÷3 after a kept step). Stops after ``startup.rounds`` rounds, or once at the final kernel
    no pose moves by more than a tenth of a voxel (rotation times the scan's range) or the
    damping exceeds 10⁶ (no step lowers the cost).
    """
    c = solver.config
    v = solver.map.voxel_size if solver.map is not None else 1.0
    lam, rounds = 1e-4, 0
    kern = max(float(c.solver.kernel), float(c.solver.kernel_start))
    H, g, cost = _joint_system(solver, motion, used, gate, kern, sa, memo)
    while rounds < c.startup.rounds:
        k_r = max(
            float(c.solver.kernel),
            float(c.solver.kernel_start) * float(c.solver.kernel_decay) ** rounds,
        )
        rounds += 1
        if k_r != kern:
            kern = k_r
            H, g, cost = _joint_system(solver, motion, used, gate, kern, sa, memo)
        A = H[6:, 6:] + lam * np.diag(np.diag(H[6:, 6:]))
        try:
            delta = -np.linalg.solve(A, g[6:])
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(delta)):
            break
        old = [f.pose for f in used]
        moved = 0.0
        for i, f in enumerate(used[1:]):
            dx = delta[6 * i : 6 * i + 6]
            f.pose = exp_se3(dx) @ f.pose
            moved = max(moved, float(np.linalg.norm(dx[:3]) + np.linalg.norm(dx[3:]) * f.rng))
        H2, g2, cost2 = _joint_system(solver, motion, used, gate, kern, sa, memo)
        if cost2 < cost:
            H, g, cost = H2, g2, cost2
            lam = max(lam / 3.0, 1e-7)
        else:
            for f, T in zip(used, old, strict=True):
                f.pose = T
            lam *= 10.0
            moved = float("inf")
        if kern <= c.solver.kernel and (moved < 0.1 * v or lam > 1e6):
            break
    return rounds


def _joint_is_surer(
    solver: MapSolver,
    motion: ConstantVelocityFilter,
    used: list[WindowFrame],
    gate: float,
    sa: np.ndarray,
    memo: PairMemo,
) -> bool:
    """Is the joint refinement more certain of the window's last pose than the filter?

    **[interpretation, measured]** The joint problem's covariance of the last frame (the
    inverse of its normal equations at the final kernel, without the regularising weak
    prior, body frame) against the filter's own pose covariance: the refinement replaces
    the tracked poses only if its largest 1σ in translation and in rotation are both at
    most the filter's. On the suite's first 10 frames the joint's 1σ exceeds the filter's
    on envisat-tumble-64 (0.62° against 0.39°), sim-bennu, sim-voyager, iridium-helical-64
    (2.6 m against 1.9 m) and sim-orion, the first four being where the refinement made
    the APE worse.
    """
    H, _, _ = _joint_system(
        solver, motion, used, gate, float(solver.config.solver.kernel), sa, memo, regular=False
    )
    assert motion is not None
    try:
        C = np.linalg.inv(H[6:, 6:])[-6:, -6:]
    except np.linalg.LinAlgError:
        return False
    Ad = adjoint(invert(used[-1].pose))  # left (target frame) → body
    C = Ad @ C @ Ad.T
    P = motion.P[:6, :6]

    def big(M: np.ndarray) -> float:
        return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1])

    return bool(big(C[:3, :3]) <= big(P[:3, :3]) and big(C[3:, 3:]) <= big(P[3:, 3:]))


def _joint_system(
    solver: MapSolver,
    motion: ConstantVelocityFilter,
    used: list[WindowFrame],
    gate: float,
    kern: float,
    sa: np.ndarray,
    memo: PairMemo | None = None,
    regular: bool = True,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Normal equations ``(H, g)`` (6n) and the cost of the window's joint problem at the
    current poses.

    Every map point of every frame (target frame, at the current poses) is paired with its
    nearest point of *another* frame within ``gate``; the residual ``T_i p − T_j q`` is
    weighted by the plane information of ``q``'s neighbourhood in the union of the frames
    (:func:`~relnav.navigation.voxel_map.plane_information`) and a Geman–McClure kernel
    of scale ``kern`` (cost ``ρ(d²) = k² d² / (k² + d²)``; an unpaired point costs ``k²``),
    and both poses are in its Jacobian (left perturbations). With ``startup.prior`` ``motion``
    or ``velocity`` the constant-velocity terms are added (:func:`_motion_terms`,
    :func:`_velocity_terms`). The first frame's weak prior on each pose keeps ``H``
    regular (not in the cost).
    """
    c = solver.config
    key = b"".join(f.pose.tobytes() for f in used)
    if memo is not None and key in memo:
        Y, lab, Om, a, b = memo[key]
    else:
        Y, lab, Om, a, b = _window_pairs(solver, used, gate)
        if memo is not None:
            if len(memo) >= 2:  # the current poses and the last kept ones
                del memo[next(iter(memo))]
            memo[key] = (Y, lab, Om, a, b)
    n = len(used)
    k2 = kern**2
    H, g, cost = _pair_system(Y, a, b, lab, Om, k2, n)
    cost += k2 * float(len(Y) - len(a))
    if c.startup.prior in ("motion", "velocity"):
        cost += _motion_terms(used, sa, H, g)
    if c.startup.prior == "velocity":
        assert motion is not None
        cost += _velocity_terms(used, motion.velocity, motion.P[6:, 6:], H, g)
    for i, f in enumerate(used):
        if regular:
            H[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] += solver.weak_prior(f.pose)
    return H, g, cost


def _window_pairs(
    solver: MapSolver, used: list[WindowFrame], gate: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The window's map points at the current poses and their pairs (:func:`_joint_system`):
    ``(Y, lab, Om, a, b)``, the points ``Y`` (N, 3, target frame, m), their frames ``lab``
    (N,), plane information ``Om`` (N, 3, 3) and the pairs ``Y[a] ↔ Y[b]``."""
    c, s0 = solver.config, solver.spacing0
    n = len(used)
    Y = np.concatenate([f.Pm @ f.pose[:3, :3].T + f.pose[:3, 3] for f in used])
    lab = np.concatenate([np.full(len(f.Pm), i) for i, f in enumerate(used)])
    tree = kd_build_select(Y, 16)
    dn, nb = kd_knn(*tree, Y, min(c.map.k_neighbors, len(Y)))
    Om, _ = plane_information(Y, nb, c.startup.inplane_sigma * s0, c.map.noise_floor * s0)
    # the pair: the nearest point of another frame among the ``kq`` nearest within the gate,
    # found among the plane neighbours first, the few points they do not settle queried again
    kq = min(len(Y), 2 * n + 8)
    dn, nb = dn[:, :kq], nb[:, :kq]
    other = (dn < gate) & (lab[nb] != lab[:, None])
    b = np.where(other.any(axis=1), nb[np.arange(len(Y)), np.argmax(other, axis=1)], -1)
    more = np.nonzero((b < 0) & (dn[:, -1] < gate) & (kq > nb.shape[1]))[0]
    if len(more):
        _, idx = kd_knn_within(*tree, Y[more], kq, np.full(len(more), gate**2))
        other = (idx >= 0) & (lab[idx] != lab[more, None])
        b[more] = np.where(
            other.any(axis=1), idx[np.arange(len(more)), np.argmax(other, axis=1)], -1
        )
    a = np.nonzero(b >= 0)[0]
    return Y, lab, Om, a, b[a]


@njit(cache=True, inline="always")
def _times_skew(
    M: np.ndarray, x: np.ndarray, out: np.ndarray, transpose: bool
) -> None:  # pragma: no cover - numba
    """``out = M [x]×`` (or ``Mᵀ [x]×``) for 3×3 ``M``, ``[x]×`` the cross-product matrix."""
    for i in range(3):
        m0, m1, m2 = (M[0, i], M[1, i], M[2, i]) if transpose else (M[i, 0], M[i, 1], M[i, 2])
        out[i, 0] = m1 * x[2] - m2 * x[1]
        out[i, 1] = m2 * x[0] - m0 * x[2]
        out[i, 2] = m0 * x[1] - m1 * x[0]


@njit(cache=True)
def _pair_system(
    Y: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    lab: np.ndarray,
    Om: np.ndarray,
    k2: float,
    n: int,
) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    """Normal equations ``(H, g)`` (6n) and robust cost of the pairs ``Y[a] ↔ Y[b]``.

    Residual ``r = Y[a] − Y[b]`` (target frame, m) with information ``Om[b]`` (3×3), weight
    ``w = (k²/(k² + d²))²`` and cost ``k² d² / (k² + d²)`` (Geman–McClure, ``d² = rᵀ Ω r``); the
    Jacobians in the left perturbations ``(δt, δθ)`` of the poses of frames ``lab[a]`` and
    ``lab[b]`` are ``J_a = [I, −A]`` and ``J_b = −[I, −B]`` (``A = [Y[a]]×``, ``B = [Y[b]]×``).
    With ``W = w Ω``, ``P = W A``, ``Q = W B`` and ``Xᵀ = −X`` the blocks are ``J_aᵀ W J_a =
    [[W, −P], [−Pᵀ, Pᵀ A]]``, ``J_aᵀ W J_b = −[[W, −Q], [−Pᵀ, Pᵀ B]]``, ``J_bᵀ W J_b =
    [[W, −Q], [−Qᵀ, Qᵀ B]]`` and ``J_bᵀ W J_a`` the transpose of the second.
    """
    H = np.zeros((6 * n, 6 * n))
    g = np.zeros(6 * n)
    cost = 0.0
    W = np.empty((3, 3))
    P = np.empty((3, 3))
    Q = np.empty((3, 3))
    PA = np.empty((3, 3))
    PB = np.empty((3, 3))
    QB = np.empty((3, 3))
    r = np.empty(3)
    Or = np.empty(3)
    v = np.empty(3)
    for m in range(len(a)):
        p, q = a[m], b[m]
        A, B = Y[p], Y[q]
        O = Om[q]
        for i in range(3):
            r[i] = A[i] - B[i]
        for i in range(3):
            Or[i] = O[i, 0] * r[0] + O[i, 1] * r[1] + O[i, 2] * r[2]
        d2 = r[0] * Or[0] + r[1] * Or[1] + r[2] * Or[2]
        cost += k2 * d2 / (k2 + d2)
        w = (k2 / (k2 + d2)) ** 2
        for i in range(3):
            for j in range(3):
                W[i, j] = w * O[i, j]
        _times_skew(W, A, P, False)
        _times_skew(W, B, Q, False)
        _times_skew(P, A, PA, True)
        _times_skew(P, B, PB, True)
        _times_skew(Q, B, QB, True)
        ia, ib = 6 * lab[p], 6 * lab[q]
        for i in range(3):
            for j in range(3):
                H[ia + i, ia + j] += W[i, j]
                H[ib + i, ib + j] += W[i, j]
                H[ia + i, ib + j] -= W[i, j]
                H[ib + i, ia + j] -= W[i, j]
                H[ia + i, ia + 3 + j] -= P[i, j]
                H[ia + 3 + j, ia + i] -= P[i, j]
                H[ib + i, ib + 3 + j] -= Q[i, j]
                H[ib + 3 + j, ib + i] -= Q[i, j]
                H[ia + i, ib + 3 + j] += Q[i, j]
                H[ib + 3 + j, ia + i] += Q[i, j]
                H[ib + i, ia + 3 + j] += P[i, j]
                H[ia + 3 + j, ib + i] += P[i, j]
                H[ia + 3 + i, ia + 3 + j] += PA[i, j]
                H[ib + 3 + i, ib + 3 + j] += QB[i, j]
                H[ia + 3 + i, ib + 3 + j] -= PB[i, j]
                H[ib + 3 + j, ia + 3 + i] -= PB[i, j]
        # gradient Jᵀ W r: J_aᵀ v = [v, A v] and J_bᵀ v = −[v, B v] (A v = Y[a] × v)
        for i in range(3):
            v[i] = w * Or[i]
            g[ia + i] += v[i]
            g[ib + i] -= v[i]
        g[ia + 3] += A[1] * v[2] - A[2] * v[1]
        g[ia + 4] += A[2] * v[0] - A[0] * v[2]
        g[ia + 5] += A[0] * v[1] - A[1] * v[0]
        g[ib + 3] -= B[1] * v[2] - B[2] * v[1]
        g[ib + 4] -= B[2] * v[0] - B[0] * v[2]
        g[ib + 5] -= B[0] * v[1] - B[1] * v[0]
    return H, g, cost


@njit(cache=True)
def _step_error(Ts: np.ndarray, vdt: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``log(T₀⁻¹ T₁) − log(T₁⁻¹ T₂)`` for three poses ``Ts`` (3, 4, 4), or
    ``log(T₀⁻¹ T₁) − vdt`` for two."""
    D = np.empty((len(Ts) - 1, 4, 4))
    for m in range(len(Ts) - 1):
        Ri = Ts[m, :3, :3].T.copy()
        Ti = np.eye(4)
        Ti[:3, :3] = Ri
        Ti[:3, 3] = -(Ri @ Ts[m, :3, 3].copy())
        D[m] = Ti @ Ts[m + 1]
    e = log_se3_nb(D[0])
    return e - (log_se3_nb(D[1]) if len(Ts) == 3 else vdt)


@njit(cache=True)
def _step_jacobian(
    Ts: np.ndarray, vdt: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """:func:`_step_error` and its Jacobian (6, 6·len(Ts)) by central differences in the
    poses' left perturbations."""
    eps = 1e-6
    e = _step_error(Ts, vdt)
    J = np.zeros((6, 6 * len(Ts)))
    for m in range(len(Ts)):
        for q in range(6):
            dq = np.zeros(6)
            dq[q] = eps
            Tp, Tm = Ts.copy(), Ts.copy()
            Tp[m] = exp_se3_nb(dq) @ Ts[m]
            Tm[m] = exp_se3_nb(-dq) @ Ts[m]
            J[:, 6 * m + q] = (_step_error(Tp, vdt) - _step_error(Tm, vdt)) / (2 * eps)
    return e, J


def _add_pose_term(
    poses: list[np.ndarray],
    ids: list[int],
    W: np.ndarray,
    H: np.ndarray,
    g: np.ndarray,
    vdt: np.ndarray | None = None,
) -> float:
    """Add one term ``eᵀ W e`` of the window frames ``ids`` to ``H`` and ``g`` in place, ``e``
    the constant-velocity error of three poses or the step-against-``vdt`` error of two
    (:func:`_step_error`), its Jacobians by central differences in the poses' left
    perturbations; returns the term's cost."""
    v = np.zeros(6) if vdt is None else np.asarray(vdt, dtype=np.float64)
    e, J = _step_jacobian(np.stack(poses).astype(np.float64), v)
    for p_, ip in enumerate(ids):
        Jp = J[:, 6 * p_ : 6 * p_ + 6]
        g[6 * ip : 6 * ip + 6] += Jp.T @ W @ e
        for q_, iq in enumerate(ids):
            H[6 * ip : 6 * ip + 6, 6 * iq : 6 * iq + 6] += Jp.T @ W @ J[:, 6 * q_ : 6 * q_ + 6]
    return float(e @ W @ e)


def _motion_terms(used: list[WindowFrame], sa: np.ndarray, H: np.ndarray, g: np.ndarray) -> float:
    """Add the constant-velocity terms of consecutive triples to ``H`` and ``g`` in place:
    ``e = log(T_a⁻¹ T_b) − log(T_b⁻¹ T_c)`` with information ``diag(1/sa²)``, Jacobians by
    central differences in the left perturbations of the three poses; returns their
    cost ``Σ eᵀ W e``."""
    Wm = np.diag(1.0 / sa**2)
    cost = 0.0

    for i in range(len(used) - 2):
        fa, fb, fc = used[i], used[i + 1], used[i + 2]
        if fb.frame != fa.frame + 1 or fc.frame != fb.frame + 1:
            continue
        cost += _add_pose_term([fa.pose, fb.pose, fc.pose], [i, i + 1, i + 2], Wm, H, g)
    return cost


def _velocity_terms(
    used: list[WindowFrame], v: np.ndarray, P_vv: np.ndarray, H: np.ndarray, g: np.ndarray
) -> float:
    """Add a prior on each step of consecutive frames, ``e = log(T_a⁻¹ T_b) − v Δt`` with
    information ``(P_vv Δt² · m)⁻¹`` (``m`` steps: together they weigh as one velocity
    measurement), to ``H`` and ``g`` in place; Jacobians by central differences. Returns
    their cost ``Σ eᵀ W e``."""
    pairs = [
        (i, i + 1)
        for i in range(len(used) - 1)
        if used[i + 1].frame == used[i].frame + 1 and used[i + 1].t > used[i].t
    ]
    if not pairs:
        return 0.0
    cost = 0.0
    for i, j in pairs:
        fa, fb = used[i], used[j]
        dt = fb.t - fa.t
        try:
            W = np.linalg.inv(P_vv * dt**2 * len(pairs))
        except np.linalg.LinAlgError:
            return cost

        cost += _add_pose_term([fa.pose, fb.pose], [i, j], W, H, g, v * dt)
    return cost


def _neighbour_prior(
    used: list[WindowFrame], i: int, sa: np.ndarray, T: np.ndarray, Lam: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity prior of window frame ``i`` from its neighbours: the midpoint of
    frames ``i − 1`` and ``i + 1`` (1σ ``sa/√2``, body frame) or, for the last frame, the
    previous step repeated (1σ ``sa``); ``(T, Lam)`` when the neighbours are not consecutive
    frames."""
    f, a = used[i], used[i - 1]
    if a.frame != f.frame - 1:
        return T, Lam
    if i + 1 < len(used) and used[i + 1].frame == f.frame + 1:
        b = used[i + 1]
        centre = a.pose @ exp_se3(0.5 * log_se3(invert(a.pose) @ b.pose))
        S = np.diag(sa**2 / 2.0)
    elif i >= 2 and used[i - 2].frame == a.frame - 1:
        centre = a.pose @ invert(used[i - 2].pose) @ a.pose
        S = np.diag(sa**2)
    else:
        return T, Lam
    return centre, left_information(centre, S)


def refine_window(
    frames: list[WindowFrame], solver: MapSolver, motion: ConstantVelocityFilter
) -> tuple[int, bool, list[np.ndarray]]:
    """Multi-view refinement of the window's poses, leave-one-out (``startup.window``).

    **[interpretation]** A step registered onto a map of a few sparse scans, under a motion
    prior whose velocity is not yet known, is weak in the target's aspect (a rotation about
    the target against a lateral translation), and the whole map keeps the early frames'
    error. Here each accepted frame of the window but the first (the anchor, fixed) is
    registered again onto the union of the *other* frames (several times denser than one
    scan), from its current pose under the first frame's weak prior (Gauss–Seidel: each
    new pose is used at once), in rounds until no pose moves by more than a tenth of a
    voxel (rotation times the scan's range) or ``startup.rounds``. A registration with too
    few pairs or too little overlap keeps its pose. Frames not in the map follow the
    correction of the last accepted frame before them. Then the map is rebuilt from the
    refined poses, the filter's pose is the refined one and its velocity its own
    (``startup.velocity="keep"``) or the mean of the refined last steps (``"refined"``: half of the
    window's steps, at least two), and the smoother
    restarts at the last frame: :meth:`Navigator.finalize` returns the refined poses for the window
    (:meth:`relnav.navigation.startup.StartupWindow.observe` makes the correction).

    The poses of ``frames`` are refined in place (restored when refused); ``motion`` is read,
    never written. Returns the rounds run, whether the refinement was accepted and the poses
    before it.
    """
    c = solver.config
    assert solver.map is not None
    used = [f for f in frames if f.ok]
    before = [f.pose.copy() for f in frames]
    v = solver.map.voxel_size
    gate = float(max(c.startup.gate * solver.spacing0, 2.0 * v))
    rounds, moved = 0, float("inf")
    sa = c.startup.prior_scale * np.array(
        [c.prior.sigma_acc_t * solver.spacing0] * 3 + [math.radians(c.prior.sigma_acc_r_deg)] * 3
    )
    accepted = True
    if c.startup.solver == "joint" and len(used) > 2:
        memo: PairMemo = {}
        rounds = _joint_refine(solver, motion, used, gate, sa, memo)
        if c.startup.check and not _joint_is_surer(solver, motion, used, gate, sa, memo):
            accepted = False
            for f, T0 in zip(frames, before, strict=True):
                f.pose = T0
    while c.startup.solver == "loo" and rounds < c.startup.rounds and moved > 0.1 * v:
        if len(used) <= 2:
            break
        rounds += 1
        moved = 0.0
        for i, f in enumerate(used[1:], start=1):
            T_pr, Lam = f.pose, solver.weak_prior(f.pose)
            if c.startup.prior == "motion":
                T_pr, Lam = _neighbour_prior(used, i, sa, T_pr, Lam)
            m = solver.new_map()
            for g in used:
                if g is not f:
                    m.insert(g.Pm @ g.pose[:3, :3].T + g.pose[:3, 3], g.frame)
            fit = solve_scan_to_map(
                f.P,
                m,
                np.ascontiguousarray(f.pose),
                np.ascontiguousarray(T_pr),
                np.ascontiguousarray(Lam),
                gate,
                float(c.solver.kernel),
                int(c.solver.max_iter),
                c.solver.tolerance * v,
                c.solver.tolerance * v / f.rng,
                c0=float(c.solver.kernel_start),
                decay=float(c.solver.kernel_decay),
            )
            overlap = float(np.count_nonzero(fit.d2 >= 0)) / max(len(f.P), 1)
            if not (
                np.all(np.isfinite(fit.T))
                and fit.n_pairs >= c.solver.min_points
                and overlap >= c.solver.min_overlap
            ):
                continue
            D = invert(f.pose) @ fit.T
            ang = rotation_angle(D[:3, :3])
            moved = max(moved, float(np.linalg.norm(D[:3, 3])) + ang * f.rng)
            f.pose = fit.T.copy()
    if not accepted:
        log.debug("multi-view refinement of %d frames refused", len(frames))
    return rounds, accepted, before
