"""Periodic multisine records from files that are not bags: CSV exports and Matlab .mat files.

A level is one file. It holds an input and an output signal of M phase realizations × P periods
of N samples each; the period length N is given by the user (the excitation's period), P and
M follow from the record. Layouts:

- CSV (a header row naming the columns, one sample per row, comma separated; dSPACE and
  benchmark exports): the rows are realization after realization, each P whole periods, so a
  column holds M·P·N values (M from ``realizations``, default 1). The sampling frequency comes
  from ``fs`` or from a column named ``fs`` (any case) whose non-empty cells must all agree
  (the F-16 benchmark writes it in the first row only); when both are given they must agree.
- MAT (``scipy.io.loadmat`` for v5/v7 files, ``h5py`` for v7.3/HDF5 files, whose arrays are
  transposed back to Matlab's order): the input and output are variables. A vector holds
  M·P·N samples as above; a 2-D array is samples × realizations (T, M) (Matlab's one column
  per channel; a 1 × T row vector is read as a column); a 3-D array is (N, P, M), the order of
  `PeriodicData`. The sampling frequency is a scalar variable ``fs`` (or ``Fs``, ``FS``) or the
  ``fs`` argument, both agreeing when both are given.

Nothing is silently dropped or patched: a record whose length is not a whole number of periods,
a missing column or variable, a non-finite sample or an inconsistent sampling frequency raises
a `RecordError` (a ValueError) naming the file and the column. Leading periods are dropped only
when asked (``drop_periods``), and the drop is recorded in the returned `LevelRecord`.

The excited lines are found from the input spectrum (`detect_excited_lines`): the records do
not carry the excitation plan.
"""

import csv
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aero_identification.dataset import Dataset, LevelRecord
from aero_identification.periodic_data import PeriodicData, transient_periods

FORMATS = ("csv", "mat")
FS_NAMES = ("fs", "Fs", "FS")

# Excited-line detection: a bin is excited when its period-averaged input amplitude lies less
# than EXCITED_BELOW_DB under the median amplitude of the strong bins (those within
# STRONG_WITHIN_DB of the strongest). Mains hum and harmonics of a measured force lie far lower.
STRONG_WITHIN_DB = 40.0
EXCITED_BELOW_DB = 20.0


class RecordError(ValueError):
    """A record file that cannot be read as periodic multisine data.

    Attributes:
        path: the file.
        column: the column (CSV) or variable (MAT) concerned, or None.
    """

    def __init__(self, path: str | Path, message: str, column: str | None = None) -> None:
        self.path = Path(path)
        self.column = column
        where = f"{self.path}" + (f", column {column!r}" if column is not None else "")
        super().__init__(f"{where}: {message}")


class RecordLengthError(RecordError):
    """The record is not a whole number of periods (of every realization)."""


class MissingColumnError(RecordError):
    """A requested column or variable is not in the file; the message lists those that are."""


class NonFiniteError(RecordError):
    """A sample is NaN, inf or empty; the message says where."""


class SamplingRateError(RecordError):
    """No sampling frequency, or inconsistent ones (within a file, with --fs, between files)."""


def level_name(path: str | Path) -> str:
    """Short name of the level in a file: k for a stem containing "Level<k>" (any case,
    optionally "level_k" or "level-k"), otherwise the file stem."""
    stem = Path(path).stem
    match = re.search(r"level[_\- ]?(\d+)", stem, flags=re.IGNORECASE)
    return str(int(match.group(1))) if match else stem


def detect_excited_lines(
    u: np.ndarray, fs: float, band: tuple[float, float] | None = None
) -> np.ndarray:
    """DFT bins excited by the periodic input u (N, P, M).

    The period-averaged input spectrum (RMS over realizations) is compared with the median of its
    strong bins (within STRONG_WITHIN_DB of the strongest, DC excluded); a bin is excited if it
    lies less than EXCITED_BELOW_DB below that median. With ``band`` (f_min, f_max) [Hz] only
    bins inside it are considered.

    Returns:
        (F,) int bins in 1 … ⌈N/2⌉−1, ascending.

    Raises:
        ValueError: if no bin qualifies (a constant input, or a band without excitation).
    """
    N = u.shape[0]
    U = np.fft.rfft(u, axis=0).mean(axis=1)  # (N//2+1, M) period-averaged
    amp = np.sqrt(np.mean(np.abs(U) ** 2, axis=1))
    k = np.arange(amp.size)
    allowed = (k >= 1) & (2 * k < N)
    if band is not None:
        f = k * fs / N
        allowed &= (f >= band[0] * (1 - 1e-12)) & (f <= band[1] * (1 + 1e-12))
    a = np.where(allowed, amp, 0.0)
    if not np.any(a > 0):
        raise ValueError(
            "the input has no power at any DFT bin"
            + (f" in the band {band[0]:g} … {band[1]:g} Hz" if band else "")
        )
    strong = a[a >= a.max() * 10 ** (-STRONG_WITHIN_DB / 20)]
    threshold = float(np.median(strong)) * 10 ** (-EXCITED_BELOW_DB / 20)
    return np.flatnonzero(a >= threshold).astype(np.int64)


# --- CSV ------------------------------------------------------------------------------------


def _csv_columns(path: Path, wanted: Sequence[str]) -> tuple[dict[str, list[str]], list[str]]:
    """The raw cells of the wanted columns (those present) and the header."""
    try:
        with path.open(newline="") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise RecordError(path, "the file is empty (no header row)") from None
            index = {name: header.index(name) for name in wanted if name in header}
            cells: dict[str, list[str]] = {name: [] for name in index}
            for row in reader:
                if not row or all(not c.strip() for c in row):
                    continue  # blank line (e.g. a trailing newline)
                for name, i in index.items():
                    cells[name].append(row[i] if i < len(row) else "")
    except UnicodeDecodeError as exc:
        raise RecordError(path, f"not a text CSV file ({exc})") from exc
    return cells, [h for h in header if h]


def _parse(path: Path, column: str, cells: list[str], first_line: int = 2) -> np.ndarray:
    """Floats of a column's cells; empty or unparsable cells raise, naming the line."""
    values = np.empty(len(cells))
    for i, cell in enumerate(cells):
        text = cell.strip()
        if not text:
            raise NonFiniteError(path, f"empty cell at line {first_line + i} (sample {i})", column)
        try:
            values[i] = float(text)
        except ValueError:
            raise RecordError(
                path, f"cannot read {text!r} at line {first_line + i} as a number", column
            ) from None
    return values


def _csv_fs(path: Path, cells: dict[str, list[str]], fs_col: str | None) -> float | None:
    if fs_col is None:
        return None
    found: dict[float, int] = {}
    for i, cell in enumerate(cells[fs_col]):
        if cell.strip():
            try:
                value = float(cell)
            except ValueError:
                raise SamplingRateError(
                    path, f"cannot read {cell!r} at line {i + 2} as a sampling frequency", fs_col
                ) from None
            found.setdefault(value, i + 2)
    if not found:
        return None
    if len(found) > 1:
        where = ", ".join(f"{v:g} Hz at line {line}" for v, line in found.items())
        raise SamplingRateError(path, f"the sampling frequency differs within the file: {where}")
    return next(iter(found))


def read_csv_signals(
    path: str | Path, input_col: str, output_col: str
) -> tuple[np.ndarray, np.ndarray, float | None]:
    """Input and output columns of a CSV file and its fs column's value (None if absent)."""
    path = Path(path)
    probe_header = _csv_header(path)
    fs_col = next((h for h in probe_header if h.lower() == "fs"), None)
    wanted = [input_col, output_col] + ([fs_col] if fs_col else [])
    cells, header = _csv_columns(path, wanted)
    for col in (input_col, output_col):
        if col not in cells:
            raise MissingColumnError(
                path, f"no such column; the file has columns {header}", column=col
            )
    u = _parse(path, input_col, cells[input_col])
    y = _parse(path, output_col, cells[output_col])
    for col, x in ((input_col, u), (output_col, y)):
        _check_finite(path, col, x, lambda i: f"line {i + 2} (sample {i})")
    return u, y, _csv_fs(path, cells, fs_col)


def _csv_header(path: Path) -> list[str]:
    try:
        with path.open(newline="") as fh:
            row = next(csv.reader(fh), None)
    except UnicodeDecodeError as exc:
        raise RecordError(path, f"not a text CSV file ({exc})") from exc
    if row is None:
        raise RecordError(path, "the file is empty (no header row)")
    return [h.strip() for h in row]


def _check_finite(path: Path, column: str, x: np.ndarray, where: Any) -> None:
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        first = ", ".join(str(where(int(i))) for i in bad[:3])
        raise NonFiniteError(
            path, f"{bad.size} non-finite value(s) (NaN or inf), first at {first}", column
        )


# --- MAT ------------------------------------------------------------------------------------


def _mat_variables(path: Path) -> dict[str, Any]:
    """Variables of a .mat file (v5/v7 via scipy, v7.3 via h5py), arrays in Matlab's order."""
    import scipy.io

    try:
        major, _ = scipy.io.matlab.matfile_version(str(path))
    except Exception as exc:
        raise RecordError(path, f"not a Matlab .mat file ({exc})") from exc
    if major == 2:  # v7.3: HDF5
        import h5py

        out: dict[str, Any] = {}
        with h5py.File(path, "r") as fh:
            for name, obj in fh.items():
                if isinstance(obj, h5py.Dataset) and not name.startswith("#"):
                    out[name] = np.asarray(obj[()]).T  # HDF5 stores Matlab arrays transposed
        return out
    try:
        return {k: v for k, v in scipy.io.loadmat(str(path)).items() if not k.startswith("__")}
    except Exception as exc:
        raise RecordError(path, f"cannot read the .mat file ({exc})") from exc


def _mat_array(path: Path, variables: dict[str, Any], name: str) -> np.ndarray:
    if name not in variables:
        raise MissingColumnError(
            path, f"no such variable; the file has variables {sorted(variables)}", column=name
        )
    x = np.asarray(variables[name])
    if x.dtype.kind not in "biuf":
        raise RecordError(path, f"is not a real numeric array (dtype {x.dtype})", column=name)
    return x.astype(float)


def _mat_fs(path: Path, variables: dict[str, Any]) -> float | None:
    for name in FS_NAMES:
        if name in variables:
            x = np.asarray(variables[name], dtype=float).reshape(-1)
            if x.size == 0 or not np.all(x == x[0]):
                raise SamplingRateError(
                    path, f"the sampling-frequency variable holds {x.tolist()[:5]}", column=name
                )
            return float(x[0])
    return None


def _to_npm(
    path: Path, column: str, x: np.ndarray, N: int, realizations: int
) -> tuple[np.ndarray, str]:
    """(N, P, M) from a vector, a (T, M) array or an (N, P, M) array; checks whole periods."""
    if x.ndim == 3:
        if x.shape[0] != N:
            raise RecordLengthError(
                path,
                f"a 3-D array must be (N, P, M) = samples × periods × realizations; its first "
                f"dimension is {x.shape[0]}, the period is N={N} samples",
                column,
            )
        return x, f"(N, P, M) array {x.shape}"
    if x.ndim == 2 and 1 in x.shape:
        x = x.reshape(-1)
    if x.ndim == 1:
        M = realizations
        T = x.size
        if T % (M * N):
            raise RecordLengthError(
                path,
                f"{T} samples are not a whole number of periods of N={N} samples for M={M} "
                f"realization(s) ({T / (M * N):.4g} periods per realization); check --period "
                "and --realizations, or cut the record to whole periods",
                column,
            )
        P = T // (M * N)
        return x.reshape(M, P, N).transpose(2, 1, 0), f"{M} realization(s) of {P} periods"
    if x.ndim == 2:
        T, M = x.shape
        if T % N:
            raise RecordLengthError(
                path,
                f"a (T, M) = {x.shape} array (samples × realizations): T={T} is not a whole "
                f"number of periods of N={N} samples ({T / N:.4g} periods)",
                column,
            )
        return x.reshape(T // N, N, M).transpose(1, 0, 2), f"(T, M) array {x.shape}"
    raise RecordError(path, f"cannot use a {x.ndim}-D array {x.shape} as a signal", column)


# --- one file, several files ----------------------------------------------------------------


def read_record(
    path: str | Path,
    fmt: str,
    input_col: str,
    output_col: str,
    period: int,
    fs: float | None = None,
    *,
    realizations: int = 1,
    drop_periods: int = 0,
    band: tuple[float, float] | None = None,
) -> LevelRecord:
    """Read one level's periodic record (module docstring for the layouts).

    Args:
        path: the CSV or .mat file.
        fmt: "csv" or "mat".
        input_col, output_col: column (CSV) or variable (MAT) names of input and output.
        period: N, samples per period.
        fs: sampling frequency [Hz]; None: from the file's fs column/variable.
        realizations: M for a record stored as one vector/column (consecutive realizations).
        drop_periods: leading periods of every realization to drop (a start-up transient);
            only when asked, and recorded in the result.
        band: (f_min, f_max) [Hz] to which the excited-line detection is restricted.

    Raises:
        RecordError (ValueError) subclasses, naming the file and the column.
    """
    path = Path(path)
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; choose one of {FORMATS}")
    if period < 4:
        raise ValueError(f"the period must be at least 4 samples; got {period}")
    if realizations < 1:
        raise ValueError(f"realizations must be >= 1; got {realizations}")
    if not path.is_file():
        raise RecordError(path, "no such file")
    notes: list[str] = []
    if fmt == "csv":
        u_raw, y_raw, fs_file = read_csv_signals(path, input_col, output_col)
        fs_origin = "the file's fs column"
    else:
        variables = _mat_variables(path)
        u_raw = _mat_array(path, variables, input_col)
        y_raw = _mat_array(path, variables, output_col)
        fs_file = _mat_fs(path, variables)
        fs_origin = "the file's fs variable"
        for col, x in ((input_col, u_raw), (output_col, y_raw)):
            _check_finite(
                path, col, x.reshape(-1, order="F"), lambda i: f"element {i} (column-major)"
            )
    if fs is not None and fs_file is not None and not math.isclose(fs, fs_file, rel_tol=1e-9):
        raise SamplingRateError(
            path, f"the file says fs = {fs_file:g} Hz but --fs is {fs:g} Hz; drop one"
        )
    fs_used = fs if fs is not None else fs_file
    if fs_used is None:
        raise SamplingRateError(
            path, "no sampling frequency: the file has no fs column/variable; give --fs HZ"
        )
    if not (math.isfinite(fs_used) and fs_used > 0):
        raise SamplingRateError(path, f"the sampling frequency {fs_used} is not positive")
    notes.append(f"fs = {fs_used:g} Hz from " + ("--fs" if fs is not None else fs_origin))
    u, layout = _to_npm(path, input_col, u_raw, period, realizations)
    y, _ = _to_npm(path, output_col, y_raw, period, realizations)
    if u.shape != y.shape:
        raise RecordLengthError(
            path,
            f"input {input_col!r} gives (N, P, M) = {u.shape} but output gives {y.shape}; both "
            "must hold the same periods",
            output_col,
        )
    N, P, M = u.shape
    notes.append(f"{layout}: M={M} realization(s) × P={P} periods × N={N} samples")
    if not 0 <= drop_periods < P:
        raise RecordLengthError(
            path,
            f"--drop-periods {drop_periods} must leave at least one of the {P} periods",
            input_col,
        )
    try:
        lines = detect_excited_lines(u[:, drop_periods:, :], fs_used, band)
    except ValueError as exc:
        raise RecordError(path, str(exc), input_col) from exc
    data = PeriodicData(u, y, fs_used, lines)
    if drop_periods:
        data = data.drop_leading(drop_periods)
        notes.append(f"dropped the first {drop_periods} period(s) of every realization (asked)")
    df = fs_used / N
    notes.append(
        f"{lines.size} excited lines detected in the input, {lines[0] * df:g} … "
        f"{lines[-1] * df:g} Hz"
    )
    name = level_name(path)
    return LevelRecord(
        name,
        data,
        key=name,
        path=path,
        periods_in_file=P,
        dropped_periods=drop_periods,
        notes=tuple(notes),
    )


def find_files(source: str | Path, fmt: str, patterns: Sequence[str] | None = None) -> list[Path]:
    """The files of a level set: a file itself, or a directory's files matching the patterns
    (glob, default ``*.csv`` / ``*.mat``), sorted by name."""
    source = Path(source)
    if source.is_file():
        if patterns:
            raise ValueError("--levels selects files in a directory; the source is one file")
        return [source]
    if not source.is_dir():
        raise ValueError(f"{source} is neither a file nor a directory")
    pats = list(patterns) if patterns else [f"*.{fmt}"]
    files = sorted({p for pat in pats for p in source.glob(pat) if p.is_file()})
    if not files:
        present = sorted(p.name for p in source.iterdir() if p.is_file())
        raise ValueError(f"no file in {source} matches {pats}; the directory holds {present[:20]}")
    return files


def read_records(
    source: str | Path,
    fmt: str,
    input_col: str,
    output_col: str,
    period: int,
    fs: float | None = None,
    *,
    patterns: Sequence[str] | None = None,
    realizations: int = 1,
    drop_periods: int = 0,
    band: tuple[float, float] | None = None,
) -> list[LevelRecord]:
    """Read every level of a file or directory (`find_files`, `read_record`).

    Raises:
        RecordError: as `read_record`; SamplingRateError when files disagree on fs;
        ValueError when two files give the same level name or the periods differ.
    """
    files = find_files(source, fmt, patterns)
    records = [
        read_record(
            f,
            fmt,
            input_col,
            output_col,
            period,
            fs,
            realizations=realizations,
            drop_periods=drop_periods,
            band=band,
        )
        for f in files
    ]
    first, first_file = records[0], files[0]
    for rec, file in zip(records[1:], files[1:], strict=True):
        if not math.isclose(rec.periods.fs, first.periods.fs, rel_tol=1e-9):
            raise SamplingRateError(
                file,
                f"fs = {rec.periods.fs:g} Hz, but {first_file.name} has {first.periods.fs:g} Hz; "
                "all levels must share one sampling frequency",
            )
    names: dict[str, Path] = {}
    for rec, file in zip(records, files, strict=True):
        if rec.name in names:
            raise ValueError(
                f"{names[rec.name].name} and {file.name} both give level {rec.name!r}; "
                "select one with --levels"
            )
        names[rec.name] = file
    return records


def records_dataset(records: Sequence[LevelRecord], source: str = "") -> Dataset:
    """The CSV/MAT source: level records as a `Dataset`, lowest input RMS first, with the
    reading account as its data quality (the reader refuses what it cannot read whole, so a
    dataset of records is clean) and a warning per level whose first periods look transient
    (`periodic_data.transient_periods`: reported, nothing dropped unless asked)."""
    levels = sorted(records, key=lambda r: r.input_rms)
    warnings = []
    for rec in levels:
        assert rec.data is not None
        hint = transient_periods(rec.data) if rec.data.P >= 3 else 0
        if hint:
            warnings.append(
                f"level {rec.name}: the first {hint} kept period(s) differ from the last ones by "
                "more than twice the noise (a transient, or slow drift); nothing dropped: use "
                "--drop-periods K to drop leading periods"
            )
    quality = {
        "clean": True,
        "records": [
            {
                "level": rec.name,
                "file": str(rec.path),
                "samples": int(rec.data.u.size) if rec.data is not None else 0,
                "periods_in_file": rec.periods_in_file,
                "realizations": rec.data.M if rec.data is not None else 0,
                "dropped_periods": rec.dropped_periods,
            }
            for rec in levels
        ],
    }
    first = levels[0].data
    assert first is not None
    return Dataset(
        first.fs,
        list(levels),
        quality=quality,
        warnings=warnings,
        source=source or ", ".join(str(r.path) for r in levels),
    )
