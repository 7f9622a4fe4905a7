"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS;
identifier node and offline fits."""

from aero_identification.bla import BLA, estimate_bla
from aero_identification.clustering import ClusterResult, cluster_periods, period_clusters
from aero_identification.data import PeriodicData, transient_periods

__all__ = [
    "BLA",
    "ClusterResult",
    "PeriodicData",
    "cluster_periods",
    "estimate_bla",
    "period_clusters",
    "transient_periods",
]
