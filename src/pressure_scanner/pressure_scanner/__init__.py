"""Simulated dynamic-stall wing with 49 pressure taps, Scanivalve-style UDP scanner driver,
lift by pressure integration."""
