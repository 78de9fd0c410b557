"""Evaluation: trajectory metrics (paper 1 and evo), alignment, plots and the Rerun export. The
benchmark system (grids, store, reports) is :mod:`relnav.bench`."""
