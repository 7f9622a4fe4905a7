"""Fit of a polynomial nonlinear state-space (PNLSS) model by Levenberg–Marquardt.

The model (Paduart et al., "Identification of nonlinear systems using polynomial nonlinear state
space models", Automatica 46(4) 2010), its monomials, normalised coordinates and operating point
are described in state_space_models.py (PNLSSModel).

Fit (Paduart 2010; the PNLSS toolbox's weighted Levenberg–Marquardt):

- start from the linear model (E = F = 0) in a canonical real modal basis (`modal_basis`), so
  that the start, and with it the fit, depends on the linear model's transfer function and not
  on the state basis its subspace fit happened to return (issue 22: BLAS rounding moved it);
- each of the P·M periods is an independent periodic record; its transient is removed by
  prepending the last n_transient input samples of the same record (steady state of a periodic
  input), whose outputs are simulated but not part of the cost;
- the cost is the mean squared simulation error in normalised output units, optionally weighted
  per DFT bin (1/σ²_Y(k), the output noise variance estimated over the periods: the
  nonparametric noise model the BLA uses);
- the Jacobian comes from the forward sensitivity recursion (pnlss_kernels.py), its columns are
  normalised to unit norm and the Levenberg–Marquardt step δ = −V diag(s/(s²+λ²)) Uᵀ e is taken
  from the SVD of J, with the rank capped at n_θ − nx² (the similarity transform x ↦ T x leaves
  the input–output behaviour unchanged, so J has nx² null directions); the SVD comes from the
  eigendecomposition of JᵀJ (default) or from an in-place QR of J (`lm_directions`). Memory:
  one (n_samples × (n_θ + 1)) float64 buffer [J | e];
- divergence guard: a trial step whose training or validation simulation leaves the state bound
  or is NaN is rejected and λ raised; the returned model is the one best on the validation
  record (the initial linear model included), or the last accepted one without validation.
"""

import contextlib
import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg

from aero_identification.monomials import (
    STRUCTURES,
    check_degrees,
    evaluate_monomials,
    structure_exponents,
)
from aero_identification.periodic_data import PeriodicData
from aero_identification.pnlss_kernels import bounded_records, jacobian_records, simulate_records
from aero_identification.state_space_models import (
    STATE_BOUND,
    LinearStateSpace,
    LMIteration,
    PNLSSModel,
)

# Where the monomials enter (Paduart et al. 2010, eq. 2): the state equation only (E), or the
# state and the output equation (E and F).
EQUATIONS = ("state", "state+output")

try:  # a dependency of scikit-learn; optional here
    from threadpoolctl import ThreadpoolController
except ImportError:  # pragma: no cover
    ThreadpoolController = None


def one_blas_thread() -> contextlib.AbstractContextManager:
    """Limit BLAS to one thread inside the block (no-op without threadpoolctl).

    Measured on the 2-core target machine with a busy neighbour process: a multi-threaded
    OpenBLAS makes the 58×58 SVD take tens of ms and the tall QR of the Jacobian 10× slower
    (threads waiting for a core), and an order-10 subspace fit of one F-16 level 0.6 s with
    one thread against 8.5 s (up to 70 s) with two; one thread is fast and predictable.
    """
    if ThreadpoolController is None:
        return contextlib.nullcontext()
    return ThreadpoolController().limit(limits=1, user_api="blas")


# --- parameter vector -----------------------------------------------------------------------


@dataclass(frozen=True)
class _Layout:
    nx: int
    nu: int
    ny: int
    Kz: int
    Ke: int
    fit_offset: bool

    @property
    def sizes(self) -> list[tuple[str, tuple[int, int]]]:
        s = [
            ("A", (self.nx, self.nx)), ("B", (self.nx, self.nu)), ("E", (self.nx, self.Kz)),
            ("C", (self.ny, self.nx)), ("D", (self.ny, self.nu)), ("F", (self.ny, self.Ke)),
        ]  # fmt: skip
        if self.fit_offset:
            s.append(("offset", (self.ny, 1)))
        return s

    @property
    def n_par(self) -> int:
        return sum(a * b for _, (a, b) in self.sizes)

    def pack(self, mats: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([np.asarray(mats[k], float).ravel() for k, _ in self.sizes])

    def unpack(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        i = 0
        for k, (a, b) in self.sizes:
            out[k] = np.ascontiguousarray(theta[i : i + a * b].reshape(a, b))
            i += a * b
        if not self.fit_offset:
            out["offset"] = np.zeros((self.ny, 1))
        return out


# --- frequency-domain weighting -------------------------------------------------------------


def _pack_spectrum(e: np.ndarray, sqrt_w: np.ndarray) -> np.ndarray:
    """Weighted real packing of the DFT of period records, Parseval-exact for unit weights.

    Args:
        e: (..., N, ny) real time records (N along axis -2).
        sqrt_w: (N//2+1, ny) square roots of the per-bin weights.

    Returns:
        (..., N, ny) real: [Re E_0 … Re E_⌊N/2⌋, Im E_1 … Im E_(last interior)] scaled so that
        Σ out² = Σ_k c_k w_k |E_k|² / N with c_k = 1 for DC and Nyquist, 2 otherwise
        (= Σ e² when w ≡ 1).
    """
    N = e.shape[-2]
    nr = N // 2 + 1
    n_im = N - nr
    E = np.fft.rfft(e, axis=-2) * sqrt_w
    fac = np.full(nr, math.sqrt(2.0 / N))
    fac[0] = 1.0 / math.sqrt(N)
    if N % 2 == 0:
        fac[-1] = 1.0 / math.sqrt(N)
    out = np.empty(e.shape)
    out[..., :nr, :] = E.real * fac[:, None]
    out[..., nr:, :] = E.imag[..., 1 : 1 + n_im, :] * math.sqrt(2.0 / N)
    return out


def _noise_weights(y_n: np.ndarray) -> np.ndarray:
    """(N//2+1, 1) weights 1/σ²_Y(k) from the period-to-period variance of the output DFT.

    Args:
        y_n: (N, P, M) normalised outputs; P >= 2 needed.
    """
    P = y_n.shape[1]
    if P < 2:
        raise ValueError(
            "weighting='noise' estimates the output noise variance over periods and needs "
            f"P >= 2 periods per realization; got P={P}. Use weighting=None."
        )
    Y = np.fft.rfft(y_n, axis=0)
    var = np.mean(np.var(Y, axis=1, ddof=1), axis=1)  # (N//2+1,) mean over realizations
    if not np.all(var > 0):
        raise ValueError(
            "the output noise variance is zero at some DFT bins (noise-free data?); use "
            "weighting=None or pass explicit weights"
        )
    return (1.0 / var)[:, None]


def _normalise_weights(w: np.ndarray, N: int) -> np.ndarray:
    """Scale per-bin weights so a uniform error gives the same cost as unit weights."""
    c = np.full(N // 2 + 1, 2.0)
    c[0] = 1.0
    if N % 2 == 0:
        c[-1] = 1.0
    return w * (N / np.sum(c[:, None] * w, axis=0))


# --- the fit --------------------------------------------------------------------------------


def stress_periods(
    periods: np.ndarray, scale: float, realizations: int = 2, seed: int = 0
) -> np.ndarray:
    """(N, R) input periods -> (N, R·(1 + realizations)) periods at `scale` times the amplitude.

    Each period is scaled about its mean, and `realizations` random-phase periods with the same
    amplitude spectrum (the same class of excitation: Pintelon & Schoukens 2012, §3.2 on
    random-phase multisines; seeded, so the check is deterministic) are added: a model is used
    on other phase realizations than the ones it was validated on, and a polynomial model's
    divergence depends on the waveform's peaks, not only its RMS.
    """
    N = periods.shape[0]
    centre = periods.mean(axis=0, keepdims=True)
    dev = periods - centre
    rng = np.random.default_rng(seed)
    spectrum = np.abs(np.fft.rfft(dev, axis=0))
    out = [centre + scale * dev]
    for _ in range(realizations):
        phase = np.exp(2j * np.pi * rng.random(spectrum.shape))
        phase[0] = 1.0
        if N % 2 == 0:
            phase[-1] = 1.0
        out.append(centre + scale * np.fft.irfft(spectrum * phase, n=N, axis=0))
    return np.concatenate(out, axis=1)


def default_transient(A: np.ndarray, N: int, decay: float = 1e-4) -> int:
    """Samples for the slowest mode of A to decay to `decay`, capped at one period N."""
    rho = float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
    if rho <= 0.0:
        return 1
    if rho >= 1.0:
        return N
    return int(min(N, max(1, math.ceil(math.log(decay) / math.log(rho)))))


def linear_states(A: np.ndarray, B: np.ndarray, u_rec: np.ndarray) -> np.ndarray:
    """States of x(t+1) = A x(t) + B u(t) from x = 0 for (R, T, nu) records -> (R, T, nx)."""
    nx, nu = B.shape
    empty = np.zeros((0, nx + nu), dtype=np.int64)
    return simulate_records(  # the PNLSS kernel with E = F = 0 and the states as outputs
        np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(B, dtype=float),
        np.eye(nx), np.zeros((nx, nu)), np.zeros((nx, 0)), np.zeros((nx, 0)), empty, empty,
        np.ascontiguousarray(u_rec, dtype=float), np.zeros((u_rec.shape[0], nx)), np.inf,
    )  # fmt: skip


def periodic_records(u: np.ndarray, n_transient: int) -> np.ndarray:
    """(N, P, M) periods -> (P·M, n_transient + N, 1) records, each preceded by its own tail.

    The input is periodic, so simulating the last n_transient samples of a period before it
    starts the period in (close to) its steady state; those leading outputs are discarded.
    """
    N, P, M = u.shape
    per = np.asarray(u, dtype=float).transpose(2, 1, 0).reshape(P * M, N)
    tail = np.arange(-n_transient, 0) % N
    return np.ascontiguousarray(np.concatenate([per[:, tail], per], axis=1)[:, :, None])


def modal_basis(
    A: np.ndarray, B: np.ndarray, C: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C) in a canonical real modal basis: one that depends on the transfer function only.

    A subspace fit returns its states in the basis of an SVD, which rounding moves: two
    OpenBLAS kernels gave the same poles to 1e-6 but A entries differing by 1e-2 (issue 22).
    The PNLSS monomials and the LM's column scaling live in that basis, so a basis that rounding
    moves is a start that rounding moves. Here the basis is fixed by the system itself: real
    modal (block-diagonal) form (e.g. Ljung 1999, §4.3's diagonal forms), modes sorted by
    frequency then by pole radius, each 2×2 block rotated (a rotation commutes with it) so
    that its B entries are (1, 0), each real mode scaled so that its B entry is 1 (a mode the
    input does not reach keeps its eigenvector's scale).
    Defective or near-repeated poles (an ill-conditioned eigenbasis) keep the given basis.
    """
    nx = A.shape[0]
    if nx == 0:
        return A.copy(), B.copy(), C.copy()
    lam, V = np.linalg.eig(A)
    keep = np.flatnonzero(lam.imag >= -1e-12 * np.maximum(1.0, np.abs(lam)))
    keep = keep[np.lexsort((-np.abs(lam[keep]), np.abs(np.angle(lam[keep]))))]
    cols: list[np.ndarray] = []
    blocks: list[int] = []
    for i in keep:
        if abs(lam[i].imag) <= 1e-12 * max(1.0, abs(lam[i])):
            cols.append(V[:, i].real)
            blocks.append(1)
        else:
            cols += [V[:, i].real, V[:, i].imag]
            blocks.append(2)
    if len(cols) != nx:
        return A.copy(), B.copy(), C.copy()
    T = np.column_stack(cols)
    if not np.all(np.isfinite(T)) or np.linalg.cond(T) > 1e8:
        return A.copy(), B.copy(), C.copy()
    # A block's columns times S change only that block's B entries, to S⁻¹b: S = b for a real
    # mode, and S = [[b₀, −b₁], [b₁, b₀]] (rotation by atan2(b₁, b₀) times |b|, which commutes
    # with the block) for a pair, so every block's B becomes 1 or (1, 0).
    b_modal = np.linalg.solve(T, B)[:, 0]
    j = 0
    for size in blocks:
        b = b_modal[j : j + size]
        if np.any(b != 0):
            S = np.array([[b[0]]]) if size == 1 else np.array([[b[0], -b[1]], [b[1], b[0]]])
            T[:, j : j + size] = T[:, j : j + size] @ S
        j += size
    Am = np.linalg.solve(T, A @ T)
    return Am, np.linalg.solve(T, B), C @ T


def _initial_from_linear(
    lin: LinearStateSpace,
    u_rec: np.ndarray,
    u_scale: np.ndarray,
    y_scale: np.ndarray,
    record_weights: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Linear model in normalised coordinates, states scaled to unit RMS on the training input
    (each record weighted by `record_weights` when given)."""
    if not lin.is_stable():
        raise ValueError(
            "the initial linear model is unstable; fit it with fit_linear_ss (stable by "
            "construction) or stabilise it first"
        )
    A, B, C = modal_basis(lin.A, lin.B, lin.C)
    B = B * u_scale[None, :]
    C = C / y_scale[:, None]
    D = lin.D * u_scale[None, :] / y_scale[:, None]
    nx = A.shape[0]
    x = linear_states(A, B, u_rec)  # their RMS on the training records
    if record_weights is None:
        std = np.sqrt(np.mean(x.reshape(-1, nx) ** 2, axis=0))
    else:
        per_record = np.mean(x**2, axis=1)  # (R, nx)
        std = np.sqrt(np.average(per_record, axis=0, weights=record_weights))
    std[~(std > 0)] = 1.0
    return {
        "A": A * std[None, :] / std[:, None],  # T⁻¹ A T with T = diag(std)
        "B": B / std[:, None],
        "C": C * std[None, :],
        "D": D,
    }


@dataclass(frozen=True)
class PnlssSettings:
    """The hyperparameters of a PNLSS fit: the method's choices, apart from the data it fits.

    Attributes:
        degrees: total degrees of the monomials (each >= 2), e.g. (2, 3); stored sorted and
            without repeats (monomials.check_degrees).
        structure: "full", "statesonly" or "inputsonly" (monomials.py).
        equations: where the monomials enter: "state" (E only: x(t+1) = Ax + Bu + Eζ,
            y = Cx + Du, the PNLSS toolbox's default structure) or "state+output" (E and F:
            also y = Cx + Du + Fη).
        max_iter: number of LM trials (accepted or rejected).
        n_transient: samples prepended to each record; None: the decay time of the slowest
            linear mode to 1e-4 (at most one period).
        weighting: None (time-domain cost), "noise" (1/σ²_Y(k) per DFT bin, from the periods;
            needs P >= 2) or an explicit (N//2+1,) array of non-negative per-bin weights
            (settings holding an array do not compare or hash).
        fit_offset: estimate the output offset (the model output at the operating point).
        lambda_init: initial damping relative to the largest singular value of the normalised
            Jacobian (1 = PNLSS toolbox default; a tiny value makes the first steps Gauss–Newton).
        solver: how the SVD of the normalised Jacobian is obtained (`lm_directions`):
            "normal" (eigendecomposition of JᵀJ; about 5× cheaper than "qr" on long records,
            singular values below ~1e-5·s_max are dropped) or "qr" (Householder QR in place,
            then SVD of R; backward stable). On the Duffing benchmark both give the same fit
            to 12 digits.
        stress: with validation, also simulate the validation inputs scaled about their mean by
            this factor (e.g. 1.3), and for periodic validation data two random-phase periods of
            the same amplitude spectrum per record (`stress_periods`): a trial step whose
            stressed simulation diverges (leaves the state bound) is rejected like one that
            diverges on the data, so the returned model stays bounded beyond the validated
            amplitudes (issue 22: every F-16 candidate fitted on levels 1-5 diverged at level 7,
            1.33× level 5). None: no such check.

    A fit from an `initial_model` keeps that model's degrees, structure and terms (degrees,
    structure and equations are then not used).

    Raises:
        ValueError: for a value the fit cannot use (the checks that need the data, such as the
            length of a weighting array, are the fit's).
    """

    degrees: tuple[int, ...] = (2, 3)
    structure: str = "full"
    equations: str = "state+output"
    max_iter: int = 100
    n_transient: int | None = None
    weighting: str | np.ndarray | None = None
    fit_offset: bool = True
    lambda_init: float = 1.0
    solver: str = "normal"
    stress: float | None = None

    def __post_init__(self) -> None:
        if self.max_iter < 0:
            raise ValueError(f"max_iter must be >= 0; got {self.max_iter}")
        if self.solver not in ("qr", "normal"):
            raise ValueError(f"unknown solver {self.solver!r}; use 'qr' or 'normal'")
        if self.equations not in EQUATIONS:
            raise ValueError(f"unknown equations {self.equations!r}; choose one of {EQUATIONS}")
        if self.structure not in STRUCTURES:
            raise ValueError(
                f"unknown PNLSS structure {self.structure!r}; choose one of {STRUCTURES}"
            )
        object.__setattr__(self, "degrees", check_degrees(self.degrees))
        if self.n_transient is not None and int(self.n_transient) < 0:
            raise ValueError(f"n_transient must be >= 0; got {int(self.n_transient)}")
        stress = self.stress
        if stress is not None and not (math.isfinite(stress) and stress > 0):
            raise ValueError(f"stress needs validation data and a positive factor; got {stress}")
        if isinstance(self.weighting, str) and self.weighting != "noise":
            raise ValueError(f"unknown weighting {self.weighting!r}; use None, 'noise' or an array")


def fit_pnlss(
    data: PeriodicData,
    lin: LinearStateSpace,
    settings: PnlssSettings = PnlssSettings(),
    *,
    validation: tuple[np.ndarray, np.ndarray] | PeriodicData | None = None,
    initial_model: PNLSSModel | None = None,
    record_weights: np.ndarray | None = None,
    validation_weights: np.ndarray | None = None,
) -> PNLSSModel:
    """Fit a PNLSS model to periodic data by Levenberg–Marquardt (module docstring).

    Args:
        data: PeriodicData with u, y of shape (N, P, M); every period is a training record.
        lin: the initial linear model (A, B, C, D are used; its operating point is replaced by
            the training-data means).
        settings: the fit's hyperparameters (PnlssSettings).
        validation: (u_val, y_val), 1-D records of equal length in absolute units, whose
            first min(n_transient, length // 2) samples are left out of the validation error
            (the simulation starts at the operating point); or PeriodicData of held-out periods
            (same N), each simulated in steady state like the training records. Used for the
            divergence guard and to choose the returned model.
        initial_model: start from this PNLSS model instead of `lin` (its normalisation,
            degrees, structure and terms are kept, not the settings'; `lin` is then only used
            for n_transient).
        record_weights: one non-negative weight per training record (record r = m·P + p, as
            the periods of data): the cost is Σ_r w_r ||e_r||², so records measured on
            different scales (e.g. levels of one campaign) can count by their relative error.
            None: every record weighs 1.
        validation_weights: the same for the PeriodicData validation records (R_val = P·M of
            `validation`), so the returned iterate is chosen by the same criterion.

    Returns:
        The PNLSSModel with `history_`, `cost_`, `cost_val_`.

    Raises:
        ValueError: for inconsistent data, arguments or a diverging initial model.
    """
    if not isinstance(data, PeriodicData):
        raise TypeError(f"data must be a PeriodicData (N, P, M) record; got {type(data).__name__}")
    if lin.nu != 1 or lin.ny != 1:
        raise ValueError(
            f"PeriodicData is SISO but the linear model has nu={lin.nu}, ny={lin.ny}; fit a "
            "SISO linear model"
        )
    N, P, M = data.u.shape
    R = P * M
    sqrt_rw = _record_weights(record_weights, R, "record_weights")
    nx = lin.nx if initial_model is None else initial_model.nx
    frame = _frame(data, nx, settings, initial_model, record_weights)

    # Records: each period, with the tail of its own input prepended (periodic steady state).
    nt = default_transient(lin.A, N) if settings.n_transient is None else int(settings.n_transient)
    u_rec = periodic_records((data.u - frame.u_mean[0]) / frame.u_scale[0], nt)
    y_per = ((data.y - frame.y_mean[0]) / frame.y_scale[0]).transpose(2, 1, 0).reshape(R, N)
    y_rec = np.ascontiguousarray(y_per[:, :, None])
    x0_rec = np.zeros((R, nx))
    held = _held_out(validation, frame, N, nt, settings.stress, validation_weights)
    sqrt_w = _bin_weights(settings.weighting, data, frame)

    Kz, Ke = frame.exp_state.shape[0], frame.exp_output.shape[0]
    layout = _Layout(nx, 1, 1, Kz, Ke, settings.fit_offset)
    theta = _start_parameters(lin, initial_model, layout, frame, u_rec, sqrt_rw)
    n_rows = R * N * layout.ny
    if n_rows <= layout.n_par:
        raise ValueError(f"{n_rows} samples are too few for {layout.n_par} parameters")
    problem = _Problem(layout, frame, nt, u_rec, y_rec, x0_rec, sqrt_rw, sqrt_w, held)
    best, history = _levenberg_marquardt(problem, theta, settings)

    _, theta_best, cost_best, cost_val_best = best
    m = layout.unpack(theta_best)
    return PNLSSModel(
        A=m["A"], B=m["B"], C=m["C"], D=m["D"], E=m["E"], F=m["F"],
        exponents_state=frame.exp_state, exponents_output=frame.exp_output,
        u_mean=frame.u_mean, u_scale=frame.u_scale,
        y_mean=frame.y_mean + frame.y_scale * m["offset"][:, 0], y_scale=frame.y_scale,
        fs=data.fs, degrees=frame.degrees, structure=frame.structure, n_transient=nt,
        history_=history, cost_=cost_best, cost_val_=cost_val_best,
    )  # fmt: skip


@dataclass(frozen=True)
class _Frame:
    """The model's coordinates and terms: normalisation (nu = ny = 1), monomial exponents,
    degrees and structure."""

    u_mean: np.ndarray
    u_scale: np.ndarray
    y_mean: np.ndarray
    y_scale: np.ndarray
    exp_state: np.ndarray
    exp_output: np.ndarray
    degrees: tuple[int, ...]
    structure: str


def _frame(
    data: PeriodicData,
    nx: int,
    settings: PnlssSettings,
    initial_model: PNLSSModel | None,
    record_weights: np.ndarray | None,
) -> _Frame:
    """The initial model's frame, or a new one from the training data and the settings."""
    if initial_model is not None:
        m = initial_model
        return _Frame(
            m.u_mean, m.u_scale, m.y_mean, m.y_scale, m.exponents_state, m.exponents_output,
            m.degrees, m.structure,
        )  # fmt: skip
    # Record weights weigh the normalisation statistics too: a record that does not count
    # in the cost does not move the model's coordinates either.
    u_mean, u_scale = _weighted_stats(data.u, record_weights)
    y_mean, y_scale = _weighted_stats(data.y, record_weights)
    if not (u_scale[0] > 0 and y_scale[0] > 0):
        raise ValueError(
            "training input or output is constant (zero standard deviation); an "
            "excited record is needed to fit a PNLSS model"
        )
    exp_state = structure_exponents(nx, 1, settings.degrees, settings.structure)
    exp_output = exp_state.copy() if settings.equations == "state+output" else exp_state[:0].copy()
    return _Frame(
        u_mean, u_scale, y_mean, y_scale, exp_state, exp_output, settings.degrees,
        settings.structure,
    )  # fmt: skip


@dataclass(frozen=True)
class _HeldOut:
    """Validation records: normalised inputs (R_val, nt + T, 1), the absolute outputs compared
    (R_val, T - nt), the samples left out, the stressed inputs and √(record weights)."""

    u: np.ndarray
    y_tail: np.ndarray
    nt: int
    u_stress: np.ndarray | None
    sqrt_w: np.ndarray | None


def _held_out(
    validation: tuple[np.ndarray, np.ndarray] | PeriodicData | None,
    frame: _Frame,
    N: int,
    nt: int,
    stress: float | None,
    validation_weights: np.ndarray | None,
) -> _HeldOut | None:
    """The validation records in the fit's coordinates (None without validation), checked."""
    if validation is None:
        if stress is not None:
            raise ValueError(f"stress needs validation data and a positive factor; got {stress}")
        if validation_weights is not None:
            raise ValueError("validation_weights need a PeriodicData validation set")
        return None
    u_val_n, y_val_tail, nt_val = _validation_records(validation, frame, N, nt)

    # Stressed validation inputs: the same records scaled about their own mean.
    u_stress_n: np.ndarray | None = None
    if stress is not None:
        if isinstance(validation, PeriodicData):
            periods = validation.u.transpose(2, 1, 0).reshape(-1, N).T  # (N, R_val)
            stressed = (stress_periods(periods, float(stress)) - frame.u_mean[0]) / frame.u_scale[0]
            u_stress_n = periodic_records(stressed[:, None, :], nt)
        else:
            centre = np.mean(u_val_n, axis=1, keepdims=True)
            u_stress_n = np.ascontiguousarray(centre + float(stress) * (u_val_n - centre))

    sqrt_vw: np.ndarray | None = None
    if validation_weights is not None:
        if not isinstance(validation, PeriodicData):
            raise ValueError("validation_weights need a PeriodicData validation set")
        sqrt_vw = _record_weights(
            validation_weights, validation.u.shape[1] * validation.u.shape[2], "validation_weights"
        )
    return _HeldOut(u_val_n, y_val_tail, nt_val, u_stress_n, sqrt_vw)


def _validation_records(
    validation: tuple[np.ndarray, np.ndarray] | PeriodicData, frame: _Frame, N: int, nt: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Periodic validation (each period in steady state, like the training records) or one 1-D
    record simulated from the operating point -> (normalised inputs, outputs compared, nt)."""
    if isinstance(validation, PeriodicData):
        if validation.u.shape[0] != N:
            raise ValueError(
                f"validation periods have {validation.u.shape[0]} samples; training periods "
                f"have {N}"
            )
        u_val_n = periodic_records((validation.u - frame.u_mean[0]) / frame.u_scale[0], nt)
        return u_val_n, validation.y.transpose(2, 1, 0).reshape(-1, N), nt
    u_val, y_val = (np.asarray(v, dtype=float).reshape(-1) for v in validation)
    if u_val.shape != y_val.shape:
        raise ValueError(
            f"validation u and y must have the same length; got {u_val.size}, {y_val.size}"
        )
    if u_val.size < 4 or not (np.all(np.isfinite(u_val)) and np.all(np.isfinite(y_val))):
        raise ValueError(
            f"the validation record must be finite with at least 4 samples; got "
            f"{u_val.size} samples"
        )
    nt_val = min(nt, u_val.size // 2)
    u_val_n = np.ascontiguousarray(((u_val - frame.u_mean[0]) / frame.u_scale[0])[None, :, None])
    return u_val_n, y_val[None, nt_val:], nt_val


def _bin_weights(
    weighting: str | np.ndarray | None, data: PeriodicData, frame: _Frame
) -> np.ndarray | None:
    """√ of the normalised per-DFT-bin weights (N//2+1, 1), or None for the time-domain cost."""
    if weighting is None:
        return None
    N = data.u.shape[0]
    if isinstance(weighting, str):  # "noise" (PnlssSettings checks the name)
        w = _noise_weights((data.y - frame.y_mean[0]) / frame.y_scale[0])
    else:
        w = np.asarray(weighting, dtype=float).reshape(-1, 1)
        if w.shape[0] != N // 2 + 1 or np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError(
                f"weighting must be N//2+1={N // 2 + 1} finite non-negative per-bin weights; "
                f"got shape {np.shape(weighting)}"
            )
    return np.sqrt(_normalise_weights(w, N))


def _start_parameters(
    lin: LinearStateSpace,
    initial_model: PNLSSModel | None,
    layout: _Layout,
    frame: _Frame,
    u_rec: np.ndarray,
    sqrt_rw: np.ndarray | None,
) -> np.ndarray:
    """The starting parameter vector: the initial model's, or the linear model's with E = F = 0;
    the offset starts at 0."""
    if initial_model is not None:
        mats = {k: getattr(initial_model, k) for k in "ABCDEF"}
    else:
        mats = _initial_from_linear(
            lin, u_rec, frame.u_scale, frame.y_scale, None if sqrt_rw is None else sqrt_rw**2
        )
        mats["E"] = np.zeros((layout.nx, layout.Kz))
        mats["F"] = np.zeros((layout.ny, layout.Ke))
    mats["offset"] = np.zeros((layout.ny, 1))
    return layout.pack(mats)


@dataclass(frozen=True)
class _Problem:
    """The least-squares problem: training records (R, nt + N, 1) -> (R, N, 1) in normalised
    units, their weights, the validation records; the costs and Jacobian of a parameter vector."""

    layout: _Layout
    frame: _Frame
    nt: int
    u_rec: np.ndarray
    y_rec: np.ndarray
    x0_rec: np.ndarray
    sqrt_rw: np.ndarray | None
    sqrt_w: np.ndarray | None
    held: _HeldOut | None

    def simulate(self, th: np.ndarray, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
        m = self.layout.unpack(th)
        y = simulate_records(
            m["A"], m["B"], m["C"], m["D"], m["E"], m["F"], self.frame.exp_state,
            self.frame.exp_output, u, x0, STATE_BOUND,
        )  # fmt: skip
        return y + m["offset"][:, 0]

    def bounded(self, th: np.ndarray, u: np.ndarray, x0: np.ndarray) -> bool:
        """Whether every record's simulation stays finite (its states bounded), without
        computing its outputs."""
        m = self.layout.unpack(th)
        ok = bounded_records(
            m["A"], m["B"], m["E"], self.frame.exp_state, u, x0, STATE_BOUND
        )  # fmt: skip
        return bool(np.all(ok))

    def residual(self, y_sim: np.ndarray) -> np.ndarray:
        e = y_sim[:, self.nt :, :] - self.y_rec
        if self.sqrt_rw is not None:
            e = e * self.sqrt_rw[:, None, None]
        return e if self.sqrt_w is None else _pack_spectrum(e, self.sqrt_w)

    def train_cost(self, th: np.ndarray) -> float:
        e = self.residual(self.simulate(th, self.u_rec, self.x0_rec))
        c = float(np.mean(e * e))
        return c if math.isfinite(c) else math.inf

    def val_cost(self, th: np.ndarray) -> float:
        """Validation mean squared error [output units²]; nan without validation, inf if the
        validation (or stressed) simulation diverges."""
        held = self.held
        if held is None:
            return math.nan
        nx = self.layout.nx
        x0 = np.zeros((held.u.shape[0], nx))
        if held.u_stress is not None:
            x0s = np.zeros((held.u_stress.shape[0], nx))
            if not self.bounded(th, held.u_stress, x0s):
                return math.inf  # diverges at the stressed amplitude
        y_mean, y_scale = self.frame.y_mean, self.frame.y_scale
        y = y_mean[0] + y_scale[0] * self.simulate(th, held.u, x0)[:, held.nt :, 0]
        e2 = (y - held.y_tail) ** 2
        c = float(np.mean(e2 if held.sqrt_w is None else e2 * (held.sqrt_w**2)[:, None]))
        return c if math.isfinite(c) else math.inf

    def directions(
        self, theta: np.ndarray, J: np.ndarray, solver: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The weighted Jacobian [J | e] at theta, written into J, and its `lm_directions`."""
        layout, frame = self.layout, self.frame
        m = layout.unpack(theta)
        ok = jacobian_records(
            m["A"], m["B"], m["C"], m["D"], m["E"], m["F"], frame.exp_state, frame.exp_output,
            self.u_rec, self.y_rec, self.nt, m["offset"][:, 0].copy(), layout.fit_offset,
            STATE_BOUND, J,
        )  # fmt: skip
        if not np.all(ok):
            raise RuntimeError("internal error: an accepted model diverged in the Jacobian")
        R, N, ny = self.y_rec.shape
        if self.sqrt_rw is not None:  # rows are record-major: record r's N·ny rows
            J *= np.repeat(self.sqrt_rw, N * ny)[:, None]
        if self.sqrt_w is not None:
            _pack_columns_in_place(J, R, N, ny, self.sqrt_w)
        return lm_directions(J, layout.n_par, layout.n_par - layout.nx * layout.nx, solver)


_Iterate = tuple[float, np.ndarray, float, float]  # (criterion, theta, cost, cost_val)


def _levenberg_marquardt(
    problem: _Problem, theta: np.ndarray, settings: PnlssSettings
) -> tuple[_Iterate, list[LMIteration]]:
    """The LM trials from theta -> (the iterate kept, the history).

    A trial is accepted if it lowers the training cost and (with validation) its validation
    simulation stays finite; the iterate kept is the best on the validation records (the
    start included), or the last accepted one without validation. A trial that does not lower
    the training cost is rejected without its validation simulations.
    """
    validated = problem.held is not None
    cost = problem.train_cost(theta)
    cost_val = problem.val_cost(theta)
    if not math.isfinite(cost):
        raise ValueError("the initial model diverges on the training data; check lin and data")
    history = [LMIteration(0, cost, cost_val, math.nan, True)]
    best: _Iterate = (cost_val if validated else cost, theta, cost, cost_val)

    # One Jacobian buffer [J | e], Fortran order so the QR works in place (memory: n_rows ×
    # (n_par + 1) float64, once).
    n_rows, n_par = problem.y_rec.size, problem.layout.n_par
    J = np.empty((n_rows, n_par + 1), order="F") if settings.max_iter > 0 else np.empty((0, 0))
    lam_rel = float(settings.lambda_init)
    need_jacobian = True
    V = s = g = col_norm = np.empty(0)
    with one_blas_thread():
        for it in range(1, settings.max_iter + 1):
            if need_jacobian:
                V, s, g, col_norm = problem.directions(theta, J, settings.solver)
                need_jacobian = False
            lam = lam_rel * s[0]
            step = -(V @ (s / (s * s + lam * lam) * g)) / col_norm
            trial = theta + step
            c_tr = problem.train_cost(trial)
            # The validation simulations only decide between trials that lower the training
            # cost: a trial that does not is rejected without them (cost_val nan).
            cv_tr = problem.val_cost(trial) if c_tr < cost else math.nan
            accepted = c_tr < cost and (not validated or math.isfinite(cv_tr))
            history.append(LMIteration(it, c_tr, cv_tr, lam_rel, accepted))
            if accepted:
                theta, cost, cost_val = trial, c_tr, cv_tr
                crit = cost_val if validated else cost
                if crit <= best[0]:
                    best = (crit, theta, cost, cost_val)
                lam_rel /= 2.0  # PNLSS toolbox schedule: halve on success, ×√10 on failure
                need_jacobian = True
            else:
                lam_rel *= math.sqrt(10.0)
                if lam_rel > 1e12:  # every direction damped away: no further progress possible
                    break
    return best, history


def output_equation_start(
    data: PeriodicData,
    lin: LinearStateSpace,
    settings: PnlssSettings = PnlssSettings(),
    *,
    validation: PeriodicData | None = None,
    record_weights: np.ndarray | None = None,
    validation_weights: np.ndarray | None = None,
) -> PNLSSModel:
    """A PNLSS start whose output equation already holds the static nonlinearity.

    With E = 0 the states are those of the linear model, and y is linear in (C, D, F, offset):
    one least-squares solve on the steady-state states of every training period gives them
    (the usual PNLSS initialisation puts F = 0, Paduart et al. 2010 §4; here the lift curve's
    curvature over several offsets is far from linear, and LM starts much closer this way).
    With ``equations="state"`` (no F) the same solve refits C, D and the offset. Pass the
    result, with the same settings, to `fit_pnlss(..., initial_model=...)`; the start uses the
    settings' degrees, structure, equations and n_transient, not their max_iter (no LM trial)
    nor their stress (no trial to reject). The other arguments are fit_pnlss's.
    """
    weights = record_weights
    base = fit_pnlss(
        data, lin, replace(settings, max_iter=0, stress=None), validation=validation,
        record_weights=weights, validation_weights=validation_weights,
    )  # fmt: skip
    nx = base.nx
    un_all = (data.u - base.u_mean[0]) / base.u_scale[0]
    # Steady-state states of every period: one whole period of its input simulated first.
    states = linear_states(base.A, base.B, periodic_records(un_all, data.N))[:, data.N :]
    rows, targets = [], []
    for m in range(data.M):
        for p in range(data.P):
            un = un_all[:, p, m]
            x = states[m * data.P + p]
            z = np.column_stack([x, un])
            eta = evaluate_monomials(z, base.exponents_output)
            # Weighted least squares: record r's rows and target scaled by √w_r.
            sw = 1.0 if weights is None else math.sqrt(weights[m * data.P + p])
            rows.append(sw * np.column_stack([x, un, eta, np.ones(data.N)]))
            targets.append(sw * (data.y[:, p, m] - base.y_mean[0]) / base.y_scale[0])
    R, t = np.vstack(rows), np.concatenate(targets)
    scale = np.maximum(np.sqrt(np.mean(R**2, axis=0)), 1e-12)
    theta = np.linalg.lstsq(R / scale, t, rcond=None)[0] / scale
    k = base.exponents_output.shape[0]
    return replace(
        base,
        C=theta[:nx].reshape(1, nx),
        D=theta[nx : nx + 1].reshape(1, 1),
        F=theta[nx + 1 : nx + 1 + k].reshape(1, k),
        y_mean=base.y_mean + base.y_scale * theta[-1],
    )


def lm_directions(
    J: np.ndarray, n_par: int, rank_cap: int, solver: str = "qr"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """SVD of the column-normalised Jacobian for the Levenberg–Marquardt step.

    With Jn = J diag(1/c) = U S Vᵀ and residual e, the step for damping λ is
    δ = −diag(1/c) V diag(s/(s² + λ²)) Uᵀe (Paduart 2010; PNLSS toolbox). Singular
    values below the numerical tolerance are dropped and at most `rank_cap` (n_θ − nx²) kept.

    Args:
        J: (n_rows, n_par + 1) Fortran-ordered [J | e]; overwritten with "qr".
        n_par: number of parameters.
        rank_cap: largest rank kept.
        solver: "qr": Householder QR of [J e] in place (Qᵀe comes out as the last column of R)
            and SVD of the small R, backward stable; "normal": eigendecomposition of the
            normalised [J e]ᵀ[J e], about 5× cheaper; its squared singular values carry an
            absolute error ~ n_par·√n_rows·ε·s_max², so directions with s below
            ~1e-5·s_max are dropped (they are damped away by λ in practice).

    Returns:
        V (n_par, k), s (k,), g = Uᵀe (k,), c (n_par,) column norms.
    """
    eps = np.finfo(float).eps
    if solver == "normal":
        Gaug = J.T @ J  # [JᵀJ, Jᵀe; eᵀJ, eᵀe]
        c = np.sqrt(np.diag(Gaug)[:n_par]).copy()
        c[~(c > 0)] = 1.0  # a parameter without effect: left unscaled
        Gn = Gaug[:n_par, :n_par] / np.outer(c, c)
        b = Gaug[:n_par, n_par] / c
        w, V = np.linalg.eigh(Gn)
        w, V = w[::-1], V[:, ::-1]
        s_max = math.sqrt(max(w[0], 0.0))
        tol2 = (s_max * s_max) * n_par * math.sqrt(J.shape[0]) * eps * 10
        keep = min(rank_cap, int(np.sum(w > tol2)))
        s = np.sqrt(w[:keep])
        return V[:, :keep], s, (V[:, :keep].T @ b) / s, c
    c = np.array([math.sqrt(float(np.dot(J[:, j], J[:, j]))) for j in range(n_par)])
    c[~(c > 0)] = 1.0
    for j in range(n_par):
        J[:, j] /= c[j]
    # QR of [J e] in place: J = Q R, and Qᵀe is the last column of R.
    (_, _), Raug = scipy.linalg.qr(J, mode="raw", overwrite_a=True, check_finite=False)
    Ur, s, Vt = np.linalg.svd(Raug[:n_par, :n_par])
    g = Ur.T @ Raug[:n_par, n_par]
    keep = min(rank_cap, int(np.sum(s > s[0] * J.shape[0] * eps)))
    return Vt.T[:, :keep], s[:keep], g[:keep], c


def _weighted_stats(x: np.ndarray, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of (N, P, M) records, each record r = m·P + p weighted."""
    if weights is None:
        return np.atleast_1d(np.mean(x)), np.atleast_1d(np.std(x))
    w = np.broadcast_to(
        np.asarray(weights, dtype=float).reshape(x.shape[2], x.shape[1]).T[None], x.shape
    )
    mean = float(np.average(x, weights=w))
    return np.atleast_1d(mean), np.atleast_1d(np.sqrt(np.average((x - mean) ** 2, weights=w)))


def _record_weights(weights: np.ndarray | None, count: int, name: str) -> np.ndarray | None:
    """√w of per-record weights, checked: `count` finite non-negative values, not all zero."""
    if weights is None:
        return None
    w = np.asarray(weights, dtype=float).reshape(-1)
    if w.size != count or not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError(
            f"{name} must be {count} finite non-negative weights (one per record), not all "
            f"zero; got {np.asarray(weights).tolist()}"
        )
    return np.sqrt(w)


def _pack_columns_in_place(J: np.ndarray, R: int, N: int, ny: int, sqrt_w: np.ndarray) -> None:
    """Replace every column of J (rows record-major) by its weighted DFT packing, in chunks."""
    chunk = 8
    for c0 in range(0, J.shape[1], chunk):
        c1 = min(J.shape[1], c0 + chunk)
        block = J[:, c0:c1].T.reshape(c1 - c0, R, N, ny)  # a view of F-ordered columns
        block[...] = _pack_spectrum(block, sqrt_w)
