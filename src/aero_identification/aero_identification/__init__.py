"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS;
identifier node and offline fits."""

from aero_identification.bla import BLA, estimate_bla
from aero_identification.clustering import ClusterResult, cluster_periods, period_clusters
from aero_identification.data import PeriodicData, transient_periods
from aero_identification.metrics import predict_bla_sine, relative_rms_error

__all__ = [
    "BLA",
    "ClusterResult",
    "PeriodicData",
    "cluster_periods",
    "estimate_bla",
    "period_clusters",
    "predict_bla_sine",
    "relative_rms_error",
    "transient_periods",
]
