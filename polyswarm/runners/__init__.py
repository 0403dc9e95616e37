"""Experiment runners behind commands (command layer: may drive the simulator)."""
