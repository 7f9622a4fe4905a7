"""Surface pressures of the simulated wing from the aero model's state (docs/plant.md §3).

Cp at a surface point φ (naca_section.py) is built in a "working frame" where the suction side
is the upper surface (α_E ≥ 0; negative α_E is handled by mirroring z → −z, which swaps the
surfaces and flips the signs of α, C_n and C_m):

  1. Attached inviscid flow at an equivalent angle α_c (panel.py): Cp_inv = 1 − (a cos α_c +
     b sin α_c)². α_c is not α: it is solved per sample so that the fine-grid integral of the
     blended distribution (step 2) gives exactly the aero model's circulatory lift C_l,circ at
     the true α. It is the "reduced circulation" of Kirchhoff flow plus the viscous de-cambering
     that brings the inviscid panel slope (7.26/rad) down to C_lα = 0.104/° (5.96/rad).
  2. Kirchhoff blend on the suction side: aft of the separation point x_s = f the pressure is
     the base (free-streamline) pressure Cp_b = max(Cp_inv(x_s), Cp_b,min), held to the
     trailing edge; over [x_s − w, x_s] the attached Cp blends into it (smoothstep, w = the
     blend width, shrunk near the edges so that the leading-edge point stays attached and
     f = 1 is the attached distribution). The floor Cp_b,min (a bluff-body base pressure)
     makes deep stall a flat suction plateau over a loaded lower surface.
  3. Leading-edge vortex: a travelling suction bump −A_v (1 − u²)², u = (x − x_v)/h_v, on the
     suction side, x_v moving aft with the vortex time; A_v gives the model's vortex lift.
  4. Added mass: ∓(A_nc/2)(8/π)√(x(1−x)) on the upper/lower surface (the thin-aerofoil
     non-circulatory loading shape), A_nc giving the model's π T_u α̇ lift.

The fine-grid integrals of each part (C_n, C_a, C_m per unit amplitude, or tabulated over
(α_c, x_s) for parts 1–2 on a 2 × 401-point cosine grid) are computed once; the per-sample
"fine-grid truth" is read from these tables (bilinear; within 4e-4 of integrating the
synthesised Cp directly on the fine grid), which is what makes the 49-tap integration error
measurable at 100k samples/s. A lift target outside the table (α_c ∈ [−5°, 28°]) is clamped,
and then the truth's fine-grid C_l differs from the model's C_l — which shows the clamping.

numba's cache does not see edits in aero.py's column constants or random_stream.py from the
kernels here: after changing those, delete this package's __pycache__/*.nbi and *.nbc files.

Sensing: p = q·Cp, then per tap a first-order tube lag (time constant τ_i drawn once per rig in
[tube_lag_min_s, tube_lag_max_s]), discretised exactly for pressure varying linearly between
samples: y_k = e y_{k−1} + u_k − e u_{k−1} − (τ/T)(1 − e)(u_k − u_{k−1}), e = exp(−T/τ); then a
zero drift (Ornstein–Uhlenbeck per tap, starting at 0 as after a scanner zero) and white noise.
"""

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit

from pressure_scanner.integration import contour_weights
from pressure_scanner.naca_section import chord_station, contour_point
from pressure_scanner.taps import TapLayout
from wing_sim import aero
from wing_sim.panel import speed_basis
from wing_sim.random_stream import normal_pair
from wing_sim.wing_params import WingParams

N_FINE = 401  # fine-grid points per surface, leading and trailing edge included
# α_c range: the blended lift grows monotonically with α_c over it for every separation point
# and every α in [-5°, 45°] (checked when the tables are built; with the base-pressure floor
# that fails first near α_c = 29° at small α and x_s). α_c = 28° attached gives C_l = 3.4 and
# fully separated ≈ 2, above any target of the model; targets beyond are clamped (see truth).
ALPHA_C_MIN_DEG, ALPHA_C_MAX_DEG, ALPHA_C_STEP_DEG = -5.0, 28.0, 0.25
N_THETA = 241  # separation-point grid, uniform in θ = arccos(1 − 2 x_s)
X_SEP_MIN = 0.005  # separation never closer to the leading edge than this (x/c)
N_VORTEX = 131
N_BASE = 2049  # suction-side speed table for the base pressure

# Per-point columns of a point set (taps or fine grid).
P_X, P_SIDE, P_A, P_B, P_A_MIRROR, P_B_MIRROR, P_ADDED_MASS = 0, 1, 2, 3, 4, 5, 6
N_POINT = 7

# Scalar coefficients of the synthesis kernel.
(K_Q, K_AC0, K_DAC, K_NAC, K_TH0, K_DTH, K_NTH, K_BLEND, K_XSMIN, K_HV, K_XV0, K_DXV, K_NXV) = (
    range(13)
)
K_NCN, K_NCA, K_NCM, K_NOISE, K_DRIFT_E, K_DRIFT_S, K_SENSOR_ON, K_DBASE, K_NBASE = range(13, 22)
K_CPB_MIN = 22
N_K = 23

# Truth columns per sample.
T_CN, T_CA, T_CM, T_CL, T_CD, T_ALPHA_C, T_CL_TARGET = range(7)
N_TRUTH = 7


def smoothstep(t: np.ndarray) -> np.ndarray:
    """3t² − 2t³ on t clipped to [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def blend_weight(x_c: np.ndarray, x_sep: float, blend_width: float) -> np.ndarray:
    """Weight of the attached Cp on the suction side (1 − weight: base pressure): 1 ahead of
    x_s − w, 0 from x_s aft, smoothstep between; w = min(blend_width, x_s, 1 − x_s)."""
    width = max(min(blend_width, x_sep, 1.0 - x_sep), 1e-9)
    return smoothstep((x_sep - np.asarray(x_c, dtype=float)) / width)


@dataclass(frozen=True)
class FineGridTables:
    """Fine-grid integrals used by the synthesis kernel (working frame, module docstring).

    circulation: (3, n_alpha_c, N_THETA) C_n, C_a, C_m of the blended attached distribution on
        the α_c grid × separation grid.
    alpha_c_top: (N_THETA,) last α_c index up to which the lift grows with α_c.
    vortex: (N_VORTEX, 3) C_n, C_a, C_m of a unit suction bump centred at each x_v.
    added_mass: (3,) C_n, C_a, C_m of the unit added-mass loading.
    base_speed: (N_BASE, 2) suction-side a, b on a uniform θ grid over [0, π].
    phi, x, z: (2 N_FINE − 1,) the fine contour (lower TE → LE → upper TE).
    """

    alpha_c_deg: np.ndarray
    theta_sep: np.ndarray
    vortex_x: np.ndarray
    circulation: np.ndarray
    alpha_c_top: np.ndarray
    vortex: np.ndarray
    added_mass: np.ndarray
    base_speed: np.ndarray
    phi: np.ndarray
    x: np.ndarray
    z: np.ndarray


@lru_cache(maxsize=4)
def fine_grid_tables(
    thickness_ratio: float,
    blend_width: float,
    vortex_half_width: float,
    vortex_start: float,
    vortex_end: float,
    base_pressure_min: float,
) -> FineGridTables:
    """Build (once per shape parameter set) the fine-grid integral tables."""
    basis = speed_basis(thickness_ratio)
    phi = np.linspace(-np.pi, np.pi, 2 * N_FINE - 1)
    x, z = contour_point(phi, thickness_ratio)
    weights = contour_weights(x, z)  # (3, P); the contour is closed: both ends at (1, 0)
    a, b = basis.speeds(phi)
    upper = phi > 0.0

    alpha_c_deg = np.arange(ALPHA_C_MIN_DEG, ALPHA_C_MAX_DEG + 1e-9, ALPHA_C_STEP_DEG)
    ac = np.deg2rad(alpha_c_deg)
    v = a[None, :] * np.cos(ac)[:, None] + b[None, :] * np.sin(ac)[:, None]
    cp_inv = 1.0 - v * v  # (n_alpha_c, P)

    theta_min = math.acos(1.0 - 2.0 * X_SEP_MIN)
    theta_sep = np.linspace(theta_min, np.pi, N_THETA)
    x_sep = chord_station(theta_sep)
    a_sep, b_sep = basis.speeds(theta_sep)
    circulation = np.empty((3, ac.size, N_THETA))
    lower_part = cp_inv[:, ~upper] @ weights[:, ~upper].T  # (n_alpha_c, 3)
    for j in range(N_THETA):
        w = blend_weight(x[upper], x_sep[j], blend_width)
        v_sep = a_sep[j] * np.cos(ac) + b_sep[j] * np.sin(ac)
        cp_base = np.maximum(1.0 - v_sep * v_sep, base_pressure_min)
        cp_upper = cp_inv[:, upper] * w[None, :] + cp_base[:, None] * (1.0 - w[None, :])
        circulation[:, :, j] = (lower_part + cp_upper @ weights[:, upper].T).T

    # The inversion's premise: the lift grows with α_c. For each separation point keep the
    # α_c grid up to where it stops growing for any α in [-5°, 45°] (only happens with
    # separation at the very leading edge beyond α_c ≈ 22°, far from any target there).
    growing = np.ones((ac.size - 1, N_THETA), dtype=bool)
    for alpha in np.deg2rad(np.arange(-5.0, 45.1, 2.5)):
        lift = circulation[0] * np.cos(alpha) - circulation[1] * np.sin(alpha)
        growing &= np.diff(lift, axis=0) > 0.0
    alpha_c_top = np.where(growing.all(axis=0), ac.size - 1, np.argmin(growing, axis=0))
    if np.any(alpha_c_deg[alpha_c_top] < 15.0):
        raise RuntimeError(
            "fine-grid tables: lift stops growing with α_c below 15° for some separation "
            "point; change the shape parameters (blend width, base pressure floor)"
        )

    vortex_x = np.linspace(vortex_start, vortex_end, N_VORTEX)
    u = (x[None, upper] - vortex_x[:, None]) / vortex_half_width
    bump = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
    vortex = -bump @ weights[:, upper].T  # Cp = −bump on the suction side

    shape = (8.0 / np.pi) * np.sqrt(np.clip(x * (1.0 - x), 0.0, None))
    cp_am = np.where(upper, -0.5 * shape, np.where(phi < 0.0, 0.5 * shape, 0.0))
    added_mass = weights @ cp_am

    theta_base = np.linspace(0.0, np.pi, N_BASE)
    a_base, b_base = basis.speeds(theta_base)
    return FineGridTables(
        alpha_c_deg=alpha_c_deg,
        theta_sep=theta_sep,
        vortex_x=vortex_x,
        circulation=np.ascontiguousarray(circulation),
        alpha_c_top=alpha_c_top.astype(np.int64),
        vortex=np.ascontiguousarray(vortex),
        added_mass=added_mass,
        base_speed=np.ascontiguousarray(np.stack([a_base, b_base], axis=1)),
        phi=phi,
        x=x,
        z=z,
    )


def point_set(x_c: np.ndarray, side: np.ndarray, thickness_ratio: float) -> np.ndarray:
    """(n, N_POINT) per-point data for the synthesis kernel at surface points (x/c, side)."""
    basis = speed_basis(thickness_ratio)
    x = np.asarray(x_c, dtype=float)
    s = np.asarray(side, dtype=float)
    phi = s * np.arccos(np.clip(1.0 - 2.0 * x, -1.0, 1.0))
    a, b = basis.speeds(phi)
    a_m, b_m = basis.speeds(-phi)
    points = np.empty((x.size, N_POINT))
    points[:, P_X] = x
    points[:, P_SIDE] = s
    points[:, P_A], points[:, P_B] = a, b
    points[:, P_A_MIRROR], points[:, P_B_MIRROR] = a_m, b_m
    points[:, P_ADDED_MASS] = (8.0 / np.pi) * np.sqrt(np.clip(x * (1.0 - x), 0.0, None))
    return points


@njit(cache=True)
def _invert_alpha_c(
    target: float, alpha: float, theta: float, table: np.ndarray, top: np.ndarray, k: np.ndarray
) -> tuple[float, float, float, float]:
    """α_c whose blended distribution has lift `target` at α; returns (α_c, C_n, C_a, C_m)."""
    n_th = int(k[K_NTH])
    t = (theta - k[K_TH0]) / k[K_DTH]
    j = min(max(int(t), 0), n_th - 2)
    wt = min(max(t - j, 0.0), 1.0)
    ca_ = math.cos(alpha)
    sa = math.sin(alpha)

    def lift(i: int) -> float:
        cn = (1.0 - wt) * table[0, i, j] + wt * table[0, i, j + 1]
        cax = (1.0 - wt) * table[1, i, j] + wt * table[1, i, j + 1]
        return cn * ca_ - cax * sa

    lo = 0
    hi = min(top[j], top[j + 1])
    g_lo = lift(lo)
    g_hi = lift(hi)
    if target <= g_lo:
        i, w = 0, 0.0
    elif target >= g_hi:
        i, w = hi - 1, 1.0
    else:
        while hi - lo > 1:
            mid = (lo + hi) // 2
            g_mid = lift(mid)
            if g_mid <= target:
                lo, g_lo = mid, g_mid
            else:
                hi, g_hi = mid, g_mid
        i = lo
        w = (target - g_lo) / (g_hi - g_lo)
    result = np.empty(3)
    for r in range(3):
        v0 = (1.0 - wt) * table[r, i, j] + wt * table[r, i, j + 1]
        v1 = (1.0 - wt) * table[r, i + 1, j] + wt * table[r, i + 1, j + 1]
        result[r] = (1.0 - w) * v0 + w * v1
    alpha_c = math.radians(k[K_AC0] + (i + w) * k[K_DAC])
    return alpha_c, result[0], result[1], result[2]


@njit(cache=True)
def synthesize(
    aero_out: np.ndarray,
    points: np.ndarray,
    circulation: np.ndarray,
    top: np.ndarray,
    vortex: np.ndarray,
    base_speed: np.ndarray,
    k: np.ndarray,
    tube: np.ndarray,
    sensor: np.ndarray,
    rng: np.ndarray,
    pressure_out: np.ndarray,
    cp_out: np.ndarray,
    truth_out: np.ndarray,
) -> None:
    """Pressures for the aero samples aero_out (K, aero.N_OUT).

    points (n, N_POINT); tube (n, 2) = e, (τ/T)(1 − e) per point; sensor (3n + 1,) state: lag
    output, previous clean pressure, drift, started flag (advanced in place). Writes
    pressure_out (K, n) [Pa], cp_out (K, n) clean Cp if it has K rows (skipped if 0 rows),
    truth_out (K, N_TRUTH).
    """
    n = points.shape[0]
    want_cp = cp_out.shape[0] > 0
    q = k[K_Q]
    sensor_on = k[K_SENSOR_ON] != 0.0
    for s_idx in range(aero_out.shape[0]):
        alpha_e = aero_out[s_idx, aero.O_ALPHA_E]
        sign = 1.0 if alpha_e >= 0.0 else -1.0
        alpha_w = sign * aero_out[s_idx, aero.O_ALPHA]
        target = sign * aero_out[s_idx, aero.O_CL_CIRC]
        x_sep = min(max(aero_out[s_idx, aero.O_F], k[K_XSMIN]), 1.0)
        theta = math.acos(1.0 - 2.0 * x_sep)
        alpha_c, cn, cax, cm = _invert_alpha_c(target, alpha_w, theta, circulation, top, k)
        cos_c = math.cos(alpha_c)
        sin_c = math.sin(alpha_c)
        cos_w = math.cos(alpha_w)
        sin_w = math.sin(alpha_w)
        # Base pressure: suction-side Cp_inv at the separation point.
        tb = theta / k[K_DBASE]
        ib = min(int(tb), int(k[K_NBASE]) - 2)
        wb = tb - ib
        a_s = (1.0 - wb) * base_speed[ib, 0] + wb * base_speed[ib + 1, 0]
        b_s = (1.0 - wb) * base_speed[ib, 1] + wb * base_speed[ib + 1, 1]
        v_s = a_s * cos_c + b_s * sin_c
        cp_base = max(1.0 - v_s * v_s, k[K_CPB_MIN])
        # Blend band [x_s − w, x_s]: w shrinks to x_s at the leading edge (the leading-edge
        # point stays attached) and to 1 − x_s at the trailing edge (f = 1 is fully attached).
        width = max(min(k[K_BLEND], x_sep, 1.0 - x_sep), 1e-9)
        # Vortex bump amplitude for the model's vortex lift.
        x_v = aero_out[s_idx, aero.O_X_V]
        tv = min(max((x_v - k[K_XV0]) / k[K_DXV], 0.0), k[K_NXV] - 1.0)
        iv = min(int(tv), int(k[K_NXV]) - 2)
        wv = tv - iv
        vn = (1.0 - wv) * vortex[iv, 0] + wv * vortex[iv + 1, 0]
        va = (1.0 - wv) * vortex[iv, 1] + wv * vortex[iv + 1, 1]
        vm = (1.0 - wv) * vortex[iv, 2] + wv * vortex[iv + 1, 2]
        amp_v = sign * aero_out[s_idx, aero.O_CL_VORTEX] / (vn * cos_w - va * sin_w)
        # Added-mass loading amplitude for the model's π T_u α̇ lift.
        amp_nc = sign * aero_out[s_idx, aero.O_CL_NC] / (k[K_NCN] * cos_w - k[K_NCA] * sin_w)
        # Truth in the working frame, then back to the wing frame.
        cn_w = cn + amp_v * vn + amp_nc * k[K_NCN]
        ca_w = cax + amp_v * va + amp_nc * k[K_NCA]
        cm_w = cm + amp_v * vm + amp_nc * k[K_NCM]
        alpha = aero_out[s_idx, aero.O_ALPHA]
        cn_t = sign * cn_w
        truth_out[s_idx, T_CN] = cn_t
        truth_out[s_idx, T_CA] = ca_w
        truth_out[s_idx, T_CM] = sign * cm_w
        truth_out[s_idx, T_CL] = cn_t * math.cos(alpha) - ca_w * math.sin(alpha)
        truth_out[s_idx, T_CD] = cn_t * math.sin(alpha) + ca_w * math.cos(alpha)
        truth_out[s_idx, T_ALPHA_C] = sign * alpha_c
        truth_out[s_idx, T_CL_TARGET] = aero_out[s_idx, aero.O_CL]
        started = sensor[3 * n] != 0.0
        for i in range(n):
            side = sign * points[i, P_SIDE]
            if sign > 0.0:
                v = points[i, P_A] * cos_c + points[i, P_B] * sin_c
            else:
                v = points[i, P_A_MIRROR] * cos_c + points[i, P_B_MIRROR] * sin_c
            cp = 1.0 - v * v
            xi = points[i, P_X]
            if side > 0.0:
                ts = min(max((x_sep - xi) / width, 0.0), 1.0)
                wgt = ts * ts * (3.0 - 2.0 * ts)
                cp = wgt * cp + (1.0 - wgt) * cp_base
                u = (xi - x_v) / k[K_HV]
                if abs(u) < 1.0:
                    cp -= amp_v * (1.0 - u * u) ** 2
                cp -= 0.5 * amp_nc * points[i, P_ADDED_MASS]
            elif side < 0.0:
                cp += 0.5 * amp_nc * points[i, P_ADDED_MASS]
            if want_cp:
                cp_out[s_idx, i] = cp
            p_clean = q * cp
            if not sensor_on:
                pressure_out[s_idx, i] = p_clean
                continue
            if not started:
                sensor[i] = p_clean
                sensor[n + i] = p_clean
            e = tube[i, 0]
            p_prev = sensor[n + i]
            sensor[i] = e * sensor[i] + p_clean - e * p_prev - tube[i, 1] * (p_clean - p_prev)
            sensor[n + i] = p_clean
            pressure_out[s_idx, i] = sensor[i] + sensor[2 * n + i]
        if sensor_on:
            sensor[3 * n] = 1.0
            # Drift and noise, drawn in pairs (Box–Muller gives two).
            for i in range(0, n, 2):
                z0, z1 = normal_pair(rng)
                sensor[2 * n + i] = sensor[2 * n + i] * k[K_DRIFT_E] + k[K_DRIFT_S] * z0
                if i + 1 < n:
                    sensor[2 * n + i + 1] = sensor[2 * n + i + 1] * k[K_DRIFT_E] + k[K_DRIFT_S] * z1
            for i in range(0, n, 2):
                z0, z1 = normal_pair(rng)
                pressure_out[s_idx, i] += k[K_NOISE] * z0
                if i + 1 < n:
                    pressure_out[s_idx, i + 1] += k[K_NOISE] * z1


class PressureModel:
    """Tap-pressure synthesis for one wing and tap layout (module docstring).

    `synthesize(aero_out, rng, pressure_out, cp_out, truth_out)` advances the per-tap sensor
    state (tube lags, drift); `clean(aero_out)` gives noise-free Cp at any point set.
    """

    def __init__(self, params: WingParams, taps: TapLayout) -> None:
        self.params = params
        self.taps = taps
        self.tables = fine_grid_tables(
            params.thickness_ratio,
            params.separation_blend_width_c,
            params.vortex_half_width_c,
            params.vortex_start_c,
            params.vortex_end_c,
            params.base_pressure_min,
        )
        if abs(taps.thickness_ratio - params.thickness_ratio) > 1e-9:
            raise ValueError(
                f"tap layout is for t/c = {taps.thickness_ratio}, the wing has "
                f"t/c = {params.thickness_ratio}; use taps made for this section"
            )
        self.points = point_set(taps.x_c, taps.side, params.thickness_ratio)
        self.fine_points = point_set(
            self.tables.x, np.sign(self.tables.phi), params.thickness_ratio
        )
        t = self.tables
        k = np.zeros(N_K)
        k[K_Q] = params.dynamic_pressure_pa
        k[K_AC0], k[K_DAC], k[K_NAC] = t.alpha_c_deg[0], ALPHA_C_STEP_DEG, t.alpha_c_deg.size
        k[K_TH0] = t.theta_sep[0]
        k[K_DTH] = t.theta_sep[1] - t.theta_sep[0]
        k[K_NTH] = t.theta_sep.size
        k[K_BLEND], k[K_XSMIN], k[K_HV] = (
            params.separation_blend_width_c,
            X_SEP_MIN,
            params.vortex_half_width_c,
        )
        k[K_XV0], k[K_DXV], k[K_NXV] = (
            t.vortex_x[0],
            t.vortex_x[1] - t.vortex_x[0],
            t.vortex_x.size,
        )
        k[K_NCN], k[K_NCA], k[K_NCM] = t.added_mass
        period = params.sample_period_s
        k[K_NOISE] = params.pressure_noise_pa
        k[K_DRIFT_E] = math.exp(-period / params.drift_time_s)
        k[K_DRIFT_S] = params.drift_std_pa * math.sqrt(1.0 - k[K_DRIFT_E] ** 2)
        k[K_SENSOR_ON] = 1.0
        k[K_DBASE], k[K_NBASE] = np.pi / (N_BASE - 1), N_BASE
        k[K_CPB_MIN] = params.base_pressure_min
        self.coefficients = k
        self._clean_coefficients = k.copy()
        self._clean_coefficients[K_SENSOR_ON] = 0.0
        # Tube lags: fixed hardware, so drawn from the rig's own seed, not the run seed.
        rig_rng = np.random.default_rng(params.tube_layout_seed)
        self.tube_lag_s = rig_rng.uniform(params.tube_lag_min_s, params.tube_lag_max_s, taps.n_taps)
        e = np.exp(-period / self.tube_lag_s)
        self.tube = np.ascontiguousarray(np.stack([e, self.tube_lag_s / period * (1.0 - e)], 1))
        self.sensor_state = np.zeros(3 * taps.n_taps + 1)

    def synthesize(
        self,
        aero_out: np.ndarray,
        rng: np.ndarray,
        pressure_out: np.ndarray,
        cp_out: np.ndarray,
        truth_out: np.ndarray,
    ) -> None:
        """Kernel call at the taps (advances sensor state and rng); see `synthesize`."""
        t = self.tables
        synthesize(
            aero_out,
            self.points,
            t.circulation,
            t.alpha_c_top,
            t.vortex,
            t.base_speed,
            self.coefficients,
            self.tube,
            self.sensor_state,
            rng,
            pressure_out,
            cp_out,
            truth_out,
        )

    def clean_cp(self, aero_out: np.ndarray, fine: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free Cp (K, n) at the taps (or the fine contour if fine) and truth (K, N_TRUTH)
        for aero samples (K, aero.N_OUT); no sensor state is touched."""
        points = self.fine_points if fine else self.points
        kk = aero_out.shape[0]
        n = points.shape[0]
        cp = np.empty((kk, n))
        pressure = np.empty((kk, n))
        truth = np.empty((kk, N_TRUTH))
        t = self.tables
        synthesize(
            np.ascontiguousarray(aero_out),
            points,
            t.circulation,
            t.alpha_c_top,
            t.vortex,
            t.base_speed,
            self._clean_coefficients,
            np.zeros((n, 2)),
            np.zeros(3 * n + 1),
            np.zeros(4, dtype=np.uint64),
            pressure,
            cp,
            truth,
        )
        return cp, truth
