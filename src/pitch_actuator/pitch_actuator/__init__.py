"""Pitch actuator: shared safety layer, simulated actuator node and UDP hardware driver node."""
