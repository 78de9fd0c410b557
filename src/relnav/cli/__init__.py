"""The relnav command-line interface."""
