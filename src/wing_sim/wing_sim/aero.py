"""Unsteady lift of the pitching wing: Beddoes–Leishman in the Hansen–Gaunaa–Madsen form, with
a leading-edge vortex and bistable, stochastic stall.

References
    [HGM] Hansen, Gaunaa & Madsen, "A Beddoes–Leishman type dynamic stall model in state-space
          and indicial formulations", Risø-R-1354 (2004), §2.
    [LB]  Leishman & Beddoes, "A semi-empirical model for dynamic stall", J. Am. Helicopter Soc.
          34(3), 1989 (Kirchhoff lift, vortex lift).

States (time unit T_u = c/2U; all lags integrated at `substeps` × the sample rate with exact
exponential updates x ← x e^{-h/T} + (1 − e^{-h/T}) target, the target evaluated at the substep
midpoint with α linearly interpolated between samples):
    x1, x2  Wagner lags: T_i = T_u/b_i, target A_i α_3/4;  α_E = α_3/4(1 − A1 − A2) + x1 + x2
            with α_3/4 = α + α̇ c (3/4 − x_pivot)/U                           [HGM eq. 9–10]
    x3      pressure lag T_p of C_l^p = C_lα α_E + π T_u α̇;  α_F = x3/C_lα     [HGM eq. 13–14]
    x4      separation point, lag T_f (T_f,down while f falls, T_f,up while it rises) towards
            the static f(α_F) of the current flow regime                       [HGM eq. 15]
    η       Ornstein–Uhlenbeck noise on √f, driven only in separated flow:
            f_dyn = clip(√x4 + η, 0, 1)² (on √f so that the lift noise is Gaussian, C_l being
            linear in √f, and f stays in [0, 1] without piling up at a clip)
    regime  attached / separated: a random switch per substep with hazards
            λ_stall = Φ((|α_F| − α_stall)/Δ)/τ and λ_reattach = Φ((α_reattach − |α_F|)/Δ)/τ
    V       vortex lift: while the vortex time τ_v < T_VL, V' = −V/T_V + κ·max(Ċ_v, 0) with
            C_v = C_lα|α_E|(1 − K(x4)) the lift lost to separation [LB eq. 24–25]; afterwards
            V decays with T_V/2. τ_v restarts at each stall event; κ is log-normal per event.
Lift (sign of α_E for the vortex part):
    C_l = C_lα α_E K(f_dyn) + V + π T_u α̇,   K(f) = ((1 + √f)/2)²   (Kirchhoff, [LB eq. 13]).
The quasi-static lift on each branch is C_lα α K(f_branch(α)) — the parametrisation of the two
static separation curves is in wing_params.WingParams and docs/plant.md §2.
"""

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from wing_sim.random_stream import new_state, normal, normal_pair, uniform
from wing_sim.wing_params import WingParams

# Coefficient vector (built once from WingParams by aero_coefficients).
C_H, C_M, C_FS, C_TU, C_CLA = 0, 1, 2, 3, 4
C_A1, C_A2, C_E1, C_E2, C_EP, C_EFD, C_EFU, C_DOWNWASH = 5, 6, 7, 8, 9, 10, 11, 12
C_ALIN, C_AFULL, C_PEXP, C_FFULL, C_FREATT = 13, 14, 15, 16, 17
C_ASTALL, C_AREATT, C_SPREAD, C_RATE, C_EETA, C_SETA = 18, 19, 20, 21, 22, 23
C_EV, C_GV, C_EV2, C_TVL, C_KMU, C_KSIG, C_XV0, C_XV1 = 24, 25, 26, 27, 28, 29, 30, 31
C_RATE_TO_LIGHT, C_RATE_TO_DEEP, C_LIGHT_FRACTION = 32, 33, 34
N_COEF = 35

# State vector.
S_X1, S_X2, S_X3, S_X4, S_ETA, S_VORTEX, S_TAU_V, S_KAPPA = 0, 1, 2, 3, 4, 5, 6, 7
S_CV_PREV, S_STALLED, S_ALPHA_PREV, S_STARTED, S_LIGHT = 8, 9, 10, 11, 12
N_STATE = 13

# Output columns per sample.
O_ALPHA, O_ALPHA_DOT, O_ALPHA_E, O_ALPHA_F, O_F = 0, 1, 2, 3, 4
O_CL_CIRC, O_CL_VORTEX, O_CL_NC, O_CL, O_X_V, O_TAU_V, O_STALLED = 5, 6, 7, 8, 9, 10, 11
O_LIGHT = 12
N_OUT = 13

_NO_VORTEX = 1.0e9  # vortex time meaning "no vortex on the wing"


def aero_coefficients(params: WingParams) -> np.ndarray:
    """(N_COEF,) coefficient vector of the aero kernel, precomputed from params."""
    c = np.zeros(N_COEF)
    h = params.sample_period_s / params.substeps
    tu = params.convective_time_s
    c[C_H], c[C_M], c[C_FS], c[C_TU] = h, params.substeps, params.sample_rate_hz, tu
    c[C_CLA] = params.lift_slope_per_rad
    c[C_A1], c[C_A2] = params.wagner_a1, params.wagner_a2
    c[C_E1] = math.exp(-h * params.wagner_b1 / tu)
    c[C_E2] = math.exp(-h * params.wagner_b2 / tu)
    c[C_EP] = math.exp(-h / (params.pressure_lag_tu * tu))
    c[C_EFD] = math.exp(-h / (params.separation_lag_down_tu * tu))
    c[C_EFU] = math.exp(-h / (params.separation_lag_up_tu * tu))
    c[C_DOWNWASH] = params.chord_m * (0.75 - params.pivot_x_c) / params.velocity_m_s
    c[C_ALIN] = math.radians(params.alpha_linear_deg)
    c[C_AFULL] = math.radians(params.alpha_full_separation_deg)
    c[C_PEXP] = params.separation_exponent
    c[C_FFULL], c[C_FREATT] = params.f_full_separation, params.f_reattach
    c[C_ASTALL] = math.radians(params.alpha_stall_deg)
    c[C_AREATT] = math.radians(params.alpha_reattach_deg)
    c[C_SPREAD] = math.radians(params.switch_spread_deg)
    c[C_RATE] = 1.0 / params.switch_time_s
    e_eta = math.exp(-h / params.separation_noise_time_s)
    c[C_EETA], c[C_SETA] = e_eta, params.separation_noise_std * math.sqrt(1.0 - e_eta**2)
    t_v = params.vortex_lag_tu * tu
    c[C_EV] = math.exp(-h / t_v)
    c[C_GV] = (t_v / h) * (1.0 - c[C_EV])  # exact gain for an input ramp over the substep
    c[C_EV2] = math.exp(-2.0 * h / t_v)
    c[C_TVL] = params.vortex_travel_tu * tu
    sig2 = math.log(1.0 + params.vortex_strength_cv**2)
    c[C_KMU] = math.log(params.vortex_strength_mean) - 0.5 * sig2
    c[C_KSIG] = math.sqrt(sig2)
    c[C_XV0], c[C_XV1] = params.vortex_start_c, params.vortex_end_c
    # Stall-type regime: a two-state Markov process with mean dwell light_stall_dwell_s in the
    # light (trailing-edge) regime, a stationary fraction light_stall_fraction of the time in it.
    frac = params.light_stall_fraction
    c[C_LIGHT_FRACTION] = frac
    if frac > 0.0:
        c[C_RATE_TO_DEEP] = 1.0 / params.light_stall_dwell_s
        c[C_RATE_TO_LIGHT] = c[C_RATE_TO_DEEP] * frac / (1.0 - frac)
    return c


@njit(cache=True)
def kirchhoff_factor(f: float) -> float:
    """K(f) = ((1 + √f)/2)²: lift fraction kept with separation at x/c = f [LB eq. 13]."""
    r = 0.5 * (1.0 + math.sqrt(max(f, 0.0)))
    return r * r


@njit(cache=True)
def f_attached_branch(alpha_abs: float, c: np.ndarray) -> float:
    """Static separation point of the attached branch at |α| (rad)."""
    if alpha_abs <= c[C_ALIN]:
        return 1.0
    if alpha_abs >= c[C_AFULL]:
        return c[C_FFULL]
    s = (alpha_abs - c[C_ALIN]) / (c[C_AFULL] - c[C_ALIN])
    return 1.0 - (1.0 - c[C_FFULL]) * s ** c[C_PEXP]


@njit(cache=True)
def f_separated_branch(alpha_abs: float, c: np.ndarray) -> float:
    """Static separation point of the separated (stalled) branch at |α| (rad)."""
    if alpha_abs >= c[C_AFULL]:
        return c[C_FFULL]
    slope = (c[C_FREATT] - c[C_FFULL]) / (c[C_AFULL] - c[C_AREATT])
    return min(c[C_FFULL] + slope * (c[C_AFULL] - alpha_abs), f_attached_branch(alpha_abs, c))


@njit(cache=True)
def _std_normal_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


@njit(cache=True)
def _initialise(alpha: float, state: np.ndarray, rng: np.ndarray, c: np.ndarray) -> None:
    """Steady flow at α: lags at equilibrium, attached unless |α| is past the stall mid-point."""
    a_abs = abs(alpha)
    state[S_X1] = c[C_A1] * alpha
    state[S_X2] = c[C_A2] * alpha
    state[S_X3] = c[C_CLA] * alpha
    # Regime from its stationary distribution; no draw when the regime process is off, so the
    # random stream (and every result) is that of the plant without regimes.
    light = c[C_LIGHT_FRACTION] > 0.0 and uniform(rng) < c[C_LIGHT_FRACTION]
    state[S_LIGHT] = 1.0 if light else 0.0
    stalled = not light and a_abs >= c[C_ASTALL]
    state[S_STALLED] = 1.0 if stalled else 0.0
    f = f_separated_branch(a_abs, c) if stalled else f_attached_branch(a_abs, c)
    state[S_X4] = f
    state[S_ETA] = 0.0
    state[S_VORTEX] = 0.0
    state[S_TAU_V] = _NO_VORTEX
    state[S_KAPPA] = 0.0
    state[S_CV_PREV] = c[C_CLA] * a_abs * (1.0 - kirchhoff_factor(f))
    state[S_ALPHA_PREV] = alpha
    state[S_STARTED] = 1.0


@njit(cache=True)
def advance_aero(
    alpha: np.ndarray, state: np.ndarray, rng: np.ndarray, c: np.ndarray, out: np.ndarray
) -> None:
    """Advance the aero model over samples alpha (K,) [rad]; write out (K, N_OUT).

    Sample k integrates from the previous sample's α to alpha[k] (linear in between); the first
    sample ever seen starts from steady flow. state (N_STATE,) and rng (4,) advance in place.
    """
    h = c[C_H]
    m = int(c[C_M])
    cla = c[C_CLA]
    a_inst = 1.0 - c[C_A1] - c[C_A2]
    for k in range(alpha.shape[0]):
        a_now = alpha[k]
        n_sub = m
        if state[S_STARTED] == 0.0:  # first sample: steady flow, nothing to integrate
            _initialise(a_now, state, rng, c)
            n_sub = 0
        a_prev = state[S_ALPHA_PREV]
        alpha_dot = (a_now - a_prev) * c[C_FS]
        downwash = alpha_dot * c[C_DOWNWASH]
        cl_nc = math.pi * c[C_TU] * alpha_dot
        alpha_e = a_inst * a_now + state[S_X1] + state[S_X2]
        for j in range(n_sub):
            a_mid = a_prev + (a_now - a_prev) * (j + 0.5) / m
            a_end = a_prev + (a_now - a_prev) * (j + 1.0) / m
            a34_mid = a_mid + downwash
            # Wagner lags [HGM eq. 9]
            state[S_X1] = state[S_X1] * c[C_E1] + (1.0 - c[C_E1]) * c[C_A1] * a34_mid
            state[S_X2] = state[S_X2] * c[C_E2] + (1.0 - c[C_E2]) * c[C_A2] * a34_mid
            alpha_e_mid = a_inst * a34_mid + state[S_X1] + state[S_X2]
            alpha_e = a_inst * (a_end + downwash) + state[S_X1] + state[S_X2]
            # Pressure lag [HGM eq. 13]
            target_p = cla * alpha_e_mid + cl_nc
            state[S_X3] = state[S_X3] * c[C_EP] + (1.0 - c[C_EP]) * target_p
            alpha_f_abs = abs(state[S_X3] / cla)
            # Stall-type regime switch (two-state Markov process, docs/plant.md §2)
            if c[C_LIGHT_FRACTION] > 0.0:
                rate = c[C_RATE_TO_DEEP] if state[S_LIGHT] != 0.0 else c[C_RATE_TO_LIGHT]
                if uniform(rng) < -math.expm1(-rate * h):
                    state[S_LIGHT] = 1.0 - state[S_LIGHT]
            light = state[S_LIGHT] != 0.0
            stalled = state[S_STALLED] != 0.0
            if stalled:
                f_target = f_separated_branch(alpha_f_abs, c)
            else:
                f_target = f_attached_branch(alpha_f_abs, c)
            e_f = c[C_EFD] if f_target < state[S_X4] else c[C_EFU]
            state[S_X4] = state[S_X4] * e_f + (1.0 - e_f) * f_target
            # Separation-point noise, driven only while separated
            if stalled:
                state[S_ETA] = state[S_ETA] * c[C_EETA] + c[C_SETA] * normal(rng)
            else:
                state[S_ETA] = state[S_ETA] * c[C_EETA]
            # Bistable regime switch with α-dependent hazard
            if stalled:
                hazard = c[C_RATE] * _std_normal_cdf((c[C_AREATT] - alpha_f_abs) / c[C_SPREAD])
            elif light:
                hazard = 0.0  # trailing-edge stall: no leading-edge stall event
            else:
                hazard = c[C_RATE] * _std_normal_cdf((alpha_f_abs - c[C_ASTALL]) / c[C_SPREAD])
            if uniform(rng) < -math.expm1(-hazard * h):
                if stalled:
                    state[S_STALLED] = 0.0
                else:
                    state[S_STALLED] = 1.0
                    state[S_TAU_V] = 0.0
                    z, _ = normal_pair(rng)
                    state[S_KAPPA] = math.exp(c[C_KMU] + c[C_KSIG] * z)
            # Vortex lift [LB eq. 24-25]: fed by growth of the separation lift deficit
            cv = cla * abs(alpha_e) * (1.0 - kirchhoff_factor(state[S_X4]))
            if state[S_TAU_V] < c[C_TVL]:
                feed = max(cv - state[S_CV_PREV], 0.0)
                state[S_VORTEX] = state[S_VORTEX] * c[C_EV] + state[S_KAPPA] * feed * c[C_GV]
            else:
                state[S_VORTEX] = state[S_VORTEX] * c[C_EV2]
            state[S_CV_PREV] = cv
            if state[S_TAU_V] < _NO_VORTEX:
                state[S_TAU_V] += h
        root_f = min(max(math.sqrt(max(state[S_X4], 0.0)) + state[S_ETA], 0.0), 1.0)
        f_dyn = root_f * root_f
        sign = 1.0 if alpha_e >= 0.0 else -1.0
        cl_circ = cla * alpha_e * kirchhoff_factor(f_dyn)
        cl_vortex = sign * state[S_VORTEX]
        travel = min(state[S_TAU_V] / c[C_TVL], 1.0)
        out[k, O_ALPHA] = a_now
        out[k, O_ALPHA_DOT] = alpha_dot
        out[k, O_ALPHA_E] = alpha_e
        out[k, O_ALPHA_F] = state[S_X3] / cla
        out[k, O_F] = f_dyn
        out[k, O_CL_CIRC] = cl_circ
        out[k, O_CL_VORTEX] = cl_vortex
        out[k, O_CL_NC] = cl_nc
        out[k, O_CL] = cl_circ + cl_vortex + cl_nc
        out[k, O_X_V] = c[C_XV0] + (c[C_XV1] - c[C_XV0]) * travel
        out[k, O_TAU_V] = min(state[S_TAU_V], _NO_VORTEX) / c[C_TU]
        out[k, O_STALLED] = state[S_STALLED]
        out[k, O_LIGHT] = state[S_LIGHT]
        state[S_ALPHA_PREV] = a_now


def static_separation_point(
    alpha_rad: np.ndarray | float, params: WingParams | None = None, branch: str = "attached"
) -> np.ndarray:
    """Static separation point f(α) (x/c) on the 'attached' or 'separated' branch."""
    c = aero_coefficients(params or WingParams())
    if branch not in ("attached", "separated"):
        raise ValueError(f"branch must be 'attached' or 'separated', got {branch!r}")
    fn = f_attached_branch if branch == "attached" else f_separated_branch
    a = np.abs(np.asarray(alpha_rad, dtype=float))
    return np.vectorize(lambda x: fn(x, c), otypes=[float])(a)


def static_lift_coefficient(
    alpha_rad: np.ndarray | float, params: WingParams | None = None, branch: str = "attached"
) -> np.ndarray:
    """Quasi-static Kirchhoff lift C_lα α K(f(α)) on a branch (the model's static target)."""
    p = params or WingParams()
    f = static_separation_point(alpha_rad, p, branch)
    return p.lift_slope_per_rad * np.asarray(alpha_rad, dtype=float) * (0.5 * (1 + np.sqrt(f))) ** 2


@dataclass(frozen=True)
class AeroSeries:
    """Aero model outputs per 200 Hz sample, all (K,).

    alpha, alpha_dot [rad, rad/s]; alpha_effective (α_E) and alpha_lagged (α_F) [rad];
    separation_point f_dyn (x/c); cl_circulatory, cl_vortex, cl_added_mass and their sum cl;
    vortex_position (x/c of the suction bump), vortex_time_tu (τ_v / T_u); stalled (bool);
    light_stall (bool): the stall-type regime is the light (trailing-edge) one.
    """

    alpha: np.ndarray
    alpha_dot: np.ndarray
    alpha_effective: np.ndarray
    alpha_lagged: np.ndarray
    separation_point: np.ndarray
    cl_circulatory: np.ndarray
    cl_vortex: np.ndarray
    cl_added_mass: np.ndarray
    cl: np.ndarray
    vortex_position: np.ndarray
    vortex_time_tu: np.ndarray
    stalled: np.ndarray
    light_stall: np.ndarray

    @classmethod
    def from_output(cls, out: np.ndarray) -> "AeroSeries":
        return cls(
            alpha=out[:, O_ALPHA].copy(),
            alpha_dot=out[:, O_ALPHA_DOT].copy(),
            alpha_effective=out[:, O_ALPHA_E].copy(),
            alpha_lagged=out[:, O_ALPHA_F].copy(),
            separation_point=out[:, O_F].copy(),
            cl_circulatory=out[:, O_CL_CIRC].copy(),
            cl_vortex=out[:, O_CL_VORTEX].copy(),
            cl_added_mass=out[:, O_CL_NC].copy(),
            cl=out[:, O_CL].copy(),
            vortex_position=out[:, O_X_V].copy(),
            vortex_time_tu=out[:, O_TAU_V].copy(),
            stalled=out[:, O_STALLED] != 0.0,
            light_stall=out[:, O_LIGHT] != 0.0,
        )


class UnsteadyAerodynamics:
    """The aero model alone (no pressures): angle of attack in, lift and states out.

    params: WingParams (defaults if None); seed: run seed of the stochastic stall.
    `simulate(alpha_rad)` continues from the current state, so consecutive calls equal one call
    on the concatenated input.
    """

    AERO_STREAM = 1  # random stream id of the aero model (sensor noise uses others)

    def __init__(self, params: WingParams | None = None, seed: int = 0) -> None:
        self.params = params or WingParams()
        self.coefficients = aero_coefficients(self.params)
        self.state = np.zeros(N_STATE)
        self.rng = new_state(seed, self.AERO_STREAM)

    def advance(self, alpha_rad: np.ndarray, out: np.ndarray) -> None:
        """Kernel call: alpha_rad (K,) float64 contiguous, out (K, N_OUT) written in place."""
        advance_aero(alpha_rad, self.state, self.rng, self.coefficients, out)

    def simulate(self, alpha_rad: np.ndarray) -> AeroSeries:
        """Aero outputs for the angle-of-attack samples alpha_rad (K,) [rad] at the sample rate."""
        alpha = np.ascontiguousarray(alpha_rad, dtype=np.float64)
        if alpha.ndim != 1:
            raise ValueError(f"alpha_rad must be 1-D (K,), got shape {alpha.shape}")
        if not np.all(np.isfinite(alpha)):
            raise ValueError("alpha_rad contains NaN or inf; the aero model needs finite angles")
        out = np.empty((alpha.size, N_OUT))
        self.advance(alpha, out)
        return AeroSeries.from_output(out)
