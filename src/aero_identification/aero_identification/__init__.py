"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS; identifier node and offline fits."""

from aero_identification.bla import BLA
from aero_identification.data import PeriodicData

__all__ = ["BLA", "PeriodicData"]
