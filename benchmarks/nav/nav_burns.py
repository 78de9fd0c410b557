"""Impulsive burns the motion model does not predict: ``solver.recover_unmatched``.

    python benchmarks/nav/nav_burns.py --out bench/nav --perturb 3

After a burn the scan can lie outside the pair gate that the motion model's prediction sets
(narrow when the model is confident, narrowest with the chaser's attitude input): no pair, the
step fails, the pose coasts on the old velocity and the next scans are farther still.
``solver.recover_unmatched`` registers such a scan again under the first frame's weak prior, as
a scan that disagrees with the model already is: ``never``; ``with_attitude`` (the default since
session 28: only when the prediction took the measured attitude, the weak prior then keeping the
measured rotation and the filter widened in translation only); ``always``. This script runs
relnav with each, with and without the chaser's measured attitude (``attitude=1``), under the
first ``--perturb`` neutral
perturbations of ``nav_weak_directions.py``, on the manoeuvre group
(``configs/nav-manoeuvre.yaml``, where the option was built), on five burn sequences made after
its first version (:data:`FRESH`) and on five made after its second (:data:`FRESH_2`). It prints
per sequence and configuration the median APE (causal, m) with its range, the median RPE_t (m),
the median wrong steps and the median wrong steps not flagged. The fresh sequences are simulated
once into ``OUT/burns/<name>`` and ``OUT/burns2/<name>``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

from nav_premap import print_table, simulate_scenarios
from nav_weak_directions import PERTURBATIONS

from relnav.bench.nav_suite import manoeuvre, simulate_suite


def _cw(
    target: dict[str, Any], rows: int, seed: int, state0: list[float], burns: list[list[float]]
) -> dict[str, Any]:
    """A 120-frame, 10 s flash-LIDAR scenario on a CW relative orbit with ``burns``."""
    return {
        "target": target,
        "sensors": [
            {
                "preset": "goldeneye",
                "name": "flash",
                "overrides": {"rows": rows, "cols": rows, "range_sigma": 0.02},
            }
        ],
        "seed": seed,
        "dt": 10.0,
        "trajectory": {"kind": "cw", "params": {"state0": state0, "burns": burns}},
    }


FRESH: dict[str, dict[str, Any]] = {
    "voyager-vbar-hop": _cw(
        {"path": "../shared/data/targets/voyager.ply", "scale_to": 10.0},
        128,
        101,
        [0.0, 40.0, 0.0, 0.0, 0.0, 0.0],
        [[200.0, 0.0, -0.15, 0.0], [300.0, 0.0, 0.15, 0.0], [700.0, 0.03, 0.0, 0.1]],
    ),
    "iridium-vbar-burn": _cw(
        {"name": "iridium", "scale_to": 6.0},
        128,
        102,
        [0.0, -35.0, 0.0, 0.0, 0.0, 0.0],
        [[250.0, 0.0, 0.15, 0.0], [350.0, 0.0, -0.15, 0.0], [800.0, 0.0, 0.0, -0.1]],
    ),
    "comet-cw-burn": _cw(
        {"path": "../shared/data/targets/comet67p.ply", "scale_to": 12.0},
        64,
        103,
        [25.0, 0.0, 0.0, 0.0, -0.0566, 0.0],
        [[300.0, 0.0, 0.1, 0.0], [600.0, -0.1, 0.0, 0.05]],
    ),
    "asteroid-cw-burn": _cw(
        {"name": "asteroid", "scale_to": 10.0},
        64,
        104,
        [20.0, 0.0, 8.0, 0.0, -0.0453, 0.0],
        [[400.0, 0.0, 0.3, 0.0], [500.0, 0.0, -0.3, 0.0]],
    ),
    "orion-vbar-hop": _cw(
        {"path": "../shared/data/targets/orion.ply", "scale_to": 6.0},
        128,
        105,
        [0.0, -30.0, 0.0, 0.0, 0.0, 0.0],
        [[300.0, 0.0, 0.1, 0.1], [400.0, 0.0, -0.1, -0.1], [900.0, 0.05, 0.0, 0.0]],
    ),
}
"""Burn sequences made after the first version of ``solver.recover_unmatched`` (the weak prior
in rotation too; session 28): 0.1-0.3 m/s burns on V-bar holds and CW ellipses, other targets
than the manoeuvre group's, with the chaser's measured attitude (0.01°)."""

FRESH_2: dict[str, dict[str, Any]] = {
    "capsule-vbar-burn": _cw(
        {"name": "capsule", "scale_to": 6.0},
        128,
        111,
        [0.0, -30.0, 0.0, 0.0, 0.0, 0.0],
        [[200.0, 0.0, 0.15, 0.0], [300.0, 0.0, -0.15, 0.0], [600.0, 0.05, 0.0, 0.05]],
    ),
    "aura-cw-burn": _cw(
        {"path": "../shared/data/targets/aura.ply", "scale_to": 10.0},
        128,
        112,
        [20.0, 0.0, 5.0, 0.0, -0.04526, 0.0],
        [[300.0, 0.0, 0.2, 0.0], [450.0, 0.0, -0.2, 0.0]],
    ),
    "eros-vbar-hop": _cw(
        {"path": "../shared/data/targets/eros.ply", "scale_to": 12.0},
        64,
        113,
        [0.0, 45.0, 0.0, 0.0, 0.0, 0.0],
        [[250.0, 0.0, -0.2, 0.0], [350.0, 0.0, 0.2, 0.0], [800.0, 0.0, 0.0, 0.1]],
    ),
    "voyager-cw-burn": _cw(
        {"path": "../shared/data/targets/voyager.ply", "scale_to": 10.0},
        128,
        114,
        [25.0, 0.0, 0.0, 0.0, -0.0566, 0.0],
        [[350.0, 0.1, 0.1, 0.0], [700.0, -0.1, -0.1, 0.0]],
    ),
    "envisat-vbar-hop": _cw(
        {"name": "envisat", "scale_to": 10.0},
        128,
        115,
        [0.0, -40.0, 0.0, 0.0, 0.0, 0.0],
        [[300.0, 0.0, 0.25, 0.0], [380.0, 0.0, -0.25, 0.0]],
    ),
}
"""Burn sequences made after the second version (the measured rotation kept in the weak prior),
run once with it before the third (no widening in rotation after such a retry) was chosen."""

CONFIGS: dict[str, dict[str, str]] = {
    "recover_unmatched=never": {"solver.recover_unmatched": "never"},
    "defaults (with_attitude)": {},
    "recover_unmatched=always": {"solver.recover_unmatched": "always"},
}
"""The navigator's configurations compared."""


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("bench/nav"))
    p.add_argument("--perturb", type=int, default=3, help="runs per cell (1 = unperturbed)")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore", FutureWarning)  # the perturbations' flat option names
    if not 1 <= a.perturb <= len(PERTURBATIONS):
        p.error(f"--perturb must be 1..{len(PERTURBATIONS)}")
    folders = {
        **simulate_suite(a.out, list(manoeuvre())),
        **simulate_scenarios(a.out / "burns", FRESH),
        **simulate_scenarios(a.out / "burns2", FRESH_2),
    }
    print_table(folders, CONFIGS, a.perturb)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
