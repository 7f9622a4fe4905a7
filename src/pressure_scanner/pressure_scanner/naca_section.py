"""NACA 00xx section geometry, parametrised by the cosine-spacing angle.

All lengths are in chords (x/c, z/c): x along the chord from the leading edge, z normal to the
chord, positive on the upper (suction side at positive α) surface.

The contour parameter φ ∈ [-π, π] runs from the trailing edge along the lower surface (φ < 0) to
the leading edge (φ = 0) and back along the upper surface (φ > 0) to the trailing edge, with
x/c = (1 - cos φ)/2. Equal steps in φ cluster points at both edges ("cosine spacing"), and
quantities that vary like √x near the leading edge (z, surface speed) are smooth in φ.
"""

import numpy as np

NACA0018_THICKNESS = 0.18

# Closed-trailing-edge variant of the NACA four-digit thickness polynomial (Abbott & von
# Doenhoff, Theory of Wing Sections, 1959, §6.4, with the last coefficient -0.1036 instead of
# -0.1015 so that z(1) = 0, which the panel method's Kutta condition needs).
_THICKNESS_COEFFICIENTS = (0.2969, -0.1260, -0.3516, 0.2843, -0.1036)


def half_thickness(
    x_c: np.ndarray | float, thickness_ratio: float = NACA0018_THICKNESS
) -> np.ndarray:
    """Half thickness z_t/c of a symmetric NACA 00xx section at chord stations x/c.

    x_c: any shape, values in [0, 1]. Returns an array of the same shape.
    """
    x = np.asarray(x_c, dtype=float)
    if np.any((x < 0.0) | (x > 1.0)):
        raise ValueError(
            f"chord stations must lie in [0, 1] (x/c), got min {x.min()}, max {x.max()}"
        )
    a0, a1, a2, a3, a4 = _THICKNESS_COEFFICIENTS
    return 5.0 * thickness_ratio * (a0 * np.sqrt(x) + x * (a1 + x * (a2 + x * (a3 + x * a4))))


def chord_station(phi: np.ndarray | float) -> np.ndarray:
    """x/c = (1 - cos φ)/2 of contour parameter φ (either surface)."""
    return 0.5 * (1.0 - np.cos(np.asarray(phi, dtype=float)))


def contour_parameter(x_c: np.ndarray | float, side: np.ndarray | float) -> np.ndarray:
    """Contour parameter φ of chord station x/c on a side (+1 upper, -1 lower, 0 leading edge).

    Inverse of `chord_station`: φ = side · arccos(1 - 2 x/c).
    """
    x = np.clip(np.asarray(x_c, dtype=float), 0.0, 1.0)
    return np.sign(np.asarray(side, dtype=float)) * np.arccos(1.0 - 2.0 * x)


def contour_point(
    phi: np.ndarray | float, thickness_ratio: float = NACA0018_THICKNESS
) -> tuple[np.ndarray, np.ndarray]:
    """(x/c, z/c) of contour parameter φ ∈ [-π, π]; z < 0 for φ < 0 (lower surface)."""
    phi_arr = np.asarray(phi, dtype=float)
    x = chord_station(phi_arr)
    z = np.sign(phi_arr) * half_thickness(x, thickness_ratio)
    return x, z


def panel_nodes(
    n_panels: int, thickness_ratio: float = NACA0018_THICKNESS
) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-spaced panel corner points, clockwise from the lower trailing edge.

    n_panels must be even so that a node sits exactly on the leading edge.
    Returns (x (n_panels+1,), z (n_panels+1,)); first and last node are the trailing edge.
    """
    if n_panels < 20 or n_panels % 2:
        raise ValueError(f"n_panels must be an even number >= 20, got {n_panels}")
    phi = np.linspace(-np.pi, np.pi, n_panels + 1)
    return contour_point(phi, thickness_ratio)
