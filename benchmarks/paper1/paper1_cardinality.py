"""Points per scan of paper 1's five HPR presets, fixed model cloud vs per-frame resampling.

Usage: ``python benchmarks/paper1/paper1_cardinality.py [--modes fixed resample] [--stride 1]``

Prints mean (min–max) points per scan next to the paper's mean (±25 % is the acceptance band
of :mod:`relnav.sim.presets`). Scans are made in memory (nothing written).
"""

from __future__ import annotations

import argparse

import numpy as np

from relnav.sim.presets import PAPER_MEAN_POINTS, get_preset
from relnav.sim.scenario import _build_sensor, scenario_poses
from relnav.sim.targets import get_target

PRESETS = ("sim-eoi", "sim-helical", "sim-voyager", "sim-orion", "sim-bennu")


def counts(name: str, mode: str, stride: int) -> np.ndarray:
    sc = get_preset(name, model_cloud=mode)
    target = get_target(sc.target.spec, seed=sc.target.seed, scale_to=sc.target.scale_to)
    sensor = _build_sensor(sc.sensors[0])
    _, T_W_rig, T_W_target = scenario_poses(sc)
    T_rs = sc.sensors[0].T_rig_sensor
    out = []
    for k in range(0, sc.frames, stride):
        T = np.linalg.inv(T_W_target[k]) @ T_W_rig[k] @ T_rs
        out.append(len(sensor.scan(target, T, np.random.default_rng(k))))
    return np.asarray(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--modes", nargs="+", default=["fixed", "resample"])
    ap.add_argument("--presets", nargs="+", default=list(PRESETS))
    ap.add_argument("--stride", type=int, default=1)
    a = ap.parse_args()
    print(f"{'preset':12s} {'mode':9s} {'mean':>7s} {'min':>6s} {'max':>6s} {'paper':>6s} ratio")
    for name in a.presets:
        for mode in a.modes:
            c = counts(name, mode, a.stride)
            p = PAPER_MEAN_POINTS[name]
            print(
                f"{name:12s} {mode:9s} {c.mean():7.0f} {c.min():6d} {c.max():6d} {p:6.0f} "
                f"{c.mean() / p:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
