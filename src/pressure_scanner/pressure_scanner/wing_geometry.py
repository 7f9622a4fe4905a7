"""The rig's wing model and nominal free stream: what the scanner driver and the lift
integration need to know about the wing.

The simulated wing's full parameter set (``wing_sim.wing_params.WingParams``) extends this
dataclass, so the simulation and the rig nodes share one set of values.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class RigGeometry:
    """NACA 0018 wing model in the VUB wind tunnel (see ``WingParams`` for the full story).

    chord_m, span_m: 0.300 m chord, 0.540 m semi-span; thickness_ratio 0.18 (NACA 0018).
    velocity_m_s, air_density_kg_m3: U = 14.3 m/s, ρ = 1.19 kg/m³ → q = ½ρU² ≈ 122 Pa.
    """

    chord_m: float = 0.300
    span_m: float = 0.540
    thickness_ratio: float = 0.18
    velocity_m_s: float = 14.3
    air_density_kg_m3: float = 1.19

    @property
    def dynamic_pressure_pa(self) -> float:
        """q = ½ρU²."""
        return 0.5 * self.air_density_kg_m3 * self.velocity_m_s**2
