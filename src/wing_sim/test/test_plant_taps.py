"""The plant's tap positions in metres in the wing frame (layout: pressure_scanner's taps.yaml)."""

import numpy as np

from wing_sim.plant import WingPlant


def test_tap_positions_in_metres_in_the_wing_frame() -> None:
    plant = WingPlant()
    xyz = plant.tap_xyz
    taps = plant.taps
    assert xyz.shape == (49, 3)
    np.testing.assert_allclose(xyz[:, 0], 0.300 * taps.x_c)
    np.testing.assert_allclose(xyz[:, 1], 0.270)  # mid-span row of the 0.540 m semi-span
    np.testing.assert_allclose(xyz[:, 2], 0.300 * taps.z_c)
    assert xyz[taps.upper, 2].min() > 0 > xyz[taps.lower, 2].max()
