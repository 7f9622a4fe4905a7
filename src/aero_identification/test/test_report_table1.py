"""Reports: Table 1 layout (Markdown, CSV) and the figures as non-empty PNGs."""

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from aero_identification import BLA, PeriodicData, estimate_bla
from aero_identification.data import random_phase_period
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
