"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS;
identifier node and offline fits."""

from aero_identification.bla import BLA, estimate_bla
from aero_identification.data import PeriodicData, transient_periods

__all__ = ["BLA", "PeriodicData", "estimate_bla", "transient_periods"]
