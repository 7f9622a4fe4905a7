"""PNLSS kernels: analytic Jacobian against finite differences; monomial sets; spectrum packing."""

from math import comb

import numpy as np
import pytest

from aero_identification.monomials import (
    evaluate_monomials,
    monomial_exponents,
    structure_exponents,
)
from aero_identification.pnlss import _Layout, _pack_spectrum
from aero_identification.pnlss_kernels import jacobian_records, simulate_records


@pytest.mark.parametrize(("structure", "fit_offset"), [("full", True), ("statesonly", False)])
def test_analytic_jacobian_matches_finite_differences(structure: str, fit_offset: bool):
    rng = np.random.default_rng(0)
    nx, nu, ny = 2, 1, 1
    exps = structure_exponents(nx, nu, (2, 3), structure)
    K = exps.shape[0]
    layout = _Layout(nx, nu, ny, K, K, fit_offset)
    mats = {
        "A": np.array([[0.8, 0.2], [-0.2, 0.7]]),
        "B": rng.standard_normal((nx, nu)),
        "C": rng.standard_normal((ny, nx)),
        "D": rng.standard_normal((ny, nu)),
        "E": 0.05 * rng.standard_normal((nx, K)),
        "F": 0.05 * rng.standard_normal((ny, K)),
        "offset": np.array([[0.3]]),
    }
    theta = layout.pack(mats)
    R, N, n_skip = 2, 40, 7
    u = 0.5 * rng.standard_normal((R, n_skip + N, nu))
    y_meas = rng.standard_normal((R, N, ny))

    def simulate(th: np.ndarray) -> np.ndarray:
        m = layout.unpack(th)
        y = simulate_records(m["A"], m["B"], m["C"], m["D"], m["E"], m["F"], exps, exps, u,
                             np.zeros((R, nx)), 1e4)  # fmt: skip
        return (y[:, n_skip:, :] + m["offset"][:, 0]).ravel()

    J = np.empty((R * N * ny, layout.n_par + 1), order="F")
    m = layout.unpack(theta)
    ok = jacobian_records(m["A"], m["B"], m["C"], m["D"], m["E"], m["F"], exps, exps, u, y_meas,
                          n_skip, m["offset"][:, 0].copy(), fit_offset, 1e4, J)  # fmt: skip
    assert ok.all()
    J_fd = np.empty((R * N * ny, layout.n_par))
    for i in range(layout.n_par):
        d = np.zeros_like(theta)
        d[i] = 1e-6
        J_fd[:, i] = (simulate(theta + d) - simulate(theta - d)) / 2e-6
    np.testing.assert_allclose(J[:, :-1], J_fd, atol=1e-7 * np.abs(J_fd).max())
    # Last column: the residual of the simulated output.
    np.testing.assert_allclose(J[:, -1], simulate(theta) - y_meas.ravel(), atol=1e-12)


def test_jacobian_has_the_similarity_transform_null_space():
    """J v = 0 for the nx² directions of x ↦ (I + εS) x: why the LM step caps the rank."""
    rng = np.random.default_rng(1)
    nx, nu, ny = 2, 1, 1
    exps = structure_exponents(nx, nu, (2,), "full")
    K = exps.shape[0]
    layout = _Layout(nx, nu, ny, K, K, False)
    A = np.array([[0.7, 0.3], [-0.3, 0.6]])
    mats = {"A": A, "B": rng.standard_normal((nx, 1)), "C": rng.standard_normal((1, nx)),
            "D": np.zeros((1, 1)), "E": 0.1 * rng.standard_normal((nx, K)),
            "F": 0.1 * rng.standard_normal((1, K))}  # fmt: skip
    R, N = 1, 60
    u = rng.standard_normal((R, N, nu))
    J = np.empty((N, layout.n_par + 1), order="F")
    ok = jacobian_records(mats["A"], mats["B"], mats["C"], mats["D"], mats["E"], mats["F"], exps,
                          exps, u, np.zeros((R, N, 1)), 0, np.zeros(1), False, 1e4, J)  # fmt: skip
    assert ok.all()
    s = np.linalg.svd(J[:, :-1], compute_uv=False)
    assert s[-nx * nx :].max() < 1e-9 * s[0]
    assert s[-nx * nx - 1] > 1e-6 * s[0]


def test_monomial_counts_and_structures():
    # C(n + d − 1, d) monomials of degree d in n variables.
    assert monomial_exponents(3, (2, 3)).shape == (comb(4, 2) + comb(5, 3), 3)
    full = structure_exponents(2, 1, (2, 3, 4, 5), "full")
    states = structure_exponents(2, 1, (2, 3, 4, 5), "statesonly")
    inputs = structure_exponents(2, 1, (2, 3, 4, 5), "inputsonly")
    assert np.all(states[:, 2] == 0) and states.shape[0] == 3 + 4 + 5 + 6
    assert np.all(inputs[:, :2] == 0) and inputs.shape[0] == 4
    assert full.shape[0] == sum(comb(d + 2, d) for d in (2, 3, 4, 5))
    assert len({tuple(r) for r in full}) == full.shape[0]
    z = np.array([[2.0, 3.0, 5.0]])
    values = evaluate_monomials(z, np.array([[2, 0, 1], [0, 1, 1]]))
    np.testing.assert_allclose(values, [[20.0, 15.0]])
    with pytest.raises(ValueError, match="structure"):
        structure_exponents(2, 1, (2,), "outputsonly")
    with pytest.raises(ValueError, match=">= 2"):
        monomial_exponents(3, (1,))


@pytest.mark.parametrize("N", [16, 15])
def test_spectrum_packing_keeps_the_cost_for_unit_weights(N: int):
    rng = np.random.default_rng(2)
    e = rng.standard_normal((3, N, 1))
    packed = _pack_spectrum(e, np.ones((N // 2 + 1, 1)))
    assert packed.shape == e.shape
    assert np.sum(packed**2) == pytest.approx(np.sum(e**2), rel=1e-12)
    # A weight only on bin 2 keeps only that bin's energy (Parseval for one line).
    w = np.zeros((N // 2 + 1, 1))
    w[2] = 1.0
    E2 = np.fft.rfft(e, axis=1)[:, 2, 0]
    assert np.sum(_pack_spectrum(e, w) ** 2) == pytest.approx(2 * np.sum(np.abs(E2) ** 2) / N)
