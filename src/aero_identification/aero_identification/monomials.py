"""Multivariate monomials of the PNLSS state and input, ζ(x, u) and η(x, u).

Paduart et al., Automatica 46(4) 2010: the nonlinear terms of a polynomial
nonlinear state-space model are all products x_1^{e_1} ⋯ x_nx^{e_nx} u_1^{e_{nx+1}} ⋯ of the
chosen total degrees. A monomial set is stored as an integer exponent matrix of shape
(K, nx + nu): row k holds the powers of [x; u] in monomial k.

Structures (which variables may appear in a monomial):

- ``"full"``: every monomial of [x; u] (state, input and cross terms).
- ``"statesonly"``: monomials of the states only (nonlinear feedback, e.g. a Duffing spring).
- ``"inputsonly"``: monomials of the inputs only (a static input nonlinearity feeding the
  linear dynamics, Hammerstein-like).

Degree 1 is excluded (it duplicates A, B, C, D) and so is degree 0 (a constant; the output
offset is estimated separately, see pnlss.py).
"""

from collections.abc import Sequence
from itertools import combinations_with_replacement

import numpy as np

STRUCTURES = ("full", "statesonly", "inputsonly")


def check_degrees(degrees: Sequence[int]) -> tuple[int, ...]:
    """Validate and sort the total degrees of the monomials.

    Raises:
        ValueError: if a degree is not an integer ≥ 2 or the list is empty.
    """
    out: list[int] = []
    for d in degrees:
        if int(d) != d or int(d) < 2:
            raise ValueError(
                f"monomial degrees must be integers >= 2 (degree 1 is the linear part A, B, C, "
                f"D); got {list(degrees)}"
            )
        out.append(int(d))
    if not out:
        raise ValueError("degrees is empty; give at least one total degree, e.g. (2, 3)")
    return tuple(sorted(set(out)))


def monomial_exponents(n_vars: int, degrees: Sequence[int]) -> np.ndarray:
    """All monomials of `n_vars` variables with a total degree in `degrees`.

    Args:
        n_vars: number of variables (nx + nu for [x; u]).
        degrees: total degrees to include, each ≥ 2.

    Returns:
        (K, n_vars) int64 exponent matrix, ordered by degree, then lexicographically.
        K = Σ_d C(n_vars + d − 1, d).
    """
    if n_vars < 1:
        raise ValueError(f"n_vars must be >= 1; got {n_vars}")
    rows: list[np.ndarray] = []
    for d in check_degrees(degrees):
        for combo in combinations_with_replacement(range(n_vars), d):
            rows.append(np.bincount(np.asarray(combo), minlength=n_vars))
    return np.asarray(rows, dtype=np.int64).reshape(-1, n_vars)


def structure_exponents(nx: int, nu: int, degrees: Sequence[int], structure: str) -> np.ndarray:
    """Exponent matrix of [x; u] monomials for one of the named structures.

    Args:
        nx: number of states.
        nu: number of inputs.
        degrees: total degrees (≥ 2).
        structure: "full", "statesonly" or "inputsonly" (module docstring).

    Returns:
        (K, nx + nu) int64 exponent matrix.

    Raises:
        ValueError: for an unknown structure.
    """
    if structure not in STRUCTURES:
        raise ValueError(f"unknown PNLSS structure {structure!r}; choose one of {STRUCTURES}")
    exps = monomial_exponents(nx + nu, degrees)
    if structure == "statesonly":
        exps = exps[exps[:, nx:].sum(axis=1) == 0]
    elif structure == "inputsonly":
        exps = exps[exps[:, :nx].sum(axis=1) == 0]
    return np.ascontiguousarray(exps)


def evaluate_monomials(z: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Evaluate monomials at the points z (plain numpy; the numba kernels do this per sample).

    Args:
        z: (T, n_vars) points, rows [x; u].
        exponents: (K, n_vars) exponent matrix.

    Returns:
        (T, K) monomial values.
    """
    z = np.atleast_2d(np.asarray(z, dtype=float))
    return np.prod(z[:, None, :] ** exponents[None, :, :], axis=2)
