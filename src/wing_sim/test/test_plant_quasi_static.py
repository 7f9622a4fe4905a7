"""Quasi-static baseline sweep (0.5°/s to 30° and back), lift by pressure integration: the
paper's Fig. 5 regimes — linear, separating, hysteretic, fully separated."""

import numpy as np
import pytest

from pressure_scanner.integration import PressureIntegrator
from wing_sim.plant import quasi_static_sweep


@pytest.fixture(scope="module")
def sweep() -> dict[str, np.ndarray]:
    alpha, pressure, truth = quasi_static_sweep(rate_deg_s=0.5, alpha_max_deg=30.0, seed=0)
    coeffs = PressureIntegrator().integrate(pressure, alpha, 121.67)
    assert coeffs.valid.all()
    half = alpha.size // 2 + 1
    deg = np.rad2deg(alpha)
    return {
        "up_deg": deg[:half],
        "up_cl": coeffs.cl[:half],
        "down_deg": deg[half:][::-1],
        "down_cl": coeffs.cl[half:][::-1],
        "up_f": truth.separation_point[:half],
        "down_stalled": truth.stalled[half:][::-1],
        "up_stalled": truth.stalled[:half],
    }


def _binned(deg: np.ndarray, cl: np.ndarray, lo: float, hi: float) -> float:
    sel = (deg >= lo) & (deg < hi)
    return float(cl[sel].mean())


def test_linear_below_10_degrees_with_the_paper_slope(sweep: dict[str, np.ndarray]) -> None:
    sel = (sweep["up_deg"] > 0.5) & (sweep["up_deg"] < 9.0)
    slope, _ = np.polyfit(sweep["up_deg"][sel], sweep["up_cl"][sel], 1)
    assert slope == pytest.approx(0.104, rel=0.05)
    residual = sweep["up_cl"][sel] - np.polyval(
        np.polyfit(sweep["up_deg"][sel], sweep["up_cl"][sel], 1), sweep["up_deg"][sel]
    )
    assert np.abs(residual).max() < 0.01  # straight, not just the right mean slope


def test_slope_falls_above_10_degrees(sweep: dict[str, np.ndarray]) -> None:
    d, c = sweep["up_deg"], sweep["up_cl"]
    slope_low = (_binned(d, c, 7.5, 8.5) - _binned(d, c, 3.5, 4.5)) / 4.0
    slope_12 = (_binned(d, c, 13.5, 14.5) - _binned(d, c, 11.5, 12.5)) / 2.0
    slope_16 = (_binned(d, c, 17.5, 18.5) - _binned(d, c, 15.5, 16.5)) / 2.0
    assert slope_12 < 0.8 * slope_low
    assert slope_16 < slope_12
    assert sweep["up_f"][(d > 14.0) & (d < 15.0)].max() < 1.0  # trailing-edge separation


def test_hysteresis_loop_opens_between_16_and_24_degrees(sweep: dict[str, np.ndarray]) -> None:
    up_d, up_c = sweep["up_deg"], sweep["up_cl"]
    dn_d, dn_c = sweep["down_deg"], sweep["down_cl"]
    for lo in (18.0, 19.0):
        gap = _binned(up_d, up_c, lo, lo + 1.0) - _binned(dn_d, dn_c, lo, lo + 1.0)
        assert gap > 0.3
    for lo in (2.0, 8.0, 12.0, 14.0):
        gap = _binned(up_d, up_c, lo, lo + 1.0) - _binned(dn_d, dn_c, lo, lo + 1.0)
        assert abs(gap) < 0.01
    # the loop closes where the flow switches: stall on the way up, reattachment down
    stall_deg = up_d[np.argmax(sweep["up_stalled"])]
    reattach_deg = dn_d[np.flatnonzero(sweep["down_stalled"]).min()]
    assert 20.0 < stall_deg < 24.0
    assert 15.5 < reattach_deg < 18.0


def test_fully_separated_above_24_degrees(sweep: dict[str, np.ndarray]) -> None:
    up_d, up_c = sweep["up_deg"], sweep["up_cl"]
    dn_d, dn_c = sweep["down_deg"], sweep["down_cl"]
    above = up_d > 24.0
    assert sweep["up_stalled"][above].all()
    assert np.median(sweep["up_f"][above]) < 0.05
    for lo in (24.5, 26.5, 28.5):
        up = _binned(up_d, up_c, lo, lo + 1.5)
        down = _binned(dn_d, dn_c, lo, lo + 1.5)
        assert abs(up - down) < 0.05  # one branch: only the separated-flow unsteadiness
    assert _binned(up_d, up_c, 25.0, 27.0) < 0.7 * up_c.max()
