"""The semi-empirical baseline (beddoes_leishman.py): the Kirchhoff inversion of a known static
curve, and the calibration of the HGM model recovering the time constants of data it made."""

import numpy as np
import pytest

from aero_identification.beddoes_leishman import (
    BeddoesLeishman,
    StaticLift,
    fit_beddoes_leishman,
    static_lift,
)
from aero_identification.dataset import QuasiStaticSweep
from aero_identification.periodic_data import PeriodicData, random_phase_period

FS = 200.0
SLOPE, ALPHA0 = 0.104, -0.5  # C_lα [1/°], zero-lift angle [°]


def separation(alpha: np.ndarray) -> np.ndarray:
    """A known f^st: attached below 11°, separating smoothly to 0.05 at 26°."""
    s = np.clip((np.asarray(alpha) - 11.0) / 15.0, 0.0, 1.0)
    return 1.0 - 0.95 * (3 * s**2 - 2 * s**3)


def true_static() -> StaticLift:
    alpha = np.arange(-2.0, 32.0, 0.05)
    f = separation(alpha)
    cl = SLOPE * (alpha - ALPHA0) * ((1 + np.sqrt(f)) / 2) ** 2  # Kirchhoff [LB]
    attached = SLOPE * (alpha - ALPHA0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cl_fs = np.where(f < 0.98, (cl - attached * f) / (1 - f), 0.5 * cl)
    return StaticLift(alpha, cl, f, cl_fs, SLOPE, ALPHA0, (-2.0, 10.0))


def sweep_of(model: BeddoesLeishman, rng: np.random.Generator, noise: float) -> QuasiStaticSweep:
    rate = 0.5
    up = np.arange(0.0, 30.0, rate / FS)
    alpha = np.concatenate([up, up[::-1]])
    cl = model.simulate(alpha) + noise * rng.standard_normal(alpha.size)
    n = up.size
    return QuasiStaticSweep(alpha[:n], cl[:n], alpha[n:], cl[n:], rate, 0)


def multisine_records(
    model: BeddoesLeishman, rng: np.random.Generator, noise: float, offsets: list[float]
) -> PeriodicData:
    N = 2000
    lines = np.arange(1, 200, 2)  # odd lines up to 19.9 Hz … kept to 10 Hz below
    lines = lines[lines * FS / N <= 10.0]
    u = np.empty((N, 1, len(offsets)))
    y = np.empty_like(u)
    for r, offset in enumerate(offsets):
        period = random_phase_period(rng, N, lines)
        alpha = offset + 2.4 * period / np.std(period)
        u[:, 0, r] = alpha
        y[:, 0, r] = model.simulate(np.tile(alpha, 3))[2 * N :] + noise * rng.standard_normal(N)
    return PeriodicData(u, y, FS, lines)


def test_kirchhoff_inversion_recovers_the_static_curves() -> None:
    truth = BeddoesLeishman(true_static(), FS, 0.01, 0.015, 0.06, 0.0)
    sweep = sweep_of(truth, np.random.default_rng(0), noise=0.0)
    st = static_lift(sweep)
    assert st.slope_per_deg == pytest.approx(SLOPE, rel=0.01)
    assert st.alpha0_deg == pytest.approx(ALPHA0, abs=0.1)
    inside = (st.alpha_deg > 2.0) & (st.alpha_deg < 29.0)
    assert np.max(np.abs(st.f[inside] - separation(st.alpha_deg[inside]))) < 0.03
    # The model's static lift on the inverted curves is the sweep's again.
    assert (
        np.max(
            np.abs(
                st.cl_fs_of(st.alpha_deg) * (1 - st.f)
                + SLOPE * (st.alpha_deg - st.alpha0_deg) * st.f
                - st.cl
            )[inside]
        )
        < 5e-3
    )


def test_static_lift_refuses_a_sweep_without_a_lift_slope() -> None:
    alpha = np.linspace(0.0, 1.0, 400)
    flat = QuasiStaticSweep(alpha, np.zeros_like(alpha), alpha[::-1], np.zeros_like(alpha), 0.5)
    with pytest.raises(ValueError, match="too few"):
        static_lift(flat)


def test_fit_recovers_the_time_constants_of_its_own_model() -> None:
    rng = np.random.default_rng(1)
    truth = BeddoesLeishman(true_static(), FS, t_u_s=0.02, t_p_s=0.05, t_f_s=0.4,
                            downwash_s=0.01)  # fmt: skip
    sweep = sweep_of(truth, rng, noise=0.005)
    train = multisine_records(truth, rng, 0.01, [6.6, 15.7, 19.9])
    held = multisine_records(truth, rng, 0.01, [6.6, 15.7, 19.9])
    model = fit_beddoes_leishman(sweep, train, held)
    # The separation lag shapes the stall most: recovered within 15 %.
    assert model.t_f_s == pytest.approx(0.4, rel=0.15)
    # The held-out error sits near the noise: (noise 0.01) / the output's std.
    floor = 0.01 / float(np.std(held.y))
    assert model.history_["validation_error"] < 1.6 * floor
    # A model with the lags off is clearly worse on the same held-out data.
    static_only = BeddoesLeishman(model.static, FS, 1e-4, 1e-4, 1e-4, 0.0)
    y = held.y.transpose(2, 1, 0).reshape(-1)
    from aero_identification.beddoes_leishman import _steady_state

    err_static = np.sqrt(np.mean((_steady_state(static_only, held) - y) ** 2)) / np.std(y)
    assert err_static > 3 * model.history_["validation_error"]
