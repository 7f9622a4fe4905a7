"""WingPlant API: batch == step, reproducible per seed, truth, refusal of bad angles."""

import math

import numpy as np
import pytest

from wing_sim.plant import WingPlant, WingTruth

# 1 Hz sine through the stall band: exercises regime switches, vortex and OU noise.
T = np.arange(1500) / 200.0
ALPHA = np.deg2rad(19.9 + 4.7 * np.sin(2 * math.pi * 1.0 * T))


def test_simulate_equals_repeated_step_for_the_same_seed() -> None:
    batch, truth = WingPlant(seed=3).simulate(ALPHA)
    stepper = WingPlant(seed=3)
    stepped = np.array([stepper.step(a) for a in ALPHA])
    np.testing.assert_array_equal(stepped, batch)
    assert stepper.truth == truth.at(len(ALPHA) - 1)
    assert truth.stalled.any() and not truth.stalled.all()  # the record did cross the stall


def test_chunked_simulation_continues_the_state() -> None:
    whole, _ = WingPlant(seed=8).simulate(ALPHA)
    plant = WingPlant(seed=8)
    parts = [plant.simulate(ALPHA[:1]), plant.simulate(ALPHA[1:700]), plant.simulate(ALPHA[700:])]
    np.testing.assert_array_equal(np.vstack([p for p, _ in parts]), whole)
    assert plant.samples == ALPHA.size


def test_seed_reproduces_and_changes_the_run() -> None:
    a, ta = WingPlant(seed=5).simulate(ALPHA)
    b, _ = WingPlant(seed=5).simulate(ALPHA)
    _, tc = WingPlant(seed=6).simulate(ALPHA)
    np.testing.assert_array_equal(a, b)
    assert np.abs(ta.cl - tc.cl).max() > 0.1  # different stall history
    # the rig's tube lags are hardware, not run randomness
    np.testing.assert_array_equal(WingPlant(seed=5).tube_lag_s, WingPlant(seed=6).tube_lag_s)


def test_truth_reports_the_models_state() -> None:
    plant = WingPlant(seed=0)
    with pytest.raises(RuntimeError, match="no sample"):
        _ = plant.truth
    pressure = plant.step(math.radians(5.0))
    truth = plant.truth
    assert isinstance(truth, WingTruth)
    assert pressure.shape == (49,)
    assert truth.cl == pytest.approx(0.104 * 5.0, rel=1e-9)  # steady, attached
    assert truth.cl_fine == pytest.approx(truth.cl, abs=1e-9)
    assert truth.separation_point == 1.0 and not truth.stalled
    assert truth.cm < 0.0 < truth.cd
    # stagnation just under the leading edge (no tap exceeds q = total − static pressure),
    # suction peak on the upper surface near the leading edge
    q = plant.dynamic_pressure_pa
    upper, lower = plant.taps.upper, plant.taps.lower
    assert 0.9 * q < pressure.max() < q + 3.0 and np.argmax(pressure) == lower[0]
    assert np.argmin(pressure) in upper[:5] and pressure.min() < -1.0 * q


def test_bad_angles_are_refused_and_leave_the_state_untouched() -> None:
    clean = WingPlant(seed=2)
    probed = WingPlant(seed=2)
    clean.simulate(ALPHA[:10])
    probed.simulate(ALPHA[:10])
    for bad in (float("nan"), float("inf"), math.radians(60.0)):
        with pytest.raises(ValueError, match="alpha_rad"):
            probed.step(bad)
    with pytest.raises(ValueError, match=r"alpha_rad\[3\]"):
        probed.simulate(np.r_[ALPHA[10:13], np.nan])
    np.testing.assert_array_equal(probed.step(ALPHA[10]), clean.step(ALPHA[10]))
    with pytest.raises(ValueError, match="seed"):
        WingPlant(seed=-1)
