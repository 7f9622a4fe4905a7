"""A second nonlinear model class beside the PNLSS: a state-space model whose coefficients are
B-spline functions of the measured angle of attack, polynomial in the state:

    x(t+1) = Σ_j w_j(α(t)) Σ_m E_j,m φ_m(x(t)),    y(t) = C x(t) + Σ_j w_j(α(t)) d_j,

w_j the cubic B-splines on uniform knots over the training input's range [deBoor2001] (α
clamped to it, so the coefficients are constant beyond), φ_m the monomials of the state of
total degree 0 … ``state_degree`` (degree 0 and 1 give b(α) + A(α) x: a linear-parameter-varying
model scheduled on its own input [Toth2010], a local-linear model network with B-spline
validity functions [Nelles2001]; higher degrees let one angle hold two flow states,
the stall's hysteresis). The B-splines are a partition of unity and local: each w_j is
non-zero over four knot intervals only, so a low-offset record is described by the splines it
visits, and a model that is linear there stays linear (the global polynomial of the PNLSS
couples every angle with every other).

Estimation (`fit_bspline_lpv`), in the PNLSS's manner [Paduart2010]:

1. the start: the BLA's linear model (E_j: its A and, on its line, its b(α) = B(α − u0); d(α)
   = D(α − u0) + y0, through the values at the Greville abscissae, which B-splines of degree
   ≥ 1 reproduce exactly [deBoor2001]), its state scaled to unit RMS on the training input;
   then, with A fixed, b_j and d_j by linear least squares (the output is linear in them): a
   Hammerstein start;
2. Levenberg–Marquardt on every E_j,m and d_j, the Jacobian by forward sensitivities of the
   simulation, each record in periodic steady state (one period simulated before it);
3. of the two starts and every iterate, the one of lowest error on the held-out periods is
   kept: on those periods the model is never worse than the linear model it started from.
"""

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numba import njit
from scipy.interpolate import BSpline

from .monomials import monomial_exponents
from .periodic_data import PeriodicData
from .state_space_models import LinearStateSpace

__all__ = [
    "LPV_MAX_PARAMETERS",
    "BSplineLPV",
    "LpvScan",
    "LpvSettings",
    "fit_bspline_lpv",
    "fit_lpv_candidate",
    "lpv_parameters",
    "scan_bspline_lpv",
]

SPLINE_DEGREE = 3
# Largest model the pipeline fits: its forward sensitivities cost about samples × nx × this
# per iteration (nx 1, 8 intervals, state degree 3 on the default campaign: 55, 3 s per fit).
LPV_MAX_PARAMETERS = 400
STATE_BOUND = 1e3  # |x| (unit RMS on the training input) beyond this: diverged (outputs NaN)


def state_exponents(nx: int, degree: int) -> np.ndarray:
    """(M, nx) exponents of the state monomials of total degree 0 … degree: the constant, the
    states in order, then `monomials.monomial_exponents` of degrees 2 … degree (the PNLSS's)."""
    rows = [np.zeros((1, nx), dtype=np.int64), np.eye(nx, dtype=np.int64)]
    if degree >= 2:
        rows.append(monomial_exponents(nx, range(2, degree + 1)))
    return np.concatenate(rows)


def lpv_parameters(nx: int, intervals: int, state_degree: int = 1) -> int:
    """Free parameters: E_j (nx × monomials) and d_j for each of intervals + 3 B-splines."""
    n_mono = state_exponents(nx, state_degree).shape[0]
    return (intervals + SPLINE_DEGREE) * (nx * n_mono + 1)


@dataclass(frozen=True)
class LpvSettings:
    """Hyperparameters of one fit: knot intervals over the input range, the state monomials'
    highest degree, Levenberg–Marquardt iterations."""

    intervals: int = 8
    state_degree: int = 3
    max_iter: int = 60
    weighting: str = "none"  # or "relative": each record by 1 / its output's variance
    stress: float = 1.3  # iterates must stay bounded on the held-out inputs scaled so (0: off)

    def __post_init__(self) -> None:
        if self.intervals < 1:
            raise ValueError(f"intervals must be ≥ 1; got {self.intervals}")
        if self.state_degree < 1:
            raise ValueError(f"state_degree must be ≥ 1; got {self.state_degree}")
        if self.max_iter < 0:
            raise ValueError(f"max_iter must be ≥ 0; got {self.max_iter}")
        if self.weighting not in ("none", "relative"):
            raise ValueError(f"weighting must be 'none' or 'relative'; got {self.weighting!r}")


def _knots(lo: float, hi: float, intervals: int) -> np.ndarray:
    inner = np.linspace(lo, hi, intervals + 1)
    return np.concatenate([[lo] * SPLINE_DEGREE, inner, [hi] * SPLINE_DEGREE])


def _basis(alpha: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """(T, nb) B-spline weights of α, clamped into the knots' range."""
    lo, hi = knots[SPLINE_DEGREE], knots[-SPLINE_DEGREE - 1]
    x = np.clip(np.asarray(alpha, dtype=float), lo, hi)
    return np.ascontiguousarray(BSpline.design_matrix(x, knots, SPLINE_DEGREE).toarray())


@dataclass
class BSplineLPV:
    """The fitted model (module docstring). ``simulate(u)`` maps α [deg] to C_l from x = 0.

    Attributes:
        knots: the cubic B-splines' knot vector (clamped).
        E: (nb, nx, M) coefficients of the state monomials ``exponents`` (M, nx); C: (nx,);
            d: (nb,).
        fs: sampling frequency [Hz].
        history_: the fit's record: the starts' and the kept iterate's errors, iterations.
    """

    knots: np.ndarray
    E: np.ndarray
    exponents: np.ndarray
    C: np.ndarray
    d: np.ndarray
    fs: float
    history_: dict[str, Any] = field(default_factory=dict)

    @property
    def nx(self) -> int:
        return int(self.C.size)

    @property
    def intervals(self) -> int:
        return int(self.knots.size - 2 * SPLINE_DEGREE - 1)

    @property
    def state_degree(self) -> int:
        return int(self.exponents.sum(axis=1).max())

    @property
    def n_params(self) -> int:
        return int(self.E.size + self.d.size)

    @property
    def theta(self) -> np.ndarray:
        return np.concatenate([self.E.reshape(-1), self.d])

    def with_theta(self, theta: np.ndarray) -> "BSplineLPV":
        n_e = self.E.size
        return BSplineLPV(
            self.knots, theta[:n_e].reshape(self.E.shape).copy(), self.exponents, self.C.copy(),
            theta[n_e:].copy(), self.fs,
        )  # fmt: skip

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """The output for the α record ``u`` [deg] from x = 0 (NaN after a divergence)."""
        W = _basis(np.asarray(u, dtype=float).reshape(-1), self.knots)
        y, _ = _simulate(W, self.E, self.exponents, self.C, self.d, np.zeros(self.nx),
                         STATE_BOUND)  # fmt: skip
        return y

    def describe(self) -> str:
        lo, hi = self.knots[SPLINE_DEGREE], self.knots[-SPLINE_DEGREE - 1]
        return (
            f"nx {self.nx}, state degree {self.state_degree}, {self.intervals} knot intervals "
            f"over {lo:.1f}–{hi:.1f}°, {self.n_params} parameters"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": "bspline_lpv_state_space",
            "degree": SPLINE_DEGREE,
            "knots": self.knots.tolist(),
            "E": self.E.tolist(),
            "exponents": self.exponents.tolist(),
            "C": self.C.tolist(),
            "d": self.d.tolist(),
            "fs": self.fs,
            "nx": self.nx,
            "state_degree": self.state_degree,
            "intervals": self.intervals,
            "parameters": self.n_params,
            "fit": self.history_,
        }


@njit(cache=True, nogil=True)
def _monomials(x, exps, phi, dphi):
    """phi[m] = Π_i x_i^exps[m, i] and dphi[m, i] = ∂phi[m]/∂x_i."""
    n_mono, nx = exps.shape
    for m in range(n_mono):
        v = 1.0
        for i in range(nx):
            e = exps[m, i]
            if e:
                v *= x[i] ** e
        phi[m] = v
        for i in range(nx):
            e = exps[m, i]
            if e == 0:
                dphi[m, i] = 0.0
                continue
            g = e * x[i] ** (e - 1)
            for ll in range(nx):
                if ll != i and exps[m, ll]:
                    g *= x[ll] ** exps[m, ll]
            dphi[m, i] = g


@njit(cache=True, nogil=True)
def _simulate(W, E, exps, C, d, x0, bound):
    T, nb = W.shape
    nx = C.size
    n_mono = exps.shape[0]
    y = np.empty(T)
    x = x0.copy()
    xn = np.empty(nx)
    phi = np.empty(n_mono)
    dphi = np.empty((n_mono, nx))
    for k in range(T):
        acc = 0.0
        for i in range(nx):
            acc += C[i] * x[i]
        for j in range(nb):
            acc += W[k, j] * d[j]
        y[k] = acc
        _monomials(x, exps, phi, dphi)
        for p in range(nx):
            s = 0.0
            for j in range(nb):
                w = W[k, j]
                if w != 0.0:
                    for m in range(n_mono):
                        s += w * E[j, p, m] * phi[m]
            xn[p] = s
        diverged = False
        for p in range(nx):
            x[p] = xn[p]
            if not abs(x[p]) < bound:
                diverged = True
        if diverged:
            for kk in range(k + 1, T):
                y[kk] = np.nan
            break
    return y, x


@njit(cache=True, nogil=True)
def _sensitivities(W, E, exps, C, d, keep_from):
    """Output and its Jacobian over θ = (E, d) (row-major), for the samples from ``keep_from``
    on, by forward sensitivities from x = 0."""
    T, nb = W.shape
    nx = C.size
    n_mono = exps.shape[0]
    n_e = nb * nx * n_mono
    n_theta = n_e + nb
    rows = T - keep_from
    y = np.empty(rows)
    J = np.zeros((rows, n_theta))
    x = np.zeros(nx)
    xn = np.empty(nx)
    S = np.zeros((nx, n_e))
    Sn = np.empty((nx, n_e))
    Jx = np.empty((nx, nx))
    phi = np.empty(n_mono)
    dphi = np.empty((n_mono, nx))
    for k in range(T):
        if k >= keep_from:
            r = k - keep_from
            acc = 0.0
            for i in range(nx):
                acc += C[i] * x[i]
            for j in range(nb):
                acc += W[k, j] * d[j]
                J[r, n_e + j] = W[k, j]
            y[r] = acc
            for t in range(n_e):
                s = 0.0
                for i in range(nx):
                    s += C[i] * S[i, t]
                J[r, t] = s
        _monomials(x, exps, phi, dphi)
        for p in range(nx):
            xp = 0.0
            for q in range(nx):
                Jx[p, q] = 0.0
            for j in range(nb):
                w = W[k, j]
                if w != 0.0:
                    for m in range(n_mono):
                        c = w * E[j, p, m]
                        xp += c * phi[m]
                        for q in range(nx):
                            Jx[p, q] += c * dphi[m, q]
            xn[p] = xp
        for p in range(nx):
            for t in range(n_e):
                s = 0.0
                for q in range(nx):
                    s += Jx[p, q] * S[q, t]
                Sn[p, t] = s
        for j in range(nb):
            w = W[k, j]
            if w != 0.0:
                for p in range(nx):
                    base = (j * nx + p) * n_mono
                    for m in range(n_mono):
                        Sn[p, base + m] += w * phi[m]
        for p in range(nx):
            x[p] = xn[p]
            for t in range(n_e):
                S[p, t] = Sn[p, t]
    return y, J


def _records(data: PeriodicData) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every (realization, period) record as (u, y), in the order of ``data.y``'s flattening."""
    return [(data.u[:, p, m], data.y[:, p, m]) for m in range(data.M) for p in range(data.P)]


class _Problem:
    """The steady-state output error of a model on a set of periodic records."""

    def __init__(self, knots: np.ndarray, data: PeriodicData, relative: bool = False) -> None:
        self.N = data.N
        self.records = [(_basis(np.concatenate([u, u]), knots), y) for u, y in _records(data)]
        self.y = np.concatenate([y for _, y in self.records])
        self.spread = float(np.sqrt(np.mean((self.y - self.y.mean()) ** 2)))
        # Per-sample weights: each record by 1 / its output's variance ("relative"), scaled
        # to a mean of 1; else 1.
        w = [np.full(self.N, 1.0 / np.var(y) if relative else 1.0) for _, y in self.records]
        self.sqrt_w = np.sqrt(np.concatenate(w) / np.mean(np.concatenate(w)))

    def output(self, m: BSplineLPV) -> np.ndarray:
        out = []
        for W, _ in self.records:
            y, _x = _simulate(W, m.E, m.exponents, m.C, m.d, np.zeros(m.nx), STATE_BOUND)
            out.append(y[self.N :])
        return np.concatenate(out)

    def error(self, m: BSplineLPV) -> float:
        """Relative RMS error over the records (inf after a divergence)."""
        y_hat = self.output(m)
        if not np.all(np.isfinite(y_hat)):
            return math.inf
        return float(np.sqrt(np.mean((self.sqrt_w * (self.y - y_hat)) ** 2)) / self.spread)

    def jacobian(self, m: BSplineLPV) -> tuple[np.ndarray, np.ndarray]:
        ys, Js = [], []
        for W, _ in self.records:
            y, J = _sensitivities(W, m.E, m.exponents, m.C, m.d, self.N)
            ys.append(y)
            Js.append(J)
        return np.concatenate(ys), np.vstack(Js)

    def states_rms(self, m: BSplineLPV) -> np.ndarray:
        """RMS of each state over the records (steady state), for the start's scaling: each
        state simulated as the output of the model with C = e_i and d = 0."""
        rms = np.empty(m.nx)
        zero = np.zeros_like(m.d)
        for i in range(m.nx):
            pick = np.zeros(m.nx)
            pick[i] = 1.0
            parts = []
            for W, _ in self.records:
                x, _x = _simulate(W, m.E, m.exponents, pick, zero, np.zeros(m.nx), STATE_BOUND)
                parts.append(x[self.N :])
            rms[i] = float(np.sqrt(np.mean(np.concatenate(parts) ** 2)))
        return rms


def linear_start(linear: LinearStateSpace, knots: np.ndarray, exponents: np.ndarray) -> BSplineLPV:
    """The linear model as a B-spline model: A(α) = A, b(α) = B (α − u0), d(α) = D (α − u0) +
    y0 through their values at the Greville abscissae (exact for a line); higher state
    monomials zero."""
    nb = knots.size - SPLINE_DEGREE - 1
    nx = linear.A.shape[0]
    greville = np.array([knots[j + 1 : j + SPLINE_DEGREE + 1].mean() for j in range(nb)])
    u0 = float(linear.u_mean[0]) if linear.u_mean.size else 0.0
    y0 = float(linear.y_mean[0]) if linear.y_mean.size else 0.0
    E = np.zeros((nb, nx, exponents.shape[0]))
    E[:, :, 0] = (greville - u0)[:, None] * np.asarray(linear.B, dtype=float)[:, 0][None, :]
    E[:, :, 1 : 1 + nx] = np.asarray(linear.A, dtype=float)[None]
    d = float(np.asarray(linear.D)[0, 0]) * (greville - u0) + y0
    C = np.asarray(linear.C, dtype=float)[0].copy()
    return BSplineLPV(knots, E, exponents, C, d, linear.fs)


def _scaled(model: BSplineLPV, s: np.ndarray) -> BSplineLPV:
    """The same linear model in states x' = x / s (A' = S⁻¹ A S, b' = S⁻¹ b, C' = C S)."""
    nx = model.nx
    E = model.E.copy()
    E[:, :, 0] /= s[None, :]
    E[:, :, 1 : 1 + nx] *= s[None, None, :] / s[None, :, None]
    return BSplineLPV(model.knots, E, model.exponents, model.C * s, model.d.copy(), model.fs)


def fit_bspline_lpv(
    train: PeriodicData,
    linear: LinearStateSpace,
    settings: LpvSettings | None = None,
    validation: PeriodicData | None = None,
) -> BSplineLPV:
    """Fit the model (module docstring, steps 1–3) on ``train``'s periods, from ``linear`` (the
    BLA's state-space model, at the model's order nx); ``validation`` chooses the kept
    iterate among the starts and the LM iterates (without it, the last iterate).

    Raises:
        ValueError: a training input of no range, or a linear model with more than one input
            or output.
    """
    settings = settings or LpvSettings()
    if linear.B.shape[1] != 1 or linear.C.shape[0] != 1:
        raise ValueError("the B-spline LPV model is single-input single-output")
    t0 = time.perf_counter()
    lo, hi = float(train.u.min()), float(train.u.max())
    if not hi > lo:
        raise ValueError("the training input is constant: no range for the splines")
    knots = _knots(lo, hi, settings.intervals)
    exponents = state_exponents(linear.A.shape[0], settings.state_degree)
    relative = settings.weighting == "relative"
    problem = _Problem(knots, train, relative)
    held = _Problem(knots, validation, relative) if validation is not None else None
    sw = problem.sqrt_w

    # An iterate is eligible only if it stays bounded on the held-out inputs scaled about
    # their mean by ``stress`` (as the PNLSS's: pnlss.PnlssSettings.stress): a model that
    # diverges just outside the data would diverge on a validation sine.
    stressed = None
    if settings.stress:
        ref = validation if validation is not None else train
        mean = ref.u.mean(axis=0, keepdims=True)
        stressed = _Problem(knots, PeriodicData(mean + settings.stress * (ref.u - mean), ref.y,
                                                ref.fs, ref.excited_lines))  # fmt: skip

    def score(m: BSplineLPV) -> float:
        if stressed is not None and not np.all(np.isfinite(stressed.output(m))):
            return math.inf
        return held.error(m) if held is not None else problem.error(m)

    start = linear_start(linear, knots, exponents)
    rms = problem.states_rms(start)
    start = _scaled(start, np.where(rms > 0, rms, 1.0))
    # The Hammerstein start: with A fixed the output is linear in b and d.
    y_hat, J = problem.jacobian(start)
    nb, nx, n_mono = start.E.shape
    cols = np.zeros(start.theta.size, dtype=bool)
    cols[[(j * nx + p) * n_mono for j in range(nb) for p in range(nx)]] = True
    cols[start.E.size :] = True
    delta, *_ = np.linalg.lstsq(sw[:, None] * J[:, cols], sw * (problem.y - y_hat), rcond=None)
    theta = start.theta
    theta[cols] += delta
    hammerstein = start.with_theta(theta)
    candidates = [("linear", start, score(start)), ("hammerstein", hammerstein, score(hammerstein))]
    model = hammerstein
    best_name, best, best_score = min(candidates, key=lambda c: c[2])
    residual = sw * (problem.output(model) - problem.y)
    cost = float(residual @ residual) if np.all(np.isfinite(residual)) else math.inf
    lam, iterations = 1e-2, 0
    for iterations in range(1, settings.max_iter + 1):
        y_hat, J = problem.jacobian(model)
        r = sw * (y_hat - problem.y)
        J *= sw[:, None]
        H = J.T @ J
        g = J.T @ r
        scale = np.maximum(np.diag(H), 1e-9 * max(float(np.max(np.diag(H))), 1e-300))
        accepted = False
        for _ in range(12):
            try:
                step = np.linalg.solve(H + lam * np.diag(scale), -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            trial = model.with_theta(model.theta + step)
            r_trial = sw * (problem.output(trial) - problem.y)
            cost_trial = float(r_trial @ r_trial) if np.all(np.isfinite(r_trial)) else math.inf
            if cost_trial < cost:
                accepted = True
                break
            lam *= 4.0
        if not accepted:
            break
        improvement = (cost - cost_trial) / cost
        model, cost, lam = trial, cost_trial, max(lam / 3.0, 1e-9)
        s = score(model)
        if s < best_score:
            best_name, best, best_score = f"iteration {iterations}", model, s
        if improvement < 1e-7:
            break
    kept = best.with_theta(best.theta)
    kept.history_ = {
        "linear_start_error": candidates[0][2],
        "hammerstein_start_error": candidates[1][2],
        "kept": best_name,
        "kept_error": best_score,
        "scored_on": "held-out periods" if held is not None else "training periods",
        "training_error": problem.error(kept),
        "iterations": iterations,
        "seconds": time.perf_counter() - t0,
    }
    return kept


@dataclass
class LpvScan:
    """The B-spline LPV structure scan: one row per (knot intervals, state degree), the kept
    model by the one-standard-error rule on the held-out periods (scan.one_standard_error)."""

    rows: list[dict[str, Any]]
    models: list[BSplineLPV | None]
    best_index: int
    rule: str
    seconds: float = 0.0

    @property
    def best(self) -> BSplineLPV:
        model = self.models[self.best_index]
        assert model is not None  # only fitted candidates are kept
        return model

    def to_markdown(self) -> str:
        lines = [
            "| nx | knot intervals | state degree | parameters | validation error | SE | "
            "training error | fit [s] | status | kept |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for i, r in enumerate(self.rows):
            lines.append(
                f"| {r['nx']} | {r['intervals']} | {r['state_degree']} | {r['n_params']} | "
                f"{r['validation_error']:.4g} | {r['validation_se']:.2g} | "
                f"{r['training_error']:.4g} | {r['fit_seconds']:.1f} | {r['status']} | "
                f"{'yes' if i == self.best_index else ''} |"
            )
        return "\n".join(lines) + f"\n\n{self.rule}\n"


def fit_lpv_candidate(
    train: PeriodicData,
    validation: PeriodicData,
    linear: LinearStateSpace,
    settings: LpvSettings,
) -> tuple[dict[str, Any], BSplineLPV | None]:
    """One grid point of the scan: its row (structure, held-out error and SE by
    scan.periodic_error, status) and its model (None unless it fitted and stayed bounded); a
    failed fit is a row with its reason, never a crash. A task for a Dask worker too."""
    from .scan import periodic_error

    t_fit = time.perf_counter()
    nx = int(linear.A.shape[0])
    iv, sd = settings.intervals, settings.state_degree
    row: dict[str, Any] = {
        "nx": nx, "intervals": iv, "state_degree": sd, "n_params": lpv_parameters(nx, iv, sd)
    }  # fmt: skip
    model: BSplineLPV | None = None
    try:
        model = fit_bspline_lpv(train, linear, settings, validation)
        error, se = periodic_error(model, validation)
        status = "ok" if math.isfinite(error) else "diverges on the held-out periods"
    except (ValueError, np.linalg.LinAlgError) as exc:
        error, se, status = math.inf, math.nan, f"failed: {exc}"
    row.update(
        validation_error=error, validation_se=se,
        training_error=math.inf if model is None else model.history_["training_error"],
        fit_seconds=time.perf_counter() - t_fit, status=status,
    )  # fmt: skip
    return row, (model if status == "ok" else None)


def scan_bspline_lpv(
    train: PeriodicData,
    validation: PeriodicData,
    linear: LinearStateSpace,
    intervals: Sequence[int],
    state_degrees: Sequence[int],
    settings: LpvSettings | None = None,
    client: Any = None,
) -> LpvScan:
    """Fit every (intervals, state degree) of the grid from ``linear`` (``settings`` gives the
    rest) and keep one by the one-standard-error rule on ``validation``, each scored by
    scan.periodic_error, the PNLSS scan's error and SE, so both classes' scores compare.
    ``client``: a Dask client the grid's fits run on (the PNLSS scan's, pnlss_training.
    fit_client), the data scattered once; None: one after another in this process (a local
    cluster's start-up costs more than the grid's few fits).

    Raises:
        ValueError: an empty grid, or no candidate that fitted and stayed bounded.
    """
    from .scan import one_standard_error

    base = settings or LpvSettings()
    grid = [(iv, sd) for iv in dict.fromkeys(intervals) for sd in dict.fromkeys(state_degrees)]
    if not grid:
        raise ValueError("the B-spline LPV scan's grid is empty")
    t0 = time.perf_counter()
    each = [replace(base, intervals=iv, state_degree=sd) for iv, sd in grid]
    if client is None:
        fits = [fit_lpv_candidate(train, validation, linear, st) for st in each]
    else:
        train_f, val_f = client.scatter([train, validation], broadcast=True)
        futures = [client.submit(fit_lpv_candidate, train_f, val_f, linear, st, pure=False)
                   for st in each]  # fmt: skip
        fits = [f.result() for f in futures]
    rows = [row for row, _ in fits]
    models = [model for _, model in fits]
    scores = {
        i: (r["validation_error"], r["validation_se"], r["n_params"])
        for i, r in enumerate(rows)
        if r["status"] == "ok"
    }
    if not scores:
        reasons = "; ".join(f"{r['intervals']} intervals, degree {r['state_degree']}: "
                            f"{r['status']}" for r in rows)  # fmt: skip
        raise ValueError(f"no B-spline LPV candidate could be fitted: {reasons}")
    best, i_min, bound, within = one_standard_error(scores)
    rule = (
        f"one-standard-error rule: the lowest validation error is "
        f"{rows[i_min]['validation_error']:.4g} ± {rows[i_min]['validation_se']:.4g} "
        f"({rows[i_min]['intervals']} intervals, state degree {rows[i_min]['state_degree']}); "
        f"of the {len(within)} candidate(s) within {bound:.4g}, the one with the fewest "
        f"parameters is kept ({rows[best]['n_params']} parameters)."
    )
    return LpvScan(rows, models, best, rule, time.perf_counter() - t0)
