"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS;
identifier node and offline fits."""

from aero_identification.bla import BLA, estimate_bla
from aero_identification.clustering import ClusterResult, cluster_periods, period_clusters
from aero_identification.data import PeriodicData, transient_periods
from aero_identification.metrics import predict_bla_sine, relative_rms_error
from aero_identification.pnlss import LMIteration, PNLSSModel, fit_pnlss
from aero_identification.subspace import LinearStateSpace, fit_linear_ss

__all__ = [
    "BLA",
    "ClusterResult",
    "LMIteration",
    "LinearStateSpace",
    "PNLSSModel",
    "PeriodicData",
    "cluster_periods",
    "estimate_bla",
    "fit_linear_ss",
    "fit_pnlss",
    "period_clusters",
    "predict_bla_sine",
    "relative_rms_error",
    "transient_periods",
]
