"""Validation: Table 1 on the single sines (relative RMS error and its spread over the sine's
periods) and errors on held-out levels (step 4 of `pipeline.identify`)."""

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from . import model_payload as msg
from .dataset import Dataset, SineData
from .identification_result import SELECTED_LPV, SELECTED_PNLSS, IdentificationResult, LevelResult
from .metrics import (
    noise_floor,
    predict_bla_sine,
    relative_rms_error,
    relative_rms_error_spread,
    steady_state_response,
)
from .periodic_data import PeriodicData
from .report_tables import LPV_ROW, SELECTED_ROW, SEMI_EMPIRICAL_ROW

PNLSS_ROW = "PNLSS"  # Table 1's row of the PNLSS models

__all__ = ["held_out_errors", "nearest_level", "record_error", "validate", "validate_sine"]


def validate(dataset: Dataset, result: IdentificationResult) -> None:
    result.errors_all.clear()
    result.errors_level1.clear()
    result.spreads_all.clear()
    result.spreads_level1.clear()
    result.predictions.clear()
    result.noise_floor.clear()
    for rec in dataset.sines:
        validate_sine(rec, result)
    result.held_out_errors = held_out_errors(result)


def nearest_level(levels: Sequence[LevelResult], offset: float | None, rms: float) -> LevelResult:
    """The level nearest an operating point (by plan offset when known, else by input RMS)."""
    if offset is not None and all(lv.record.offset_deg is not None for lv in levels):
        return min(levels, key=lambda lv: abs(lv.offset_deg - offset))
    return min(levels, key=lambda lv: abs(lv.record.input_rms - rms))


def validate_sine(rec: SineData, result: IdentificationResult) -> None:
    estimation = [lv for lv in result.levels.values() if lv.role == "estimation"]
    if not estimation:
        return
    own = nearest_level(estimation, rec.offset_deg, float(np.std(rec.u)))
    low = estimation[0]
    name = own.name
    f = round(rec.frequency_hz, 6)
    y_mean, u_mean = float(np.mean(rec.y)), float(np.mean(rec.u))
    preds: dict[str, np.ndarray] = {}
    if len(rec.y) >= 2 * rec.samples_per_period:
        result.noise_floor[(name, f)] = noise_floor(rec.y, rec.samples_per_period)

    def score(
        errors: dict[tuple[str, str, float], float],
        spreads: dict[tuple[str, str, float], float],
        model_name: str,
        y_hat: np.ndarray,
        may_diverge: bool = False,
    ) -> None:
        """Table 1's cell (error over all periods) and its ± (std of the per-period errors)."""
        cell = (model_name, name, f)
        if may_diverge and not np.all(np.isfinite(y_hat)):  # a diverged PNLSS simulation
            errors[cell], spreads[cell] = float("inf"), float("nan")
            return
        errors[cell] = relative_rms_error(rec.y, y_hat)
        spreads[cell] = relative_rms_error_spread(rec.y, y_hat, rec.samples_per_period)

    # Linear models predict deviations: centred on the record's measured means.
    for lin_level, errors, spreads, key in (
        (own, result.errors_all, result.spreads_all, msg.BLA_SS_OWN),
        (low, result.errors_level1, result.spreads_level1, msg.BLA_SS_LEVEL1),
    ):
        if lin_level.bla is None or lin_level.linear is None:
            continue
        y_frf = predict_bla_sine(lin_level.bla, rec.frequency_hz, rec.u, y_mean)
        score(errors, spreads, "BLA FRF", y_frf)
        lin = lin_level.linear.with_operating_point(u_mean, y_mean)
        y_ss = steady_state_response(lin, rec.u, rec.samples_per_period)
        score(errors, spreads, "BLA SS", y_ss)
        preds[key] = y_ss
    for model, errors, spreads, key in (
        (result.pnlss_all, result.errors_all, result.spreads_all, msg.PNLSS_ALL),
        (result.pnlss_level1, result.errors_level1, result.spreads_level1, msg.PNLSS_LEVEL1),
    ):
        if model is None:
            continue
        y_hat = steady_state_response(model, rec.u, rec.samples_per_period)
        score(errors, spreads, "PNLSS", y_hat, may_diverge=True)
        preds[key] = y_hat
    if result.lpv_all is not None:
        y_hat = steady_state_response(result.lpv_all, rec.u, rec.samples_per_period)
        score(result.errors_all, result.spreads_all, LPV_ROW, y_hat, may_diverge=True)
        preds[msg.LPV_ALL] = y_hat
    chosen = {SELECTED_PNLSS: msg.PNLSS_ALL, SELECTED_LPV: msg.LPV_ALL}.get(
        result.selection.get("class", "")
    )
    if chosen is not None and chosen in preds:
        source = PNLSS_ROW if chosen == msg.PNLSS_ALL else LPV_ROW
        cell = (source, name, f)
        if cell in result.errors_all:
            result.errors_all[(SELECTED_ROW, name, f)] = result.errors_all[cell]
            result.spreads_all[(SELECTED_ROW, name, f)] = result.spreads_all[cell]
            preds[msg.SELECTED] = preds[chosen]
    if result.beddoes_leishman is not None:
        y_hat = steady_state_response(result.beddoes_leishman, rec.u, rec.samples_per_period)
        score(result.errors_all, result.spreads_all, SEMI_EMPIRICAL_ROW, y_hat, may_diverge=True)
        preds[msg.BEDDOES_LEISHMAN] = y_hat
    result.predictions.append(
        {
            msg.NAME: f"sine {name} {rec.frequency_hz:g} Hz",
            msg.LEVEL: name,
            msg.FREQUENCY_HZ: rec.frequency_hz,
            msg.SAMPLES_PER_PERIOD: rec.samples_per_period,
            msg.ALPHA_DEG: rec.u.tolist(),
            msg.series_key(msg.MEASURED): rec.y.tolist(),
            **{msg.series_key(k): v.tolist() for k, v in preds.items()},
        }
    )


def record_error(model: Any, data: PeriodicData, centred: bool) -> float:
    """Relative RMS error over every realization's periods (steady-state simulation). Linear
    models map deviations: with ``centred`` they are put at the record's means."""
    num, den = 0.0, 0.0
    for m in range(data.M):
        u = data.u[:, :, m].T.reshape(-1)
        y = data.y[:, :, m].T.reshape(-1)
        mod = model.with_operating_point(u.mean(), y.mean()) if centred else model
        y_hat = steady_state_response(mod, u, data.N)
        if not np.all(np.isfinite(y_hat)):
            return math.inf
        e = relative_rms_error(y, y_hat)
        spread2 = float(np.mean((y - y.mean()) ** 2))
        num += e * e * spread2
        den += spread2
    return math.sqrt(num / den)


def held_out_errors(result: IdentificationResult) -> list[dict[str, Any]]:
    """Errors of the linear models (nearest and lowest estimation level), of the all-levels
    PNLSS and of the B-spline LPV model on every held-out level's periods."""
    estimation = [
        lv for lv in result.levels.values() if lv.role == "estimation" and lv.linear is not None
    ]
    rows: list[dict[str, Any]] = []
    for lv in result.levels.values():
        data = lv.record.data
        if lv.role != "held out" or data is None or not estimation:
            continue
        nearest = nearest_level(estimation, lv.record.offset_deg, lv.record.input_rms)
        rows.append(
            {
                "level": lv.name,
                "input_rms": lv.record.input_rms,
                "nearest_estimation_level": nearest.name,
                "linear_nearest": record_error(nearest.linear, data, centred=True),
                "linear_lowest": record_error(estimation[0].linear, data, centred=True),
                "pnlss": None
                if result.pnlss_all is None
                else record_error(result.pnlss_all, data, centred=False),
                "lpv": None
                if result.lpv_all is None
                else record_error(result.lpv_all, data, centred=False),
            }
        )
    return rows
