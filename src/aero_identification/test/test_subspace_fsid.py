"""Frequency-domain subspace identification against discrete systems with known poles."""

import json
from collections.abc import Sequence

import numpy as np
import pytest

from aero_identification.bla import BLA
from aero_identification.state_space_models import LinearStateSpace
from aero_identification.subspace import (
    fit_linear_ss,
    smooth_variance,
    stabilize,
    variance_dof,
)

N = 1024
LINES = np.arange(1, N // 2, 2)  # odd lines, as from an odd multisine


def companion(poles: Sequence[complex], zeros_gain: float = 0.3) -> tuple[np.ndarray, ...]:
    """Real (A, B, C, D) with the given poles (controllable canonical form)."""
    a = np.real(np.poly(poles))
    n = len(poles)
    A = np.zeros((n, n))
    A[0, :] = -a[1:]
    A[1:, :-1] = np.eye(n - 1)
    B = np.zeros((n, 1))
    B[0, 0] = 1.0
    C = np.full((1, n), zeros_gain)
    C[0, 0] = 1.0
    return A, B, C, np.array([[0.1]])


def frf(A, B, C, D, lines: np.ndarray) -> np.ndarray:
    z = np.exp(2j * np.pi * lines / N)
    return np.array([(C @ np.linalg.solve(zk * np.eye(len(A)) - A, B) + D)[0, 0] for zk in z])


def noisy_bla(G_true: np.ndarray, rel_std: float, seed: int, fs: float = 200.0) -> BLA:
    """A BLA record whose G has circular complex noise of the stated variance."""
    rng = np.random.default_rng(seed)
    var = (rel_std * np.abs(G_true)) ** 2 + 1e-12
    noise = np.sqrt(var / 2) * (rng.standard_normal(G_true.size) + 1j * rng.standard_normal(
        G_true.size))  # fmt: skip
    e = np.zeros(0)
    return BLA(
        fs=fs, N=N, lines=LINES, freq=LINES * fs / N, G=G_true + noise, var_noise=var,
        var_total=var, var_nl=np.zeros_like(var), M=2, P=2, U_mean=e, Y_mean=e,
        excited_level=e, odd_lines=e, odd_freq=e, odd_nl_level=e, even_lines=e, even_freq=e,
        even_nl_level=e, noise_lines=e, noise_freq=e, noise_level=e,
    )  # fmt: skip


def assert_poles_within(estimated: np.ndarray, true: np.ndarray, rel: float) -> None:
    est = list(estimated)
    for p in true:  # match every true pole to its nearest estimate
        k = int(np.argmin(np.abs(np.asarray(est) - p)))
        assert abs(est[k] - p) <= rel * abs(p), f"pole {p} estimated as {est[k]}"
        est.pop(k)


SECOND = [0.95 * np.exp(0.3j), 0.95 * np.exp(-0.3j)]
FOURTH = [0.97 * np.exp(0.2j), 0.97 * np.exp(-0.2j), 0.9 * np.exp(1.0j), 0.9 * np.exp(-1.0j)]


@pytest.mark.parametrize("poles", [SECOND, FOURTH], ids=["2nd order", "4th order"])
def test_subspace_recovers_poles_within_one_percent(poles):
    A, B, C, D = companion(poles)
    bla = noisy_bla(frf(A, B, C, D, LINES), rel_std=0.02, seed=len(poles))
    model = fit_linear_ss(bla, max_order=6)  # order scanned
    assert model.order == len(poles)
    assert_poles_within(model.poles(), np.asarray(poles), rel=0.01)
    # With the right order the weighted cost is a χ² with ~2F degrees of freedom.
    assert model.cost < 1.5 * LINES.size
    assert model.weighting == "total"


def test_subspace_never_returns_an_unstable_model():
    # Tempting data: the FRF of an unstable system and one with a pole at the unit circle.
    for poles in ([1.05], [1.0, 0.5], [1.02 * np.exp(0.4j), 1.02 * np.exp(-0.4j)]):
        A, B, C, D = companion(poles)
        bla = noisy_bla(frf(A, B, C, D, LINES), rel_std=0.05, seed=3)
        for nx in (None, 1, 2, 3):
            model = fit_linear_ss(bla, nx=nx, max_order=4)
            assert model.is_stable(), (poles, nx, model.poles())
            assert np.all(np.abs(model.poles()) < 1)
    # Reflection keeps a real matrix and maps |λ| > 1 to 1/|λ|.
    As = stabilize(np.array([[1.25, 0.0], [0.0, 0.5]]))
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(As))), [0.5, 0.8])


def test_simulate_in_steady_state_matches_frf_with_operating_point():
    A, B, C, D = companion(SECOND)
    bla = noisy_bla(frf(A, B, C, D, LINES), rel_std=0.01, seed=4)
    model = fit_linear_ss(bla, nx=2).with_operating_point(u_mean=0.2, y_mean=1.5)
    rng = np.random.default_rng(5)
    lines = np.array([3, 17, 41])
    u_period = np.cos(2 * np.pi * np.outer(np.arange(N), lines) / N + rng.random(3)).sum(axis=1)
    y = model.simulate(np.tile(0.2 + u_period, 4))[-N:]
    U = np.fft.rfft(u_period)[lines]
    Y = np.fft.rfft(y - 1.5)[lines]
    np.testing.assert_allclose(Y / U, model.frf(lines * bla.fs / N), rtol=1e-6)
    assert np.mean(y) == pytest.approx(1.5 + 0.0, abs=1e-9)  # no DC input deviation


def test_validation_bla_drives_selection_cost():
    A, B, C, D = companion(SECOND)
    G = frf(A, B, C, D, LINES)
    train, val = noisy_bla(G, 0.02, seed=6), noisy_bla(G, 0.02, seed=7)
    model = fit_linear_ss(train, max_order=4, validation=val)
    # M = 2: the weights are var_total pooled over neighbouring lines.
    var, window = smooth_variance(val.var_total, val.G, variance_dof(val, "total"))
    assert window > 1
    expected = np.sum(np.abs(model.frf(val.freq) - val.G) ** 2 / var)
    assert model.cost == pytest.approx(expected, rel=1e-9)
    # The scan keeps the candidate best on the validation BLA, e.g. no worse than order 2.
    assert model.cost <= fit_linear_ss(train, nx=2, validation=val).cost


def test_linear_json_round_trip_gives_identical_simulation():
    A, B, C, D = companion(FOURTH)
    model = fit_linear_ss(noisy_bla(frf(A, B, C, D, LINES), 0.02, seed=8), nx=4)
    model = model.with_operating_point(0.1, -0.4)
    again = LinearStateSpace.from_dict(json.loads(json.dumps(model.to_dict())))
    u = np.random.default_rng(9).standard_normal(500)
    np.testing.assert_array_equal(again.simulate(u), model.simulate(u))
    assert again.order == 4 and again.r == model.r and again.cost == model.cost


def test_unusable_variance_gives_a_clear_error():
    A, B, C, D = companion(SECOND)
    bla = noisy_bla(frf(A, B, C, D, LINES), 0.02, seed=10)
    bad = BLA(**{**bla.__dict__, "var_total": np.zeros(LINES.size)})
    with pytest.raises(ValueError, match="var_total"):
        fit_linear_ss(bad, nx=2, weighting="total")
    assert fit_linear_ss(bad, nx=2).weighting == "noise"  # "auto" falls back


def two_realization_bla(poles: list[complex], seed: int) -> BLA:
    """Robust BLA (M = 2, P = 2) of a linear system with output noise, from time records."""
    rng = np.random.default_rng(seed)
    A, B, C, D = companion(poles)
    M, P = 2, 2
    Gm = np.empty((LINES.size, M), complex)
    var_noise = np.zeros(LINES.size)
    for m in range(M):
        Uk = np.zeros(N // 2 + 1, complex)
        Uk[LINES] = np.exp(2j * np.pi * rng.random(LINES.size))
        u = np.fft.irfft(Uk, n=N)
        model = LinearStateSpace(A=A, B=B, C=C, D=D, fs=200.0)
        y = model.simulate(np.tile(u, P + 2))[2 * N :].reshape(P, N)
        y = y + 0.05 * np.std(y) * rng.standard_normal(y.shape)
        G_p = np.fft.rfft(y, axis=1)[:, LINES] / np.fft.rfft(u)[LINES]
        Gm[:, m] = G_p.mean(axis=0)
        var_noise += np.var(G_p, axis=0, ddof=1) / P / M**2
    G = Gm.mean(axis=1)
    var_total = np.var(Gm, axis=1, ddof=1) / M
    e = np.zeros(0)
    return BLA(
        fs=200.0, N=N, lines=LINES, freq=LINES * 200.0 / N, G=G, var_noise=var_noise,
        var_total=var_total, var_nl=np.zeros(LINES.size), M=M, P=P, U_mean=e, Y_mean=e,
        excited_level=e, odd_lines=e, odd_freq=e, odd_nl_level=e, even_lines=e, even_freq=e,
        even_nl_level=e, noise_lines=e, noise_freq=e, noise_level=e,
    )  # fmt: skip


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_order_scan_on_a_two_realization_bla_finds_the_true_order(seed: int):
    # var_total from M = 2 realizations has 2 degrees of freedom per line; used raw as a weight
    # it lets a few lines dominate and the scan over-fits them with spurious poles.
    bla = two_realization_bla(SECOND, seed)
    model = fit_linear_ss(bla, max_order=6)
    assert model.order == 2
    assert_poles_within(model.poles(), np.asarray(SECOND), rel=0.01)
