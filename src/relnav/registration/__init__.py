"""Registration methods (feature pipeline, ICP family, baselines) behind one interface."""
