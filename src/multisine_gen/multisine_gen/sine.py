"""Single-sine validation excitation on the sample grid.

A sine used for validation must be periodic on the sample grid, so that periods can be cut and
averaged exactly like multisine periods: its period holds a whole number of samples,
samples_per_period = fs / f. A requested frequency that does not fit is either moved to the
nearest frequency that fits (`on_mismatch="adjust"`, the default; the change is at most
f²/(2 fs), e.g. 0.2 % at 2 Hz and 200 Hz) or refused (`on_mismatch="refuse"`), naming the two
nearest frequencies that fit.

The sine starts at its offset going up, u[n] = offset + A sin(2π n / samples_per_period), so a
ramp that ends at the offset joins it without a jump.
"""

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from multisine_gen.multisine import ExcitationError, crest_factor

__all__ = ["Sine", "design_sine"]


@dataclass(frozen=True)
class Sine:
    """A sine of `samples_per_period` samples per period, in degrees.

    fs [Hz]; frequency_hz = fs / samples_per_period; amplitude_deg; offset_deg;
    requested_frequency_hz: what was asked for (differs when adjusted).
    """

    fs: float
    samples_per_period: int
    amplitude_deg: float
    offset_deg: float
    requested_frequency_hz: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.fs) and self.fs > 0.0):
            raise ExcitationError(f"sine: fs must be > 0 Hz, got {self.fs!r}")
        if isinstance(self.samples_per_period, bool) or not isinstance(
            self.samples_per_period, int | np.integer
        ):
            raise ExcitationError(
                f"sine: samples_per_period must be an integer, got {self.samples_per_period!r}"
            )
        if self.samples_per_period < 3:
            raise ExcitationError(
                f"sine at {self.fs / max(self.samples_per_period, 1):g} Hz is at or above "
                f"fs/2 = {self.fs / 2:g} Hz ({self.samples_per_period} samples per period); "
                f"it would alias: lower the frequency or raise fs"
            )
        if not (math.isfinite(self.amplitude_deg) and self.amplitude_deg > 0.0):
            raise ExcitationError(f"sine: amplitude_deg must be > 0, got {self.amplitude_deg!r}")
        if not math.isfinite(self.offset_deg):
            raise ExcitationError(f"sine: offset_deg must be finite, got {self.offset_deg!r}")
        object.__setattr__(self, "samples_per_period", int(self.samples_per_period))

    @property
    def frequency_hz(self) -> float:
        return self.fs / self.samples_per_period

    @property
    def period_s(self) -> float:
        return self.samples_per_period / self.fs

    def period(self) -> np.ndarray:
        """(samples_per_period,) one period in degrees, starting at the offset going up."""
        n = np.arange(self.samples_per_period)
        return self.offset_deg + self.amplitude_deg * np.sin(
            2.0 * np.pi * n / self.samples_per_period
        )

    def samples(self, periods: int) -> np.ndarray:
        """(periods · samples_per_period,) whole periods in degrees."""
        return np.tile(self.period(), periods)

    def crest_factor(self) -> float:
        """`multisine.crest_factor` of a sampled period (√2 when a sample hits the peak)."""
        return crest_factor(self.period())


def design_sine(
    fs: float,
    frequency_hz: float,
    amplitude_deg: float,
    offset_deg: float = 0.0,
    on_mismatch: Literal["adjust", "refuse"] = "adjust",
) -> Sine:
    """A sine whose period is a whole number of samples at fs (see the module docstring)."""
    if not (math.isfinite(fs) and fs > 0.0):
        raise ExcitationError(f"sine: fs must be > 0 Hz, got {fs!r}")
    if not (math.isfinite(frequency_hz) and frequency_hz > 0.0):
        raise ExcitationError(f"sine: frequency_hz must be > 0, got {frequency_hz!r}")
    if frequency_hz >= fs / 2.0:
        raise ExcitationError(
            f"sine at {frequency_hz:g} Hz is at or above fs/2 = {fs / 2:g} Hz; it would alias"
        )
    if on_mismatch not in ("adjust", "refuse"):
        raise ExcitationError(f"on_mismatch must be 'adjust' or 'refuse', got {on_mismatch!r}")
    exact = fs / frequency_hz
    samples_per_period = round(exact)
    if abs(exact - samples_per_period) > 1e-9 * exact and on_mismatch == "refuse":
        below, above = math.floor(exact), math.ceil(exact)
        raise ExcitationError(
            f"a {frequency_hz:g} Hz sine has {exact:.6g} samples per period at fs = {fs:g} Hz, "
            f"not a whole number; the nearest frequencies that fit are {fs / above:.6g} Hz and "
            f"{fs / below:.6g} Hz (or use on_mismatch='adjust')"
        )
    return Sine(
        fs=float(fs),
        samples_per_period=samples_per_period,
        amplitude_deg=float(amplitude_deg),
        offset_deg=float(offset_deg),
        requested_frequency_hz=float(frequency_hz),
    )
