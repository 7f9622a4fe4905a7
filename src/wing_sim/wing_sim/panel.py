"""Hess–Smith panel method: inviscid surface-speed bases of a symmetric NACA 00xx section.

Constant-strength source panels plus one vortex strength shared by all panels, flow tangency at
the panel midpoints and the Kutta condition (equal and opposite tangential speed on the two
trailing-edge panels) — Hess & Smith, Prog. Aerosp. Sci. 8 (1967); panel influence formulas of
Katz & Plotkin, Low-Speed Aerodynamics, 2nd ed. (2001), eqs. 10.21–10.22 and 10.39–10.40.

Potential flow with the Kutta condition is linear in the free-stream components, so the
tangential surface speed at any angle α is V_t/U = a cos α + b sin α, where a and b are the
solutions for the free stream along the chord (α = 0°) and normal to it (α = 90°). `SpeedBasis`
holds a and b as cubic splines of the contour parameter φ (see naca_section.py); the pressure
coefficient of the attached, inviscid flow is then Cp = 1 − (a cos α + b sin α)².
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.interpolate import CubicSpline

from pressure_scanner.naca_section import NACA0018_THICKNESS, panel_nodes

DEFAULT_PANELS = 240


@dataclass(frozen=True)
class PanelSolution:
    """Hess–Smith solution for unit free stream at angles 0° and 90° (columns 0 and 1).

    x_mid, z_mid, phi_mid: (N,) panel midpoints and their contour parameter.
    speed: (N, 2) signed tangential speed V_t/U at the midpoints, positive in the clockwise
        contour direction (lower trailing edge → leading edge → upper trailing edge).
    vortex_strength: (2,) the shared vortex-sheet strength γ/U of each solution.
    perimeter: contour length in chords.
    """

    x_mid: np.ndarray
    z_mid: np.ndarray
    phi_mid: np.ndarray
    speed: np.ndarray
    vortex_strength: np.ndarray
    perimeter: float

    def lift_coefficient_kutta_joukowski(self, alpha_rad: np.ndarray | float) -> np.ndarray:
        """C_l = 2Γ/(U c) with Γ = γ · perimeter (Kutta–Joukowski), for angles α."""
        alpha = np.asarray(alpha_rad, dtype=float)
        gamma = self.vortex_strength[0] * np.cos(alpha) + self.vortex_strength[1] * np.sin(alpha)
        return 2.0 * gamma * self.perimeter


def solve_hess_smith(x_nodes: np.ndarray, z_nodes: np.ndarray) -> PanelSolution:
    """Solve the Hess–Smith problem on a closed contour given clockwise from the trailing edge.

    x_nodes, z_nodes: (N+1,) panel corners in chords; the first and last node coincide at a
    sharp trailing edge and the lower surface comes first (naca_section.panel_nodes).
    """
    x_nodes = np.asarray(x_nodes, dtype=float)
    z_nodes = np.asarray(z_nodes, dtype=float)
    if x_nodes.shape != z_nodes.shape or x_nodes.ndim != 1 or x_nodes.size < 21:
        raise ValueError("x_nodes and z_nodes must be equal-length 1-D arrays of >= 21 nodes")
    dx = np.diff(x_nodes)
    dz = np.diff(z_nodes)
    length = np.hypot(dx, dz)
    if np.any(length <= 0.0):
        raise ValueError("panel nodes must be distinct (zero-length panel found)")
    cos_t = dx / length
    sin_t = dz / length
    x_mid = 0.5 * (x_nodes[:-1] + x_nodes[1:])
    z_mid = 0.5 * (z_nodes[:-1] + z_nodes[1:])
    n = x_mid.size

    # Midpoint i in the local frame of panel j (origin at its first node, x along the panel).
    ddx = x_mid[:, None] - x_nodes[None, :-1]
    ddz = z_mid[:, None] - z_nodes[None, :-1]
    xl = ddx * cos_t[None, :] + ddz * sin_t[None, :]
    zl = -ddx * sin_t[None, :] + ddz * cos_t[None, :]
    r1_sq = xl**2 + zl**2
    r2_sq = (xl - length[None, :]) ** 2 + zl**2
    log_term = np.log(r1_sq / r2_sq) / (4.0 * np.pi)
    angle_term = (np.arctan2(zl, xl - length[None, :]) - np.arctan2(zl, xl)) / (2.0 * np.pi)
    # The midpoint seen from the outer side of its own panel: subtended angle π, no log term.
    np.fill_diagonal(angle_term, 0.5)
    np.fill_diagonal(log_term, 0.0)

    # Local (u, w) of unit source: (log, angle); of unit vortex: (angle, -log). To global axes.
    src_u = log_term * cos_t[None, :] - angle_term * sin_t[None, :]
    src_w = log_term * sin_t[None, :] + angle_term * cos_t[None, :]
    vtx_u = angle_term * cos_t[None, :] + log_term * sin_t[None, :]
    vtx_w = angle_term * sin_t[None, :] - log_term * cos_t[None, :]

    normal_x, normal_z = -sin_t, cos_t
    src_normal = src_u * normal_x[:, None] + src_w * normal_z[:, None]
    src_tangent = src_u * cos_t[:, None] + src_w * sin_t[:, None]
    vtx_normal = (vtx_u * normal_x[:, None] + vtx_w * normal_z[:, None]).sum(axis=1)
    vtx_tangent = (vtx_u * cos_t[:, None] + vtx_w * sin_t[:, None]).sum(axis=1)

    system = np.zeros((n + 1, n + 1))
    system[:n, :n] = src_normal
    system[:n, n] = vtx_normal
    # Kutta condition: V_t(first panel) + V_t(last panel) = 0.
    system[n, :n] = src_tangent[0] + src_tangent[-1]
    system[n, n] = vtx_tangent[0] + vtx_tangent[-1]

    free_stream = np.array([[1.0, 0.0], [0.0, 1.0]])  # columns: α = 0°, α = 90°
    fs_normal = normal_x[:, None] * free_stream[0] + normal_z[:, None] * free_stream[1]
    fs_tangent = cos_t[:, None] * free_stream[0] + sin_t[:, None] * free_stream[1]
    rhs = np.zeros((n + 1, 2))
    rhs[:n] = -fs_normal
    rhs[n] = -(fs_tangent[0] + fs_tangent[-1])
    strengths = np.linalg.solve(system, rhs)
    sigma, gamma = strengths[:n], strengths[n]
    speed = fs_tangent + src_tangent @ sigma + vtx_tangent[:, None] * gamma[None, :]

    side = np.where(np.arange(n) < n // 2, -1.0, 1.0)
    phi_mid = side * np.arccos(np.clip(1.0 - 2.0 * x_mid, -1.0, 1.0))
    return PanelSolution(
        x_mid=x_mid,
        z_mid=z_mid,
        phi_mid=phi_mid,
        speed=speed,
        vortex_strength=gamma,
        perimeter=float(length.sum()),
    )


@dataclass(frozen=True)
class SpeedBasis:
    """Surface-speed bases a(φ), b(φ) of the attached inviscid flow (module docstring).

    Evaluate with `speeds(phi)`; `pressure_coefficient(phi, alpha)` gives Cp = 1 − V_t².
    """

    solution: PanelSolution
    thickness_ratio: float
    _spline: CubicSpline

    def speeds(self, phi: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(a, b) at contour parameters φ ∈ [-π, π]; arrays of φ's shape."""
        phi_arr = np.asarray(phi, dtype=float)
        if np.any(np.abs(phi_arr) > np.pi + 1e-12):
            raise ValueError("contour parameter φ must lie in [-π, π]")
        values = self._spline(phi_arr)
        return values[..., 0], values[..., 1]

    def pressure_coefficient(
        self, phi: np.ndarray | float, alpha_rad: np.ndarray | float
    ) -> np.ndarray:
        """Inviscid attached-flow Cp at contour points φ and angle α (broadcast together)."""
        a, b = self.speeds(phi)
        alpha = np.asarray(alpha_rad, dtype=float)
        v = a * np.cos(alpha) + b * np.sin(alpha)
        return 1.0 - v * v


@lru_cache(maxsize=8)
def speed_basis(
    thickness_ratio: float = NACA0018_THICKNESS, n_panels: int = DEFAULT_PANELS
) -> SpeedBasis:
    """Surface-speed bases of the NACA 00xx section, solved once per (thickness, panels)."""
    x_nodes, z_nodes = panel_nodes(n_panels, thickness_ratio)
    solution = solve_hess_smith(x_nodes, z_nodes)
    # Splines in φ are smooth through the leading edge; the end values extrapolate the last
    # midpoints to the trailing edge (φ = ±π).
    spline = CubicSpline(solution.phi_mid, solution.speed, axis=0, extrapolate=True)
    return SpeedBasis(solution=solution, thickness_ratio=thickness_ratio, _spline=spline)
