"""The simulated wing: angle of attack in, 49 tap pressures out, at the scanner's 200 Hz.

`WingPlant` chains the unsteady aero model (aero.py, 2 kHz internal steps) and the pressure
synthesis with tube lags, drift and noise (pressures.py). Both kernels keep their state and
random streams inside the plant, so `simulate` over a record and `step` sample by sample give
identical results for the same seed. docs/plant.md describes the model and its measured figures.

Regenerate the quasi-static figure with
    .venv/bin/python -m wing_sim.plant docs/quasi_static_lift.png
"""

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, overload

import numpy as np

from pressure_scanner.taps import TapLayout, load_taps
from wing_sim import aero, pressures
from wing_sim.aero import UnsteadyAerodynamics
from wing_sim.pressures import PressureModel
from wing_sim.random_stream import new_state
from wing_sim.wing_params import WingParams

SENSOR_STREAM = 2
MAX_ABS_ALPHA_DEG = 45.0  # beyond this the model (and its tables) are not meant to be used


@dataclass(frozen=True)
class WingTruth:
    """The model's state at one sample (what the rig cannot measure directly).

    cl: the aero model's lift coefficient (circulatory + vortex + added mass).
    cl_fine, cd, cm, cn, ca: coefficients of the synthesised pressure distribution integrated on
        the fine grid (pressure drag; moment about c/4, nose-up positive).
    separation_point: f (x/c); stalled: flow regime; vortex_lift: C_l of the vortex;
    vortex_position: x/c of its suction bump; vortex_time_tu: τ_v / T_u since the last stall;
    alpha_effective: α_E [rad]; alpha: the input α [rad]; light_stall: the stall-type regime is
    the light (trailing-edge) one (docs/plant.md §2).
    """

    cl: float
    cl_fine: float
    cd: float
    cm: float
    cn: float
    ca: float
    separation_point: float
    stalled: bool
    vortex_lift: float
    vortex_position: float
    vortex_time_tu: float
    alpha_effective: float
    alpha: float
    light_stall: bool


@dataclass(frozen=True)
class WingTruthSeries:
    """`WingTruth` fields as (K,) arrays over a simulated record."""

    cl: np.ndarray
    cl_fine: np.ndarray
    cd: np.ndarray
    cm: np.ndarray
    cn: np.ndarray
    ca: np.ndarray
    separation_point: np.ndarray
    stalled: np.ndarray
    vortex_lift: np.ndarray
    vortex_position: np.ndarray
    vortex_time_tu: np.ndarray
    alpha_effective: np.ndarray
    alpha: np.ndarray
    light_stall: np.ndarray

    @classmethod
    def from_kernels(cls, aero_out: np.ndarray, truth: np.ndarray) -> "WingTruthSeries":
        return cls(
            cl=aero_out[:, aero.O_CL].copy(),
            cl_fine=truth[:, pressures.T_CL].copy(),
            cd=truth[:, pressures.T_CD].copy(),
            cm=truth[:, pressures.T_CM].copy(),
            cn=truth[:, pressures.T_CN].copy(),
            ca=truth[:, pressures.T_CA].copy(),
            separation_point=aero_out[:, aero.O_F].copy(),
            stalled=aero_out[:, aero.O_STALLED] != 0.0,
            vortex_lift=aero_out[:, aero.O_CL_VORTEX].copy(),
            vortex_position=aero_out[:, aero.O_X_V].copy(),
            vortex_time_tu=aero_out[:, aero.O_TAU_V].copy(),
            alpha_effective=aero_out[:, aero.O_ALPHA_E].copy(),
            alpha=aero_out[:, aero.O_ALPHA].copy(),
            light_stall=aero_out[:, aero.O_LIGHT] != 0.0,
        )

    def at(self, k: int) -> WingTruth:
        """The truth of sample k."""
        return WingTruth(
            cl=float(self.cl[k]),
            cl_fine=float(self.cl_fine[k]),
            cd=float(self.cd[k]),
            cm=float(self.cm[k]),
            cn=float(self.cn[k]),
            ca=float(self.ca[k]),
            separation_point=float(self.separation_point[k]),
            stalled=bool(self.stalled[k]),
            vortex_lift=float(self.vortex_lift[k]),
            vortex_position=float(self.vortex_position[k]),
            vortex_time_tu=float(self.vortex_time_tu[k]),
            alpha_effective=float(self.alpha_effective[k]),
            alpha=float(self.alpha[k]),
            light_stall=bool(self.light_stall[k]),
        )


class WingPlant:
    """Simulated pitching NACA 0018 wing with 49 pressure taps.

    params: WingParams (defaults if None); taps: TapLayout (config/taps.yaml if None);
    seed: run seed of the stochastic stall, drift and noise (tube lags are fixed per rig by
    params.tube_layout_seed).

    step(alpha_rad) -> (n_taps,) tap pressures [Pa] of the next sample;
    simulate(alpha_rad (K,)) -> (pressures (K, n_taps), WingTruthSeries), continuing from the
    current state, identical to K calls of step; truth: WingTruth of the last sample;
    tap_xyz: (n_taps, 3) tap positions [m] in the wing frame.
    """

    def __init__(
        self, params: WingParams | None = None, taps: TapLayout | None = None, seed: int = 0
    ) -> None:
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.params = params or WingParams()
        self.taps = taps if taps is not None else load_taps()
        self.seed = int(seed)
        self._aero = UnsteadyAerodynamics(self.params, self.seed)
        self._pressures = PressureModel(self.params, self.taps)
        self._sensor_rng = new_state(self.seed, SENSOR_STREAM)
        self.tap_xyz = self.taps.xyz_m(self.params.chord_m, self.params.span_m)
        self._alpha1 = np.zeros(1)
        self._aero1 = np.zeros((1, aero.N_OUT))
        self._truth1 = np.zeros((1, pressures.N_TRUTH))
        self._no_cp = np.zeros((0, self.taps.n_taps))
        self._samples = 0

    @property
    def dynamic_pressure_pa(self) -> float:
        return self.params.dynamic_pressure_pa

    @property
    def sample_rate_hz(self) -> float:
        return self.params.sample_rate_hz

    @property
    def samples(self) -> int:
        """Samples produced so far."""
        return self._samples

    @property
    def tube_lag_s(self) -> np.ndarray:
        """(n_taps,) first-order tube lag time constant of each tap."""
        return self._pressures.tube_lag_s.copy()

    @property
    def truth(self) -> WingTruth:
        """Model truth of the last sample produced (by step or simulate)."""
        if self._samples == 0:
            raise RuntimeError("no sample produced yet: call step() or simulate() first")
        return WingTruthSeries.from_kernels(self._aero1, self._truth1).at(0)

    def step(self, alpha_rad: float) -> np.ndarray:
        """Tap pressures [Pa] (n_taps,) of the next 200 Hz sample at angle of attack alpha_rad
        (true aerodynamic angle incl. gust); α̇ comes from the previous sample."""
        alpha = float(alpha_rad)
        if not math.isfinite(alpha) or abs(alpha) > math.radians(MAX_ABS_ALPHA_DEG):
            raise ValueError(
                f"alpha_rad = {alpha_rad!r} is not a finite angle within ±{MAX_ABS_ALPHA_DEG}°; "
                "the plant state is unchanged"
            )
        self._alpha1[0] = alpha
        self._aero.advance(self._alpha1, self._aero1)
        pressure = np.empty((1, self.taps.n_taps))
        self._pressures.synthesize(
            self._aero1, self._sensor_rng, pressure, self._no_cp, self._truth1
        )
        self._samples += 1
        return pressure[0]

    @overload
    def simulate(
        self, alpha_rad: np.ndarray, *, clean_cp: Literal[False] = False
    ) -> tuple[np.ndarray, WingTruthSeries]: ...
    @overload
    def simulate(
        self, alpha_rad: np.ndarray, *, clean_cp: Literal[True]
    ) -> tuple[np.ndarray, WingTruthSeries, np.ndarray]: ...
    @overload
    def simulate(
        self, alpha_rad: np.ndarray, *, clean_cp: bool
    ) -> tuple[np.ndarray, WingTruthSeries] | tuple[np.ndarray, WingTruthSeries, np.ndarray]: ...
    def simulate(
        self, alpha_rad: np.ndarray, *, clean_cp: bool = False
    ) -> tuple[np.ndarray, WingTruthSeries] | tuple[np.ndarray, WingTruthSeries, np.ndarray]:
        """Tap pressures (K, n_taps) [Pa] and truth for alpha_rad (K,) [rad].

        With clean_cp=True also returns the noise-, lag- and drift-free tap Cp (K, n_taps).
        """
        alpha = np.ascontiguousarray(alpha_rad, dtype=np.float64)
        if alpha.ndim != 1 or alpha.size == 0:
            raise ValueError(f"alpha_rad must be a non-empty 1-D array (K,), got {alpha.shape}")
        bad = ~np.isfinite(alpha) | (np.abs(alpha) > math.radians(MAX_ABS_ALPHA_DEG))
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"alpha_rad[{k}] = {alpha[k]!r} is not a finite angle within "
                f"±{MAX_ABS_ALPHA_DEG}° ({int(bad.sum())} such samples); nothing was simulated"
            )
        n = alpha.size
        aero_out = np.empty((n, aero.N_OUT))
        self._aero.advance(alpha, aero_out)
        pressure = np.empty((n, self.taps.n_taps))
        truth = np.empty((n, pressures.N_TRUTH))
        cp = np.empty((n, self.taps.n_taps)) if clean_cp else self._no_cp
        self._pressures.synthesize(aero_out, self._sensor_rng, pressure, cp, truth)
        self._aero1[0] = aero_out[-1]
        self._truth1[0] = truth[-1]
        self._samples += n
        series = WingTruthSeries.from_kernels(aero_out, truth)
        if clean_cp:
            return pressure, series, cp
        return pressure, series


def quasi_static_sweep(
    rate_deg_s: float = 0.5,
    alpha_max_deg: float = 30.0,
    alpha_min_deg: float = 0.0,
    params: WingParams | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, WingTruthSeries]:
    """Pitch up from alpha_min to alpha_max and back at rate_deg_s (the baseline campaign run).

    Returns (alpha_rad (K,), tap pressures (K, n_taps) [Pa], truth).
    """
    p = params or WingParams()
    span = alpha_max_deg - alpha_min_deg
    if rate_deg_s <= 0 or span <= 0:
        raise ValueError("need rate_deg_s > 0 and alpha_max_deg > alpha_min_deg")
    n_half = round(span / rate_deg_s * p.sample_rate_hz)
    up = np.linspace(alpha_min_deg, alpha_max_deg, n_half + 1)
    alpha = np.deg2rad(np.concatenate([up, up[-2::-1]]))
    pressure, truth = WingPlant(p, seed=seed).simulate(alpha)
    return alpha, pressure, truth


def plot_quasi_static_lift(path: str | Path, seed: int = 0) -> Path:
    """Save the quasi-static C_l–α curve (tap-integrated, up and down sweep) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pressure_scanner.integration import PressureIntegrator
    from wing_sim.aero import static_lift_coefficient

    params = WingParams()
    alpha, pressure, _ = quasi_static_sweep(params=params, seed=seed)
    coeffs = PressureIntegrator().integrate(pressure, alpha, params.dynamic_pressure_pa)
    half = alpha.size // 2 + 1
    deg = np.rad2deg(alpha)
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=120)
    ax.plot(deg[:half], coeffs.cl[:half], lw=0.8, color="tab:blue", label="pitch up (49 taps)")
    ax.plot(deg[half:], coeffs.cl[half:], lw=0.8, color="tab:red", label="pitch down (49 taps)")
    grid = np.deg2rad(np.linspace(0.0, 30.0, 301))
    for branch, style in (("attached", "--"), ("separated", ":")):
        ax.plot(
            np.rad2deg(grid),
            static_lift_coefficient(grid, params, branch),
            style,
            color="0.3",
            lw=1.0,
            label=f"static target, {branch} branch",
        )
    ax.plot(deg, 0.104 * deg, color="0.7", lw=0.8, label="C$_{l\\alpha}$ = 0.104/°")
    for offset in (6.6, 15.7, 19.9):
        ax.axvspan(offset - 2.4, offset + 2.4, color="tab:green", alpha=0.08)
    ax.set_xlim(0, 30)
    ax.set_ylim(0, 1.8)
    ax.set_xlabel("angle of attack α [°]")
    ax.set_ylabel("lift coefficient C$_l$")
    ax.set_title("Simulated quasi-static sweep, 0.5°/s (shaded: multisine offsets ± 1σ)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


if __name__ == "__main__":
    target = sys.argv[1] if len(sys.argv) > 1 else "docs/quasi_static_lift.png"
    print(plot_quasi_static_lift(target))
