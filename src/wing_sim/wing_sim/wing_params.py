"""All parameters of the simulated wing in one dataclass (docs/design.md §6; docs/plant.md).

Angles in the parameter set are in degrees where the name says `_deg`; times in seconds unless
the name ends in `_tu`, meaning units of the convective time T_u = c/(2U) (≈ 10.5 ms here), as
in Hansen, Gaunaa & Madsen, Risø-R-1354 (2004).
"""

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any

from pressure_scanner.wing_geometry import RigGeometry


@dataclass(frozen=True)
class WingParams(RigGeometry):
    """Simulated NACA 0018 wing in the VUB wind tunnel: flow, aerodynamics, pressure sensing.

    Flow and geometry
        chord_m, span_m: 0.300 m chord, 0.540 m semi-span; thickness_ratio 0.18 (NACA 0018).
        velocity_m_s, air_density_kg_m3: U = 14.3 m/s, ρ = 1.19 kg/m³ → q = ½ρU² ≈ 122 Pa.
        pivot_x_c: pitch axis (quarter chord) for the 3/4-chord downwash of the pitch rate.
    Time
        sample_rate_hz: output rate (200 Hz, the scanner rate); substeps: aero integration
        steps per sample (10 → 2 kHz).
    Attached-flow unsteady aerodynamics (HGM form of Beddoes–Leishman)
        lift_slope_per_deg: C_lα = 0.104 /° (the paper's quasi-static slope below 10°).
        wagner_a1, wagner_b1, wagner_a2, wagner_b2: two-term Wagner (Jones) approximation.
        pressure_lag_tu: T_p = 1.7 T_u; separation_lag_down_tu / _up_tu: T_f when the
        separation point moves forward (3 T_u) / aft, reattaching (6 T_u).
    Static separation point f(α) (Kirchhoff, docs/plant.md §2): attached branch
        f = 1 for |α| ≤ alpha_linear_deg, then 1 − (1 − f_full)·s^separation_exponent with
        s = (|α| − α_lin)/(α_full − α_lin), reaching f_full_separation at
        alpha_full_separation_deg; separated branch f = f_full + (f_reattach − f_full)·
        (α_full − |α|)/(α_full − α_reattach), capped by the attached branch.
    Bistable stall (random regime switch, hazards on the lagged angle α_F)
        alpha_stall_deg, alpha_reattach_deg: hazard mid-points (22°, 16.5°);
        switch_spread_deg: 0.5° (Gaussian-CDF ramp of the hazard); switch_time_s: τ = 0.015 s
        (hazard 1/τ far past the mid-point). The first design sketch suggested 0.7° and 0.2 s
        (docs/design.md §6); with those the stall time at 19.9° varies so much from cycle to cycle
        that even the period-averaged response explains only ~40% of a sine's variance, and
        the per-cycle randomness buries the stall-type regimes below: measured on the default
        campaign, the high level's SNR near 1.02 Hz is 15.6 dB (paper: 9 dB; 20 dB with 0.5° /
        0.015 s) but its periods form one cluster (docs/plant.md §7).
        separation_noise_std, separation_noise_time_s: Ornstein–Uhlenbeck noise on √f in
        separated flow (σ = 0.03 → C_l std ≈ 0.045 fully separated at 25°).
    Stall-type regimes (docs/plant.md §2; a two-state Markov process in time)
        light_stall_fraction: long-run fraction of the time in the light (trailing-edge) stall
        regime, 0.2; 0 switches the regimes off (preset "repeatable_stall"). In it the
        leading-edge stall event does not happen: the separation point follows the attached
        branch's trailing-edge separation both ways, without hysteresis or vortex. The rest of
        the time the wing is in the deep (leading-edge) stall regime described above.
        light_stall_dwell_s: mean duration of a light-stall episode, 80 s (exponential); the
        deep regime's mean duration follows as dwell·(1 − fraction)/fraction = 320 s.
    Leading-edge vortex (Beddoes–Leishman vortex lift, Leishman & Beddoes, JAHS 34(3), 1989)
        vortex_lag_tu: T_V0 = 6; vortex_travel_tu: T_VL = 11 (vortex at the trailing edge);
        vortex_strength_mean, vortex_strength_cv: per-stall-event log-normal strength factor.
    Pressure synthesis (pressures.py)
        separation_blend_width_c: chordwise width of the Kirchhoff blend to base pressure.
        base_pressure_min: floor of the base pressure Cp_b (bluff-body base pressure of the
        stalled section, Roshko, NACA TN 3169, 1954), so deep stall shows a flat suction
        plateau over an over-pressured lower surface.
        vortex_half_width_c, vortex_start_c, vortex_end_c: the travelling suction bump.
        tube_lag_min_s, tube_lag_max_s, tube_layout_seed: per-tap first-order tube lags, drawn
        once per rig (fixed seed, not the run seed) uniformly in [min, max].
        pressure_noise_pa: 0.5 Pa white noise per tap and sample.
        drift_std_pa, drift_time_s: per-tap zero drift (Ornstein–Uhlenbeck, σ, τ).
    """

    # chord_m, span_m, thickness_ratio, velocity_m_s, air_density_kg_m3: from RigGeometry
    pivot_x_c: float = 0.25

    sample_rate_hz: float = 200.0
    substeps: int = 10

    lift_slope_per_deg: float = 0.104
    wagner_a1: float = 0.165
    wagner_b1: float = 0.0455
    wagner_a2: float = 0.335
    wagner_b2: float = 0.3
    pressure_lag_tu: float = 1.7
    separation_lag_down_tu: float = 3.0
    separation_lag_up_tu: float = 6.0

    alpha_linear_deg: float = 10.0
    alpha_full_separation_deg: float = 24.0
    separation_exponent: float = 1.5
    f_full_separation: float = 0.02
    f_reattach: float = 0.10

    alpha_stall_deg: float = 22.0
    alpha_reattach_deg: float = 16.5
    switch_spread_deg: float = 0.5
    switch_time_s: float = 0.015
    separation_noise_std: float = 0.03
    separation_noise_time_s: float = 0.05

    vortex_lag_tu: float = 6.0
    vortex_travel_tu: float = 11.0
    vortex_strength_mean: float = 1.7
    vortex_strength_cv: float = 0.3

    light_stall_fraction: float = 0.2
    light_stall_dwell_s: float = 80.0

    separation_blend_width_c: float = 0.05
    base_pressure_min: float = -0.7
    vortex_half_width_c: float = 0.2
    vortex_start_c: float = 0.25
    vortex_end_c: float = 0.9
    tube_lag_min_s: float = 0.002
    tube_lag_max_s: float = 0.004
    tube_layout_seed: int = 4
    pressure_noise_pa: float = 0.5
    drift_std_pa: float = 0.3
    drift_time_s: float = 300.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value):
                raise ValueError(f"WingParams.{f.name} must be finite, got {value}")
        positive = (
            "chord_m span_m thickness_ratio velocity_m_s air_density_kg_m3 sample_rate_hz "
            "substeps lift_slope_per_deg wagner_b1 wagner_b2 pressure_lag_tu "
            "separation_lag_down_tu separation_lag_up_tu alpha_linear_deg separation_exponent "
            "f_full_separation switch_spread_deg switch_time_s separation_noise_time_s "
            "vortex_lag_tu vortex_travel_tu vortex_strength_mean separation_blend_width_c "
            "light_stall_dwell_s "
            "vortex_half_width_c tube_lag_min_s drift_time_s"
        ).split()
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"WingParams.{name} must be > 0, got {getattr(self, name)}")
        non_negative = (
            "separation_noise_std vortex_strength_cv pressure_noise_pa drift_std_pa "
            "wagner_a1 wagner_a2"
        ).split()
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ValueError(f"WingParams.{name} must be >= 0, got {getattr(self, name)}")
        if not isinstance(self.substeps, int):
            raise ValueError(f"WingParams.substeps must be an int, got {self.substeps!r}")
        if self.wagner_a1 + self.wagner_a2 >= 1.0:
            raise ValueError("WingParams: wagner_a1 + wagner_a2 must be < 1")
        if not (0.0 < self.thickness_ratio <= 0.3):
            raise ValueError("WingParams.thickness_ratio must lie in (0, 0.3]")
        if not (0.0 <= self.pivot_x_c <= 1.0):
            raise ValueError("WingParams.pivot_x_c must lie in [0, 1] (chords)")
        if not (
            self.alpha_linear_deg
            < self.alpha_reattach_deg
            < self.alpha_stall_deg
            < self.alpha_full_separation_deg
            <= 40.0
        ):
            raise ValueError(
                "WingParams: need alpha_linear_deg < alpha_reattach_deg < alpha_stall_deg < "
                "alpha_full_separation_deg <= 40, got "
                f"{self.alpha_linear_deg}, {self.alpha_reattach_deg}, {self.alpha_stall_deg}, "
                f"{self.alpha_full_separation_deg}"
            )
        if not (0.0 < self.f_full_separation < self.f_reattach < 1.0):
            raise ValueError("WingParams: need 0 < f_full_separation < f_reattach < 1")
        if not (0.0 <= self.light_stall_fraction < 0.5):
            raise ValueError(
                "WingParams.light_stall_fraction must lie in [0, 0.5): the light-stall regime is "
                "the minority one (0: no regimes)"
            )
        if not (0.0 <= self.vortex_start_c < self.vortex_end_c <= 1.0):
            raise ValueError("WingParams: need 0 <= vortex_start_c < vortex_end_c <= 1")
        if self.vortex_start_c - self.vortex_half_width_c < 0.0:
            raise ValueError(
                "WingParams: the vortex bump must not reach the leading edge "
                "(vortex_start_c >= vortex_half_width_c)"
            )
        if not (-3.0 <= self.base_pressure_min <= 0.0):
            raise ValueError("WingParams.base_pressure_min must lie in [-3, 0]")
        if self.separation_blend_width_c >= 0.5:
            raise ValueError("WingParams.separation_blend_width_c must be < 0.5 chords")
        if self.tube_lag_max_s < self.tube_lag_min_s:
            raise ValueError("WingParams: tube_lag_max_s must be >= tube_lag_min_s")

    @property
    def convective_time_s(self) -> float:
        """T_u = c/(2U), the time unit of the Beddoes–Leishman constants."""
        return self.chord_m / (2.0 * self.velocity_m_s)

    @property
    def lift_slope_per_rad(self) -> float:
        return self.lift_slope_per_deg * 180.0 / math.pi

    @property
    def sample_period_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    @property
    def reynolds_number(self) -> float:
        """Chord Reynolds number with ν = 1.5e-5 m²/s (air near 20 °C)."""
        return self.velocity_m_s * self.chord_m / 1.5e-5


# Named parameter sets (docs/plant.md, "Presets"). "stall_regimes" is the default wing;
# "repeatable_stall" is the wing of release 0.1, before the stall-type regimes: every period at
# the high offset in deep stall, only the stall switch varying from cycle to cycle. It gives bit
# for bit the results of that plant for a seed.
PRESETS: dict[str, dict[str, Any]] = {
    "stall_regimes": {},
    "repeatable_stall": {"light_stall_fraction": 0.0},
}


def wing_params_preset(name: str = "stall_regimes", **overrides: Any) -> WingParams:
    """WingParams of a named preset (PRESETS), with field overrides on top."""
    if name not in PRESETS:
        raise ValueError(f"unknown wing preset {name!r}; choose one of {sorted(PRESETS)}")
    unknown = set(overrides) - {f.name for f in fields(WingParams)}
    if unknown:
        raise ValueError(f"WingParams has no field(s) {sorted(unknown)}")
    return dataclasses.replace(WingParams(), **{**PRESETS[name], **overrides})
