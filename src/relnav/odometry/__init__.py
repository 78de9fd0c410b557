"""Frame-to-frame odometry: :class:`Odometry` and :func:`run_sequence`."""
