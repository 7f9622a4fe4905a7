"""Reports: Table 1 layout (Markdown, CSV), its ± (the spread over the sine's periods) from the
metric through the pipeline to the tables and models.json, and the figures as non-empty PNGs."""

import csv
import dataclasses
import io
from pathlib import Path

import numpy as np
import pytest

from aero_identification import (
    BLA,
    IdentificationConfig,
    IdentificationResult,
    PeriodicData,
    SineData,
    estimate_bla,
    relative_rms_error,
    relative_rms_error_spread,
)
from aero_identification.dataset import LevelRecord
from aero_identification.identification_result import LevelResult
from aero_identification.periodic_data import random_phase_period
from aero_identification.report import (
    plot_cl_alpha,
    plot_clusters,
    plot_frf,
    plot_output_spectrum,
    plot_time_series,
    table1,
)

LEVELS = ["low", "medium", "high"]
FREQS = [0.4, 1.0, 1.6]
# The paper's Table 1 as the known truth for the layout.
PAPER = {
    "BLA FRF": [0.52, 0.14, 0.12, 1.68, 0.59, 0.55, 2.36, 0.99, 0.80],
    "BLA SS": [0.03, 0.04, 0.02, 0.76, 0.68, 0.58, 1.76, 1.02, 0.80],
    "PNLSS": [0.02, 0.03, 0.05, 0.08, 0.10, 0.13, 0.18, 0.16, 0.25],
}


def paper_errors() -> dict[tuple[str, str, float], float]:
    cols = [(lv, f) for lv in LEVELS for f in FREQS]
    return {
        (model, lv, f): v
        for model, row in PAPER.items()
        for (lv, f), v in zip(cols, row, strict=True)
    }


def test_table1_markdown_and_csv_layout() -> None:
    errors = paper_errors()
    del errors[("PNLSS", "high", 1.6)]  # a model not fitted at one point
    markdown, csv_text = table1(errors, LEVELS, FREQS)
    md_lines = markdown.strip().splitlines()
    assert md_lines[0] == (
        "| model | low 0.4 Hz | low 1 Hz | low 1.6 Hz | medium 0.4 Hz | medium 1 Hz | "
        "medium 1.6 Hz | high 0.4 Hz | high 1 Hz | high 1.6 Hz |"
    )
    assert md_lines[1].count("---") == 10
    assert md_lines[2] == (
        "| BLA FRF | 0.52 | 0.14 | 0.12 | 1.68 | 0.59 | 0.55 | 2.36 | 0.99 | 0.80 |"
    )
    assert md_lines[4].startswith("| PNLSS | 0.02 |") and md_lines[4].endswith("| 0.16 | – |")
    rows = list(csv.reader(io.StringIO(csv_text)))
    assert len(rows) == 4 and rows[0][0] == "model" and rows[0][4] == "medium 0.4 Hz"
    assert [r[0] for r in rows[1:]] == ["BLA FRF", "BLA SS", "PNLSS"]
    assert float(rows[2][5]) == 0.68  # BLA SS, medium, 1 Hz
    assert rows[3][9] == ""


def test_table1_rejects_keys_outside_the_layout() -> None:
    with pytest.raises(ValueError, match="not in the table layout"):
        table1({("PNLSS", "low", 0.5): 0.1}, LEVELS, FREQS)
    with pytest.raises(ValueError, match="not in the table layout"):
        table1({("ARX", "low", 0.4): 0.1}, LEVELS, FREQS)


# --- the spread (±) of Table 1's cells -----------------------------------------------------------


def test_spread_is_the_std_of_the_per_period_errors() -> None:
    base = np.array([1.0, -1.0, 1.0, -1.0])  # one period: mean 0, rms deviation 1
    # Period 0: error 0.1; period 1: error 0.3 (each period against its own deviation).
    y = np.concatenate([base, base])
    y_hat = np.concatenate([base + 0.1, base + 0.3])
    assert relative_rms_error_spread(y, y_hat, 4) == pytest.approx(0.2 / np.sqrt(2), rel=1e-12)
    # A third period at another offset and scale: deviation rms 2, error 1.2 / 2 = 0.6. Each
    # period is centred on its own mean: errors 0.1, 0.3, 0.6, sample std (ddof = 1).
    y3 = np.concatenate([y, 5.0 + 2.0 * base])
    y3_hat = np.concatenate([y_hat, 5.0 + 2.0 * base + 1.2])
    assert relative_rms_error_spread(y3, y3_hat, 4) == pytest.approx(
        np.std([0.1, 0.3, 0.6], ddof=1), rel=1e-12
    )
    assert relative_rms_error_spread(y3, y3_hat, 4) == pytest.approx(np.sqrt(0.19 / 3), rel=1e-12)
    # Equal per-period errors: no spread, whatever the overall error.
    assert relative_rms_error_spread(y, y + 0.2, 4) == pytest.approx(0.0, abs=1e-15)
    # One period: undefined.
    assert np.isnan(relative_rms_error_spread(base, base + 0.1, 4))
    with pytest.raises(ValueError, match="whole periods"):
        relative_rms_error_spread(y[:6], y_hat[:6], 4)
    with pytest.raises(ValueError, match="same shape"):
        relative_rms_error_spread(y, y_hat[:4], 4)
    with pytest.raises(ValueError, match="positive integer"):
        relative_rms_error_spread(y, y_hat, 0)


def test_table1_with_spreads_markdown_and_csv() -> None:
    errors = paper_errors()
    del errors[("PNLSS", "high", 1.6)]
    spreads = {
        ("BLA FRF", "low", 0.4): 0.0123,  # shown with the value's digits
        ("BLA SS", "medium", 1.0): 0.05,
        ("PNLSS", "low", 1.0): float("nan"),  # a single period: no ±
    }
    markdown, csv_text = table1(errors, LEVELS, FREQS, spreads=spreads)
    plain_md, plain_csv = table1(errors, LEVELS, FREQS)
    md_lines = markdown.strip().splitlines()
    assert md_lines[:2] == plain_md.strip().splitlines()[:2]  # same header
    assert md_lines[2] == (
        "| BLA FRF | 0.52 ± 0.01 | 0.14 | 0.12 | 1.68 | 0.59 | 0.55 | 2.36 | 0.99 | 0.80 |"
    )
    assert "| 0.68 ± 0.05 |" in md_lines[3]
    assert md_lines[4] == plain_md.strip().splitlines()[4]  # NaN spread: cells unchanged
    assert "±" not in plain_md and markdown.count("±") == 2
    assert table1(errors, LEVELS, FREQS, digits=3, spreads=spreads)[0].count("0.520 ± 0.012") == 1

    rows = list(csv.reader(io.StringIO(csv_text)))
    columns = [f"{lv} {f:g} Hz" for lv in LEVELS for f in FREQS]
    assert rows[0] == ["model"] + [c for col in columns for c in (col, f"{col} std")]
    table = {r[0]: dict(zip(rows[0], r, strict=True)) for r in rows[1:]}
    assert float(table["BLA FRF"]["low 0.4 Hz std"]) == 0.0123
    assert float(table["BLA SS"]["medium 1 Hz std"]) == 0.05
    assert table["PNLSS"]["low 1 Hz std"] == ""  # NaN: empty
    assert table["BLA FRF"]["low 1 Hz std"] == ""  # no spread given
    assert table["PNLSS"]["high 1.6 Hz"] == table["PNLSS"]["high 1.6 Hz std"] == ""
    # Every value column is the one of the table without spreads.
    plain = list(csv.DictReader(io.StringIO(plain_csv)))
    assert list(plain[0]) == ["model", *columns]  # no spreads: no std columns
    for row in plain:
        assert all(table[row["model"]][k] == v for k, v in row.items())


def test_table1_rejects_spread_keys_outside_the_layout() -> None:
    with pytest.raises(ValueError, match="not in the table layout"):
        table1(paper_errors(), LEVELS, FREQS, spreads={("PNLSS", "low", 0.5): 0.01})
    with pytest.raises(ValueError, match="not in the table layout"):
        table1(paper_errors(), LEVELS, FREQS, spreads={("PNLSS", "extreme", 0.4): 0.01})


class _Gain:
    """A stand-in model: ŷ = gain · u + bias (what validation and payload need)."""

    def __init__(self, gain: float, bias: float = 0.0) -> None:
        self.gain, self.bias = gain, bias

    def simulate(self, u: np.ndarray) -> np.ndarray:
        return self.gain * np.asarray(u) + self.bias

    def to_dict(self) -> dict[str, float]:
        return {"gain": self.gain, "bias": self.bias}


def test_validation_fills_spreads_beside_errors_into_tables_and_json() -> None:
    from aero_identification.validation import validate_sine

    n, periods = 50, 4
    t = np.arange(n * periods)
    u = 10.0 + 4.0 * np.sin(2 * np.pi * t / n)
    # The measured output: a gain whose deviation from the model's differs period by period.
    scale = np.repeat([1.0, 1.1, 0.95, 1.2], n)
    y = 0.1 * (u - 10.0) * scale + 1.0
    sine = SineData("sine 1 Hz at 10°", 1.0, 10.0, n, u, y)
    config = IdentificationConfig()
    result = IdentificationResult(config=config, fs=float(n), sines_planned=True)
    result.levels["low"] = LevelResult(LevelRecord("low", None, key="1", offset_deg=10.0))
    result.pnlss_all = _Gain(0.1, 0.0)
    result.pnlss_level1 = _Gain(np.inf)  # diverged
    validate_sine(sine, result)
    y_hat = 0.1 * u
    key = ("PNLSS", "low", 1.0)
    assert result.errors_all[key] == relative_rms_error(y, y_hat)  # the value is unchanged
    per_period = [
        relative_rms_error(y[p * n : (p + 1) * n], y_hat[p * n : (p + 1) * n])
        for p in range(periods)
    ]
    assert result.spreads_all[key] == pytest.approx(np.std(per_period, ddof=1), rel=1e-12)
    assert result.spreads_all[key] > 0.01
    assert result.errors_level1[key] == np.inf and np.isnan(result.spreads_level1[key])
    assert set(result.spreads_all) == set(result.errors_all)

    tables = result.tables()
    md, csv_text = tables["table1_all_levels"]
    error, spread = result.errors_all[key], result.spreads_all[key]
    assert f"| PNLSS | {error:.2f} ± {spread:.2f} |" in md
    row = next(r for r in csv.DictReader(io.StringIO(csv_text)) if r["model"] == "PNLSS")
    assert float(row["low 1 Hz"]) == error and float(row["low 1 Hz std"]) == spread
    assert "±" not in tables["table1_level1"][0]  # inf with NaN spread: no ±
    payload = result.to_json_dict()
    assert payload["errors"]["all_levels"] == [["PNLSS", "low", 1.0, error]]
    assert payload["errors"]["all_levels_std"] == [["PNLSS", "low", 1.0, spread]]
    assert payload["errors"]["level1_std"] == [["PNLSS", "low", 1.0, None]]
    assert f"{error:.2f} ± {spread:.2f}" in payload["table1"]["markdown"]
    # The variant without clustering carries its own spreads.
    result.no_clustering = dataclasses.replace(
        result, spreads_all={key: 0.5}, errors_all={key: 0.25}
    )
    assert "| PNLSS | 0.25 ± 0.50 |" in result.tables()["table1_no_clustering"][0]


def small_bla() -> tuple[PeriodicData, BLA]:
    rng = np.random.default_rng(0)
    N, P, M = 128, 3, 2
    lines = np.array([1, 3, 7, 9, 11, 15])
    u = np.empty((N, P, M))
    for m in range(M):
        u[:, :, m] = random_phase_period(rng, N, lines)[:, None]
    y = 0.5 * u + 0.2 * u**2 + 0.01 * rng.standard_normal(u.shape)
    data = PeriodicData(u, y, 20.0, lines)
    return data, estimate_bla(data)


def assert_png(path: Path) -> None:
    assert path.exists() and path.stat().st_size > 5000
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_figures_are_written_as_png(tmp_path: Path) -> None:
    data, bla = small_bla()
    assert_png(plot_frf(bla, tmp_path / "frf.png"))
    assert_png(plot_output_spectrum(bla, tmp_path / "spectra" / "out.png"))
    labels = np.zeros((data.P, data.M), dtype=int)
    labels[1, 0] = 1
    assert_png(plot_clusters(labels, tmp_path / "clusters.png", y=data.y, fs=data.fs))
    assert_png(plot_clusters(labels, tmp_path / "clusters_grid.png"))
    t = np.arange(200) / 20.0
    y = np.sin(t)
    assert_png(plot_time_series(t, y, {"PNLSS": 0.9 * y}, tmp_path / "time.png"))
    alpha = 15 + 4.7 * np.sin(2 * np.pi * 0.4 * t)
    qs = (np.linspace(0, 30, 31), 0.1 * np.linspace(0, 30, 31))
    path = plot_cl_alpha(alpha, 0.1 * alpha, tmp_path / "cl.png", {"BLA SS": 0.09 * alpha}, qs)
    assert_png(path)
    with pytest.raises(ValueError, match=r"\(P, M\)"):
        plot_clusters(labels, tmp_path / "bad.png", y=data.y[:, :2])


def test_table1_with_estimation_spreads_shows_both() -> None:
    """The bootstrap's estimation spread (bootstrap.py): a second ± in Markdown, an
    "estimation std" column after each "std" column in the CSV; the rest unchanged."""
    errors = paper_errors()
    spreads = {("BLA FRF", "low", 0.4): 0.0123, ("BLA SS", "medium", 1.0): 0.05}
    boot = {
        ("BLA FRF", "low", 0.4): 0.031,
        ("PNLSS", "low", 1.0): 0.02,  # no period spread: "–" in its place
        ("BLA SS", "medium", 1.0): float("nan"),  # undefined: only the period spread
    }
    markdown, csv_text = table1(errors, LEVELS, FREQS, spreads=spreads, estimation_spreads=boot)
    with_periods, periods_csv = table1(errors, LEVELS, FREQS, spreads=spreads)
    lines = markdown.strip().splitlines()
    assert lines[2].startswith("| BLA FRF | 0.52 ± 0.01 ± 0.03 | 0.14 |")
    assert "| 0.68 ± 0.05 |" in lines[3]
    assert lines[4].startswith("| PNLSS | 0.02 | 0.03 ± – ± 0.02 | 0.05 |")
    rows = list(csv.reader(io.StringIO(csv_text)))
    columns = [f"{lv} {f:g} Hz" for lv in LEVELS for f in FREQS]
    assert rows[0] == ["model"] + [
        c for col in columns for c in (col, f"{col} std", f"{col} estimation std")
    ]
    table = {r[0]: dict(zip(rows[0], r, strict=True)) for r in rows[1:]}
    assert float(table["BLA FRF"]["low 0.4 Hz estimation std"]) == 0.031
    assert table["BLA SS"]["medium 1 Hz estimation std"] == ""
    # The value and "std" columns are those of the table without estimation spreads.
    for row in csv.DictReader(io.StringIO(periods_csv)):
        assert all(table[row["model"]][k] == v for k, v in row.items())
    assert with_periods.count("±") == 2
    # The replicates' mean: a CSV column after each "estimation std"; the Markdown unchanged.
    means = {("BLA FRF", "low", 0.4): 0.55, ("PNLSS", "low", 1.0): float("nan")}
    md_means, csv_means = table1(
        errors, LEVELS, FREQS, spreads=spreads, estimation_spreads=boot, estimation_means=means
    )
    assert md_means == markdown
    rows = list(csv.reader(io.StringIO(csv_means)))
    assert rows[0] == ["model"] + [
        c
        for col in columns
        for c in (col, f"{col} std", f"{col} estimation std", f"{col} estimation mean")
    ]
    with_mean = {r[0]: dict(zip(rows[0], r, strict=True)) for r in rows[1:]}
    assert float(with_mean["BLA FRF"]["low 0.4 Hz estimation mean"]) == 0.55
    assert with_mean["PNLSS"]["low 1 Hz estimation mean"] == ""  # NaN: empty
    assert all(with_mean[m][k] == v for m, row in table.items() for k, v in row.items())
    with pytest.raises(ValueError, match="not in the table layout"):
        table1(errors, LEVELS, FREQS, estimation_spreads={("PNLSS", "low", 0.5): 0.01})


def test_noise_floor_recovers_the_noise_of_a_periodic_record() -> None:
    from aero_identification.metrics import noise_floor

    rng = np.random.default_rng(3)
    n, periods, sigma = 400, 20, 0.05
    t = np.arange(n * periods)
    g = np.sin(2 * np.pi * t / n) + 0.3 * np.sin(6 * np.pi * t / n) ** 2  # periodic response
    y = g + sigma * rng.standard_normal(g.size)
    spread = np.sqrt(np.mean((y - y.mean()) ** 2))
    floor = noise_floor(y, n)
    # The floor estimates sigma / rms(y − mean y) (8000 noise samples: within a few per cent) …
    assert floor == pytest.approx(sigma / spread, rel=0.03)
    # … which is the true periodic response's own error: no model of α does better.
    assert floor == pytest.approx(relative_rms_error(y, g), rel=0.03)
    # Without the √(P/(P−1)) factor it would be the period mean's error, √(19/20) lower.
    mean_period = np.tile(y.reshape(periods, n).mean(axis=0), periods)
    assert relative_rms_error(y, mean_period) == pytest.approx(
        floor * np.sqrt((periods - 1) / periods), rel=1e-12
    )
    assert noise_floor(np.tile(g[:n], 3), n) == pytest.approx(0.0, abs=1e-12)  # noise-free
    with pytest.raises(ValueError, match="at least 2 periods"):
        noise_floor(y[:n], n)
    with pytest.raises(ValueError, match="whole periods"):
        noise_floor(y[:-1], n)


def test_noise_floor_row_and_ratios_in_tables_json_and_summary() -> None:
    from aero_identification.report import summary_markdown
    from aero_identification.validation import validate_sine

    rng = np.random.default_rng(4)
    n, periods = 50, 8
    t = np.arange(n * periods)
    u = 10.0 + 4.0 * np.sin(2 * np.pi * t / n)
    y = 0.1 * (u - 10.0) + 1.0 + 0.02 * rng.standard_normal(t.size)
    sine = SineData("sine 1 Hz at 10°", 1.0, 10.0, n, u, y)
    result = IdentificationResult(config=IdentificationConfig(), fs=float(n), sines_planned=True)
    result.levels["low"] = LevelResult(LevelRecord("low", None, key="1", offset_deg=10.0))
    result.pnlss_all = _Gain(0.12, 0.0)  # a gain 20 % off: well above the floor
    validate_sine(sine, result)
    floor = result.noise_floor[("low", 1.0)]
    assert 0.05 < floor < 0.2
    error = result.errors_all[("PNLSS", "low", 1.0)]
    assert error > 1.5 * floor

    tables = result.tables()
    md, csv_text = tables["table1_all_levels"]
    assert md.strip().splitlines()[-1] == f"| noise floor | {floor:.2f} |"
    row = next(r for r in csv.DictReader(io.StringIO(csv_text)) if r["model"] == "noise floor")
    assert float(row["low 1 Hz"]) == floor and row["low 1 Hz std"] == ""
    assert "| noise floor |" in tables["table1_level1"][0]  # the same sines, the same floor
    ratios = {r["model"]: r for r in csv.DictReader(io.StringIO(tables["table1_floor_ratios"][1]))}
    assert set(ratios) == {"PNLSS (all-levels table)"}  # level 1 fitted nothing here
    assert float(ratios["PNLSS (all-levels table)"]["low 1 Hz"]) == pytest.approx(error / floor)
    payload = result.to_json_dict()
    assert payload["errors"]["noise_floor"] == [["low", 1.0, floor]]
    assert "| noise floor |" in payload["table1"]["markdown"]
    assert f"{error / floor:.2f}" in payload["table1"]["markdown_floor_ratios"]
    result.pnlss_all = None  # the stand-in has no structure for the summary's PNLSS line
    summary = summary_markdown(result)
    assert "divided by the noise floor" in summary and f"| {error / floor:.2f} |" in summary
    # A sine of one period has no floor: the row is there, its cell blank.
    result.noise_floor.clear()
    validate_sine(dataclasses.replace(sine, u=u[:n], y=y[:n]), result)
    assert result.noise_floor == {}
    assert "| noise floor | – |" in result.tables()["table1_all_levels"][0]
    assert "table1_floor_ratios" not in result.tables()


def test_a_floor_without_any_model_cell_still_makes_its_table() -> None:
    """A sine measured while no model could be fitted (e.g. an anomaly excluded the level's
    periods): the floor alone fills Table 1's columns."""
    result = IdentificationResult(config=IdentificationConfig(), fs=50.0, sines_planned=True)
    result.levels["single"] = LevelResult(LevelRecord("single", None, key="0", offset_deg=6.6))
    result.noise_floor[("single", 1.0)] = 0.07
    assert result.sine_freqs == [1.0]
    md = result.tables()["table1_all_levels"][0]
    assert md.splitlines()[0] == "| model | single 1 Hz |"
    assert md.strip().splitlines()[-1] == "| noise floor | 0.07 |"
