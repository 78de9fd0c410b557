"""How much of the contour observer's error is inherited through its merges (issue 15).

Diagnostics with the truth (never used by the filters) on the observations cached by
``paper2_experiment.py --work WORK`` (``obsNNN_16f_3m_src.npz``, which record the match shares
``W``). Per observation ``k`` the error ``e_k`` of the observed pose in body axes (a right
perturbation ``[t (m), θ (rad)]`` of ``T_{S_k,B}``; frame 0 defines ``B`` exactly) is split into
the part inherited from the merged frames, ``Σ_j W_kj e_j``, and the rest ``v_k`` — the one
registration's own error, which ``TwistorUKF(merge_slots=…)`` takes to be distributed as the
observer's reported covariance. Prints, in Markdown:

1. RMS and mean of ``e_k`` and ``v_k`` against the reported 1σ (moved to body axes), the
   per-axis ``RMS(v/σ)`` and the mean ``vᵀR⁻¹v`` (6 dof);
2. the same per frame index (the views are the same in every seed);
3. other mixing rules for the inherited part (what would explain more of ``e_k``);
4. with ``--calibrate``: an ORACLE run of the merge-state filter whose per-registration
   covariance is the second moment of ``v_k`` per frame index measured with the truth of the
   calibration seeds — what an honest σ would give with the inherited structure (not a
   method: it uses the truth).

Run: ``python benchmarks/paper2/paper2_merge_errors.py --work WORK --seeds 0:20 --calibrate 20:40``
(seconds).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import paper2_experiment as pe
from scipy.spatial.transform import Rotation

from relnav.geometry.rotations import quat_to_matrix
from relnav.geometry.se3 import invert

SCALE = np.r_[[1e3] * 3, [np.degrees(1.0)] * 3]  # m → mm, rad → deg
MERGES = "ukf+offset+merges+jackknife"
BIAS = "ukf+offset+bias+jackknife"  # the random-walk bias fed the jackknife covariance


def load(work: Path, seed: int) -> dict[str, np.ndarray]:
    """One seed's cached observations with their match shares."""
    f = work / f"obs{seed:03d}_16f_3m_src.npz"
    if not f.is_file():
        raise SystemExit(f"{f} missing: run paper2_experiment.py --work {work} first")
    return dict(np.load(f))


def body_errors(rec: dict[str, np.ndarray]) -> np.ndarray:
    """``(K, 6)`` errors ``[t (m), θ (rad)]`` of the observations, body axes (right
    perturbation), truth anchored at frame 0 (which defines the body frame exactly)."""
    obs, T_gt = rec["obs"], rec["T_s_target"]
    K = len(obs)
    T = np.tile(np.eye(4), (K, 1, 1))
    T[:, :3, :3] = quat_to_matrix(obs[:, 3:])
    T[:, :3, 3] = obs[:, :3]
    A = invert(T_gt[0]) @ T[0]
    e = np.zeros((K, 6))
    for k in range(K):
        G = invert(T_gt[k] @ A) @ T[k]
        e[k] = np.r_[G[:3, 3], Rotation.from_matrix(G[:3, :3]).as_rotvec()]
    return e


def body_sigma(rec: dict[str, np.ndarray], k: int) -> np.ndarray:
    """Reported covariance of observation ``k`` in body axes ``(6, 6)``."""
    J = np.eye(6)
    J[:3, :3] = quat_to_matrix(rec["obs"][k, 3:]).T
    return J @ rec["R"][k] @ J.T


def _row(v: np.ndarray) -> str:
    return " | ".join(f"{x:.2f}" for x in v * SCALE)


def split(recs: list[dict[str, np.ndarray]]) -> None:
    """Tables 1 and 2."""
    E, V, S, nv = [], [], [], []
    for rec in recs:
        e = body_errors(rec)
        W = np.nan_to_num(rec["W"])
        for k in range(1, len(e)):
            v = e[k] - W[k] @ e
            C = body_sigma(rec, k)
            E.append(e[k])
            V.append(v)
            S.append(np.sqrt(np.diag(C)))
            nv.append(float(v @ np.linalg.solve(C, v)))
    E, V, S, nv = map(np.asarray, (E, V, S, nv))
    print(f"## Inherited and own error ({len(recs)} seeds, {len(E)} observations, body axes)\n")
    print("| | t x | t y | t z (mm) | θ x | θ y | θ z (deg) |")
    print("|---|---|---|---|---|---|---|")
    print(f"| RMS e (the observation's error) | {_row(np.sqrt(np.mean(E**2, 0)))} |")
    print(f"| mean e | {_row(E.mean(0))} |")
    print(f"| RMS v = e − Σ W e (one registration's own) | {_row(np.sqrt(np.mean(V**2, 0)))} |")
    print(f"| mean v | {_row(V.mean(0))} |")
    print(f"| median reported 1σ | {_row(np.median(S, 0))} |")
    print(f"| RMS reported 1σ | {_row(np.sqrt(np.mean(S**2, 0)))} |")
    ratio = " | ".join(f"{x:.2f}" for x in np.sqrt(np.mean((V / S) ** 2, 0)))
    print(f"| RMS(v / reported σ) | {ratio} |")
    print(
        f"\nMean vᵀR⁻¹v {np.mean(nv):.0f}, median {np.median(nv):.0f} (6 dof: expected 6); "
        f"share above 100: {np.mean(nv > 100):.0%}.\n"
    )
    K = len(recs[0]["time"]) - 1
    Ek, Vk, Sk = (a.reshape(len(recs), K, 6) for a in (E, V, S))
    print("Per frame (RMS over the seeds; t in mm, θ z in deg):\n")
    print(
        "| frame | e: t x, t y, θ z | v: t x, t y, θ z | mean v: t x, t y | RMS σ: t x, t y, θ z |"
    )
    print("|---|---|---|---|---|")
    for k in range(K):

        def r3(a: np.ndarray, k: int = k) -> str:
            x = np.sqrt(np.mean(a[:, k] ** 2, 0)) * SCALE
            return f"{x[0]:.1f}, {x[1]:.1f}, {x[5]:.2f}"

        m = Vk[:, k].mean(0) * SCALE
        print(f"| {k + 1} | {r3(Ek)} | {r3(Vk)} | {m[0]:.1f}, {m[1]:.1f} | {r3(Sk)} |")


def mixing(recs: list[dict[str, np.ndarray]]) -> None:
    """Table 3: RMS of what each mixing rule leaves unexplained."""

    def share(e: np.ndarray, W: np.ndarray, k: int) -> np.ndarray:
        return W[k] @ e

    def share2(e: np.ndarray, W: np.ndarray, k: int) -> np.ndarray:
        w = W[k] ** 2
        return (w / w.sum()) @ e if w.sum() > 0 else np.zeros(6)

    rules = {
        "none (v = e)": lambda e, W, k: np.zeros(6),
        "match shares W (the filter's model)": share,
        "squared shares, renormalised": share2,
        "largest share only": lambda e, W, k: e[int(np.argmax(W[k]))],
        "previous frame only": lambda e, W, k: e[k - 1],
    }
    print("\n## Other mixing rules: RMS of the unexplained part (body axes)\n")
    print("| rule | t x | t y | t z (mm) | θ x | θ y | θ z (deg) |")
    print("|---|---|---|---|---|---|---|")
    data = [(body_errors(r), np.nan_to_num(r["W"])) for r in recs]
    for name, f in rules.items():
        V = np.array([e[k] - f(e, W, k) for e, W in data for k in range(1, len(e))])
        print(f"| {name} | {_row(np.sqrt(np.mean(V**2, 0)))} |")


def oracle(recs: list[dict[str, np.ndarray]], cal: list[dict[str, np.ndarray]]) -> None:
    """Table 4: the filters with the per-registration covariance from the truth of ``cal``."""
    V = []
    for rec in cal:
        e = body_errors(rec)
        V.append(e - np.nan_to_num(rec["W"]) @ e)
    V = np.asarray(V)
    M2 = np.einsum("ski,skj->kij", V, V) / len(cal)  # (K, 6, 6) second moment, body axes
    pe.VARIANTS = {k: v for k, v in pe.VARIANTS.items() if k in (BIAS, MERGES)}
    runs = []
    for rec in recs:
        r = {k: np.array(v, copy=True) for k, v in rec.items()}
        for k in range(1, len(r["time"])):
            J = np.eye(6)
            J[:3, :3] = quat_to_matrix(r["obs"][k, 3:])
            r["R"][k] = J @ (M2[k] + 1e-10 * np.eye(6)) @ J.T
        runs.append(pe.run_variants(r))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        agg = pe.aggregate(runs, 3)
    print(
        f"\n## ORACLE (truth): per-registration covariance = second moment of v per frame, "
        f"from {len(cal)} other seeds\n"
    )
    print(
        "| variant | NIS [band] | NIS steps in band | NEES [band] | NEES steps in band | blocks |"
    )
    print("|---|---|---|---|---|---|")
    for name, st in agg.items():
        c = st["consistency"]
        print(
            f"| {name} | {c['nis_mean']:.3g} [{c['nis_band'][0]:.2f}, {c['nis_band'][1]:.2f}] "
            f"| {c['anis_steps_in_band']:.0%} | {c['nees_mean']:.3g} "
            f"[{c['nees_band'][0]:.2f}, {c['nees_band'][1]:.2f}] | {c['anees_steps_in_band']:.0%} "
            f"| {' / '.join(f'{x:.3g}' for x in c['nees_block_means'])} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--seeds", type=pe.seed_span, default=range(0, 20), help="A:B (B excluded)")
    ap.add_argument("--calibrate", type=pe.seed_span, default=None, help="A:B: oracle run")
    args = ap.parse_args()
    recs = [load(args.work, s) for s in args.seeds]
    split(recs)
    mixing(recs)
    if args.calibrate is not None:
        oracle(recs, [load(args.work, s) for s in args.calibrate])


if __name__ == "__main__":
    main()
