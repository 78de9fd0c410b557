"""Benchmark report: ``report.md`` + ``tables/*.csv`` + ``figures/*.png`` from a results store.

:func:`write_report` reads a benchmark folder (``grid.yaml``, ``results.sqlite``, the saved
estimates and sequences) and writes, in the layout of Paper 1:

- **per scenario**, the Appendix-A table: one block per filter (rows = descriptors, grouper
  GCC), then the competitor block; columns drift, T_error %, e^T_max, e^T_avg, per-axis
  maxima and means, e^R_avg, e^R_max, e^RT, t (ms) — mean ± standard deviation over seeds;
- the **cross-scenario normalised e^RT** of Paper 1 §4 per descriptor and per filter, and a
  Table-4-style **top module per scenario**;
- the **ablations** in the layout of Tables 3 (with/without filter), 5 (GCC vs RANSAC), 6
  (proposed vs CLGV) and B1 (ICP at 20 vs 1000 iterations), when the grid has the variants;
- **figures**: trajectories (best per filter, competitors) and per-axis errors per scenario,
  normalised e^RT vs time (Fig. 14), time vs points per scan (Fig. 15), normalised e^RT per
  filter (Fig. 16), error-vs-nuisance curves for the robustness sweeps;
- **against the paper**: our best values beside Paper 1's (:mod:`relnav.bench.paper1_reference`)
  and whether its qualitative conclusions hold here.

Normalisation (Paper 1 §4) **[interpretation]**: per scenario, the least accurate descriptor
(largest mean e^RT over filters) is dropped (``discard_worst_descriptor``); for the descriptor
view each e^RT(d, f) is divided by the worst e^RT of its filter f, for the filter view by the
worst e^RT of its descriptor d; both are then divided by the ground-truth path length (m) and
multiplied by ``normalisation_constant`` (default 1000), and averaged over filters (resp.
descriptors). Tables 5, 6 and B1 of the paper divide by the path length only; so do ours.

Rows are the mean over the seeds that finished ``ok``; a column ``ok`` gives ``ok/runs``.
Tables only use the clean (no-nuisance) level; nuisance levels feed the robustness section.
"""

from __future__ import annotations

from relnav.bench.report.aggregation import (
    APPENDIX_COLUMNS,
    DESCRIPTOR_NAMES,
    FILTER_NAMES,
    Aggregate,
    MethodInfo,
    aggregate,
    classify_method,
)
from relnav.bench.report.normalised import normalised_ert
from relnav.bench.report.writer import export_report, write_report

__all__ = [
    "APPENDIX_COLUMNS",
    "DESCRIPTOR_NAMES",
    "FILTER_NAMES",
    "Aggregate",
    "MethodInfo",
    "aggregate",
    "classify_method",
    "export_report",
    "normalised_ert",
    "write_report",
]
