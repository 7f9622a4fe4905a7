"""PNLSS fits against simulated systems with a known truth (Duffing oscillator, linear system)."""

import dataclasses
import itertools
import json
import math
from dataclasses import dataclass

import numpy as np
import pytest

from aero_identification.bla import BLA
from aero_identification.periodic_data import PeriodicData
from aero_identification.pnlss import PnlssSettings, fit_pnlss
from aero_identification.state_space_models import STATE_BOUND, LinearStateSpace, PNLSSModel
from aero_identification.subspace import fit_linear_ss

N = 1024  # samples per period
P = 3  # periods per realization
M = 2  # realizations
LINES = np.arange(1, int(0.15 * N), 2)  # odd multisine up to 0.15 fs
NOISE_REL = 0.005  # output noise std relative to the output std


def odd_multisine(rng: np.random.Generator, rms: float) -> np.ndarray:
    """(N,) one period of a random-phase odd multisine with flat amplitude spectrum."""
    U = np.zeros(N // 2 + 1, complex)
    U[LINES] = np.exp(2j * np.pi * rng.random(LINES.size))
    u = np.fft.irfft(U, n=N)
    return u / np.std(u) * rms


def duffing(u: np.ndarray, k3: float) -> np.ndarray:
    """Discrete Duffing oscillator y'' + c y' + k y + k3 y³ = u (semi-implicit Euler, h = 0.1).

    This discretisation is itself a polynomial state-space model of degree 3, so a PNLSS model
    with nx = 2 and degrees (2, 3) contains the truth.
    """
    h, c, k = 0.1, 0.1, 1.0
    x1 = x2 = 0.0
    y = np.empty(u.size)
    for t in range(u.size):
        y[t] = x1
        x2 = x2 + h * (u[t] - c * x2 - k * x1 - k3 * x1**3)
        x1 = x1 + h * x2
    return y


def steady_state(u_period: np.ndarray, k3: float, periods: int) -> np.ndarray:
    """Noise-free output over `periods` periods after two settling periods."""
    return duffing(np.tile(u_period, periods + 2), k3)[2 * N :]


def robust_bla(data: PeriodicData) -> BLA:
    """Robust BLA (Pintelon & Schoukens 2012, §4.3.1) written out here, independent of bla.py."""
    U = np.fft.rfft(data.u, axis=0)[LINES]
    Y = np.fft.rfft(data.y, axis=0)[LINES]
    G_mp = Y / U
    G_m = G_mp.mean(axis=1)
    G = G_m.mean(axis=1)
    var_noise = np.sum(np.var(G_mp, axis=1, ddof=1) / P, axis=1) / M**2
    var_total = np.var(G_m, axis=1, ddof=1) / M
    e = np.zeros(0)
    return BLA(
        fs=data.fs, N=N, lines=LINES, freq=LINES * data.fs / N, G=G, var_noise=var_noise,
        var_total=var_total, var_nl=np.maximum(var_total - var_noise, 0), M=M, P=P, U_mean=e,
        Y_mean=e, excited_level=e, odd_lines=e, odd_freq=e, odd_nl_level=e, even_lines=e,
        even_freq=e, even_nl_level=e, noise_lines=e, noise_freq=e, noise_level=e,
    )  # fmt: skip


@dataclass
class Case:
    data: PeriodicData
    lin: LinearStateSpace
    u_val: np.ndarray
    y_val: np.ndarray  # noisy
    y_val_true: np.ndarray
    k3: float


def make_case(k3: float, seed: int) -> Case:
    rng = np.random.default_rng(seed)
    u = np.empty((N, P, M))
    y = np.empty((N, P, M))
    for m in range(M):
        period = odd_multisine(rng, rms=0.15) + 0.3  # operating point ū = 0.3
        u[:, :, m] = np.tile(period, P).reshape(P, N).T
        y[:, :, m] = steady_state(period, k3, P).reshape(P, N).T
    noise_std = NOISE_REL * np.std(y)
    y = y + noise_std * rng.standard_normal(y.shape)
    data = PeriodicData(u=u, y=y, fs=1.0, excited_lines=LINES)
    lin = fit_linear_ss(robust_bla(data), nx=2).with_operating_point(u.mean(), y.mean())
    u_val = np.tile(odd_multisine(rng, rms=0.15) + 0.3, 2)
    y_val_true = steady_state(u_val[:N], k3, 2)
    y_val = y_val_true + noise_std * rng.standard_normal(y_val_true.size)
    return Case(data, lin, u_val, y_val, y_val_true, k3)


def rel_rms(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Relative RMS error on the second period of the validation record (after the transient
    of a simulation started at the operating point)."""
    return float(np.sqrt(np.mean((y[N:] - y_hat[N:]) ** 2)) / np.std(y[N:]))


@pytest.fixture(scope="module")
def duffing_case() -> Case:
    return make_case(k3=1.0, seed=1)


@pytest.fixture(scope="module")
def duffing_model(duffing_case: Case) -> PNLSSModel:
    c = duffing_case
    settings = PnlssSettings(degrees=(2, 3), structure="full", max_iter=40)
    return fit_pnlss(c.data, c.lin, settings, validation=(c.u_val, c.y_val))


def test_pnlss_duffing_beats_linear_tenfold_and_reaches_noise_floor(duffing_case, duffing_model):
    c = duffing_case
    noise_floor = rel_rms(c.y_val, c.y_val_true)
    e_lin = rel_rms(c.y_val, c.lin.simulate(c.u_val))
    e_pnlss = rel_rms(c.y_val, duffing_model.simulate(c.u_val))
    assert e_lin > 0.1  # the test is only meaningful if the system is clearly nonlinear
    assert e_pnlss <= e_lin / 10
    assert e_pnlss <= 2 * noise_floor


def test_pnlss_noise_weighted_fit_reaches_noise_floor(duffing_case):
    c = duffing_case
    settings = PnlssSettings(degrees=(2, 3), structure="statesonly", max_iter=30,
                             weighting="noise")  # fmt: skip
    model = fit_pnlss(c.data, c.lin, settings, validation=(c.u_val, c.y_val))
    noise_floor = rel_rms(c.y_val, c.y_val_true)
    assert rel_rms(c.y_val, model.simulate(c.u_val)) <= 2 * noise_floor


def test_pnlss_on_linear_system_is_not_worse_than_linear_model():
    case = make_case(k3=0.0, seed=2)
    model = fit_pnlss(case.data, case.lin, PnlssSettings(degrees=(2, 3), max_iter=15),
                      validation=(case.u_val, case.y_val))  # fmt: skip
    e_lin = rel_rms(case.y_val, case.lin.simulate(case.u_val))
    e_pnlss = rel_rms(case.y_val, model.simulate(case.u_val))
    noise_floor = rel_rms(case.y_val, case.y_val_true)
    assert e_pnlss <= e_lin * (1 + 1e-9)
    assert e_pnlss <= 1.2 * noise_floor


def _validation_mse(model: PNLSSModel, u_val: np.ndarray, y_val: np.ndarray) -> float:
    y = model.simulate(u_val)
    return float(np.mean((y[model.n_transient :] - y_val[model.n_transient :]) ** 2))


def _check_history(model: PNLSSModel) -> int:
    """Accepted costs never increase; λ rises after every rejection and falls after acceptance;
    a trial that does not lower the training cost is rejected without its validation runs
    (cost_val nan). Returns the number of those trials."""
    h = model.history_
    current, unsimulated = h[0].cost, 0
    for r in h[1:]:
        if not r.cost < current:
            assert not r.accepted and math.isnan(r.cost_val)
            unsimulated += 1
        elif r.accepted:
            current = r.cost
    accepted_costs = [r.cost for r in h if r.accepted]
    assert all(b <= a for a, b in itertools.pairwise(accepted_costs))
    for prev, nxt in itertools.pairwise(h[1:]):
        if prev.accepted:
            assert nxt.lambda_ < prev.lambda_
        else:
            assert nxt.lambda_ > prev.lambda_
    return unsimulated


def test_diverging_steps_from_a_bad_start_are_rejected(duffing_case):
    c = duffing_case
    # Bad start: the linear model (canonical modal basis, pnlss.modal_basis) plus the largest
    # softening cubic term x₁³ in the first state equation that keeps the training simulation
    # finite.
    start = fit_pnlss(c.data, c.lin, PnlssSettings(degrees=(2, 3), max_iter=0))
    cubic = int(np.flatnonzero((start.exponents_state == [3, 0, 0]).all(axis=1))[0])
    for size in (0.3, 0.2, 0.1, 0.05, 0.03):
        E = start.E.copy()
        E[0, cubic] = -size
        bad = dataclasses.replace(start, E=E)
        try:
            fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=0), initial_model=bad)
            break
        except ValueError:  # the initial model diverges: too bad a start
            continue
    # Small initial damping: long, nearly Gauss–Newton steps from the bad start.
    model = fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=30, lambda_init=1e-2),
                      validation=(c.u_val, c.y_val), initial_model=bad)  # fmt: skip
    h = model.history_
    assert h[0].cost > 10 * start.cost_  # the start really is bad
    diverged = [r for r in h if not math.isfinite(r.cost)]
    assert diverged and not any(r.accepted for r in diverged)
    assert _check_history(model) >= len(diverged)
    best_val = min(r.cost_val for r in h if r.accepted)
    assert _validation_mse(model, c.u_val, c.y_val) == pytest.approx(best_val, rel=1e-9)
    assert best_val < h[0].cost_val / 100  # ... and the fit recovered from the bad start


def test_step_that_diverges_on_validation_only_is_rejected(duffing_case):
    c = duffing_case
    # Validation at four times the training amplitude: polynomial models fitted on small signals
    # blow up there although they improve the training cost.
    u_big = 0.3 + 4 * (c.u_val - 0.3)
    y_big = steady_state(u_big[:N], c.k3, 2)
    model = fit_pnlss(
        c.data, c.lin, PnlssSettings(degrees=(2, 3), max_iter=20), validation=(u_big, y_big)
    )
    h = model.history_
    current = h[0].cost
    guarded = 0
    for r in h[1:]:
        if math.isfinite(r.cost) and r.cost < current and not math.isfinite(r.cost_val):
            assert not r.accepted
            guarded += 1
        if r.accepted:
            current = r.cost
    assert guarded >= 1
    _check_history(model)
    y = model.simulate(u_big)
    assert np.all(np.isfinite(y))
    best_val = min(r.cost_val for r in h if r.accepted)
    assert _validation_mse(model, u_big, y_big) == pytest.approx(best_val, rel=1e-9)
    assert best_val < h[0].cost_val


def test_pnlss_json_round_trip_gives_identical_simulation(duffing_case, duffing_model):
    text = json.dumps(duffing_model.to_dict())
    again = PNLSSModel.from_dict(json.loads(text))
    u = duffing_case.u_val
    np.testing.assert_array_equal(again.simulate(u), duffing_model.simulate(u))
    x0 = np.array([0.3, -0.2])
    np.testing.assert_array_equal(again.simulate(u, x0), duffing_model.simulate(u, x0))


def test_pnlss_rejects_bad_arguments(duffing_case):
    c = duffing_case
    with pytest.raises(ValueError, match="structure"):
        fit_pnlss(c.data, c.lin, PnlssSettings(structure="everything", max_iter=1))
    with pytest.raises(ValueError, match="degrees"):
        fit_pnlss(c.data, c.lin, PnlssSettings(degrees=(1, 3), max_iter=1))
    with pytest.raises(ValueError, match="same length"):
        fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=1), validation=(c.u_val, c.y_val[:-1]))


def test_qr_and_normal_equation_solvers_give_the_same_fit(duffing_case):
    c = duffing_case
    fits = [
        fit_pnlss(
            c.data, c.lin, PnlssSettings(max_iter=12, solver=solver), validation=(c.u_val, c.y_val)
        )
        for solver in ("qr", "normal")
    ]
    assert [r.accepted for r in fits[0].history_] == [r.accepted for r in fits[1].history_]
    np.testing.assert_allclose(fits[0].simulate(c.u_val), fits[1].simulate(c.u_val), rtol=1e-6,
                               atol=1e-9 * np.std(c.y_val))  # fmt: skip


def test_periodic_validation_periods_choose_the_model_in_steady_state(duffing_case):
    c = duffing_case
    held_out = PeriodicData(
        u=c.u_val[N:, None, None], y=c.y_val[N:, None, None], fs=1.0, excited_lines=LINES
    )
    model = fit_pnlss(c.data, c.lin, PnlssSettings(degrees=(2, 3), max_iter=40),
                      validation=held_out)  # fmt: skip
    noise_floor = rel_rms(c.y_val, c.y_val_true)
    assert rel_rms(c.y_val, model.simulate(c.u_val)) <= 2 * noise_floor
    # cost_val_ is the steady-state error on the held-out period (second period of a
    # two-period simulation from the operating point).
    y_hat = model.simulate(c.u_val)[N:]
    assert model.cost_val_ == pytest.approx(np.mean((y_hat - c.y_val[N:]) ** 2), rel=1e-3)
    with pytest.raises(ValueError, match="validation periods have"):
        short = PeriodicData(u=held_out.u[:-2], y=held_out.y[:-2], fs=1.0, excited_lines=LINES)
        fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=1), validation=short)


def test_state_equation_only_has_no_output_terms_and_fits_the_duffing_truth(duffing_case):
    """The Duffing discretisation has its cubic term in the state equation only (E, F = 0)."""
    c = duffing_case
    settings = PnlssSettings(degrees=(2, 3), max_iter=30, equations="state")
    model = fit_pnlss(c.data, c.lin, settings, validation=(c.u_val, c.y_val))
    assert model.F.shape == (1, 0) and model.exponents_output.shape[0] == 0
    assert model.E.shape[1] == model.exponents_state.shape[0] > 0
    noise_floor = rel_rms(c.y_val, c.y_val_true)
    assert rel_rms(c.y_val, model.simulate(c.u_val)) <= 2 * noise_floor
    restored = PNLSSModel.from_dict(json.loads(json.dumps(model.to_dict())))
    assert np.array_equal(restored.simulate(c.u_val), model.simulate(c.u_val))


def test_record_weights_unit_or_uniform_change_nothing(duffing_case):
    c = duffing_case
    settings = PnlssSettings(degrees=(2, 3), max_iter=8)
    base = fit_pnlss(c.data, c.lin, settings)
    ones = fit_pnlss(c.data, c.lin, settings, record_weights=np.ones(P * M))
    np.testing.assert_allclose(ones.E, base.E, rtol=1e-8, atol=1e-12)
    assert ones.cost_ == pytest.approx(base.cost_, rel=1e-9)
    scaled = fit_pnlss(c.data, c.lin, settings, record_weights=np.full(P * M, 7.0))
    # The LM step is invariant to a common scale of the cost (only the reported cost scales).
    np.testing.assert_allclose(scaled.E, base.E, rtol=1e-6, atol=1e-9)
    assert scaled.cost_ == pytest.approx(7.0 * base.cost_, rel=1e-6)


def test_a_record_with_zero_weight_does_not_move_the_fit(duffing_case):
    """A corrupted record weighted 0 gives the fit of the clean records alone."""
    c = duffing_case
    clean = PeriodicData(c.data.u[:, :, :1], c.data.y[:, :, :1], c.data.fs, LINES)
    y_bad = c.data.y.copy()
    y_bad[:, :, 1] += 5.0 * np.std(c.data.y) * np.sin(np.arange(N) / 7.0)[:, None]
    corrupted = PeriodicData(c.data.u, y_bad, c.data.fs, LINES)
    w = np.r_[np.ones(P), np.zeros(P)]  # record r = m·P + p: realization 1 weighs 0
    a = fit_pnlss(clean, c.lin, PnlssSettings(degrees=(2, 3), max_iter=6))
    b = fit_pnlss(corrupted, c.lin, PnlssSettings(degrees=(2, 3), max_iter=6), record_weights=w)
    np.testing.assert_allclose(b.E, a.E, rtol=1e-5, atol=1e-8)
    with pytest.raises(ValueError, match="record_weights must be 6"):
        fit_pnlss(corrupted, c.lin, PnlssSettings(max_iter=1), record_weights=np.ones(3))
    with pytest.raises(ValueError, match="unknown equations"):
        fit_pnlss(corrupted, c.lin, PnlssSettings(max_iter=1, equations="output"))


def test_the_start_does_not_depend_on_the_linear_models_state_basis(duffing_case):
    """Issue 22: two BLAS kernels gave the subspace model in different state bases (same poles
    to 1e-6, A entries 1e-2 apart), and the LM went to different minima (F-16: 10 % apart).
    The start is now taken in a canonical modal basis: any similarity transform of the linear
    model gives the same start and the same fit."""
    from aero_identification.pnlss import modal_basis

    c = duffing_case
    T = np.array([[0.7, -1.3], [0.4, 2.1]])
    A2 = np.linalg.solve(T, c.lin.A @ T)
    moved = dataclasses.replace(c.lin, A=A2, B=np.linalg.solve(T, c.lin.B), C=c.lin.C @ T)
    for a, b in zip(modal_basis(c.lin.A, c.lin.B, c.lin.C), modal_basis(moved.A, moved.B, moved.C),
                    strict=True):  # fmt: skip
        np.testing.assert_allclose(a, b, atol=1e-10)
    Am, Bm, _ = modal_basis(c.lin.A, c.lin.B, c.lin.C)
    assert Am[0, 0] == pytest.approx(Am[1, 1]) and Bm[1, 0] == pytest.approx(0.0, abs=1e-12)
    fits = [
        fit_pnlss(
            c.data, lin, PnlssSettings(degrees=(2, 3), max_iter=8), validation=(c.u_val, c.y_val)
        )
        for lin in (c.lin, moved)
    ]
    y = [m.simulate(c.u_val) for m in fits]
    np.testing.assert_allclose(y[0], y[1], rtol=1e-7, atol=1e-9 * np.std(y[0]))


def test_stress_rejects_iterates_and_models_that_diverge_at_a_larger_amplitude(duffing_case):
    """Issue 22: a model must stay bounded (and periodic) on the held-out input scaled up."""
    from aero_identification.scan import periodic_at

    c = duffing_case
    start = fit_pnlss(c.data, c.lin, PnlssSettings(degrees=(2, 3), max_iter=0))
    cubic = int(np.flatnonzero((start.exponents_state == [3, 0, 0]).all(axis=1))[0])
    E = start.E.copy()
    E[0, cubic] = 1e-3  # x₁(t+1) grows with x₁³: finite on the data, diverges at 1.5×
    grows = dataclasses.replace(start, E=E)
    fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=0), initial_model=grows)  # finite on the data
    assert periodic_at(start, c.data, 3.0)  # the linear start is stable at any amplitude
    assert periodic_at(grows, c.data, 1.0) and not periodic_at(grows, c.data, 1.5)
    # With stress 1.5 an iterate that diverges there counts as diverging: the start above is
    # flagged, and no accepted iterate is.
    val = PeriodicData(c.data.u[:, :1, :1], c.data.y[:, :1, :1], c.data.fs, c.data.excited_lines)
    flagged = fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=3, stress=1.5), validation=val,
                        initial_model=grows)  # fmt: skip
    assert math.isinf(flagged.history_[0].cost_val)
    plain = fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=0), validation=val,
                      initial_model=grows)  # fmt: skip
    assert math.isfinite(plain.history_[0].cost_val)  # without stress it passes
    settings = PnlssSettings(degrees=(2, 3), max_iter=15, stress=1.5)
    model = fit_pnlss(c.data, c.lin, settings, validation=val)
    accepted = [r for r in model.history_[1:] if r.accepted]
    assert accepted and all(math.isfinite(r.cost_val) for r in accepted)
    assert periodic_at(model, c.data, 1.5)
    with pytest.raises(ValueError, match="stress needs validation"):
        fit_pnlss(c.data, c.lin, PnlssSettings(max_iter=1, stress=1.5))


def test_the_stress_check_without_outputs_agrees_with_the_simulation(duffing_case):
    """`bounded_records` (the stressed inputs' divergence check) says a record stays bounded
    exactly when `simulate_records` gives it finite outputs, on records that diverge early,
    late and not at all."""
    from aero_identification.pnlss_kernels import bounded_records, simulate_records

    c = duffing_case
    start = fit_pnlss(c.data, c.lin, PnlssSettings(degrees=(2, 3), max_iter=0))
    cubic = int(np.flatnonzero((start.exponents_state == [3, 0, 0]).all(axis=1))[0])
    E = start.E.copy()
    E[0, cubic] = 1e-3  # diverges somewhere between 1× and 1.5× the data's amplitude
    un = (c.data.u[:, 0, 0] - start.u_mean[0]) / start.u_scale[0]
    scales = np.linspace(0.5, 3.0, 26)
    u = np.ascontiguousarray(np.stack([np.tile(s * un, 3) for s in scales])[:, :, None])
    x0 = np.zeros((u.shape[0], start.nx))
    args = (start.A, start.B, start.C, start.D, E, start.F, start.exponents_state,
            start.exponents_output, u, x0, STATE_BOUND)  # fmt: skip
    y = simulate_records(*args)
    finite = np.all(np.isfinite(y), axis=(1, 2))
    ok = bounded_records(start.A, start.B, E, start.exponents_state, u, x0, STATE_BOUND)
    assert ok.tolist() == finite.tolist()
    assert finite.any() and not finite.all()
    # A record that leaves the bound only at its last state keeps finite outputs: so does the
    # check (the state after the last sample sets no output).
    last_nan = [
        int(np.argmax(~np.isfinite(y[r, :, 0]))) for r in range(len(scales)) if not finite[r]
    ]
    assert min(last_nan) > 0
    diverging = int(np.flatnonzero(~finite)[0])
    T = last_nan[0]  # the first non-finite output: its state left the bound one step before
    cut = np.ascontiguousarray(u[diverging : diverging + 1, :T])
    assert np.all(np.isfinite(simulate_records(*args[:8], cut, x0[:1], STATE_BOUND)))
    assert bounded_records(start.A, start.B, E, start.exponents_state, cut, x0[:1], STATE_BOUND)[0]
    cut = np.ascontiguousarray(u[diverging : diverging + 1, : T + 1])
    assert not np.all(np.isfinite(simulate_records(*args[:8], cut, x0[:1], STATE_BOUND)))
    assert not bounded_records(
        start.A, start.B, E, start.exponents_state, cut, x0[:1], STATE_BOUND
    )[0]


def test_a_warm_up_without_outputs_continues_as_one_simulation(duffing_case, duffing_model):
    """`state_after` then `simulate(x0=...)` gives bit for bit the tail of one simulation of
    the whole input (scan.periodic_at's warm-up), and None where that simulation diverges."""
    c = duffing_case
    u = np.tile(c.data.u[:, 0, 0], 3)
    split = 2 * N
    whole = duffing_model.simulate(u)
    x = duffing_model.state_after(u[:split])
    assert x is not None
    assert np.array_equal(duffing_model.simulate(u[split:], x0=x), whole[split:])
    cubic = int(np.flatnonzero((duffing_model.exponents_state == [3, 0, 0]).all(axis=1))[0])
    E = duffing_model.E.copy()
    E[0, cubic] = 1.0  # the state runs away at once
    grows = dataclasses.replace(duffing_model, E=E)
    assert not np.all(np.isfinite(grows.simulate(u[:split])))
    assert grows.state_after(u[:split]) is None


def test_settings_check_their_values_before_any_fit():
    """PnlssSettings holds the fit's hyperparameters; the checks that need no data are its own."""
    assert PnlssSettings(degrees=[3, 2, 3]).degrees == (2, 3)  # type: ignore[arg-type]
    for kwargs, message in [
        ({"max_iter": -1}, "max_iter must be >= 0"),
        ({"solver": "lu"}, "unknown solver"),
        ({"equations": "output"}, "unknown equations"),
        ({"structure": "everything"}, "unknown PNLSS structure"),
        ({"degrees": ()}, "degrees is empty"),
        ({"n_transient": -1}, "n_transient must be >= 0"),
        ({"stress": 0.0}, "stress needs validation data and a positive factor"),
        ({"stress": math.inf}, "stress needs validation data and a positive factor"),
        ({"weighting": "white"}, "unknown weighting"),
    ]:
        with pytest.raises(ValueError, match=message):
            PnlssSettings(**kwargs)  # type: ignore[arg-type]
