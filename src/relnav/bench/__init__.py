"""The benchmark system: grid specification and runner (``benchmark``, ``grid``, ``worker``),
results store (``store``), report (``report``: tables and ``report.plots``), paper 1's reference
numbers (``paper1_reference``) and the navigation suite's sequence groups with the code the
navigation benchmarks share (``nav_suite``). Trajectory metrics and plots live below, in
:mod:`relnav.eval`."""
