"""Odometry-step time of hods+gcc+alphabeta with the one-sweep filter (before issue 9) and the
converged default, on the same frames (min over 3 repeats of the median over 15 steps).

Run: ``python benchmarks/speed/bench_estimator_defaults_step.py``
"""

import tempfile
import time
from pathlib import Path

import numpy as np
from bench_odometry_step import window

from relnav._threads import limit_blas_threads
from relnav.io.sequences import ScanSequence
from relnav.registration.feature import FeatureRegistration
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate

OLD = {"n_passes": 1, "projection": "frobenius", "average": False, "normalise": "sample"}
with tempfile.TemporaryDirectory() as tmp, limit_blas_threads(1):
    for preset, npts in [("sim-bennu", 150), ("sim-helical", 440), ("sim-eoi", 3100)]:
        d = Path(tmp) / preset
        simulate(get_preset(preset, max_frames=60), d)
        seq = ScanSequence(d)
        k0 = window(seq, npts, 15)
        res = {}
        for _rep in range(3):
            for label, opts in (("old", OLD), ("new", {})):
                reg = FeatureRegistration("hods", "gcc", "alphabeta", estimator_options=opts)
                prev = reg.prepare(seq[k0].points)
                reg.register_prepared(reg.prepare(seq[k0 + 1].points), prev)
                ts, te = [], []
                for k in range(k0, k0 + 15):
                    t0 = time.perf_counter()
                    cur = reg.prepare(seq[k + 1].points)
                    r = reg.register_prepared(cur, prev)
                    ts.append(time.perf_counter() - t0)
                    te.append(r.timings.get("estimate", 0.0))
                    prev = cur
                res.setdefault(label, []).append((np.median(ts) * 1e3, np.median(te) * 1e3))
        for label in ("old", "new"):
            a = np.array(res[label])
            print(
                f"{preset} {label}: step {a[:, 0].min():.2f} ms, estimate {a[:, 1].min():.3f} ms",
                flush=True,
            )
