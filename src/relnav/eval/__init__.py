"""Evaluation: metrics, benchmark grids, results store, reports and plots."""
