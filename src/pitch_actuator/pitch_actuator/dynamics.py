"""Simulated pitch actuator (docs/design.md §6).

Closed position loop as a delayed, rate-limited second-order system

    θ̈ = ω_n² (θ_r(t − τ_d) − θ) − 2 ζ ω_n θ̇,   |θ̇| ≤ θ̇_max,

with the command θ_r held over each sample interval (zero-order hold). A sample is integrated
with a fixed internal step h; within a step the reference is constant, so the linear part is
advanced by its exact discretisation (matrix exponential of the augmented system, e.g. Franklin,
Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed., §4.3.3)

    [θ', θ̇'] = E [θ, θ̇] + F θ_r,   E = e^{A h},  F = ∫₀ʰ e^{A s} ds b,

then the rate is clipped to ±θ̇_max and the position increment to θ̇_max h, so the model never
moves faster than the limit. Below the rate limit the model is linear, and
`ActuatorModel.frf` is its exact sampled frequency response (with ZOH and delay): a simulated
sine matches it to numerical precision, and it equals the continuous model's response.

Time convention (reactive plant, docs/design.md §5): `step(command k)` holds command k over
[t_k, t_k + 1/fs) and returns the state at the end of that interval as sample k, which keeps
command k's stamp. The logged pitch is the true pitch plus white noise, quantised to the encoder
step. `alpha_true_rad` adds the free-stream gust (gust.py), which the wing sees but the encoder
does not.
"""

import math
from dataclasses import dataclass, fields

import numpy as np

from pitch_actuator.gust import FreeStreamGust

__all__ = ["ActuatorModel", "ActuatorParams", "ActuatorSample"]

_NOISE_BLOCK = 4096


@dataclass(frozen=True)
class ActuatorParams:
    """Simulated actuator parameters (degrees, Hz and seconds as in parameter files)."""

    natural_frequency_hz: float = 15.0  # ω_n = 2π · 15 rad/s
    damping_ratio: float = 0.7
    delay_s: float = 0.001  # τ_d, rounded to a whole number of internal steps
    max_rate_deg_s: float = 250.0
    internal_step_s: float = 0.0005  # upper bound; shortened so a sample holds whole steps
    noise_std_deg: float = 0.01  # logged-pitch noise
    encoder_step_deg: float = 0.005  # quantisation of the logged pitch (0 = none)
    gust_std_deg: float = 0.2  # free-stream gust on α (0 = none)
    gust_time_constant_s: float = 0.1
    initial_deg: float = 0.0  # pitch at rest, where the model starts

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and math.isfinite(value)):
                raise ValueError(f"ActuatorParams.{f.name} must be a finite number, got {value!r}")
        for name in ("natural_frequency_hz", "damping_ratio", "max_rate_deg_s", "internal_step_s"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"ActuatorParams.{name} must be > 0, got {getattr(self, name)}")
        for name in ("delay_s", "noise_std_deg", "encoder_step_deg", "gust_std_deg"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"ActuatorParams.{name} must be >= 0, got {getattr(self, name)}")
        if self.gust_time_constant_s <= 0.0:
            raise ValueError(
                f"ActuatorParams.gust_time_constant_s must be > 0, got {self.gust_time_constant_s}"
            )


@dataclass(frozen=True, slots=True)
class ActuatorSample:
    """One actuator sample (SI units).

    position_rad: logged pitch (noisy, quantised), what /pitch/state carries.
    velocity_rad_s: pitch rate of the model (noise-free).
    true_position_rad: pitch of the model.
    alpha_true_rad: angle of attack the wing sees: true pitch + free-stream gust.
    """

    position_rad: float
    velocity_rad_s: float
    true_position_rad: float
    alpha_true_rad: float


def _internal_step_map(
    omega_n: float, damping_ratio: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """E (2, 2) and F (2,) of one internal step: e^{M h} of the augmented matrix
    M = [[A, b], [0, 0]] (Van Loan's trick) by scaling and squaring of a Taylor series."""
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 0] = -(omega_n**2)
    M[1, 1] = -2.0 * damping_ratio * omega_n
    M[1, 2] = omega_n**2
    Mh = M * h
    squarings = max(0, math.ceil(math.log2(max(np.abs(Mh).sum(axis=1).max(), 1e-300) / 0.1)))
    X = Mh / 2.0**squarings
    expX = np.eye(3)
    term = np.eye(3)
    for order in range(1, 20):
        term = term @ X / order
        expX = expX + term
    for _ in range(squarings):
        expX = expX @ expX
    return expX[:2, :2].copy(), expX[:2, 2].copy()


class ActuatorModel:
    """Simulated actuator stepped once per command sample.

    Args:
        params: model parameters (defaults of docs/design.md §6 when None).
        fs: command/sample rate in Hz.
        seed: seeds the encoder noise and the gust (independent streams).
    """

    def __init__(self, params: ActuatorParams | None = None, fs: float = 200.0, seed: int = 0):
        self.params = params if params is not None else ActuatorParams()
        if not (math.isfinite(fs) and fs > 0.0):
            raise ValueError(f"ActuatorModel: fs must be > 0 Hz, got {fs!r}")
        p = self.params
        self.fs = float(fs)
        ratio = 1.0 / (self.fs * p.internal_step_s)
        self.substeps = max(1, math.ceil(ratio - 1e-9))
        self.h = 1.0 / (self.fs * self.substeps)  # internal step actually used
        self.delay_steps = round(p.delay_s / self.h)  # delay actually used: delay_steps · h
        self.omega_n = 2.0 * math.pi * p.natural_frequency_hz
        self.max_rate_rad_s = math.radians(p.max_rate_deg_s)
        self._E, self._F = _internal_step_map(self.omega_n, p.damping_ratio, self.h)
        # Plain floats: numpy scalars would make the per-step loop several times slower.
        self._step_coefficients = (*map(float, self._E.ravel()), *map(float, self._F))
        # Reference seen at internal step i of sample k is command k − lag[i] (ZOH + delay).
        self._lags = [-((i - self.delay_steps) // self.substeps) for i in range(self.substeps)]
        self._history = [math.radians(p.initial_deg)] * (max(self._lags) + 1)
        self._theta = math.radians(p.initial_deg)
        self._rate = 0.0
        noise_seed, gust_seed = np.random.SeedSequence(seed).spawn(2)
        self._noise_rng = np.random.default_rng(noise_seed)
        self._noise = np.empty(0)
        self._noise_next = 0
        self._noise_std_rad = math.radians(p.noise_std_deg)
        self._encoder_step_rad = math.radians(p.encoder_step_deg)
        self.gust = FreeStreamGust(p.gust_std_deg, p.gust_time_constant_s, self.fs, gust_seed)

    @property
    def true_position_rad(self) -> float:
        return self._theta

    @property
    def velocity_rad_s(self) -> float:
        return self._rate

    def step(self, command_rad: float) -> ActuatorSample:
        """Hold command_rad over one sample interval; return the sample at its end."""
        command = float(command_rad)
        if not math.isfinite(command):
            raise ValueError(
                f"ActuatorModel.step: command must be finite, got {command_rad!r}; "
                f"pass commands through SafetyGovernor, which refuses them"
            )
        history = self._history
        history.insert(0, command)
        history.pop()
        e11, e12, e21, e22, f1, f2 = self._step_coefficients
        vmax = self.max_rate_rad_s
        dmax = vmax * self.h
        theta, rate = self._theta, self._rate
        for lag in self._lags:
            r = history[lag]
            new_theta = e11 * theta + e12 * rate + f1 * r
            rate = e21 * theta + e22 * rate + f2 * r
            if rate > vmax:
                rate = vmax
            elif rate < -vmax:
                rate = -vmax
            # Never move faster than the rate limit, even within an unclipped step.
            if new_theta > theta + dmax:
                new_theta = theta + dmax
            elif new_theta < theta - dmax:
                new_theta = theta - dmax
            theta = new_theta
        self._theta, self._rate = theta, rate
        if self._noise_next >= self._noise.size:
            self._noise = self._noise_rng.standard_normal(_NOISE_BLOCK)
            self._noise_next = 0
        measured = theta + self._noise_std_rad * float(self._noise[self._noise_next])
        self._noise_next += 1
        q = self._encoder_step_rad
        if q > 0.0:
            measured = round(measured / q) * q
        alpha = theta + math.radians(self.gust.step())
        return ActuatorSample(measured, rate, theta, alpha)

    def frf(self, freq_hz: float | np.ndarray) -> np.ndarray:
        """Frequency response of the loop as simulated (ZOH, delay, internal steps), rate limit
        inactive: ratio of the true pitch sample k to the command sample k for a sampled
        sinusoid in steady state. freq_hz: scalar or any shape; returns complex, same shape.

        Per internal step x ← E x + F r with x = [θ, θ̇]; over one sample
        x_{k+1} = Φ x_k + Σ_q Γ_q r_{k−q} and sample k is θ(t_{k+1}) = c x_{k+1}, hence
        G(z) = z c (zI − Φ)⁻¹ Σ_q Γ_q z^{−q} at z = e^{j2πf/fs}.
        """
        f = np.asarray(freq_hz, dtype=float)
        A_h, b_h = self._E, self._F
        n = self.substeps
        Phi = np.linalg.matrix_power(A_h, n)
        gammas: dict[int, np.ndarray] = {}
        for i, lag in enumerate(self._lags):
            term = np.linalg.matrix_power(A_h, n - 1 - i) @ b_h
            gammas[lag] = gammas.get(lag, np.zeros(2)) + term
        z = np.exp(2j * np.pi * f.ravel() / self.fs)
        out = np.empty(z.shape, dtype=complex)
        eye = np.eye(2)
        for idx, zk in enumerate(z):
            drive = sum(g * zk ** (-lag) for lag, g in gammas.items())
            x = np.linalg.solve(zk * eye - Phi, drive)
            out[idx] = zk * x[0]
        return out.reshape(f.shape)
