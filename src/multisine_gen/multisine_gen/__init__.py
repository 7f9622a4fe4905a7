"""Excitation design (odd random-phase multisines, sines, experiment plans) and the pitch command generator node."""
