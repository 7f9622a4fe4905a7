"""Periodic multisine excitation (Pintelon & Schoukens, *System Identification: A Frequency
Domain Approach*, 2nd ed., Wiley 2012, ch. 2–3; the paper's eq. (4)).

One period of N samples at fs holds

    u[n] = offset + Σ_{k ∈ excited_lines} a_k cos(2π k n / N + φ_k),   n = 0 … N−1,

so every excited line k is DFT bin k of the period (frequency k·fs/N): no leakage, and the
lines that are not excited stay empty up to rounding. The *odd random-phase* multisine excites
odd bins only (even nonlinearities then show at even bins) and leaves one odd bin out at random
in every group of `group_size` odd bins (the *detection lines*, where odd nonlinearities show);
P&S 2012 §3.4. Phases are uniform in [0, 2π).

The standard deviation of one period is √(Σ a_k²/2) exactly (Parseval; 0 < k < N/2), which is
how the amplitudes are scaled to `std_deg`.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = [
    "ExcitationError",
    "LineGrid",
    "LineKind",
    "Multisine",
    "design_line_grid",
    "odd_random_phase_multisine",
    "random_phase_multisine",
]

LineKind = Literal["odd_random", "odd", "even", "full"]
LINE_KINDS: tuple[str, ...] = ("odd_random", "odd", "even", "full")


class ExcitationError(ValueError):
    """An excitation that cannot be built as asked (the message says what to change)."""


def _frozen_array(values: object, dtype: type) -> np.ndarray:
    array: np.ndarray = np.array(values, dtype=dtype)
    array.setflags(write=False)
    return array


def _check_rate_and_length(fs: float, N: int) -> None:
    if not (isinstance(fs, int | float) and math.isfinite(fs) and fs > 0.0):
        raise ExcitationError(f"sampling rate fs must be a positive number of Hz, got {fs!r}")
    if isinstance(N, bool) or not isinstance(N, int | np.integer) or N < 4:
        raise ExcitationError(f"samples per period N must be an integer >= 4, got {N!r}")


def crest_factor(signal: np.ndarray) -> float:
    """max |x − mean| / std of a (n,) signal (a period, or a whole record) [Pintelon2012 §3.2]."""
    x = np.asarray(signal, dtype=float)
    if x.ndim != 1 or x.size < 2:
        raise ExcitationError(f"crest_factor needs a 1-D signal of >= 2 samples, got {x.shape}")
    centred = x - x.mean()
    std = float(np.sqrt(np.mean(centred**2)))
    if std == 0.0:
        raise ExcitationError("crest_factor of a constant signal is undefined")
    return float(np.max(np.abs(centred)) / std)


@dataclass(frozen=True, eq=False)
class LineGrid:
    """Which DFT bins of an N-sample period at fs are excited, and which are left out.

    excited_lines: (F,) int, increasing, 0 < k < N/2.
    detection_lines: (D,) int, odd bins inside the band left out on purpose (odd_random only).
    """

    fs: float
    N: int
    excited_lines: np.ndarray
    detection_lines: np.ndarray
    kind: LineKind
    group_size: int
    seed: int | None

    @property
    def resolution_hz(self) -> float:
        return self.fs / self.N

    @property
    def frequencies_hz(self) -> np.ndarray:
        """(F,) frequencies of the excited lines."""
        return self.excited_lines * self.resolution_hz


def design_line_grid(
    fs: float,
    N: int,
    f_min_hz: float,
    f_max_hz: float,
    kind: LineKind = "odd_random",
    group_size: int = 4,
    seed: int | None = None,
) -> LineGrid:
    """Excited and detection lines of a multisine in the band [f_min_hz, f_max_hz].

    kind:
        "odd_random": odd bins; the odd bins are split into consecutive groups of `group_size`
            from the lowest up and one bin of every complete group, drawn at random, is left
            out as a detection line (an incomplete last group is excited in full);
        "odd": all odd bins; "even": all even bins; "full": all bins in the band.
    seed: draws the detection lines (odd_random only).

    Raises ExcitationError when the band is empty on the grid, reaches fs/2, or is inverted.
    """
    _check_rate_and_length(fs, N)
    if kind not in LINE_KINDS:
        raise ExcitationError(f"line kind must be one of {LINE_KINDS}, got {kind!r}")
    if not (math.isfinite(f_min_hz) and math.isfinite(f_max_hz) and 0.0 < f_min_hz <= f_max_hz):
        raise ExcitationError(
            f"band must satisfy 0 < f_min_hz <= f_max_hz, got [{f_min_hz}, {f_max_hz}] Hz"
        )
    if f_max_hz >= fs / 2.0:
        raise ExcitationError(
            f"band edge f_max_hz = {f_max_hz} Hz is at or above fs/2 = {fs / 2.0} Hz: it would "
            f"alias; lower f_max_hz or raise fs"
        )
    if kind == "odd_random" and (isinstance(group_size, bool) or group_size < 2):
        raise ExcitationError(f"group_size must be an integer >= 2, got {group_size!r}")
    resolution = fs / N
    # Bins whose frequency lies in the band, with a little slack for decimal band edges.
    k_lo = math.ceil(f_min_hz / resolution - 1e-9)
    k_hi = math.floor(f_max_hz / resolution + 1e-9)
    k_hi = min(k_hi, (N - 1) // 2)  # strictly below Nyquist
    bins = np.arange(max(k_lo, 1), k_hi + 1)
    if kind in ("odd_random", "odd"):
        bins = bins[bins % 2 == 1]
    elif kind == "even":
        bins = bins[bins % 2 == 0]
    if bins.size == 0:
        raise ExcitationError(
            f"no {kind} DFT line falls in [{f_min_hz}, {f_max_hz}] Hz with resolution "
            f"fs/N = {resolution:g} Hz; widen the band or increase N"
        )
    detection = np.empty(0, dtype=np.int64)
    if kind == "odd_random":
        rng = np.random.default_rng(seed)
        n_groups = bins.size // group_size
        picks = rng.integers(0, group_size, size=n_groups)
        detection = bins[np.arange(n_groups) * group_size + picks]
        bins = np.setdiff1d(bins, detection)
    return LineGrid(
        fs=float(fs),
        N=int(N),
        excited_lines=_frozen_array(bins, np.int64),
        detection_lines=_frozen_array(detection, np.int64),
        kind=kind,
        group_size=int(group_size),
        seed=seed,
    )


@dataclass(frozen=True, eq=False)
class Multisine:
    """One realization of a periodic multisine, in degrees of pitch.

    Attributes:
        fs: sampling rate [Hz]; N: samples per period (resolution fs/N).
        excited_lines: (F,) int DFT bins, increasing, 0 < k < N/2.
        detection_lines: (D,) int bins left out on purpose (empty unless odd_random).
        amplitudes: (F,) cosine amplitudes a_k [deg], > 0.
        phases: (F,) φ_k [rad].
        offset_deg: mean of the period; std_deg: its standard deviation √(Σa²/2).
        seed: seed the phases were drawn from (None when not random, e.g. after crest-factor
            reduction, which keeps the seed of the phases it started from).
        kind: line kind of the grid ("odd_random", "odd", "even", "full").
    """

    fs: float
    N: int
    excited_lines: np.ndarray
    detection_lines: np.ndarray
    amplitudes: np.ndarray
    phases: np.ndarray
    offset_deg: float
    std_deg: float
    seed: int | None = None
    kind: LineKind = "odd_random"

    def __post_init__(self) -> None:
        _check_rate_and_length(self.fs, self.N)
        lines = np.asarray(self.excited_lines)
        if lines.ndim != 1 or lines.size == 0 or not np.issubdtype(lines.dtype, np.integer):
            raise ExcitationError("excited_lines must be a non-empty 1-D array of integer bins")
        if np.any(np.diff(lines) <= 0):
            raise ExcitationError("excited_lines must be strictly increasing")
        if lines[0] < 1 or 2 * lines[-1] >= self.N:
            raise ExcitationError(
                f"excited lines must satisfy 0 < k < N/2 = {self.N / 2:g} (below fs/2); got "
                f"bins {lines[0]}…{lines[-1]}, i.e. up to {lines[-1] * self.fs / self.N:g} Hz"
            )
        detection = np.asarray(self.detection_lines)
        if detection.ndim != 1 or (detection.size and np.intersect1d(detection, lines).size):
            raise ExcitationError("detection_lines must be 1-D and disjoint from excited_lines")
        amplitudes = np.asarray(self.amplitudes, dtype=float)
        phases = np.asarray(self.phases, dtype=float)
        if amplitudes.shape != lines.shape or phases.shape != lines.shape:
            raise ExcitationError(
                f"amplitudes {amplitudes.shape} and phases {phases.shape} must have the shape "
                f"of excited_lines {lines.shape}"
            )
        if not (np.all(np.isfinite(amplitudes)) and np.all(amplitudes > 0.0)):
            raise ExcitationError("amplitudes must be finite and > 0 (drop a line instead of 0)")
        if not np.all(np.isfinite(phases)):
            raise ExcitationError("phases must be finite")
        if not math.isfinite(self.offset_deg):
            raise ExcitationError(f"offset_deg must be finite, got {self.offset_deg!r}")
        std = math.sqrt(float(np.sum(amplitudes**2)) / 2.0)
        if not math.isclose(std, self.std_deg, rel_tol=1e-9):
            raise ExcitationError(
                f"std_deg {self.std_deg} disagrees with the amplitudes (√(Σa²/2) = {std})"
            )
        if self.kind not in LINE_KINDS:
            raise ExcitationError(f"kind must be one of {LINE_KINDS}, got {self.kind!r}")
        for name, value, dtype in (
            ("excited_lines", lines, np.int64),
            ("detection_lines", detection, np.int64),
            ("amplitudes", amplitudes, float),
            ("phases", phases, float),
        ):
            object.__setattr__(self, name, _frozen_array(value, dtype))

    @property
    def resolution_hz(self) -> float:
        return self.fs / self.N

    @property
    def period_s(self) -> float:
        return self.N / self.fs

    @property
    def frequencies_hz(self) -> np.ndarray:
        """(F,) frequencies of the excited lines."""
        return self.excited_lines * self.resolution_hz

    def spectrum(self) -> np.ndarray:
        """(N//2 + 1,) one-sided DFT of one period without offset (numpy.fft.rfft scaling):
        X[k] = (N/2) a_k e^{jφ_k} at excited lines, 0 elsewhere."""
        X = np.zeros(self.N // 2 + 1, dtype=complex)
        X[self.excited_lines] = 0.5 * self.N * self.amplitudes * np.exp(1j * self.phases)
        return X

    def period(self) -> np.ndarray:
        """(N,) one period in degrees, sample n at time n/fs."""
        return self.offset_deg + np.fft.irfft(self.spectrum(), n=self.N)

    def crest_factor(self) -> float:
        """`crest_factor` of one period (P&S 2012 §3.2)."""
        return crest_factor(self.period())

    def with_phases(self, phases: np.ndarray, seed: int | None = None) -> "Multisine":
        """Same lines, amplitudes, offset and std with other phases (F,) [rad]."""
        return Multisine(
            fs=self.fs,
            N=self.N,
            excited_lines=self.excited_lines,
            detection_lines=self.detection_lines,
            amplitudes=self.amplitudes,
            phases=np.mod(np.asarray(phases, dtype=float), 2.0 * np.pi),
            offset_deg=self.offset_deg,
            std_deg=self.std_deg,
            seed=seed,
            kind=self.kind,
        )


AmplitudeSpectrum = np.ndarray | Callable[[np.ndarray], np.ndarray] | None


def _relative_amplitudes(grid: LineGrid, relative_amplitudes: AmplitudeSpectrum) -> np.ndarray:
    F = grid.excited_lines.size
    if relative_amplitudes is None:
        return np.ones(F)
    if callable(relative_amplitudes):
        values = np.asarray(relative_amplitudes(grid.frequencies_hz), dtype=float)
    else:
        values = np.asarray(relative_amplitudes, dtype=float)
    if values.shape != (F,):
        raise ExcitationError(
            f"relative amplitudes must have one value per excited line, shape ({F},), got "
            f"{values.shape}; pass a function of frequency to avoid counting lines"
        )
    if not (np.all(np.isfinite(values)) and np.all(values > 0.0)):
        raise ExcitationError("relative amplitudes must be finite and > 0 at every excited line")
    return values


def random_phases(seed: int | None, lines: int) -> np.ndarray:
    """The phases of a random-phase realization: ``lines`` values uniform in [0, 2π) drawn
    with ``seed`` (random_phase_multisine's draw; an adaptive run's added realization,
    revision.py, repeats it)."""
    return np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, size=lines)


def random_phase_multisine(
    grid: LineGrid,
    std_deg: float,
    offset_deg: float = 0.0,
    seed: int | None = None,
    relative_amplitudes: AmplitudeSpectrum = None,
) -> Multisine:
    """A random-phase multisine on `grid`: phases uniform in [0, 2π) drawn with `seed`,
    amplitude spectrum flat (or `relative_amplitudes`: (F,) array or function of frequency in
    Hz → (F,)), scaled so that one period has standard deviation `std_deg` around
    `offset_deg`. Realizations on one grid with different seeds differ only in their phases.
    """
    if not (math.isfinite(std_deg) and std_deg > 0.0):
        raise ExcitationError(f"std_deg must be > 0, got {std_deg!r}")
    shape = _relative_amplitudes(grid, relative_amplitudes)
    amplitudes = shape * (std_deg / math.sqrt(float(np.sum(shape**2)) / 2.0))
    phases = random_phases(seed, shape.size)
    return Multisine(
        fs=grid.fs,
        N=grid.N,
        excited_lines=grid.excited_lines,
        detection_lines=grid.detection_lines,
        amplitudes=amplitudes,
        phases=phases,
        offset_deg=float(offset_deg),
        std_deg=math.sqrt(float(np.sum(amplitudes**2)) / 2.0),
        seed=seed,
        kind=grid.kind,
    )


def odd_random_phase_multisine(
    fs: float,
    N: int,
    f_min_hz: float,
    f_max_hz: float,
    std_deg: float,
    offset_deg: float = 0.0,
    group_size: int = 4,
    seed: int | None = None,
    relative_amplitudes: AmplitudeSpectrum = None,
) -> Multisine:
    """One odd random-phase multisine in one call (lines and phases both drawn from `seed`).
    For several realizations on the same lines, use `design_line_grid` once and
    `random_phase_multisine` per realization."""
    lines_seed, phases_seed = np.random.SeedSequence(seed).spawn(2)
    grid = design_line_grid(
        fs, N, f_min_hz, f_max_hz, "odd_random", group_size, int(lines_seed.generate_state(1)[0])
    )
    return random_phase_multisine(
        grid,
        std_deg,
        offset_deg,
        int(phases_seed.generate_state(1)[0]),
        relative_amplitudes,
    )
