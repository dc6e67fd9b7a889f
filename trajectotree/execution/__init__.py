"""Execution: the controllers, the simulation Diagram, tracking metrics and Meshcat playback."""
