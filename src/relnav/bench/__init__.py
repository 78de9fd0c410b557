"""The benchmark system: grid specification and runner (``benchmark``), results store
(``store``), report (``report``, ``report_plots``) and paper 1's reference numbers
(``paper1_reference``). Trajectory metrics and plots live below, in :mod:`relnav.eval`."""
