"""Scanivalve-style UDP pressure-scanner driver and lift by pressure integration over the
wing's 49 pressure taps."""
