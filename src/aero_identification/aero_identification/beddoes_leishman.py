"""The semi-empirical baseline: a Beddoes–Leishman dynamic-stall model in the state-space form
of Hansen, Gaunaa & Madsen [HGM], calibrated as practitioners do: the static lift curve and
its separation function from the run's quasi-static sweep (Kirchhoff inversion), the time
constants fitted on the multisine estimation data.

References
    [HGM] Hansen, Gaunaa & Madsen, "A Beddoes–Leishman type dynamic stall model in state-space
          and indicial formulations", Risø-R-1354 (2004), §2.
    [LB]  Leishman & Beddoes, "A semi-empirical model for dynamic stall", J. Am. Helicopter Soc.
          34(3), 1989 (the Kirchhoff lift).

States, for the measured pitch angle α (time unit T_u = c/2U, fitted in seconds since the
identification knows neither chord nor speed):
    x1, x2  Wagner lags T_u/b_i towards A_i α_q, α_q = α + t_d α̇ (t_d: the 3/4-chord
            downwash, fitted; it needs the pivot and U);
            α_E = α_q (1 − A1 − A2) + x1 + x2                              [HGM eq. 9–10]
    x3      pressure lag T_p of C_l^p = C_lα (α_E − α0) + π T_u α̇;
            α_F = x3 / C_lα + α0                                           [HGM eq. 13–14]
    x4      separation point, lag T_f towards f^st(α_F)                   [HGM eq. 15]
Lift [HGM §2]:
    C_l = C_lα (α_E − α0) x4 + C_l^fs(α_E) (1 − x4) + π T_u α̇.
Static curves [HGM §2], from the static lift C_l^st(α) = C_lα (α − α0) K(f^st),
K(f) = ((1 + √f)/2)² [LB]:
    f^st = (2 √(C_l^st / (C_lα (α − α0))) − 1)², clipped to [0, 1];
    C_l^fs = (C_l^st − C_lα (α − α0) f^st) / (1 − f^st)   (C_l^st / 2 where f^st → 1).
A1 = 0.165, A2 = 0.335, b1 = 0.0455, b2 = 0.3: the flat-plate Wagner approximation [HGM §2].

Each lag is sampled with the exact exponential update x ← a x + (1 − a) target, a = e^{−h/T},
the target held over the sample (a first-order filter, scipy.signal.lfilter). The model never
reads a level's name or offset: one model of α for the whole campaign.
"""

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from .dataset import QuasiStaticSweep
from .periodic_data import PeriodicData

__all__ = [
    "BeddoesLeishman",
    "StaticLift",
    "fit_beddoes_leishman",
    "static_lift",
]

A1, A2, B1, B2 = 0.165, 0.335, 0.0455, 0.3  # [HGM §2]
STATIC_BIN_DEG = 0.25  # the static curve: mean C_l of both sweep branches per α bin
F_ATTACHED = 0.98  # above this f^st, C_l^fs is taken as C_l^st / 2 (the limit f^st → 1)
# The time constants' bounds [s] (log-parametrised fit) and the starts tried.
T_BOUNDS_S = (1e-4, 20.0)
DOWNWASH_BOUND_S = 0.2
STARTS_TU_S = (0.005, 0.03, 0.15)


@dataclass(frozen=True)
class StaticLift:
    """The static curves of the sweep (`static_lift`), on an α grid [deg] ascending."""

    alpha_deg: np.ndarray
    cl: np.ndarray  # the static lift C_l^st
    f: np.ndarray  # the separation function f^st (Kirchhoff inversion)
    cl_fs: np.ndarray  # the fully separated lift C_l^fs
    slope_per_deg: float  # C_lα
    alpha0_deg: float  # the zero-lift angle
    attached_range_deg: tuple[float, float]  # where the line C_lα (α − α0) was fitted

    def f_of(self, alpha_deg: np.ndarray) -> np.ndarray:
        """f^st at α: 1 below the sweep (attached flow), its last value above it."""
        return np.interp(alpha_deg, self.alpha_deg, self.f, left=1.0, right=float(self.f[-1]))

    def cl_fs_of(self, alpha_deg: np.ndarray) -> np.ndarray:
        """C_l^fs at α: below the sweep half the attached line, above it its last value."""
        alpha_deg = np.asarray(alpha_deg, dtype=float)
        below = 0.5 * self.slope_per_deg * (alpha_deg - self.alpha0_deg)
        inside = np.interp(alpha_deg, self.alpha_deg, self.cl_fs, right=float(self.cl_fs[-1]))
        return np.where(alpha_deg < self.alpha_deg[0], below, inside)

    def to_dict(self) -> dict[str, Any]:
        return {
            "alpha_deg": self.alpha_deg.tolist(),
            "cl": self.cl.tolist(),
            "f": self.f.tolist(),
            "cl_fs": self.cl_fs.tolist(),
            "slope_per_deg": self.slope_per_deg,
            "alpha0_deg": self.alpha0_deg,
            "attached_range_deg": list(self.attached_range_deg),
        }


def static_lift(sweep: QuasiStaticSweep, bin_deg: float = STATIC_BIN_DEG) -> StaticLift:
    """The static lift curve of a quasi-static sweep and its Kirchhoff inversion.

    The curve is the mean C_l of both branches per α bin (`QuasiStaticSweep.static_curve`).
    The attached line C_lα (α − α0) is the least-squares line over the lower half of the angles
    from the sweep's lowest to the angle of maximum lift; f^st and C_l^fs follow [HGM §2].

    Raises:
        ValueError: a sweep too short for the line (fewer than 4 bins below the maximum lift)
            or whose line does not rise.
    """
    alpha, cl = sweep.static_curve(bin_deg)
    if alpha.size < 8:
        raise ValueError(f"the quasi-static sweep covers {alpha.size} bins of {bin_deg}°: too few")
    peak = float(alpha[int(np.argmax(cl))])
    top = alpha[0] + 0.5 * (peak - alpha[0])
    line = alpha <= top
    if np.sum(line) < 4:
        raise ValueError(
            f"the quasi-static sweep has too few angles below its maximum lift ({peak:.1f}°) for "
            "the attached lift slope"
        )
    slope, intercept = np.polyfit(alpha[line], cl[line], 1)
    if not slope > 0:
        raise ValueError(f"the quasi-static sweep's lift slope is {slope:.3g}/°, not positive")
    alpha0 = -intercept / slope
    attached = slope * (alpha - alpha0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.abs(attached) > 1e-9, cl / attached, 1.0)
    root = np.clip(2.0 * np.sqrt(np.clip(ratio, 0.0, None)) - 1.0, 0.0, 1.0)
    f = np.where(alpha <= top, 1.0, root**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        cl_fs = np.where(f < F_ATTACHED, (cl - attached * f) / (1.0 - f), 0.5 * cl)
    return StaticLift(
        alpha, cl, f, cl_fs, float(slope), float(alpha0), (float(alpha[0]), float(top))
    )


@dataclass
class BeddoesLeishman:
    """The HGM model (module docstring) at a sample rate: ``simulate(u)`` maps α [deg] to C_l.

    Attributes:
        static: the static curves.
        fs: sampling frequency [Hz].
        t_u_s, t_p_s, t_f_s: the time unit c/2U and the pressure and separation lags [s].
        downwash_s: t_d, α_q = α + t_d α̇.
        history_: the fit's record (cost, starts, held-out error), for the report.
    """

    static: StaticLift
    fs: float
    t_u_s: float = 0.02
    t_p_s: float = 0.03
    t_f_s: float = 0.12
    downwash_s: float = 0.0
    history_: dict[str, Any] = field(default_factory=dict)

    @property
    def parameters(self) -> np.ndarray:
        return np.array([self.t_u_s, self.t_p_s, self.t_f_s, self.downwash_s])

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """C_l for the α record ``u`` [deg], started at rest at its first sample (every state
        at its static value there)."""
        alpha = np.asarray(u, dtype=float).reshape(-1)
        if alpha.size < 2:
            raise ValueError("the Beddoes–Leishman simulation needs at least 2 samples")
        h = 1.0 / self.fs
        rate = np.gradient(alpha, h)  # α̇ [deg/s]
        alpha_q = alpha + self.downwash_s * rate
        a_e = alpha_q * (1.0 - A1 - A2)
        for amp, b in ((A1, B1), (A2, B2)):
            a_e = a_e + _lag(amp * alpha_q, self.t_u_s / b, h)
        st = self.static
        non_circulatory = math.pi * self.t_u_s * np.radians(rate)
        cl_p = st.slope_per_deg * (a_e - st.alpha0_deg) + non_circulatory
        alpha_f = _lag(cl_p, self.t_p_s, h) / st.slope_per_deg + st.alpha0_deg
        x4 = _lag(st.f_of(alpha_f), self.t_f_s, h)
        attached = st.slope_per_deg * (a_e - st.alpha0_deg)
        return attached * x4 + st.cl_fs_of(a_e) * (1.0 - x4) + non_circulatory

    def to_dict(self) -> dict[str, Any]:
        return {
            "class": "Beddoes-Leishman (Hansen-Gaunaa-Madsen)",
            "fs": self.fs,
            "t_u_s": self.t_u_s,
            "t_p_s": self.t_p_s,
            "t_f_s": self.t_f_s,
            "downwash_s": self.downwash_s,
            "wagner": {"A1": A1, "A2": A2, "b1": B1, "b2": B2},
            "static": self.static.to_dict(),
            "fit": self.history_,
        }

    def describe(self) -> str:
        st = self.static
        return (
            f"C_lα {st.slope_per_deg:.4f}/°, α0 {st.alpha0_deg:.2f}° (line over "
            f"{st.attached_range_deg[0]:.1f}–{st.attached_range_deg[1]:.1f}°), T_u "
            f"{self.t_u_s * 1e3:.1f} ms, T_p {self.t_p_s * 1e3:.1f} ms, T_f "
            f"{self.t_f_s * 1e3:.1f} ms, downwash {self.downwash_s * 1e3:.1f} ms"
        )


def _lag(target: np.ndarray, tau_s: float, h: float) -> np.ndarray:
    """x[k] = a x[k−1] + (1 − a) target[k], a = e^{−h/τ}, x[−1] = target[0] (at rest)."""
    a = math.exp(-h / max(tau_s, 1e-12))
    out, _ = lfilter([1.0 - a], [1.0, -a], target, zi=[a * target[0]])
    return np.asarray(out)


def _steady_state(model: BeddoesLeishman, data: PeriodicData) -> np.ndarray:
    """Each record's periodic steady state (two periods simulated before it), (N, P·M) → flat."""
    out = []
    for m in range(data.M):
        for p in range(data.P):
            u = data.u[:, p, m]
            y = model.simulate(np.concatenate([u, u, u]))
            out.append(y[2 * data.N :])
    return np.concatenate(out)


def _error(model: BeddoesLeishman, data: PeriodicData) -> float:
    y = data.y.transpose(2, 1, 0).reshape(-1)
    y_hat = _steady_state(model, data)
    return float(np.sqrt(np.mean((y - y_hat) ** 2)) / np.std(y))


def fit_beddoes_leishman(
    sweep: QuasiStaticSweep,
    train: PeriodicData,
    validation: PeriodicData | None = None,
    max_nfev: int = 200,
) -> BeddoesLeishman:
    """Calibrate the HGM model: the static curves from ``sweep`` (`static_lift`), then T_u, T_p,
    T_f (log-parametrised within T_BOUNDS_S) and the downwash time (within ±DOWNWASH_BOUND_S)
    by least squares on the steady-state periods of ``train`` (scipy's trust-region reflective
    solver), from each start of STARTS_TU_S (T_p = 1.5 T_u, T_f = 6 T_u: [HGM]'s values in
    units of T_u); the start of lowest training cost is kept. ``validation`` (held-out periods)
    is only scored, for the report."""
    static = static_lift(sweep)
    y = train.y.transpose(2, 1, 0).reshape(-1)
    scale = float(np.std(y))
    lo = [math.log(T_BOUNDS_S[0])] * 3 + [-DOWNWASH_BOUND_S]
    hi = [math.log(T_BOUNDS_S[1])] * 3 + [DOWNWASH_BOUND_S]

    def model_of(theta: np.ndarray) -> BeddoesLeishman:
        t_u, t_p, t_f = np.exp(theta[:3])
        return BeddoesLeishman(static, train.fs, float(t_u), float(t_p), float(t_f),
                               float(theta[3]))  # fmt: skip

    def residual(theta: np.ndarray) -> np.ndarray:
        return (_steady_state(model_of(theta), train) - y) / scale

    best = None
    starts = []
    for t_u in STARTS_TU_S:
        theta0 = np.array([math.log(t_u), math.log(1.5 * t_u), math.log(6.0 * t_u), 0.0])
        sol = least_squares(residual, theta0, bounds=(lo, hi), method="trf", max_nfev=max_nfev,
                            x_scale=[1.0, 1.0, 1.0, 0.01])  # fmt: skip
        cost = float(np.sqrt(np.mean(sol.fun**2)))
        starts.append({"t_u_start_s": t_u, "training_error": cost, "evaluations": int(sol.nfev)})
        if best is None or cost < best[0]:
            best = (cost, sol.x)
    assert best is not None
    model = model_of(best[1])
    model.history_ = {
        "training_error": best[0],
        "starts": starts,
        "validation_error": None if validation is None else _error(model, validation),
    }
    return model
