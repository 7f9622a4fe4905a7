"""Simulated dynamic-stall wing with 49 pressure taps (unsteady lift, surface-pressure
synthesis) and the simulated pressure scanner streaming its pressures."""
