"""Fusion speed at paper 2's Table 6 point counts, beside the paper's running times.

For each row of paper 2 Table 6 (average Kinect/LIDAR points per frame: 1 239/126 … 8 105/828)
the camera and LIDAR clouds of simulated ``li-rotating`` frames (3 m, rotation about z) are
randomly subsampled to exactly those counts, and ``cga-sphere`` (paper 2's method), the
clustering step (§G.4) and the ``cbd`` baseline are timed (median over frames × repeats, after
a warm-up call that loads numba's cache). Paper 2's times are the mean of its x/y/z columns;
the ratio ``paper / ours`` is the speed-up (target ≥ 10× for the registration).

    .venv/bin/python benchmarks/speed/bench_fusion.py [--frames 4] [--repeats 3] [--work DIR]

Figures are machine dependent; the script prints them and writes nothing unless ``--csv``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

# paper 2 Table 6: (Kinect points, LIDAR points) -> (ours x, y, z), (FMR x, y, z), (CBD x, y, z) s
TABLE6 = [
    ((1239, 126), (3.06, 3.46, 3.60), (2.06, 2.01, 2.56), (5.79, 5.60, 6.17)),
    ((1724, 217), (3.18, 3.57, 3.91), (2.15, 2.96, 2.96), (5.41, 6.54, 6.29)),
    ((2653, 358), (3.43, 3.31, 4.18), (2.40, 3.29, 3.06), (6.32, 6.38, 6.33)),
    ((4496, 641), (4.20, 3.78, 3.73), (2.43, 3.75, 3.76), (6.70, 6.25, 7.05)),
    ((7921, 951), (4.10, 4.35, 4.27), (3.18, 3.09, 3.92), (6.19, 6.06, 7.10)),
    ((8105, 828), (3.99, 3.89, 4.51), (3.26, 4.56, 4.75), (6.82, 6.14, 7.24)),
]


def _frames(work: Path, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    from relnav.io.sequences import ScanSequence
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    seq = work / "li_z_3.0"
    if not (seq / "scans_lidar").is_dir():
        sc = get_preset("li-rotating", distance=3.0, axis="z", frames=16)
        simulate(sc.model_copy(update={"format": "npy"}), seq, overwrite=True)
    cam = ScanSequence(seq)
    lid = ScanSequence(seq, sensor="lidar")
    idx = np.linspace(0, len(cam) - 1, n).round().astype(int)
    return [(cam[i].points, lid[i].points) for i in idx]


def _time(fn, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=4, help="li-rotating frames per row")
    ap.add_argument("--repeats", type=int, default=3, help="timing repeats (min taken)")
    ap.add_argument("--work", type=Path, default=None, help="where to simulate (reused)")
    ap.add_argument("--csv", type=Path, default=None, help="also write the table as CSV")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()

    from relnav.fusion.cbd import CBDRegistration
    from relnav.fusion.clustering import cluster_and_project
    from relnav.fusion.cross_source import CrossSourceRegistration

    work = a.work or Path(tempfile.mkdtemp(prefix="bench_fusion_"))
    frames = _frames(work, a.frames)
    rng = np.random.default_rng(a.seed)
    cga = CrossSourceRegistration(m=15, seed=a.seed)
    cbd = CBDRegistration(seed=a.seed)
    cga.register(frames[0][1][:200], frames[0][0][:2000])  # warm-up (numba cache load)
    rows = []
    header = (
        f"{'Kinect/LIDAR':>13} | {'cga-sphere s':>12} {'paper s':>7} {'speed-up':>8} | "
        f"{'+cluster s':>10} | {'cbd s':>6} {'paper':>6} {'speed-up':>8} | {'ok':>5}"
    )
    print(header)
    print("-" * len(header))
    for (nk, nl), ours_p, _fmr_p, cbd_p in TABLE6:
        t_cga, t_cl, t_cbd, n_ok = [], [], [], 0
        for cam, lid in frames:
            C = cam[rng.choice(cam.shape[0], min(nk, cam.shape[0]), replace=False)]
            L = lid[rng.choice(lid.shape[0], min(nl, lid.shape[0]), replace=False)]
            res = cga.register(L, C)
            n_ok += res.ok
            t_cga.append(_time(lambda C=C, L=L: cga.register(L, C), a.repeats))
            Lc = L @ res.T_target_source[:3, :3].T + res.T_target_source[:3, 3]
            t_cl.append(_time(lambda C=C, Lc=Lc: cluster_and_project(C, Lc), a.repeats))
            t_cbd.append(_time(lambda C=C, L=L: cbd.register(L, C), 1))
        m_cga, m_cl, m_cbd = (statistics.median(x) for x in (t_cga, t_cl, t_cbd))
        p_ours, p_cbd = statistics.mean(ours_p), statistics.mean(cbd_p)
        rows.append((nk, nl, m_cga, p_ours, p_ours / m_cga, m_cl, m_cbd, p_cbd, p_cbd / m_cbd))
        print(
            f"{nk:>6}/{nl:<6} | {m_cga:12.3f} {p_ours:7.2f} {p_ours / m_cga:7.1f}x | "
            f"{m_cga + m_cl:10.3f} | {m_cbd:6.2f} {p_cbd:6.2f} {p_cbd / m_cbd:7.1f}x | "
            f"{n_ok:>2}/{len(frames):<2}"
        )
    print(
        "\nspeed-up = paper 2 Table 6 time (mean of x/y/z) / our median time; "
        "'+cluster' adds plane clustering (§G.4), which paper 2 does not time."
    )
    if a.csv is not None:
        a.csv.parent.mkdir(parents=True, exist_ok=True)
        with a.csv.open("w") as f:
            f.write("kinect,lidar,cga_s,paper_s,speedup,cluster_s,cbd_s,paper_cbd_s,cbd_speedup\n")
            for r in rows:
                f.write(",".join(f"{v:.6g}" for v in r) + "\n")
        print(f"wrote {a.csv}")


if __name__ == "__main__":
    main()
