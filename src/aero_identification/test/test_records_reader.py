"""Reading periodic records from CSV and .mat files (records.py): layouts and clear errors."""

from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from aero_identification.periodic_data import random_phase_period
from aero_identification.records import (
    MissingColumnError,
    NonFiniteError,
    RecordLengthError,
    SamplingRateError,
    detect_excited_lines,
    level_name,
    read_record,
    read_records,
)

N = 64
LINES = np.arange(3, 20)


def _signals(P: int = 3, M: int = 1, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(M·P·N,) input and output: M realizations of P periods, realization-major."""
    rng = np.random.default_rng(seed)
    per = [random_phase_period(rng, N, LINES) for _ in range(M)]
    u = np.concatenate([np.tile(p, P) for p in per])
    y = 0.5 * u + 0.1 * np.roll(u, 1) + 1e-3 * rng.standard_normal(u.size)
    return u, y


def _write_csv(path: Path, u: np.ndarray, y: np.ndarray, fs_rows: dict[int, str]) -> Path:
    lines = ['"Force","Acc","Fs",']
    for i, (a, b) in enumerate(zip(u, y, strict=True)):
        lines.append(f"{float(a)!r},{float(b)!r},{fs_rows.get(i, '')},")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_csv_record_is_cut_into_periods_with_fs_from_the_first_row(tmp_path: Path) -> None:
    u, y = _signals(P=3)
    path = _write_csv(tmp_path / "Data_Level4.csv", u, y, {0: "400"})
    rec = read_record(path, "csv", "Force", "Acc", N)
    assert rec.name == "4"
    assert rec.periods.u.shape == (N, 3, 1)
    assert rec.periods.fs == 400.0
    np.testing.assert_array_equal(rec.periods.u[:, 1, 0], u[N : 2 * N])
    np.testing.assert_array_equal(rec.periods.excited_lines, LINES)
    assert rec.dropped_periods == 0


def test_drop_periods_only_when_asked_and_reported(tmp_path: Path) -> None:
    u, y = _signals(P=4)
    path = _write_csv(tmp_path / "a.csv", u, y, {0: "100"})
    rec = read_record(path, "csv", "Force", "Acc", N, drop_periods=1)
    assert rec.periods.P == 3 and rec.periods_in_file == 4 and rec.dropped_periods == 1
    assert any("dropped the first 1 period" in n for n in rec.notes)


def test_csv_realizations_are_consecutive_blocks(tmp_path: Path) -> None:
    u, y = _signals(P=2, M=3)
    path = _write_csv(tmp_path / "a.csv", u, y, {0: "100"})
    rec = read_record(path, "csv", "Force", "Acc", N, realizations=3)
    assert rec.periods.u.shape == (N, 2, 3)
    np.testing.assert_array_equal(rec.periods.u[:, 0, 2], u[4 * N : 5 * N])


def test_a_record_of_no_whole_periods_is_refused(tmp_path: Path) -> None:
    u, y = _signals(P=3)
    path = _write_csv(tmp_path / "a.csv", u[:-5], y[:-5], {0: "400"})
    with pytest.raises(RecordLengthError, match=r"a\.csv.*'Force'.*not a whole number of periods"):
        read_record(path, "csv", "Force", "Acc", N)


def test_a_missing_column_lists_the_columns(tmp_path: Path) -> None:
    u, y = _signals()
    path = _write_csv(tmp_path / "a.csv", u, y, {0: "400"})
    with pytest.raises(MissingColumnError, match=r"'Acceleration2'.*\['Force', 'Acc', 'Fs'\]"):
        read_record(path, "csv", "Force", "Acceleration2", N)


def test_non_finite_and_empty_cells_are_located(tmp_path: Path) -> None:
    u, y = _signals()
    y[70] = np.nan
    path = _write_csv(tmp_path / "a.csv", u, y, {0: "400"})
    with pytest.raises(NonFiniteError, match=r"'Acc'.*line 72 \(sample 70\)"):
        read_record(path, "csv", "Force", "Acc", N)
    text = path.read_text().splitlines()
    cells = text[11].split(",")
    text[11] = ",".join(["", *cells[1:]])  # sample 10 of Force empty
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(NonFiniteError, match=r"'Force'.*empty cell at line 12"):
        read_record(path, "csv", "Force", "Acc", N)


def test_fs_conflicts_are_refused(tmp_path: Path) -> None:
    u, y = _signals()
    two = _write_csv(tmp_path / "two.csv", u, y, {0: "400", 50: "200"})
    with pytest.raises(SamplingRateError, match="differs within the file"):
        read_record(two, "csv", "Force", "Acc", N)
    one = _write_csv(tmp_path / "one.csv", u, y, {0: "400"})
    with pytest.raises(SamplingRateError, match="--fs is 100"):
        read_record(one, "csv", "Force", "Acc", N, fs=100.0)
    none = _write_csv(tmp_path / "none.csv", u, y, {})
    with pytest.raises(SamplingRateError, match="give --fs"):
        read_record(none, "csv", "Force", "Acc", N)
    assert read_record(none, "csv", "Force", "Acc", N, fs=50.0).periods.fs == 50.0


def test_levels_with_different_fs_are_refused(tmp_path: Path) -> None:
    u, y = _signals()
    _write_csv(tmp_path / "L_Level1.csv", u, y, {0: "400"})
    _write_csv(tmp_path / "L_Level2.csv", u, y, {0: "200"})
    with pytest.raises(SamplingRateError, match="all levels must share"):
        read_records(tmp_path, "csv", "Force", "Acc", N)
    recs = read_records(tmp_path, "csv", "Force", "Acc", N, patterns=["*Level1*"])
    assert [r.name for r in recs] == ["1"]


def test_mat_v5_vector_and_matrix_layouts(tmp_path: Path) -> None:
    u, y = _signals(P=2, M=2)
    path = tmp_path / "meas.mat"
    scipy.io.savemat(path, {"u": u.reshape(2, -1).T, "y": y.reshape(2, -1).T, "fs": 1000.0})
    rec = read_record(path, "mat", "u", "y", N)
    assert rec.periods.u.shape == (N, 2, 2) and rec.periods.fs == 1000.0
    np.testing.assert_array_equal(rec.periods.u[:, 1, 1], u[3 * N : 4 * N])
    scipy.io.savemat(path, {"u": u[None, :], "y": y[None, :]})  # 1 × T row vectors
    rec = read_record(path, "mat", "u", "y", N, fs=10.0, realizations=2)
    assert rec.periods.u.shape == (N, 2, 2)
    with pytest.raises(MissingColumnError, match=r"'out'.*\['u', 'y'\]"):
        read_record(path, "mat", "u", "out", N, fs=10.0)


def test_mat_v73_via_h5py_and_its_errors(tmp_path: Path) -> None:
    u, _ = _signals(P=3)
    npm_u = u.reshape(3, N).T[:, :, None]  # (N, P, M) in Matlab's order
    path = tmp_path / "meas73.mat"
    with h5py.File(path, "w", userblock_size=512) as fh:
        fh["u"] = npm_u.T  # Matlab writes column-major: HDF5 sees the transpose
        fh["y"] = (npm_u * 0.5).T
        fh["fs"] = np.array([[250.0]])
    with path.open("r+b") as fh:  # the MATLAB 7.3 header that matfile_version reads
        head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5"
        fh.write(head.ljust(116) + b"\x00" * 8 + b"\x00\x02" + b"IM")
    rec = read_record(path, "mat", "u", "y", N)
    assert rec.periods.u.shape == (N, 3, 1) and rec.periods.fs == 250.0
    np.testing.assert_allclose(rec.periods.u, npm_u)
    with h5py.File(path, "r+") as fh:
        data = fh["y"][()]
        data[0, 1, 5] = np.inf
        fh["y"][...] = data
    with pytest.raises(NonFiniteError, match=r"meas73\.mat.*'y'.*non-finite"):
        read_record(path, "mat", "u", "y", N)


def test_mat_3d_array_must_start_with_the_period(tmp_path: Path) -> None:
    path = tmp_path / "bad.mat"
    scipy.io.savemat(path, {"u": np.ones((N + 1, 2, 1)), "y": np.ones((N + 1, 2, 1)), "fs": 1.0})
    with pytest.raises(RecordLengthError, match=r"\(N, P, M\)"):
        read_record(path, "mat", "u", "y", N)


def test_detection_ignores_a_weak_hum_and_honours_the_band() -> None:
    rng = np.random.default_rng(1)
    u = random_phase_period(rng, 256, np.arange(10, 40))
    hum = 0.05 * 2 / 256  # 26 dB below a line (unit lines: amplitude 2/N in time)
    u = u + hum * np.cos(2 * np.pi * 100 * np.arange(256) / 256)  # weak "mains" on bin 100
    x = np.tile(u[:, None, None], (1, 2, 1))
    np.testing.assert_array_equal(detect_excited_lines(x, 1.0), np.arange(10, 40))
    lines = detect_excited_lines(x, 256.0, band=(20.0, 30.0))
    np.testing.assert_array_equal(lines, np.arange(20, 31))


def test_level_names() -> None:
    assert level_name("F16Data_FullMSine_Level2_Validation.csv") == "2"
    assert level_name("run_level-03.mat") == "3"
    assert level_name("sweep.csv") == "sweep"
