"""The tables of an identification report, as (Markdown, CSV): the paper's Table 1, the
validation errors on held-out levels, and what the period clustering changed.

Light (numpy only): the result's JSON payload and the command line use them without loading
matplotlib.
"""

import csv
import io
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

TABLE1_MODELS = ("BLA FRF", "BLA SS", "PNLSS")
LPV_ROW = "B-spline LPV"  # the all-levels table's second nonlinear class (bspline_lpv.py)
SELECTED_ROW = "selected"  # the all-levels table's row of the model the held-out periods chose
SEMI_EMPIRICAL_ROW = "Beddoes-Leishman"  # the all-levels table's baseline row, when fitted
FLOOR_ROW = "noise floor"  # Table 1's last row (metrics.noise_floor)


def _column_name(level: str, freq: float) -> str:
    return f"{level} {freq:g} Hz"


def table1(
    errors: Mapping[tuple[str, str, float], float],
    levels: Sequence[str],
    freqs: Sequence[float],
    models: Sequence[str] = TABLE1_MODELS,
    digits: int = 2,
    spreads: Mapping[tuple[str, str, float], float] | None = None,
    estimation_spreads: Mapping[tuple[str, str, float], float] | None = None,
    estimation_means: Mapping[tuple[str, str, float], float] | None = None,
    floor: Mapping[tuple[str, float], float] | None = None,
) -> tuple[str, str]:
    """The paper's Table 1: relative RMS errors, rows = models, columns = levels × frequencies.

    Args:
        errors: {(model, level, freq_hz): relative RMS error}; missing cells are left blank
            ("–" in Markdown, empty in CSV).
        levels: excitation levels in column order, e.g. ["low", "medium", "high"].
        freqs: sine frequencies [Hz] in column order within each level, e.g. [0.4, 1.0, 1.6].
        models: row order.
        digits: decimals in the Markdown table (the CSV keeps full precision).
        spreads: {(model, level, freq_hz): spread} with the same keys as ``errors``: the
            standard deviation over the sine's periods of the per-period error
            (metrics.relative_rms_error_spread). A finite spread is shown as
            "error ± spread" in Markdown; a missing or NaN one leaves the cell as it is.
        estimation_spreads: the same keys: the std of the error over bootstrap refits on the
            estimation periods (bootstrap.py). Shown as a second "± s" after the spread in
            Markdown ("–" in its place when the first is missing), and in the CSV as a
            "<column> estimation std" column after the "<column> std" one.
        estimation_means: the same keys: the bootstrap refits' mean error (the mean minus the
            cell is the bootstrap's bias estimate). In the CSV only, as a "<column> estimation
            mean" column after the "<column> estimation std" one (with ``estimation_spreads``).
        floor: {(level, freq_hz): noise floor} (metrics.noise_floor): with it (even empty) the
            table ends with a "noise floor" row, blank where a sine has fewer than 2 periods.

    Returns:
        (markdown, csv_text). Columns: "model", then "<level> <freq> Hz" for each level, and
        each frequency within it. With ``spreads`` (even empty) the CSV follows each value
        column with "<column> std", the spread (full precision, empty when missing or NaN);
        the value columns are the same with or without spreads, and without ``spreads`` the
        table is exactly the one without spread columns.

    Raises:
        ValueError: for a key of ``errors`` or ``spreads`` whose model, level or frequency is
            not in the layout (a typo would otherwise drop a result silently).
    """
    freqs_arr = np.asarray(freqs, dtype=float)
    if floor is not None:
        models = (*models, FLOOR_ROW)
        errors = {**errors, **{(FLOOR_ROW, lv, f): v for (lv, f), v in floor.items()}}

    def place(values: Mapping[tuple[str, str, float], float]) -> dict[tuple[str, str, int], float]:
        cells: dict[tuple[str, str, int], float] = {}
        for (model, level, freq), value in values.items():
            match = np.flatnonzero(np.isclose(freqs_arr, float(freq), rtol=1e-9, atol=1e-12))
            if model not in models or level not in levels or match.size != 1:
                raise ValueError(
                    f"result key {(model, level, freq)} is not in the table layout (models "
                    f"{list(models)}, levels {list(levels)}, freqs {list(freqs)})"
                )
            cells[(model, level, int(match[0]))] = float(value)
        return cells

    cells = place(errors)
    spread_cells = {k: v for k, v in place(spreads or {}).items() if np.isfinite(v)}
    boot_cells = {k: v for k, v in place(estimation_spreads or {}).items() if np.isfinite(v)}
    mean_cells = {k: v for k, v in place(estimation_means or {}).items() if np.isfinite(v)}
    columns = [_column_name(lv, f) for lv in levels for f in freqs_arr]
    header = ["model", *columns]
    with_boot = estimation_spreads is not None
    with_mean = with_boot and estimation_means is not None
    with_std = spreads is not None or with_boot
    suffixes = (
        ("",)
        + ((" std",) if with_std else ())
        + ((" estimation std",) if with_boot else ())
        + ((" estimation mean",) if with_mean else ())
    )
    header_csv = ["model"] + [c + sfx for c in columns for sfx in suffixes]
    rows_md: list[list[str]] = []
    rows_csv: list[list[str]] = []
    for model in models:
        md, cs = [model], [model]
        for level in levels:
            for i in range(freqs_arr.size):
                cell = cells.get((model, level, i))
                spread = spread_cells.get((model, level, i))
                boot = boot_cells.get((model, level, i))
                text = "–" if cell is None else f"{cell:.{digits}f}"
                if cell is not None and (spread is not None or boot is not None):
                    text += " ± " + ("–" if spread is None else f"{spread:.{digits}f}")
                if cell is not None and boot is not None:
                    text += f" ± {boot:.{digits}f}"
                md.append(text)
                cs.append("" if cell is None else repr(cell))
                if with_std:
                    cs.append("" if spread is None else repr(spread))
                if with_boot:
                    cs.append("" if boot is None else repr(boot))
                if with_mean:
                    mean = mean_cells.get((model, level, i))
                    cs.append("" if mean is None else repr(mean))
        rows_md.append(md)
        rows_csv.append(cs)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows_md]
    markdown = "\n".join(lines) + "\n"
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header_csv)
    writer.writerows(rows_csv)
    return markdown, buffer.getvalue()


def floor_ratio_table(
    tables: Sequence[tuple[str, Mapping[tuple[str, str, float], float]]],
    floor: Mapping[tuple[str, float], float],
    levels: Sequence[str],
    freqs: Sequence[float],
    models: Sequence[str] = TABLE1_MODELS,
    digits: int = 2,
) -> tuple[str, str]:
    """Each Table 1 cell divided by its sine's noise floor (1: as good as the data allow), as
    (Markdown, CSV); one row per model of each table, named "<model> (<table>)".

    Args:
        tables: (label, errors) per Table 1 variant, e.g. [("all levels", errors_all)], the
            errors keyed as `table1`'s.
        floor: {(level, freq_hz): noise floor}.
        levels, freqs, models, digits: as `table1`'s.
    """
    ratios: dict[tuple[str, str, float], float] = {}
    rows: list[str] = []
    for label, errors in tables:
        for model in models:
            row = f"{model} ({label})"
            cells = {
                (row, lv, f): e / floor[(lv, f)]
                for (m, lv, f), e in errors.items()
                if m == model and floor.get((lv, f), 0.0) > 0
            }
            if cells:
                rows.append(row)
                ratios.update(cells)
    return table1(ratios, levels, freqs, models=rows, digits=digits)


def clustering_markdown(effect: Mapping[str, Any]) -> str:
    """clustering.md: what the period clustering changed, per level
    (clustering_ablation.clustering_effect)."""

    def num(value: Any, fmt: str) -> str:
        return "–" if value is None or not np.isfinite(value) else format(value, fmt)

    lines = [
        "# What the period clustering changed",
        "",
        "The same pipeline with clustering (each level's dominant cluster) and without it (every",
        "valid period; `table1_no_clustering.md`). BLA figures near 1.02 Hz as in the paper's",
        "§3.3 (SNR, SNLR: |G|² against the noise and nonlinear variance of the BLA estimate);",
        "var_nl, var_noise: mean over the excited lines of the nonlinear variance of one",
        "realization's FRF and the noise variance of one period's FRF, relative to |G|² (so BLAs",
        "from different numbers of periods compare); PNLSS (all levels): relative RMS",
        "error on the validation realization's dominant-cluster periods (both models on the same",
        "periods).",
        "",
        "| level | k | sizes | periods used (with / without) | SNR dB (with / without) "
        "| SNLR dB | var_nl dB | var_noise dB | PNLSS validation error |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, e in effect.items():
        w, wo = e.get("bla_with", {}), e.get("bla_without", {})

        def pair(
            key: str, fmt: str = ".1f", a: Mapping[str, Any] = w, b: Mapping[str, Any] = wo
        ) -> str:
            return f"{num(a.get(key), fmt)} / {num(b.get(key), fmt)}"

        sizes = e.get("sizes")
        lines.append(
            f"| {name} | {e.get('k', '–')} | {sizes if sizes is not None else '–'} "
            f"| {e.get('periods_used')} / {e.get('periods_used_without')} "
            f"| {pair('snr_db')} | {pair('snlr_db')} | {pair('var_nl_db')} "
            f"| {pair('var_noise_db')} "
            f"| {num(e.get('pnlss_validation_with'), '.3f')} / "
            f"{num(e.get('pnlss_validation_without'), '.3f')} |"
        )
    return "\n".join(lines) + "\n"


HELD_OUT_COLUMNS = (
    ("level", "held-out level"),
    ("input_rms", "input RMS"),
    ("nearest_estimation_level", "nearest estimation level"),
    ("linear_nearest", "linear SS (nearest level)"),
    ("linear_lowest", "linear SS (lowest level)"),
    ("pnlss", "PNLSS"),
    ("lpv", "B-spline LPV"),
)


def held_out_table(rows: Sequence[Mapping[str, Any]], digits: int = 3) -> tuple[str, str]:
    """Validation errors on held-out levels (relative RMS error), one row per level, as
    (Markdown, CSV); a model that was not fitted is "–" (empty in CSV)."""
    header = [title for _, title in HELD_OUT_COLUMNS]
    md = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([key for key, _ in HELD_OUT_COLUMNS])
    for row in rows:
        cells = []
        for key, _ in HELD_OUT_COLUMNS:
            v = row.get(key)
            if v is None:
                cells.append("–")
            elif isinstance(v, float):
                cells.append(f"{v:.{digits}f}" if key != "input_rms" else f"{v:.4g}")
            else:
                cells.append(str(v))
        md.append("| " + " | ".join(cells) + " |")
        writer.writerow(["" if row.get(k) is None else row[k] for k, _ in HELD_OUT_COLUMNS])
    return "\n".join(md) + "\n", buffer.getvalue()
