"""Paper 2: cross-source fusion (CGA point-to-sphere), plane clustering, twistor UKF tracking."""
