"""CPU time of one odometry step of HoD-S/GCC/αβ with paper 1's radius rule and with relnav's
per-scan radius, interleaved frame by frame (issue 39).

``radius_from="source"`` (paper 1, the default) describes the previous scan again at the new
scan's radius; ``"own"`` reuses its descriptors. CPU time (``time.process_time``) is used so
that other work on a shared machine does not bias the ratio; the per-stage times printed are
the pipeline's own (wall clock). Frames 1–20 of the preset, seed 0, one BLAS thread.

Run: ``python benchmarks/paper1/paper1_radius_step_cpu.py sim-eoi`` (any preset name).
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from relnav._threads import limit_blas_threads
from relnav.io.sequences import ScanSequence
from relnav.registration.feature import FeatureRegistration
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate


def main() -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else "sim-helical"
    d = Path(tempfile.mkdtemp()) / name
    simulate(get_preset(name, max_frames=22), d)
    seq = ScanSequence(d)
    regs = {
        rf: FeatureRegistration("hods", "gcc", "alphabeta", radius_from=rf)
        for rf in ("source", "own")
    }
    cpu: dict[str, list[float]] = defaultdict(list)
    stages: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    with limit_blas_threads(1):
        prev = {rf: r.prepare(seq[0].points) for rf, r in regs.items()}
        for rf, r in regs.items():  # warm-up (numba)
            r.register_prepared(r.prepare(seq[1].points), prev[rf])
        for k in range(1, min(21, len(seq))):
            for rf, r in regs.items():
                t0 = time.process_time()
                cur = r.prepare(seq[k].points)
                res = r.register_prepared(cur, prev[rf])
                cpu[rf].append(time.process_time() - t0)
                for key, v in res.timings.items():
                    stages[rf][key].append(v)
                prev[rf] = cur
    n = int(np.mean([len(seq[k].points) for k in range(len(seq))]))
    base = np.median(cpu["own"])
    for rf in regs:
        st = {k: round(1000 * float(np.median(v)), 1) for k, v in stages[rf].items()}
        print(
            f"{name} ({n} pts) radius_from={rf:6} CPU {1000 * np.median(cpu[rf]):7.1f} ms/step "
            f"({np.median(cpu[rf]) / base:.2f}x own)  stages ms {st}"
        )


if __name__ == "__main__":
    main()
