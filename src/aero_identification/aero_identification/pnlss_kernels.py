"""Compiled (numba) kernels of the PNLSS model: simulation and analytic Jacobian.

Model (Paduart et al., Automatica 46(4) 2010), in the normalised coordinates of
pnlss.py:

    x(t+1) = A x(t) + B u(t) + E ζ(x(t), u(t))
    y(t)   = C x(t) + D u(t) + F η(x(t), u(t)) + y_offset

ζ and η are monomials of [x; u] given by integer exponent matrices (monomials.py).

Parameter vector θ (the order of the Jacobian columns), row-major within each matrix:

    θ = [vec(A), vec(B), vec(E) | vec(C), vec(D), vec(F), y_offset (optional)]

The first block (nx² + nx·nu + nx·Kζ) drives the state; the state sensitivities
x_θ = ∂x/∂θ follow the forward recursion (Paduart 2010, the sensitivity equations of the LM fit)

    x_θ(t+1) = (A + E ∂ζ/∂x) x_θ(t) + ∂f/∂θ,       y_θ(t) = (C + F ∂η/∂x) x_θ(t) + ∂g/∂θ,

where ∂f/∂A_ij = e_i x_j, ∂f/∂B_ij = e_i u_j, ∂f/∂E_ik = e_i ζ_k (and likewise for g).

Records are simulated in parallel (prange over records); every record starts at the state x0
(normally 0, the operating point).
"""

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _powers(z: np.ndarray, max_degree: int, pw: np.ndarray) -> None:
    """pw[v, d] = z[v]**d for d = 0 … max_degree."""
    for v in range(z.shape[0]):
        pw[v, 0] = 1.0
        for d in range(1, max_degree + 1):
            pw[v, d] = pw[v, d - 1] * z[v]


@njit(cache=True)
def _monomials(pw: np.ndarray, exps: np.ndarray, out: np.ndarray) -> None:
    """out[k] = Π_v z_v^exps[k, v] from the power table."""
    K, nv = exps.shape
    for k in range(K):
        p = 1.0
        for v in range(nv):
            p *= pw[v, exps[k, v]]
        out[k] = p


@njit(cache=True)
def _monomials_dx(pw: np.ndarray, exps: np.ndarray, nx: int, out: np.ndarray, dout: np.ndarray):
    """Monomials and their derivatives with respect to the first nx variables (the states)."""
    K, nv = exps.shape
    for k in range(K):
        p = 1.0
        for v in range(nv):
            p *= pw[v, exps[k, v]]
        out[k] = p
        for i in range(nx):
            e = exps[k, i]
            if e == 0:
                dout[k, i] = 0.0
                continue
            q = e * pw[i, e - 1]
            for v in range(nv):
                if v != i:
                    q *= pw[v, exps[k, v]]
            dout[k, i] = q


@njit(cache=True)
def _max_degree(exp_state: np.ndarray, exp_output: np.ndarray) -> int:
    d = 1
    for k in range(exp_state.shape[0]):
        d = max(d, exp_state[k].sum())
    for k in range(exp_output.shape[0]):
        d = max(d, exp_output[k].sum())
    return d


@njit(cache=True, inline="always")
def _affine_row(M, x, N, u, t, P, m, i) -> float:
    """Row i of M x + N u[t] + P m: one line of the state or the output equation."""
    acc = 0.0
    for j in range(x.shape[0]):
        acc += M[i, j] * x[j]
    for j in range(u.shape[1]):
        acc += N[i, j] * u[t, j]
    for k in range(m.shape[0]):
        acc += P[i, k] * m[k]
    return acc


@njit(cache=True, inline="always")
def _next_state(A, B, E, x, u, t, zeta, bound, xn) -> bool:
    """xn = A x + B u[t] + E ζ; False when a state leaves [-bound, bound] or is not finite."""
    ok = True
    for i in range(x.shape[0]):
        xn[i] = _affine_row(A, x, B, u, t, E, zeta, i)
        if not abs(xn[i]) <= bound:  # also true for NaN
            ok = False
    return ok


@njit(cache=True)
def _simulate_one(A, B, C, D, E, F, exp_state, exp_output, u, x0, bound, y) -> int:
    """Simulate one record into y (T, ny); returns the number of valid samples.

    If a state leaves [-bound, bound] or is not finite, the rest of y is set to NaN (a
    diverging model is stopped early instead of overflowing).
    """
    nx = A.shape[0]
    nu = B.shape[1]
    ny = C.shape[0]
    Kz = exp_state.shape[0]
    Ke = exp_output.shape[0]
    T = u.shape[0]
    dmax = _max_degree(exp_state, exp_output)
    z = np.empty(nx + nu)
    pw = np.empty((nx + nu, dmax + 1))
    zeta = np.empty(Kz)
    eta = np.empty(Ke)
    x = x0.copy()
    xn = np.empty(nx)
    for t in range(T):
        for i in range(nx):
            z[i] = x[i]
        for j in range(nu):
            z[nx + j] = u[t, j]
        _powers(z, dmax, pw)
        _monomials(pw, exp_output, eta)
        _monomials(pw, exp_state, zeta)
        for i in range(ny):
            y[t, i] = _affine_row(C, x, D, u, t, F, eta, i)
        if not _next_state(A, B, E, x, u, t, zeta, bound, xn):
            y[t + 1 :, :] = np.nan
            return t + 1
        for i in range(nx):
            x[i] = xn[i]
    return T


@njit(cache=True)
def _advance(A, B, E, exp_state, u, x, bound) -> bool:
    """Advance the state x in place over the samples of u (the state equation alone, as
    `_simulate_one` steps it); False as soon as a state leaves [-bound, bound] or is not finite."""
    nx = A.shape[0]
    nu = B.shape[1]
    dmax = _max_degree(exp_state, exp_state)
    z = np.empty(nx + nu)
    pw = np.empty((nx + nu, dmax + 1))
    zeta = np.empty(exp_state.shape[0])
    xn = np.empty(nx)
    for t in range(u.shape[0]):
        for i in range(nx):
            z[i] = x[i]
        for j in range(nu):
            z[nx + j] = u[t, j]
        _powers(z, dmax, pw)
        _monomials(pw, exp_state, zeta)
        if not _next_state(A, B, E, x, u, t, zeta, bound, xn):
            return False
        for i in range(nx):
            x[i] = xn[i]
    return True


@njit(cache=True, parallel=True, nogil=True)
def advance_records(A, B, E, exp_state, u, x0, bound):
    """The states after each of R records, without the outputs (a warm-up), in parallel.

    Args: as `simulate_records` (without the output equation's C, D, F and exponents).

    Returns:
        (R, nx) states after the last sample, (R,) whether every state stayed bounded (the
        last one included).
    """
    R = u.shape[0]
    x = x0.copy()
    ok = np.empty(R, dtype=np.bool_)
    for r in prange(R):
        ok[r] = _advance(A, B, E, exp_state, u[r], x[r], bound)
    return x, ok


def bounded_records(A, B, E, exp_state, u, x0, bound):
    """Whether each of R records keeps its states bounded while it is simulated, in parallel,
    without the outputs: the divergence check of a stressed input. With finite C, D, F (the
    fit checks the training cost first) this holds exactly when `simulate_records` gives the
    record finite outputs: they are polynomials of bounded states, and the state after the
    last sample sets no output (so it is not advanced to).

    Args: as `advance_records`.

    Returns:
        (R,) booleans.
    """
    return advance_records(A, B, E, exp_state, u[:, : max(u.shape[1] - 1, 0)], x0, bound)[1]


@njit(cache=True, parallel=True, nogil=True)
def simulate_records(A, B, C, D, E, F, exp_state, exp_output, u, x0, bound):
    """Simulate R records in parallel.

    Args:
        A, B, C, D, E, F: model matrices, shapes (nx, nx), (nx, nu), (ny, nx), (ny, nu),
            (nx, Kζ), (ny, Kη), float64 C-contiguous.
        exp_state, exp_output: (Kζ, nx+nu), (Kη, nx+nu) int64 exponent matrices.
        u: (R, T, nu) inputs.
        x0: (R, nx) initial states.
        bound: largest allowed |x_i|; beyond it the record's remaining outputs are NaN.

    Returns:
        (R, T, ny) outputs (without the output offset).
    """
    R, T, _ = u.shape
    ny = C.shape[0]
    y = np.empty((R, T, ny))
    for r in prange(R):
        _simulate_one(A, B, C, D, E, F, exp_state, exp_output, u[r], x0[r], bound, y[r])
    return y


@njit(cache=True)
def _jacobian_one(A, B, C, D, E, F, exp_state, exp_output, u, y_meas, n_skip, offset,
                  fit_offset, bound, J, row_base) -> bool:  # fmt: skip
    nx = A.shape[0]
    nu = B.shape[1]
    ny = C.shape[0]
    Kz = exp_state.shape[0]
    Ke = exp_output.shape[0]
    T = u.shape[0]
    dmax = _max_degree(exp_state, exp_output)
    b0 = nx * nx
    e0 = b0 + nx * nu
    n_sp = e0 + nx * Kz
    c0 = n_sp
    d0 = c0 + ny * nx
    f0 = d0 + ny * nu
    o0 = f0 + ny * Ke
    n_par = o0 + (ny if fit_offset else 0)
    z = np.empty(nx + nu)
    pw = np.empty((nx + nu, dmax + 1))
    zeta = np.empty(Kz)
    dzeta = np.empty((Kz, nx))
    eta = np.empty(Ke)
    deta = np.empty((Ke, nx))
    Jx = np.empty((nx, nx))
    Jy = np.empty((ny, nx))
    S = np.zeros((nx, n_sp))
    Sn = np.empty((nx, n_sp))
    x = np.zeros(nx)
    xn = np.empty(nx)
    for t in range(T):
        for i in range(nx):
            z[i] = x[i]
        for j in range(nu):
            z[nx + j] = u[t, j]
        _powers(z, dmax, pw)
        _monomials_dx(pw, exp_state, nx, zeta, dzeta)
        _monomials_dx(pw, exp_output, nx, eta, deta)
        if t >= n_skip:
            # y_θ = (C + F ∂η/∂x) x_θ + ∂g/∂θ
            for i in range(ny):
                for j in range(nx):
                    acc = C[i, j]
                    for k in range(Ke):
                        acc += F[i, k] * deta[k, j]
                    Jy[i, j] = acc
            row0 = row_base + (t - n_skip) * ny
            for i in range(ny):
                row = row0 + i
                for c in range(n_sp):
                    acc = 0.0
                    for j in range(nx):
                        acc += Jy[i, j] * S[j, c]
                    J[row, c] = acc
                for c in range(c0, n_par):
                    J[row, c] = 0.0
                yi = offset[i]
                for j in range(nx):
                    J[row, c0 + i * nx + j] = x[j]
                    yi += C[i, j] * x[j]
                for j in range(nu):
                    J[row, d0 + i * nu + j] = u[t, j]
                    yi += D[i, j] * u[t, j]
                for k in range(Ke):
                    J[row, f0 + i * Ke + k] = eta[k]
                    yi += F[i, k] * eta[k]
                if fit_offset:
                    J[row, o0 + i] = 1.0
                J[row, n_par] = yi - y_meas[t - n_skip, i]  # residual column
        # x_θ(t+1) = (A + E ∂ζ/∂x) x_θ(t) + ∂f/∂θ
        for i in range(nx):
            for j in range(nx):
                acc = A[i, j]
                for k in range(Kz):
                    acc += E[i, k] * dzeta[k, j]
                Jx[i, j] = acc
        for i in range(nx):
            for c in range(n_sp):
                acc = 0.0
                for j in range(nx):
                    acc += Jx[i, j] * S[j, c]
                Sn[i, c] = acc
            for j in range(nx):
                Sn[i, i * nx + j] += x[j]
            for j in range(nu):
                Sn[i, b0 + i * nu + j] += u[t, j]
            for k in range(Kz):
                Sn[i, e0 + i * Kz + k] += zeta[k]
        if not _next_state(A, B, E, x, u, t, zeta, bound, xn):
            return False
        for i in range(nx):
            x[i] = xn[i]
        S, Sn = Sn, S
    return True


@njit(cache=True, parallel=True, nogil=True)
def jacobian_records(A, B, C, D, E, F, exp_state, exp_output, u, y_meas, n_skip, offset,
                     fit_offset, bound, J):  # fmt: skip
    """Analytic Jacobian of the simulated output and the residual, for R parallel records.

    Args:
        A … F, exp_state, exp_output: as in `simulate_records`.
        u: (R, n_skip + N, nu) inputs, the first n_skip samples of each record being the
            prepended transient (not part of the cost).
        y_meas: (R, N, ny) measured outputs.
        n_skip: number of leading samples per record excluded from the rows.
        offset: (ny,) output offset.
        fit_offset: whether the offset is a parameter (last ny columns of θ).
        bound: largest allowed |x_i| (a diverging record returns False).
        J: (R·N·ny, n_par + 1) float64 output buffer (Fortran order preferred for the QR that
            follows). Row (r·N + t)·ny + i holds ∂y_i(t)/∂θ of record r; the last column holds
            the residual y_model − y_meas.

    Returns:
        (R,) bool, False for a record whose simulation left the bound (its rows are invalid).
    """
    R = u.shape[0]
    N = y_meas.shape[1]
    ny = C.shape[0]
    nx = A.shape[0]
    n_par = nx * (nx + B.shape[1] + E.shape[1]) + ny * (nx + D.shape[1] + F.shape[1])
    n_par += ny if fit_offset else 0
    # numba does not check bounds: refuse a buffer that is too small instead of corrupting memory
    if J.shape[0] != R * N * ny or J.shape[1] != n_par + 1:
        raise ValueError("J must have shape (R*N*ny, n_par + 1); see the docstring")
    if y_meas.shape[0] != R or u.shape[1] != n_skip + N:
        raise ValueError("u must be (R, n_skip + N, nu) and y_meas (R, N, ny)")
    ok = np.empty(R, dtype=np.bool_)
    for r in prange(R):
        ok[r] = _jacobian_one(A, B, C, D, E, F, exp_state, exp_output, u[r], y_meas[r], n_skip,
                              offset, fit_offset, bound, J, r * N * ny)  # fmt: skip
    return ok
