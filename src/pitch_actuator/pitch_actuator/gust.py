"""Free-stream gust on the angle of attack: an Ornstein–Uhlenbeck process (docs/design.md §6).

dα_g = −α_g/τ dt + σ √(2/τ) dW has variance σ² and autocorrelation e^{−|lag|/τ}. Sampled at
dt it is exactly the AR(1) recursion (Gillespie, Phys. Rev. E 54, 2084, 1996)

    x_{k+1} = e^{−dt/τ} x_k + σ √(1 − e^{−2dt/τ}) w_k,   w_k ~ N(0, 1),

started from the stationary distribution x_0 = σ w_0, so every sample has std σ.
"""

import math

import numpy as np

__all__ = ["FreeStreamGust"]

_BLOCK = 4096  # normals drawn per refill; step() and sample() share the stream


class FreeStreamGust:
    """Seeded OU gust sampled at fs, in degrees.

    Args:
        std_deg: stationary standard deviation σ (0 disables the gust).
        time_constant_s: correlation time τ.
        fs: sampling rate in Hz (dt = 1/fs).
        seed: int or numpy SeedSequence; same seed → same gust.

    `step()` and `sample(n)` draw from one stream: n calls of `step()` equal one `sample(n)`.
    """

    def __init__(
        self,
        std_deg: float = 0.2,
        time_constant_s: float = 0.1,
        fs: float = 200.0,
        seed: int | np.random.SeedSequence | None = 0,
    ) -> None:
        if not (math.isfinite(std_deg) and std_deg >= 0.0):
            raise ValueError(f"FreeStreamGust: std_deg must be >= 0, got {std_deg!r}")
        if not (math.isfinite(time_constant_s) and time_constant_s > 0.0):
            raise ValueError(
                f"FreeStreamGust: time_constant_s must be > 0, got {time_constant_s!r}"
            )
        if not (math.isfinite(fs) and fs > 0.0):
            raise ValueError(f"FreeStreamGust: fs must be > 0, got {fs!r}")
        self.std_deg = float(std_deg)
        self.time_constant_s = float(time_constant_s)
        self.fs = float(fs)
        self._rng = np.random.default_rng(seed)
        self._normals = np.empty(0)
        self._next = 0
        # Exact AR(1) coefficients of the sampled OU process (module docstring).
        self.decay = math.exp(-1.0 / (self.fs * self.time_constant_s))
        self.innovation_std_deg = self.std_deg * math.sqrt(1.0 - self.decay**2)
        self._x = self.std_deg * self._draw()

    def _draw(self) -> float:
        if self._next >= self._normals.size:
            self._normals = self._rng.standard_normal(_BLOCK)
            self._next = 0
        w = float(self._normals[self._next])
        self._next += 1
        return w

    @property
    def value_deg(self) -> float:
        """The current gust sample (the one the next `step()` returns)."""
        return self._x

    def step(self) -> float:
        """Return the current gust (degrees) and advance one sample."""
        x = self._x
        self._x = self.decay * x + self.innovation_std_deg * self._draw()
        return x

    def sample(self, n: int) -> np.ndarray:
        """The next n gust samples, shape (n,), degrees."""
        if n < 0:
            raise ValueError(f"FreeStreamGust.sample: n must be >= 0, got {n}")
        out = np.empty(n)
        a, b = self.decay, self.innovation_std_deg
        x = self._x
        for k in range(n):
            out[k] = x
            x = a * x + b * self._draw()
        self._x = x
        return out
