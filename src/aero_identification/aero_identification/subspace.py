"""Linear state-space model of the BLA by frequency-domain subspace identification.

Algorithm: McKelvey, Akçay & Ljung, "Subspace-based multivariable system identification from
frequency response data", IEEE TAC 41(7) 1996 (FSID), discrete time z_k = exp(j2π k/N), with
the noise weighting of Pintelon, "Frequency-domain subspace system identification using
non-parametric noise models", Automatica 38 2002: the projected data are whitened by the
covariance implied by the nonparametric variance of G before the SVD, and B, D are fitted by
variance-weighted least squares.

Cost (the criterion for choosing order n and block rows r, and of the optional refinement):

    V = Σ_k |G_model(z_k) − G_BLA(k)|² / var(k)

with var the variance of the mean BLA (`BLA.var_total` by default: noise plus stochastic
nonlinear distortions, the right weighting for a BLA; Pintelon & Schoukens 2012, ch. 9).

Models returned are always stable (all eigenvalues of A inside the unit circle): unstable
eigenvalues of a candidate are reflected into the unit circle (z ↦ 1/z̄, which keeps the
magnitude response shape) and B, D re-fitted; a refinement that ends unstable is discarded.

The model itself (LinearStateSpace) and its operating-point convention are in
state_space_models.py. A BLA carries no DC information, so `fit_linear_ss` returns
u_mean = y_mean = 0; set them from the training data with `with_operating_point` before
simulating absolute signals.
"""

import math

import numpy as np
import scipy.linalg
import scipy.optimize

from aero_identification.bla import BLA
from aero_identification.state_space_models import LinearStateSpace, _frf

# Largest eigenvalue modulus accepted for a "stable" model; reflected/clipped poles land at or
# below it (a pole on the unit circle would be an integrator, not identifiable from the BLA).
MAX_POLE_RADIUS = 0.9999


# --- frequency-response helpers -------------------------------------------------------------


def _resolvents(A: np.ndarray, B: np.ndarray, C: np.ndarray, z: np.ndarray):
    """L = C (zI − A)⁻¹ (F, ny, nx) and R = (zI − A)⁻¹ B (F, nx, nu)."""
    nx = A.shape[0]
    Zi = z[:, None, None] * np.eye(nx)[None] - A[None]
    R = np.linalg.solve(Zi, np.broadcast_to(B.astype(complex), (z.size, *B.shape)))
    Ct = np.broadcast_to(C.T.astype(complex), (z.size, *C.T.shape))
    L = np.swapaxes(np.linalg.solve(np.swapaxes(Zi, 1, 2), Ct), 1, 2)  # (C (zI − A)⁻¹)ᵀ solved
    return L, R


def weighted_cost(G_model: np.ndarray, G: np.ndarray, var: np.ndarray) -> float:
    """V = Σ |G_model − G|² / var over lines (and matrix entries)."""
    return float(np.sum(np.abs(G_model - G) ** 2 / var))


# --- the subspace step ----------------------------------------------------------------------


def frequency_domain_subspace(
    z: np.ndarray, G: np.ndarray, var: np.ndarray, order: int, r: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One weighted FSID estimate of (A, B, C, D) from FRF samples (McKelvey 1996, Pintelon 2002).

    Args:
        z: (F,) complex points on the unit circle, exp(j2π k/N).
        G: (F, ny, nu) complex FRF samples.
        var: (F, ny, nu) positive variances of G (ones for an unweighted fit).
        order: model order n.
        r: block rows, r > n.

    Returns:
        A (n, n), B (n, nu), C (ny, n), D (ny, nu), real; A not necessarily stable.

    Raises:
        ValueError: if r <= n or there are too few lines for r block rows.
    """
    F, ny, nu = G.shape
    if r <= order:
        raise ValueError(f"block rows r={r} must exceed the order n={order}")
    if 2 * F * nu < r * (nu + ny):
        raise ValueError(
            f"{F} lines are too few for r={r} block rows (need 2·F·nu >= r·(nu+ny)); lower r "
            "or the order"
        )
    Wr = z[None, :] ** np.arange(r)[:, None]  # (r, F), McKelvey's W_r(z_k)
    # Column block k of the data: W_r(z_k) ⊗ G_k and W_r(z_k) ⊗ I (McKelvey 1996).
    # Rows (a, i) = (block a, output i), columns (k, j) = (line k, input j).
    Gbig = (Wr[:, None, :, None] * G.transpose(1, 0, 2)[None]).reshape(r * ny, F * nu)
    Wbig = (Wr[:, None, :, None] * np.eye(nu)[None, :, None, :]).reshape(r * nu, F * nu)
    Z = np.vstack([Wbig, Gbig])
    Zr = np.hstack([Z.real, Z.imag])  # real data, both signs of frequency (McKelvey 1996)
    Rq = scipy.linalg.qr(Zr.T, mode="r")[0]
    L22 = Rq[r * nu : r * (nu + ny), r * nu : r * (nu + ny)].T  # G Π⊥_W = L22 Q2ᵀ
    # Noise covariance of the projected rows (Pintelon 2002): Σ_k Re(W Wᴴ ⊗ C_G,k).
    CN = np.zeros((r * ny, r * ny))
    for j in range(nu):
        for i in range(ny):
            WW = (Wr * var[None, :, i, j]) @ Wr.conj().T  # Σ_k var_k W_r(z_k) W_r(z_k)ᴴ
            sel = np.arange(r) * ny + i
            CN[np.ix_(sel, sel)] += WW.real
    CN /= np.trace(CN) / CN.shape[0]
    Kc = np.linalg.cholesky(CN + 1e-12 * np.eye(CN.shape[0]))
    U, _, _ = np.linalg.svd(scipy.linalg.solve_triangular(Kc, L22, lower=True))
    Ob = Kc @ U[:, :order]  # extended observability matrix O_r
    C = Ob[:ny, :]
    A = np.linalg.lstsq(Ob[:-ny, :], Ob[ny:, :], rcond=None)[0]  # shift invariance
    B, D = fit_b_d(A, C, z, G, var)
    return A, B, C, D


def fit_b_d(
    A: np.ndarray, C: np.ndarray, z: np.ndarray, G: np.ndarray, var: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares B, D for fixed A, C: G_k = C (z_k I − A)⁻¹ B + D is linear in B, D.

    Args:
        A: (n, n); C: (ny, n); z: (F,); G, var: (F, ny, nu).

    Returns:
        B (n, nu), D (ny, nu).
    """
    F, ny, nu = G.shape
    n = A.shape[0]
    L, _ = _resolvents(A, np.zeros((n, nu)), C, z)  # (F, ny, n)
    Phi = np.concatenate([L, np.broadcast_to(np.eye(ny), (F, ny, ny))], axis=2)  # (F, ny, n+ny)
    B = np.empty((n, nu))
    D = np.empty((ny, nu))
    for j in range(nu):
        w = 1.0 / np.sqrt(var[:, :, j])  # (F, ny)
        Pw = (Phi * w[:, :, None]).reshape(F * ny, n + ny)
        gw = (G[:, :, j] * w).reshape(F * ny)
        theta = np.linalg.lstsq(
            np.vstack([Pw.real, Pw.imag]), np.concatenate([gw.real, gw.imag]), rcond=None
        )[0]
        B[:, j] = theta[:n]
        D[:, j] = theta[n:]
    return B, D


def stabilize(A: np.ndarray, max_radius: float = MAX_POLE_RADIUS) -> np.ndarray:
    """Reflect eigenvalues outside the unit circle to 1/z̄ and clip them to max_radius.

    Reflection keeps the shape of the magnitude response of each pole (an all-pass factor
    separates the two); the real structure is kept because conjugate pairs map to conjugate
    pairs.

    Args:
        A: (n, n) real state matrix.

    Returns:
        (n, n) real state matrix with every eigenvalue modulus <= max_radius (A itself when
        already so).
    """
    lam, V = np.linalg.eig(A)
    mag = np.abs(lam)
    if np.all(mag <= max_radius):
        return A
    new = lam.copy()
    out = mag > max_radius
    new[out] = 1.0 / np.conj(lam[out])
    big = np.abs(new) > max_radius
    new[big] = new[big] / np.abs(new[big]) * max_radius
    As = (V @ np.diag(new) @ np.linalg.inv(V)).real
    if np.max(np.abs(np.linalg.eigvals(As))) >= 1.0:
        # V nearly defective: fall back to a uniform contraction, always stable.
        As = A * (max_radius / np.max(mag)) * max_radius
    return As


# --- refinement -----------------------------------------------------------------------------


def _pack(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> np.ndarray:
    return np.concatenate([A.ravel(), B.ravel(), C.ravel(), D.ravel()])


def _unpack(theta: np.ndarray, n: int, nu: int, ny: int):
    i = 0
    A = theta[i : i + n * n].reshape(n, n)
    i += n * n
    B = theta[i : i + n * nu].reshape(n, nu)
    i += n * nu
    C = theta[i : i + ny * n].reshape(ny, n)
    i += ny * n
    D = theta[i : i + ny * nu].reshape(ny, nu)
    return A, B, C, D


def refine(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, z: np.ndarray, G: np.ndarray,
    var: np.ndarray, max_nfev: int = 200,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Weighted nonlinear least squares on all matrices (Pintelon 2002; full parametrisation).

    Minimises Σ_k |G_model(z_k) − G_k|²/var_k with scipy.optimize.least_squares and the analytic
    Jacobian ∂G/∂A_ij = C(zI−A)⁻¹ e_i e_jᵀ (zI−A)⁻¹ B. The nx² similarity directions are
    redundant; the trust-region solver handles the singular Jacobian.

    Returns:
        Refined (A, B, C, D); may be unstable (the caller checks).
    """
    F, ny, nu = G.shape
    n = A.shape[0]
    w = 1.0 / np.sqrt(var)

    def residual(theta: np.ndarray) -> np.ndarray:
        Ai, Bi, Ci, Di = _unpack(theta, n, nu, ny)
        e = (_frf(Ai, Bi, Ci, Di, z) - G) * w
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def jacobian(theta: np.ndarray) -> np.ndarray:
        Ai, Bi, Ci, _ = _unpack(theta, n, nu, ny)
        L, R = _resolvents(Ai, Bi, Ci, z)  # (F, ny, n), (F, n, nu)
        eye_y, eye_u = np.eye(ny), np.eye(nu)
        dA = np.einsum("kai,kjb->kabij", L, R).reshape(F, ny, nu, n * n)
        dB = np.einsum("kai,jb->kabij", L, eye_u).reshape(F, ny, nu, n * nu)
        dC = np.einsum("ai,kjb->kabij", eye_y, R).reshape(F, ny, nu, ny * n)
        dD = np.broadcast_to(
            np.einsum("ai,jb->abij", eye_y, eye_u).reshape(1, ny, nu, ny * nu),
            (F, ny, nu, ny * nu),
        ).astype(complex)
        Jc = np.concatenate([dA, dB, dC, dD], axis=3) * w[..., None]
        Jc = Jc.reshape(F * ny * nu, -1)
        return np.vstack([Jc.real, Jc.imag])

    sol = scipy.optimize.least_squares(
        residual, _pack(A, B, C, D), jac=jacobian, method="trf", x_scale="jac",
        max_nfev=max_nfev,
    )  # fmt: skip
    return _unpack(sol.x, n, nu, ny)


# --- the public fit -------------------------------------------------------------------------


# Weight k of the order penalty V·(1 + k·n_θ·ln(2F)/(2F)); Rissanen's MDL (Ljung 1999, ch. 16)
# has k = 1.
# k = 1 over-fits BLAs from M = 2 realizations in about 1 of 8 cases (spurious pole pairs that
# fit a few lines); k = 3 chose the true order in 25/25 2nd- and 10/10 4th-order trials.
ORDER_PENALTY = 3.0

# Degrees of freedom a per-line variance needs before it is trusted as a weight; fewer are
# pooled over neighbouring lines (see `smooth_variance`).
MIN_VARIANCE_DOF = 20


def variance_dof(bla: BLA, which: str) -> int | None:
    """Degrees of freedom (real) of the per-line variance estimate, None if unknown.

    Robust BLA (Pintelon & Schoukens 2012, §4.3.1): var_total from M realizations has
    2(M − 1); var_noise from M·P periods has 2M(P − 1). The LPM variance comes from local
    windows of a size this module does not know.
    """
    if which == "total" and bla.method == "robust" and bla.M >= 2:
        return 2 * (bla.M - 1)
    if which == "noise" and bla.method == "robust" and bla.P >= 2:
        return 2 * sum(p - 1 for p in bla.periods_per_realization)
    return None


def smooth_variance(var: np.ndarray, G: np.ndarray, dof: int | None) -> tuple[np.ndarray, int]:
    """Pool a low-dof variance estimate over neighbouring lines.

    A sample variance with few degrees of freedom (2 for M = 2 realizations) scatters over
    orders of magnitude, and 1/var weighting then lets a few lines dominate the fit (and the
    order scan over-fits them). The relative variance var/|G|² varies slowly with frequency, so
    it is averaged over a centred window of w lines with w·dof >= MIN_VARIANCE_DOF.

    Args:
        var: (F,) variances; G: (F,) complex FRF; dof: degrees of freedom per line (None: keep).

    Returns:
        (F,) pooled variances and the window length w (1 = unchanged).
    """
    if dof is None or dof >= MIN_VARIANCE_DOF or var.size < 3:
        return var, 1
    w = min(var.size, -(-MIN_VARIANCE_DOF // dof))
    w += 1 - w % 2  # odd, centred
    mag2 = np.maximum(np.abs(G) ** 2, np.finfo(float).tiny)
    rel = var / mag2
    csum = np.concatenate([[0.0], np.cumsum(rel)])
    half = w // 2
    lo = np.clip(np.arange(var.size) - half, 0, var.size)
    hi = np.clip(np.arange(var.size) + half + 1, 0, var.size)
    return (csum[hi] - csum[lo]) / (hi - lo) * mag2, w


def _bla_arrays(bla: BLA, weighting: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """z (F,), G (F, 1, 1), var (F, 1, 1) and the weighting actually used (SISO BLA)."""
    lines = np.asarray(bla.lines, dtype=float)
    G1 = np.asarray(bla.G, dtype=complex)
    if G1.shape != lines.shape:
        raise ValueError(
            f"BLA.G must have one value per excited line, shape {lines.shape}; got {G1.shape}"
        )
    if not np.all(np.isfinite(G1)):
        raise ValueError("the BLA contains NaN or inf at some lines; re-estimate it")
    z = np.exp(2j * np.pi * lines / bla.N)

    def usable(v: np.ndarray | None) -> bool:
        return v is not None and bool(np.all(np.isfinite(v)) and np.all(v > 0))

    choices = {"total": bla.var_total, "noise": bla.var_noise}
    if weighting == "auto":
        weighting = next((k for k in ("total", "noise") if usable(choices[k])), "none")
    if weighting == "none":
        var1 = np.ones(lines.size)
    elif weighting in choices:
        v = choices[weighting]
        if not usable(v):
            raise ValueError(
                f"BLA.var_{weighting} is not positive and finite at every line (needs M >= 2 "
                f"realizations for 'total', P >= 2 periods for 'noise'); use weighting='auto' "
                "or 'none'"
            )
        var1, _ = smooth_variance(
            np.asarray(v, dtype=float).reshape(-1), G1, variance_dof(bla, weighting)
        )
    else:
        raise ValueError(
            f"unknown weighting {weighting!r}; choose 'auto', 'total', 'noise' or 'none'"
        )
    return z, G1.reshape(-1, 1, 1), np.ascontiguousarray(var1.reshape(-1, 1, 1)), weighting


def _block_rows(order: int, F: int, nu: int, ny: int) -> list[int]:
    """Candidate block rows r for an order: n+1 … 2n+4, as far as the lines allow."""
    r_max = (2 * F * nu) // (nu + ny)
    return [r for r in range(order + 1, 2 * order + 5) if r <= r_max]


def fit_linear_ss(
    bla: BLA,
    nx: int | None = None,
    *,
    max_order: int = 8,
    block_rows: int | None = None,
    weighting: str = "auto",
    refine_fit: bool = True,
    validation: BLA | None = None,
) -> LinearStateSpace:
    """Stable linear state-space model of a BLA (module docstring for the method).

    Args:
        bla: the nonparametric BLA (its G, lines, N, fs and variances are used).
        nx: model order; None scans 1 … max_order.
        max_order: highest order scanned when nx is None.
        block_rows: r; None scans n+1 … 2n+4 for every order.
        weighting: "auto" (var_total if usable, else var_noise, else none), "total", "noise"
            or "none". A variance with fewer than MIN_VARIANCE_DOF degrees of freedom per
            line (e.g. var_total from M = 2 realizations) is pooled over neighbouring lines
            first (`smooth_variance`).
        refine_fit: refine the best subspace estimate of every order by weighted least squares
            (kept only if stable and cheaper).
        validation: a BLA of held-out data (e.g. another realization); when given, the order
            and r are chosen by the weighted cost on it instead of on `bla`.

    Returns:
        The selected stable LinearStateSpace (u_mean = y_mean = 0; see `with_operating_point`).

        Selection: on `bla` alone the weighted cost always falls with the order, so orders are
        compared by V·(1 + k·n_θ·ln(2F)/(2F)) (an MDL-type penalty, Ljung 1999 ch. 16, with
        k = ORDER_PENALTY) with n_θ = n(nu+ny) + nu·ny; on a validation BLA by its plain
        weighted cost.

    Raises:
        ValueError: for an unusable BLA or invalid arguments.
    """
    z, G, var, used = _bla_arrays(bla, weighting)
    F, ny, nu = G.shape
    if validation is not None:
        zv, Gv, varv, _ = _bla_arrays(validation, used)
        if validation.fs != bla.fs:
            raise ValueError("the validation BLA has a different fs; use the same sampling rate")
    orders = [nx] if nx is not None else list(range(1, max_order + 1))
    if any(n < 1 for n in orders):
        raise ValueError(f"model order must be >= 1; got {nx}")

    def selection_cost(A, B, C, D, V_fit: float) -> float:
        if validation is not None:
            return weighted_cost(_frf(A, B, C, D, zv), Gv, varv)
        n_theta = A.shape[0] * (nu + ny) + nu * ny
        return V_fit * (1.0 + ORDER_PENALTY * n_theta * math.log(2 * F) / (2 * F))

    best: tuple[float, LinearStateSpace] | None = None
    for n in orders:
        rs = [block_rows] if block_rows is not None else _block_rows(n, F, nu, ny)
        if not rs:
            continue
        cand: tuple[float, tuple, int] | None = None
        for r in rs:
            try:
                A, B, C, D = frequency_domain_subspace(z, G, var, n, r)
            except (ValueError, np.linalg.LinAlgError):
                continue
            As = stabilize(A)
            if As is not A:
                A = As
                B, D = fit_b_d(A, C, z, G, var)
            V = weighted_cost(_frf(A, B, C, D, z), G, var)
            if np.isfinite(V) and (cand is None or V < cand[0]):
                cand = (V, (A, B, C, D), r)
        if cand is None:
            continue
        V, (A, B, C, D), r = cand
        refined = False
        if refine_fit:
            Ar, Br, Cr, Dr = refine(A, B, C, D, z, G, var)
            Vr = weighted_cost(_frf(Ar, Br, Cr, Dr, z), G, var)
            stable = np.max(np.abs(np.linalg.eigvals(Ar))) <= MAX_POLE_RADIUS
            if stable and np.isfinite(Vr) and Vr < V:
                A, B, C, D, V, refined = Ar, Br, Cr, Dr, Vr, True
        S = selection_cost(A, B, C, D, V)
        cost = S if validation is not None else V
        model = LinearStateSpace(
            A=A, B=B, C=C, D=D, fs=bla.fs, r=r, cost=cost, refined=refined,
            weighting=used,
        )  # fmt: skip
        if best is None or S < best[0]:
            best = (S, model)
    if best is None:
        raise ValueError(
            f"no state-space model could be fitted: {F} lines are too few for the orders "
            f"{orders}; lower nx/max_order or give more excited lines"
        )
    model = best[1]
    if not model.is_stable():  # cannot happen by construction; never hand out an unstable one
        raise RuntimeError("internal error: selected linear model is unstable")
    return model
