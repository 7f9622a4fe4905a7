"""The fields of the ``/identification/model`` message (and ``models.json``): one contract between
the identification that writes them (identification_result.py, pipeline.py, the identifier
node) and the view and report that read them.

The message is JSON. What the view reads, by where it sits:

- top level: ``refit`` (the identifier node's count), ``stamp_ns`` (optional: the model's
  experiment time; without it the view uses the latest stamp it has seen), ``levels`` by label,
  ``predictions``, ``table1`` and ``data_quality``;
- ``levels[label]``: ``offset_deg``, ``bla`` (the FRF with its variances) and ``clusters``;
- ``predictions[i]``: one validation sine, ``alpha_deg`` and ``cl_measured`` and one series per
  model, keyed ``cl_<model name>`` (`series_key`), all of the same length.

:func:`problems` lists what a reader cannot use, naming the field.
"""

import math
from collections.abc import Iterator, Mapping
from typing import Any, Final

# -- top level -----------------------------------------------------------------------------------
REFIT: Final = "refit"
STAMP_NS: Final = "stamp_ns"
LEVELS: Final = "levels"
PREDICTIONS: Final = "predictions"
TABLE1: Final = "table1"
DATA_QUALITY: Final = "data_quality"
WARNINGS: Final = "warnings"
EXPERIMENT: Final = "experiment"

# -- a level -------------------------------------------------------------------------------------
OFFSET_DEG: Final = "offset_deg"
BLA: Final = "bla"
CLUSTERS: Final = "clusters"

# The BLA's FRF at the excited lines: G = G_RE + j·G_IM, and its variances (bla.py): the noise
# variance, the total variance and the nonlinear distortion's (var_total − var_noise / M).
FREQ_HZ: Final = "freq_hz"
G_RE: Final = "G_re"
G_IM: Final = "G_im"
VAR_NOISE: Final = "var_noise"
VAR_TOTAL: Final = "var_total"
VAR_NL: Final = "var_nl"
FRF_FIELDS: Final = (FREQ_HZ, G_RE, G_IM, VAR_NOISE, VAR_TOTAL, VAR_NL)

# k-means of the periods (clustering.py): LABELS is P x M (period x realization), -1 excluded.
LABELS: Final = "labels"
K: Final = "k"
DOMINANT: Final = "dominant"
SIZES: Final = "sizes"
SILHOUETTE: Final = "silhouette"

# Table 1 as Markdown (each cell: error ± spread over the sine's periods [± bootstrap spread]).
TABLE1_ALL_LEVELS: Final = "markdown"
TABLE1_LEVEL1: Final = "markdown_level1"
TABLE1_NO_CLUSTERING: Final = "markdown_no_clustering"
TABLE1_HELD_OUT: Final = "markdown_held_out"
TABLE1_FLOOR_RATIOS: Final = "markdown_floor_ratios"
TABLE1_TITLES: Final = {
    TABLE1_ALL_LEVELS: "Table 1, models of all levels",
    TABLE1_LEVEL1: "Table 1, models of level 1",
    TABLE1_FLOOR_RATIOS: "Table 1 divided by the noise floor",
    TABLE1_NO_CLUSTERING: "Table 1 without clustering",
    TABLE1_HELD_OUT: "Held-out levels",
}

# -- a prediction (one validation sine) ----------------------------------------------------------
NAME: Final = "name"
LEVEL: Final = "level"
FREQUENCY_HZ: Final = "frequency_hz"
SAMPLES_PER_PERIOD: Final = "samples_per_period"
ALPHA_DEG: Final = "alpha_deg"
MEASURED: Final = "measured"
SERIES_PREFIX: Final = "cl_"

# The models validation.validate_sine predicts with, in Table 1's order.
BLA_SS_OWN: Final = "BLA SS (own level)"
BLA_SS_LEVEL1: Final = "BLA SS (level 1)"
PNLSS_ALL: Final = "PNLSS (all levels)"
PNLSS_LEVEL1: Final = "PNLSS (level 1)"
LPV_ALL: Final = "B-spline LPV (all levels)"
SELECTED: Final = "selected"  # the one of PNLSS_ALL and LPV_ALL the held-out periods chose
BEDDOES_LEISHMAN: Final = "Beddoes-Leishman (all levels)"
MODELS: Final = (
    BLA_SS_OWN, BLA_SS_LEVEL1, PNLSS_ALL, PNLSS_LEVEL1, LPV_ALL, SELECTED, BEDDOES_LEISHMAN,
)  # fmt: skip
# One colour per model (RGB), the same in the report's figures and in the view.
MODEL_COLORS: Final = {
    BLA_SS_OWN: (31, 119, 180),  # blue
    BLA_SS_LEVEL1: (148, 103, 189),  # purple
    PNLSS_ALL: (255, 127, 14),  # orange
    PNLSS_LEVEL1: (140, 86, 75),  # brown
    LPV_ALL: (214, 39, 40),  # red
    SELECTED: (23, 190, 207),  # cyan: drawn over the model it repeats
    BEDDOES_LEISHMAN: (44, 160, 44),  # green
}


def model_color_hex(model: str) -> str | None:
    """A model's colour as ``#rrggbb`` (None for a model without one)."""
    rgb = MODEL_COLORS.get(model)
    return None if rgb is None else "#{:02x}{:02x}{:02x}".format(*rgb)


def series_key(model: str) -> str:
    """The prediction field of a model's C_l series (``measured``: the measured C_l)."""
    return SERIES_PREFIX + model


def prediction_series(prediction: Mapping[str, Any]) -> Iterator[tuple[str, Any]]:
    """(model name, values) of every C_l series a prediction carries, the measured one first."""
    measured = series_key(MEASURED)
    if measured in prediction:
        yield MEASURED, prediction[measured]
    for key, values in prediction.items():
        if key.startswith(SERIES_PREFIX) and key != measured:
            yield key[len(SERIES_PREFIX) :], values


def _numbers(values: Any) -> list[float] | None:
    """The values as floats (JSON null: NaN), or None if they are not a list of numbers."""
    if not isinstance(values, list):
        return None
    out = []
    for v in values:
        if v is None:
            out.append(math.nan)
        elif isinstance(v, int | float) and not isinstance(v, bool):
            out.append(float(v))
        else:
            return None
    return out


def problems(model: Mapping[str, Any]) -> list[tuple[str, str]]:
    """What a reader of the model message cannot use, as (field, what is wrong): a missing field,
    values that are not numbers, a series whose length differs from its abscissa's, or a
    non-finite prediction (a diverged simulation). Empty when the message is whole. Missing
    variances or clusters are not problems: an early refit has none."""
    out = [(name, "missing") for name in (LEVELS, PREDICTIONS, TABLE1) if name not in model]
    levels = model.get(LEVELS)
    if LEVELS in model and not isinstance(levels, Mapping):
        out.append((LEVELS, "not an object"))
        levels = {}
    for label, level in (levels or {}).items():
        out += _level_problems(f"{LEVELS}.{label}", level)
    predictions = model.get(PREDICTIONS)
    if PREDICTIONS in model and not isinstance(predictions, list):
        out.append((PREDICTIONS, "not a list"))
        predictions = []
    for i, pred in enumerate(predictions or []):
        out += _prediction_problems(i, pred)
    if TABLE1 in model and not isinstance(model.get(TABLE1), Mapping):
        out.append((TABLE1, "not an object"))
    quality = model.get(DATA_QUALITY)
    if quality is not None and not (
        isinstance(quality, Mapping) and isinstance(quality.get("samples", {}), Mapping)
    ):
        out.append((DATA_QUALITY, "not an account of samples"))
    return out


def _level_problems(where: str, level: Any) -> list[tuple[str, str]]:
    if not isinstance(level, Mapping):
        return [(where, "not an object")]
    out = []
    offset = level.get(OFFSET_DEG)
    if offset is not None and not isinstance(offset, int | float):
        out.append((f"{where}.{OFFSET_DEG}", "not a number"))
    bla = level.get(BLA)
    if bla is not None:
        freq = _numbers(bla.get(FREQ_HZ)) if isinstance(bla, Mapping) else None
        if freq is None:
            out.append((f"{where}.{BLA}.{FREQ_HZ}", "missing or not numbers"))
        else:
            for name in FRF_FIELDS[1:]:
                raw = bla.get(name)
                values = _numbers(raw)
                if values is None and (name in (G_RE, G_IM) or raw is not None):
                    out.append((f"{where}.{BLA}.{name}", "missing or not numbers"))
                elif values is not None and len(values) != len(freq):
                    out.append(
                        (
                            f"{where}.{BLA}.{name}",
                            f"{len(values)} values for {len(freq)} frequencies",
                        )
                    )
    clusters = level.get(CLUSTERS)
    if clusters is not None:
        labels = clusters.get(LABELS) if isinstance(clusters, Mapping) else None
        rows = labels if isinstance(labels, list) else []
        table = all(isinstance(r, list) and r and all(isinstance(v, int) for v in r) for r in rows)
        if not rows or not table or len({len(r) for r in rows}) != 1:
            out.append((f"{where}.{CLUSTERS}.{LABELS}", "not a periods x realizations table"))
    return out


def _prediction_problems(i: int, pred: Any) -> list[tuple[str, str]]:
    if not isinstance(pred, Mapping):
        return [(f"{PREDICTIONS}[{i}]", "not an object")]
    where = f"{PREDICTIONS}[{pred.get(NAME, i)!s}]"
    alpha = _numbers(pred.get(ALPHA_DEG))
    if alpha is None:
        return [(f"{where}.{ALPHA_DEG}", "missing or not numbers")]
    out = []
    for model_name, raw in prediction_series(pred):
        values = _numbers(raw)
        field = f"{where}.{series_key(model_name)}"
        if values is None:
            out.append((field, "not numbers"))
        elif len(values) != len(alpha):
            out.append((field, f"{len(values)} values for {len(alpha)} angles"))
        elif not all(math.isfinite(v) for v in values):
            bad = sum(not math.isfinite(v) for v in values)
            out.append((field, f"{bad} of {len(values)} values not finite"))
    return out
