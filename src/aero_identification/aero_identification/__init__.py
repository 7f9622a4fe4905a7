"""Identification of lift dynamics: BLA, period clustering, frequency-domain subspace, PNLSS;
identifier node and offline fits.

The names below load their module on first use (PEP 562), so importing a light module of the
package (campaign, refit_worker: what the identifier node needs) does not load scipy,
scikit-learn and numba.
"""

import importlib
from typing import Any

_EXPORTS = {
    "BLA": "bla",
    "estimate_bla": "bla",
    "ClusterResult": "clustering",
    "cluster_periods": "clustering",
    "period_clusters": "clustering",
    "PeriodicData": "periodic_data",
    "transient_periods": "periodic_data",
    "predict_bla_sine": "metrics",
    "relative_rms_error": "metrics",
    "relative_rms_error_spread": "metrics",
    "LMIteration": "state_space_models",
    "LinearStateSpace": "state_space_models",
    "PNLSSModel": "state_space_models",
    "StateSpaceDimensions": "state_space_models",
    "PnlssSettings": "pnlss",
    "fit_pnlss": "pnlss",
    "fit_linear_ss": "subspace",
    "ScanResult": "scan",
    "scan_pnlss": "scan",
    "Dataset": "dataset",
    "LevelRecord": "dataset",
    "SineData": "dataset",
    "campaign_dataset": "campaign_source",
    "records_dataset": "records",
    "read_records": "records",
    "IdentificationConfig": "hyperparameters",
    "IdentificationResult": "identification_result",
    "identify": "pipeline",
    "write_report": "report",
}

__all__ = [
    "BLA",
    "ClusterResult",
    "Dataset",
    "IdentificationConfig",
    "IdentificationResult",
    "LMIteration",
    "LevelRecord",
    "LinearStateSpace",
    "PNLSSModel",
    "PeriodicData",
    "PnlssSettings",
    "ScanResult",
    "SineData",
    "StateSpaceDimensions",
    "campaign_dataset",
    "cluster_periods",
    "estimate_bla",
    "fit_linear_ss",
    "fit_pnlss",
    "identify",
    "period_clusters",
    "predict_bla_sine",
    "read_records",
    "records_dataset",
    "relative_rms_error",
    "relative_rms_error_spread",
    "scan_pnlss",
    "transient_periods",
    "write_report",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'aero_identification' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"aero_identification.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
