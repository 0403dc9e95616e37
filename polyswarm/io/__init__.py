"""File input and output (maps, logs, trajectories, exports). The core does no I/O."""
