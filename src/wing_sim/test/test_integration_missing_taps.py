"""Missing taps: integrate over the remaining ones while they cover the section, else invalid."""

import math

import numpy as np
import pytest

from pressure_scanner.integration import Coverage, PressureIntegrator
from wing_sim.plant import WingPlant


@pytest.fixture(scope="module")
def attached_samples() -> tuple[np.ndarray, np.ndarray, float]:
    """Tap pressures at 5° and 9° (attached flow), one steady sample each."""
    plant = WingPlant(seed=0)
    alpha = np.deg2rad(np.r_[np.full(200, 5.0), np.full(200, 9.0)])
    pressure, _ = plant.simulate(alpha)
    return pressure[[199, 399]], alpha[[199, 399]], plant.dynamic_pressure_pa


def test_three_random_missing_taps_change_the_coefficients_by_less_than_3_percent(
    attached_samples: tuple[np.ndarray, np.ndarray, float],
) -> None:
    pressure, alpha, q = attached_samples
    integrator = PressureIntegrator()
    full = integrator.integrate(pressure, alpha, q)
    assert full.valid.all() and (full.n_excluded == 0).all()
    rng = np.random.default_rng(7)
    draws = 200
    damaged = np.repeat(pressure, draws, axis=0)
    missing = np.array([rng.choice(49, 3, replace=False) for _ in range(2 * draws)])
    damaged[np.arange(2 * draws)[:, None], missing] = np.nan
    result = integrator.integrate(damaged, np.repeat(alpha, draws), q)
    # every exclusion is reported, tap by tap
    assert (result.n_excluded == 3).all()
    expected_mask = np.zeros_like(result.excluded)
    expected_mask[np.arange(2 * draws)[:, None], missing] = True
    np.testing.assert_array_equal(result.excluded, expected_mask)
    # most draws keep enough coverage, and then the coefficients hold
    assert result.valid.mean() > 0.9
    reference = np.repeat(full.cl, draws)
    ok = result.valid
    assert np.all(np.abs(result.cl[ok] / reference[ok] - 1.0) < 0.03)
    assert np.all(np.abs(result.cn[ok] / np.repeat(full.cn, draws)[ok] - 1.0) < 0.03)
    assert np.all(np.abs(result.cm[ok] - np.repeat(full.cm, draws)[ok]) < 0.01)
    # the rejected draws say why and are never a number
    assert np.all(np.isnan(result.cl[~ok]))
    assert set(result.reason[~ok]) <= {
        Coverage.LEADING_EDGE_GAP,
        Coverage.UPPER_GAP,
        Coverage.LOWER_GAP,
        Coverage.UPPER_TRAILING_EDGE,
        Coverage.LOWER_TRAILING_EDGE,
    }


def test_half_the_upper_surface_missing_invalidates_the_sample(
    attached_samples: tuple[np.ndarray, np.ndarray, float],
) -> None:
    pressure, alpha, q = attached_samples
    integrator = PressureIntegrator()
    upper = integrator.taps.upper
    for half in (upper[:12], upper[12:], upper[6:18]):
        damaged = pressure.copy()
        damaged[:, half] = np.nan
        c = integrator.integrate(damaged, alpha, q)
        assert not c.valid.any()
        assert np.isnan(c.cl).all() and np.isnan(c.cd).all() and np.isnan(c.cm).all()
        assert (c.n_excluded == 12).all()
        assert "invalid" in c.describe(0) and integrator.taps.names[half[0]] in c.describe(0)
    # Every other upper tap gone is also half the taps, but the row still spans the surface
    # at twice the spacing: the criterion keeps it, and the lift holds.
    damaged = pressure.copy()
    damaged[:, upper[1::2]] = np.nan
    c = integrator.integrate(damaged, alpha, q)
    full = integrator.integrate(pressure, alpha, q)
    assert c.valid.all() and np.all(np.abs(c.cl / full.cl - 1.0) < 0.03)


@pytest.mark.parametrize(
    ("names", "reason"),
    [
        (("LE", "U01"), Coverage.LEADING_EDGE_GAP),
        (("U02", "U03"), Coverage.UPPER_GAP),
        (("L10", "L11", "L12"), Coverage.LOWER_GAP),
        (("U23", "U24"), Coverage.UPPER_TRAILING_EDGE),
        (("L24", "L23"), Coverage.LOWER_TRAILING_EDGE),
    ],
)
def test_each_coverage_rule_names_its_reason(
    attached_samples: tuple[np.ndarray, np.ndarray, float],
    names: tuple[str, ...],
    reason: Coverage,
) -> None:
    pressure, alpha, q = attached_samples
    integrator = PressureIntegrator()
    idx = [integrator.taps.names.index(n) for n in names]
    damaged = pressure[0].copy()
    damaged[idx] = np.nan
    c = integrator.integrate(damaged, alpha[0], q)
    assert not c.valid[0] and c.reason[0] == reason and np.isnan(c.cl[0])


def test_single_missing_taps_anywhere_keep_the_sample_valid(
    attached_samples: tuple[np.ndarray, np.ndarray, float],
) -> None:
    pressure, alpha, q = attached_samples
    integrator = PressureIntegrator()
    damaged = np.repeat(pressure[1:2], 49, axis=0)
    damaged[np.arange(49), np.arange(49)] = np.nan
    c = integrator.integrate(damaged, alpha[1], q)
    assert c.valid.all()
    full = integrator.integrate(pressure[1], alpha[1], q)
    assert np.abs(c.cl / full.cl[0] - 1.0).max() < 0.03
    two_mid = pressure[1].copy()
    two_mid[[integrator.taps.names.index("U12"), integrator.taps.names.index("U13")]] = np.inf
    assert integrator.integrate(two_mid, alpha[1], q).valid[0]  # aft of the suction peak
    assert math.isfinite(integrator.integrate(two_mid, alpha[1], q).cl[0])
