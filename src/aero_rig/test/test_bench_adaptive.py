"""bench/adaptive.py reads the fit's Table 1 CSV as `report_tables.table1` writes it: the value, the
spread sqrt(std² + estimation std²) and the bootstrap mean, each from its own column (a column
read as the wrong one would move the issue-23 comparison without any error)."""

import importlib.util
import math
from pathlib import Path
from types import ModuleType

import pytest

from aero_identification.report_tables import table1

BENCH = Path(__file__).resolve().parents[3] / "bench" / "adaptive.py"


def _bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_adaptive", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run_dir(tmp_path: Path, boot: str, means: bool) -> Path:
    levels, freqs = ["low", "high"], [0.4, 1.6]
    errors = {(m, lv, f): 0.1 + 0.01 * i for i, (m, lv, f) in enumerate(
        (m, lv, f) for m in ("BLA SS", "PNLSS") for lv in levels for f in freqs
    )}  # fmt: skip
    spreads = dict.fromkeys(errors, 0.03)
    boots = dict.fromkeys(errors, 0.04)
    boots[("PNLSS", "high", 1.6)] = math.nan  # undefined: the cell's spread is undefined too
    mean = {k: v + 0.5 for k, v in errors.items()}
    _, csv_text = table1(
        errors, levels, freqs, spreads=spreads, estimation_spreads=boots,
        estimation_means=mean if means else None,
    )  # fmt: skip
    (tmp_path / boot).mkdir(parents=True)
    (tmp_path / boot / "table1_all_levels.csv").write_text(csv_text)
    return tmp_path


@pytest.mark.parametrize("means", [True, False])
def test_the_bench_reads_values_spreads_and_means_from_their_columns(
    tmp_path: Path, means: bool
) -> None:
    bench = _bench()
    boot = bench.BOOTSTRAP_DIRS[True]
    run = _run_dir(tmp_path, boot, means)
    cells = bench.table1(run, boot)
    columns = [f"{lv} {f:g} Hz" for lv in ("low", "high") for f in (0.4, 1.6)]
    # Table 1's three rows × 4 columns: no std or mean column read as a value.
    assert set(cells) == {(m, c) for m in ("BLA FRF", "BLA SS", "PNLSS") for c in columns}
    assert math.isnan(cells[("BLA FRF", "low 0.4 Hz")][0])  # no BLA FRF cells given
    value, spread = cells[("PNLSS", "low 1.6 Hz")]
    assert value == pytest.approx(0.15) and spread == pytest.approx(0.05)  # sqrt(.03² + .04²)
    assert math.isnan(cells[("PNLSS", "high 1.6 Hz")][1])
    got = bench.procedure_means(run, boot)
    if means:
        assert set(got) == set(cells)
        assert got[("PNLSS", "low 1.6 Hz")] == pytest.approx(0.65)
    else:
        assert got == {}
    assert bench.procedure_means(run, "no_such_fit") == {}
