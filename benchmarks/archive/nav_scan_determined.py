"""Does the scan alone determine relnav's step? Its cost profiled along the weakest direction.

    python benchmarks/archive/nav_scan_determined.py --out bench/nav             # the suite
    python benchmarks/archive/nav_scan_determined.py --out bench/nav --holdout   # held out

For every frame ``relnav`` registers, the scan's robust cost on the map is profiled along the
weakest direction of the scan's own information (left twist of the target frame, rotations
scaled by the scan's median range so that one unit is one metre at the sensor): at ±0.5 m and
±1 m from the registered pose, with the other five degrees of freedom registered again each time
(the offset held by a stiff prior along that direction alone; no motion prior). The cost is the
solver's Geman–McClure on the Mahalanobis distances to the map, unpaired points at the kernel's
ceiling, divided by the frame's variance factor, so differences are in χ² units. A step is
*undetermined by its scan* when an offset fits within χ²₁(0.95) = 3.84 of the answer, or
better: the scan cannot reject a 0.5–1 m error along that direction, which the motion model then
decides. The *pull* is the best-fitting offset of the five (+ = further along the step's own
motion along that direction).

The ground truth only scores the steps (wrong: > 0.5 m or > 5°, on the evaluated trajectory as in
``nav_suite.py``). The question is whether any evidence from the scan could flag the wrong steps
without flagging the right ones: if the right steps are undetermined as often as the wrong ones,
no scan-based flag can, and the wrong steps are those where the motion model is biased.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from relnav.bench.nav_suite import (
    add_sequence_arguments,
    sequence_names,
    simulate_suite,
    step_errors,
)

OFFSETS = (-1.0, -0.5, 0.5, 1.0)  # metres at the sensor along the weakest direction
CHI2_1_95 = 3.841


def robust_cost(d2: np.ndarray, c: float) -> float:
    """Geman–McClure cost of squared Mahalanobis distances ``d2`` (−1: unpaired, at ``c²``)."""
    has = d2 >= 0
    return float(np.sum(c * c * d2[has] / (c * c + d2[has])) + c * c * np.count_nonzero(~has))


def profile(nav: Any, P: np.ndarray, result: Any) -> np.ndarray:
    """Cost differences (χ²) at :data:`OFFSETS` along the scan's weakest direction, each with
    the other five degrees of freedom registered again, minus the cost at the answer."""
    from relnav.geometry.lie import exp_se3, log_se3
    from relnav.geometry.se3 import invert

    info = result.info
    c = float(nav.config.solver.kernel)
    rng = float(np.median(np.linalg.norm(P, axis=1)))
    sc = np.array([1.0, 1.0, 1.0, rng, rng, rng])
    Hs = info["information"] / sc[:, None] / sc[None, :]
    u = np.linalg.eigh(0.5 * (Hs + Hs.T))[1][:, 0]
    step = log_se3(result.T_target_source @ invert(nav.pose)) * sc  # nav.pose: previous frame
    if step @ u < 0:
        u = -u
    w = u * sc  # w @ twist = metres along u
    hold = 1e8 * np.outer(w, w) + 1e-6 * np.eye(6)
    gate = max(float(info["gate"]), 2.0 * max(abs(s) for s in OFFSETS))
    cost = []
    for s in (0.0, *OFFSETS):
        T0 = exp_se3(u * s / sc) @ result.T_target_source
        fit = nav.solver.register_on_map(P, nav.map.information, T0, T0, hold, gate, rng)
        cost.append(robust_cost(fit.d2, c))
    return (np.asarray(cost[1:]) - cost[0]) / float(info["variance_factor"])


@contextmanager
def profiled() -> Iterator[None]:
    """Record :func:`profile` as ``info["profile"]`` of every registration while active."""
    from relnav.navigation.navigator import Navigator

    original = Navigator._register

    def register(self: Any, P: np.ndarray, T_pred: Any, P_pp: Any, timings: dict) -> Any:
        result = original(self, P, T_pred, P_pp, timings)
        if self.map is not None and result.info.get("information") is not None:
            if np.all(np.isfinite(result.T_target_source)):
                result.info["profile"] = profile(self, P, result)
        return result

    Navigator._register = register  # type: ignore[method-assign]
    try:
        yield
    finally:
        Navigator._register = original  # type: ignore[method-assign]


def sequence_figures(folder: Path, options: dict[str, str]) -> dict[str, Any]:
    """Per step: wrong (truth), undetermined (scan), pull (m) for one ``relnav`` run."""
    from relnav.io.sequences import ScanSequence
    from relnav.pipeline import run_sequence

    seq = ScanSequence(folder)
    with profiled():
        run = run_sequence(seq, "relnav", **options)
    et, er = step_errors(run.poses, seq.gt_poses)
    wrong, undetermined, pull = [], [], []
    for k, step in enumerate(run.steps[1:]):
        prof = None if step.result is None else step.result.info.get("profile")
        if prof is None:
            continue
        wrong.append(bool(et[k] > 0.5 or er[k] > 5.0))
        undetermined.append(bool(prof.min() < CHI2_1_95))
        best = int(np.argmin(prof))
        pull.append(OFFSETS[best] if prof[best] < 0 else 0.0)
    return {
        "wrong": np.array(wrong),
        "undetermined": np.array(undetermined),
        "pull": np.array(pull),
    }


def _mean(x: np.ndarray) -> str:
    return f"{x.mean():+.2f}" if len(x) else "  –  "


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_sequence_arguments(p)
    a = p.parse_args(argv)
    names = sequence_names(a.holdout, a.only)
    opts = dict(o.split("=", 1) for o in a.options)
    print(
        "| sequence | steps | wrong | undetermined: wrong | undetermined: right | "
        "pull m: wrong / right |"
    )
    print("|---|---|---|---|---|---|")
    total = np.zeros(4, dtype=int)  # wrong, wrong undetermined, right, right undetermined
    for name, folder in simulate_suite(a.out, names).items():
        f = sequence_figures(folder, opts)
        w, u = f["wrong"], f["undetermined"]
        counts = np.array([w.sum(), (w & u).sum(), (~w).sum(), (~w & u).sum()])
        total += counts
        print(
            f"| {name} | {len(w)} | {counts[0]} | {counts[1]} | {counts[3]} of {counts[2]} | "
            f"{_mean(f['pull'][w])} / {_mean(f['pull'][~w])} |",
            flush=True,
        )
    print(
        f"\npooled: undetermined {total[1]} of {total[0]} wrong steps "
        f"({total[1] / max(total[0], 1):.0%}), {total[3]} of {total[2]} right steps "
        f"({total[3] / max(total[2], 1):.0%})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
