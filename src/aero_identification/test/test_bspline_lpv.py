"""The second model class (bspline_lpv.py): the linear start is the linear model exactly, the
forward sensitivities are the simulation's derivatives, a fit recovers a nonlinear system of
the class on held-out data and is never worse there than its linear start, and the scan keeps
the simplest adequate structure."""

import numpy as np
import pytest

from aero_identification.bspline_lpv import (
    BSplineLPV,
    LpvSettings,
    _basis,
    _knots,
    _scaled,
    _sensitivities,
    fit_bspline_lpv,
    linear_start,
    lpv_parameters,
    scan_bspline_lpv,
    state_exponents,
)
from aero_identification.periodic_data import PeriodicData, random_phase_period
from aero_identification.scan import periodic_error
from aero_identification.state_space_models import LinearStateSpace

FS = 100.0


def test_state_monomials_and_parameter_count() -> None:
    assert state_exponents(1, 3).tolist() == [[0], [1], [2], [3]]
    e2 = state_exponents(2, 2).tolist()
    assert e2[:3] == [[0, 0], [1, 0], [0, 1]] and sorted(e2[3:]) == [[0, 2], [1, 1], [2, 0]]
    assert lpv_parameters(1, 8, 3) == 11 * (1 * 4 + 1)
    assert lpv_parameters(2, 4, 1) == 7 * (2 * 3 + 1)


def two_state_linear() -> LinearStateSpace:
    A = np.array([[0.9, 0.2], [-0.2, 0.9]])
    return LinearStateSpace(A, np.array([[0.5], [0.1]]), np.array([[1.0, -0.3]]),
                            np.array([[0.05]]), FS, u_mean=np.array([5.0]),
                            y_mean=np.array([0.7]))  # fmt: skip


def test_the_linear_start_is_the_linear_model_exactly() -> None:
    linear = two_state_linear()
    u = 5.0 + 3.0 * np.random.default_rng(0).standard_normal(500)
    knots = _knots(float(u.min()), float(u.max()), 6)
    start = linear_start(linear, knots, state_exponents(2, 3))
    assert np.allclose(start.simulate(u), linear.simulate(u), atol=1e-10)
    scaled = _scaled(start, np.array([2.0, 0.5]))  # a change of state coordinates
    assert np.allclose(scaled.simulate(u), linear.simulate(u), atol=1e-10)


def test_sensitivities_are_the_simulations_derivatives() -> None:
    rng = np.random.default_rng(1)
    u = 5.0 + 3.0 * rng.standard_normal(300)
    knots = _knots(float(u.min()), float(u.max()), 3)
    model = linear_start(two_state_linear(), knots, state_exponents(2, 2))
    theta = model.theta + 0.02 * rng.standard_normal(model.theta.size)  # nonlinear terms on
    model = model.with_theta(theta)
    W = _basis(u, knots)
    y, J = _sensitivities(W, model.E, model.exponents, model.C, model.d, 100)
    assert np.allclose(y, model.simulate(u)[100:])
    h = 1e-6
    for t in rng.choice(theta.size, 12, replace=False):
        up, down = theta.copy(), theta.copy()
        up[t] += h
        down[t] -= h
        fd = (model.with_theta(up).simulate(u) - model.with_theta(down).simulate(u))[100:] / (2 * h)
        assert np.allclose(J[:, t], fd, rtol=1e-4, atol=1e-7), t


def truth_records(rng: np.random.Generator, offsets: list[float], noise: float) -> PeriodicData:
    """A first-order lag whose gain and time constant vary with α, and a static stall-like
    feedthrough: inside the class (nx 1), nonlinear beyond any linear model."""
    N = 1000
    lines = np.arange(1, 80, 2)
    u = np.empty((N, 1, len(offsets)))
    y = np.empty_like(u)
    for r, offset in enumerate(offsets):
        period = random_phase_period(rng, N, lines)
        alpha = offset + 2.0 * period / np.std(period)
        a = 0.7 + 0.25 / (1 + np.exp(-(alpha - 12.0)))  # slower when stalled
        target = 0.1 * alpha - 0.04 * np.maximum(alpha - 12.0, 0.0) ** 2
        x, out = 0.0, np.empty(3 * N)
        for k, (ak, tk) in enumerate(zip(np.tile(a, 3), np.tile(target, 3), strict=True)):
            out[k] = x
            x = ak * x + (1 - ak) * tk
        u[:, 0, r] = alpha
        y[:, 0, r] = out[2 * N :] + noise * rng.standard_normal(N)
    return PeriodicData(u, y, FS, lines)


def linear_of(train: PeriodicData) -> LinearStateSpace:
    """A poor but stable one-state linear start (what the BLA of the lowest level gives)."""
    return LinearStateSpace(np.array([[0.8]]), np.array([[0.02]]), np.array([[1.0]]),
                            np.array([[0.0]]), FS, u_mean=np.array([float(train.u.mean())]),
                            y_mean=np.array([float(train.y.mean())]))  # fmt: skip


def test_a_fit_recovers_a_system_of_its_class_and_beats_its_linear_start() -> None:
    rng = np.random.default_rng(2)
    offsets = [6.0, 11.0, 15.0]
    train, held = truth_records(rng, offsets, 0.005), truth_records(rng, offsets, 0.005)
    model = fit_bspline_lpv(train, linear_of(train), LpvSettings(intervals=6, state_degree=1,
                                                               max_iter=80), held)  # fmt: skip
    h = model.history_
    assert h["kept_error"] <= h["linear_start_error"]
    error, _ = periodic_error(model, held)
    linear_error, _ = periodic_error(linear_of(train), held)
    assert linear_error > 0.3 and error < 0.08  # noise: 0.005 of an output of std ≈ 0.3
    assert model.to_dict()["parameters"] == model.n_params == lpv_parameters(1, 6, 1)


def test_the_scan_keeps_the_simplest_adequate_structure() -> None:
    rng = np.random.default_rng(3)
    offsets = [6.0, 11.0, 15.0]
    train, held = truth_records(rng, offsets, 0.005), truth_records(rng, offsets, 0.005)
    scan = scan_bspline_lpv(train, held, linear_of(train), (2, 6), (1,),
                            LpvSettings(max_iter=60))  # fmt: skip
    assert [r["intervals"] for r in scan.rows] == [2, 6]
    assert all(r["status"] == "ok" for r in scan.rows)
    best, other = scan.rows[scan.best_index], scan.rows[1 - scan.best_index]
    # Kept: the fewest parameters within one SE of the lowest error.
    lowest = min(scan.rows, key=lambda r: r["validation_error"])
    assert best["validation_error"] <= lowest["validation_error"] + lowest["validation_se"]
    assert best["n_params"] <= other["n_params"] or (
        other["validation_error"] > lowest["validation_error"] + lowest["validation_se"]
    )
    assert isinstance(scan.best, BSplineLPV) and "one-standard-error rule" in scan.rule
    assert "| kept |" in scan.to_markdown()


def test_the_scan_on_a_dask_client_gives_the_serial_scan() -> None:
    """The grid's fits as Dask tasks (the PNLSS scan's client): the same rows and kept model."""
    from dask.distributed import Client, LocalCluster

    rng = np.random.default_rng(5)
    offsets = [6.0, 15.0]
    train, held = truth_records(rng, offsets, 0.005), truth_records(rng, offsets, 0.005)
    settings = LpvSettings(max_iter=10)
    serial = scan_bspline_lpv(train, held, linear_of(train), (2, 4), (1,), settings)
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                     dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):  # fmt: skip
        remote = scan_bspline_lpv(train, held, linear_of(train), (2, 4), (1,), settings,
                                  client=client)  # fmt: skip
    key = ("intervals", "state_degree", "n_params", "validation_error", "status")
    assert [[r[k] for k in key] for r in remote.rows] == [[r[k] for k in key] for r in serial.rows]
    assert remote.best_index == serial.best_index
    np.testing.assert_array_equal(remote.best.theta, serial.best.theta)


def test_settings_refuse_what_cannot_be_fitted() -> None:
    with pytest.raises(ValueError, match="intervals"):
        LpvSettings(intervals=0)
    with pytest.raises(ValueError, match="weighting"):
        LpvSettings(weighting="noise")
    flat = PeriodicData(np.full((50, 1, 1), 3.0), np.zeros((50, 1, 1)), FS, np.array([1]))
    with pytest.raises(ValueError, match="constant"):
        fit_bspline_lpv(flat, linear_of(flat))
