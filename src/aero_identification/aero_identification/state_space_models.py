"""Model representations: the discrete-time linear state-space model (LinearStateSpace) and
the polynomial nonlinear state-space model (PNLSSModel), with simulation, frequency response and
their JSON dictionaries. The estimators that fit them are subspace.py and pnlss.py.

Operating-point convention (both models): a model maps deviations around the operating point,
y − y_mean = G (u − u_mean). `simulate(u)` takes and returns absolute signals.

PNLSS model (Paduart et al., "Identification of nonlinear systems using polynomial nonlinear
state space models", Automatica 46(4) 2010):

    x(t+1) = A x(t) + B u(t) + E ζ(x(t), u(t))
    y(t)   = C x(t) + D u(t) + F η(x(t), u(t))

ζ, η: all monomials of [x; u] of the chosen total degrees, restricted by the structure
("full", "statesonly", "inputsonly"; see monomials.py). The same monomial set is used in the
state and the output equation.

Coordinates and operating point (the same convention as the linear model: the model maps
deviations around the operating point). Internally everything is normalised so the monomials
are well conditioned:

    u_n = (u − u_mean) / u_scale,   y = y_mean + y_scale · y_n,

and the states are scaled so that the initial linear model's states have unit standard
deviation on the training input. A, B, C, D, E, F are stored in these normalised coordinates;
`simulate` takes and returns absolute signals. u_mean is the training-input mean; y_mean is
the training-output mean plus the fitted output offset (even-degree monomials have a non-zero
mean, so the model's output at the operating point is a parameter, not the data mean).
"""

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


class StateSpaceDimensions:
    """nx, nu, ny of a model with A (nx, nx), B (nx, nu) and C (ny, nx) attributes."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray

    @property
    def nx(self) -> int:
        return int(self.A.shape[0])

    @property
    def nu(self) -> int:
        return int(self.B.shape[1])

    @property
    def ny(self) -> int:
        return int(self.C.shape[0])


@dataclass(eq=False)
class LinearStateSpace(StateSpaceDimensions):
    """Discrete-time linear state-space model x(t+1) = A x + B u, y = C x + D u.

    Attributes:
        A: (nx, nx) state matrix (all eigenvalues inside the unit circle).
        B: (nx, nu) input matrix.
        C: (ny, nx) output matrix.
        D: (ny, nu) feed-through.
        fs: sampling frequency [Hz]; z = exp(j2π f/fs).
        r: block rows used by the subspace step (0 if not from subspace).
        cost: variance-weighted cost Σ|G_model − G|²/var on the data it was selected on (the
            BLA, or the validation BLA when one was given).
        u_mean: (nu,) input operating point (deviation convention in the module docstring).
        y_mean: (ny,) output operating point.
        refined: whether the weighted least-squares refinement was kept.
        weighting: which variance weighted the fit: "total", "noise" or "none".
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    fs: float
    r: int = 0
    cost: float = float("nan")
    u_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))
    refined: bool = False
    weighting: str = "none"

    def __post_init__(self) -> None:
        # C-contiguous float64: the compiled simulation kernel is specialised on the layout.
        self.A = np.ascontiguousarray(np.atleast_2d(np.asarray(self.A, dtype=float)))
        self.B = np.ascontiguousarray(np.atleast_2d(np.asarray(self.B, dtype=float)))
        self.C = np.ascontiguousarray(np.atleast_2d(np.asarray(self.C, dtype=float)))
        self.D = np.ascontiguousarray(np.atleast_2d(np.asarray(self.D, dtype=float)))
        nx, nu, ny = self.A.shape[0], self.B.shape[1], self.C.shape[0]
        if self.A.shape != (nx, nx) or self.B.shape[0] != nx or self.C.shape[1] != nx:
            raise ValueError(
                f"inconsistent state-space shapes A {self.A.shape}, B {self.B.shape}, "
                f"C {self.C.shape}; need (nx, nx), (nx, nu), (ny, nx)"
            )
        if self.D.shape != (ny, nu):
            raise ValueError(f"D must have shape (ny, nu)={(ny, nu)}; got {self.D.shape}")
        self.u_mean = _operating_point(self.u_mean, nu, "u_mean")
        self.y_mean = _operating_point(self.y_mean, ny, "y_mean")
        self.fs = float(self.fs)

    @property
    def order(self) -> int:
        """The model order nx."""
        return self.nx

    def poles(self) -> np.ndarray:
        """(nx,) complex eigenvalues of A (discrete-time poles)."""
        return np.linalg.eigvals(self.A)

    def is_stable(self) -> bool:
        """True when every pole lies strictly inside the unit circle."""
        return bool(np.all(np.abs(self.poles()) < 1.0))

    def with_operating_point(self, u_mean: Any, y_mean: Any) -> "LinearStateSpace":
        """Copy of the model with the operating point (e.g. training-data means) set."""
        return replace(
            self, A=self.A.copy(), B=self.B.copy(), C=self.C.copy(), D=self.D.copy(),
            u_mean=np.atleast_1d(u_mean), y_mean=np.atleast_1d(y_mean),
        )  # fmt: skip

    def frf(self, freq_hz: np.ndarray) -> np.ndarray:
        """Frequency response G(z) = C (zI − A)⁻¹ B + D at z = exp(j2π f/fs).

        Args:
            freq_hz: (F,) frequencies [Hz].

        Returns:
            (F,) complex for a SISO model, (F, ny, nu) otherwise.
        """
        z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float).reshape(-1) / self.fs)
        G = _frf(self.A, self.B, self.C, self.D, z)
        return G[:, 0, 0] if (self.ny == 1 and self.nu == 1) else G

    def simulate(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Simulate the output for the input u (absolute signals, see the module docstring).

        Args:
            u: (T,) or (T, nu) input samples.
            x0: (nx,) initial state (deviation from the operating point); default 0.

        Returns:
            (T,) output for a 1-D u and ny == 1, else (T, ny).
        """
        from aero_identification.pnlss_kernels import simulate_records

        u2, one_d = _as_input(u, self.nu)
        x = np.zeros(self.nx) if x0 is None else np.asarray(x0, dtype=float).reshape(self.nx)
        empty_exp = np.zeros((0, self.nx + self.nu), dtype=np.int64)
        y = simulate_records(
            self.A, self.B, self.C, self.D, np.zeros((self.nx, 0)), np.zeros((self.ny, 0)),
            empty_exp, empty_exp, (u2 - self.u_mean)[None], x[None], np.inf,
        )[0] + self.y_mean  # fmt: skip
        return y[:, 0] if (one_d and self.ny == 1) else y

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (json.dumps works); inverse of `from_dict`."""
        return {
            "kind": "linear_state_space",
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "fs": self.fs,
            "order": self.order,
            "r": int(self.r),
            "cost": float(self.cost) if math.isfinite(self.cost) else None,
            "u_mean": self.u_mean.tolist(),
            "y_mean": self.y_mean.tolist(),
            "refined": bool(self.refined),
            "weighting": self.weighting,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "LinearStateSpace":
        """Rebuild a model from `to_dict` output."""
        if d.get("kind") != "linear_state_space":
            raise ValueError(
                f"not a linear state-space dictionary (kind={d.get('kind')!r}); expected "
                "the output of LinearStateSpace.to_dict()"
            )
        return cls(
            A=np.asarray(d["A"], dtype=float).reshape(len(d["A"]), -1),
            B=np.asarray(d["B"], dtype=float).reshape(len(d["A"]), -1),
            C=np.asarray(d["C"], dtype=float).reshape(-1, len(d["A"])),
            D=np.asarray(d["D"], dtype=float),
            fs=d["fs"], r=d["r"],
            cost=float("nan") if d["cost"] is None else d["cost"],
            u_mean=np.asarray(d["u_mean"]), y_mean=np.asarray(d["y_mean"]),
            refined=d["refined"], weighting=d["weighting"],
        )  # fmt: skip


def _operating_point(value: Any, n: int, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=float).reshape(-1)
    if v.size == 0:
        return np.zeros(n)
    if v.size != n:
        raise ValueError(f"{name} must have {n} entries (one per signal); got {v.size}")
    return v


def _as_input(u: np.ndarray, nu: int) -> tuple[np.ndarray, bool]:
    """(T, nu) float64 C-contiguous input, and whether the caller gave a 1-D array."""
    u = np.asarray(u, dtype=float)
    one_d = u.ndim == 1
    u2 = u[:, None] if one_d else u
    if u2.ndim != 2 or u2.shape[1] != nu:
        raise ValueError(f"u must have shape (T,) or (T, nu) with nu={nu}; got {u.shape}")
    if not np.all(np.isfinite(u2)):
        raise ValueError("u contains NaN or inf; clean the input record before simulating")
    return np.ascontiguousarray(u2), one_d


# --- frequency response ---------------------------------------------------------------------


def _frf(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(F, ny, nu) G(z_k) = C (z_k I − A)⁻¹ B + D."""
    nx = A.shape[0]
    if nx == 0:
        return np.broadcast_to(D.astype(complex), (z.size, *D.shape)).copy()
    Zi = z[:, None, None] * np.eye(nx)[None] - A[None]
    R = np.linalg.solve(Zi, np.broadcast_to(B.astype(complex), (z.size, *B.shape)))
    return C[None] @ R + D[None]


# --- PNLSS model ----------------------------------------------------------------------------


# A normalised state beyond this magnitude (states have unit RMS under the initial linear model)
# means the simulation diverged: it is stopped there and the trial step rejected.
STATE_BOUND = 1e4


@dataclass(frozen=True)
class LMIteration:
    """One Levenberg–Marquardt trial.

    Attributes:
        iteration: trial number (0 = the initial model).
        cost: training cost of the trial parameters: mean squared (weighted) simulation error
            in normalised output units; inf if the simulation diverged.
        cost_val: validation mean squared error [output units²] (nan without validation or for
            a trial that did not lower the training cost, which is rejected unsimulated; inf if
            the validation simulation diverged).
        lambda_: damping λ used for the step (relative to the largest singular value of the
            normalised Jacobian; nan for iteration 0).
        accepted: whether the step was kept.
    """

    iteration: int
    cost: float
    cost_val: float
    lambda_: float
    accepted: bool


@dataclass(eq=False)
class PNLSSModel(StateSpaceDimensions):
    """A PNLSS model in normalised coordinates (module docstring).

    Attributes:
        A: (nx, nx); B: (nx, nu); C: (ny, nx); D: (ny, nu) linear part.
        E: (nx, Kζ) coefficients of the state-equation monomials.
        F: (ny, Kη) coefficients of the output-equation monomials.
        exponents_state: (Kζ, nx+nu) int exponents of ζ.
        exponents_output: (Kη, nx+nu) int exponents of η.
        u_mean, u_scale: (nu,) input normalisation.
        y_mean, y_scale: (ny,) output normalisation (y_mean includes the fitted offset).
        fs: sampling frequency [Hz].
        degrees: total degrees of the monomials.
        structure: "full", "statesonly" or "inputsonly".
        n_transient: samples prepended per record during the fit.
        history_: the LM trials (fit only; not serialised).
        cost_: training cost of this model (normalised output units², see LMIteration.cost).
        cost_val_: validation mean squared error of this model [output units²].
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    E: np.ndarray
    F: np.ndarray
    exponents_state: np.ndarray
    exponents_output: np.ndarray
    u_mean: np.ndarray
    u_scale: np.ndarray
    y_mean: np.ndarray
    y_scale: np.ndarray
    fs: float
    degrees: tuple[int, ...]
    structure: str
    n_transient: int = 0
    history_: list[LMIteration] = field(default_factory=list)
    cost_: float = float("nan")
    cost_val_: float = float("nan")

    def __post_init__(self) -> None:
        for name in ("A", "B", "C", "D", "E", "F"):
            setattr(self, name, np.ascontiguousarray(np.asarray(getattr(self, name), float)))
        nx, nu, ny = self.A.shape[0], self.B.shape[1], self.C.shape[0]
        self.exponents_state = np.ascontiguousarray(
            np.asarray(self.exponents_state, dtype=np.int64).reshape(-1, nx + nu)
        )
        self.exponents_output = np.ascontiguousarray(
            np.asarray(self.exponents_output, dtype=np.int64).reshape(-1, nx + nu)
        )
        expect = {
            "A": (nx, nx), "B": (nx, nu), "C": (ny, nx), "D": (ny, nu),
            "E": (nx, self.exponents_state.shape[0]), "F": (ny, self.exponents_output.shape[0]),
        }  # fmt: skip
        for name, shape in expect.items():
            if getattr(self, name).shape != shape:
                raise ValueError(
                    f"PNLSS matrix {name} has shape {getattr(self, name).shape}; expected {shape}"
                )
        for name, n in (("u_mean", nu), ("u_scale", nu), ("y_mean", ny), ("y_scale", ny)):
            v = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if v.size != n:
                raise ValueError(f"{name} must have {n} entries; got {v.size}")
            setattr(self, name, v)
        self.fs = float(self.fs)
        self.degrees = tuple(int(d) for d in self.degrees)

    @property
    def parameters(self) -> np.ndarray:
        """(n_θ,) θ = [vec A, vec B, vec E, vec C, vec D, vec F] (row-major, normalised)."""
        return np.concatenate([m.ravel() for m in (self.A, self.B, self.E, self.C, self.D, self.F)])

    def simulate(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Simulate the output for the input u (absolute signals).

        Args:
            u: (T,) or (T, nu) input samples.
            x0: (nx,) initial normalised state; default 0 (the operating point).

        Returns:
            (T,) output for a 1-D u and ny == 1, else (T, ny). Samples after a divergence
            (a normalised state beyond STATE_BOUND) are NaN.
        """
        from aero_identification.pnlss_kernels import simulate_records

        u2, one_d = _as_input(u, self.nu)
        x = np.zeros(self.nx) if x0 is None else np.asarray(x0, dtype=float).reshape(self.nx)
        un = (u2 - self.u_mean) / self.u_scale
        yn = simulate_records(
            self.A, self.B, self.C, self.D, self.E, self.F, self.exponents_state,
            self.exponents_output, un[None], x[None], STATE_BOUND,
        )[0]  # fmt: skip
        y = self.y_mean + self.y_scale * yn
        return y[:, 0] if (one_d and self.ny == 1) else y

    def state_after(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray | None:
        """The normalised state after the input u, simulated without its outputs (a warm-up
        before `simulate(..., x0=...)`, which then continues exactly as one simulation of the
        whole input would); None if a state leaves STATE_BOUND on the way.

        Args:
            u: (T,) or (T, nu) input samples (absolute).
            x0: (nx,) initial normalised state; default 0 (the operating point).
        """
        from aero_identification.pnlss_kernels import advance_records

        u2, _ = _as_input(u, self.nu)
        x = np.zeros(self.nx) if x0 is None else np.asarray(x0, dtype=float).reshape(self.nx)
        un = (u2 - self.u_mean) / self.u_scale
        states, ok = advance_records(
            self.A, self.B, self.E, self.exponents_state, un[None], x[None], STATE_BOUND
        )
        return states[0] if ok[0] else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary of the model (json.dumps works); inverse of `from_dict`."""
        return {
            "kind": "pnlss",
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "E": self.E.tolist(),
            "F": self.F.tolist(),
            "exponents_state": self.exponents_state.tolist(),
            "exponents_output": self.exponents_output.tolist(),
            "u_mean": self.u_mean.tolist(),
            "u_scale": self.u_scale.tolist(),
            "y_mean": self.y_mean.tolist(),
            "y_scale": self.y_scale.tolist(),
            "fs": self.fs,
            "degrees": list(self.degrees),
            "structure": self.structure,
            "n_transient": int(self.n_transient),
            "cost": _json_float(self.cost_),
            "cost_val": _json_float(self.cost_val_),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "PNLSSModel":
        """Rebuild a model from `to_dict` output."""
        if d.get("kind") != "pnlss":
            raise ValueError(
                f"not a PNLSS dictionary (kind={d.get('kind')!r}); expected the output of "
                "PNLSSModel.to_dict()"
            )
        nx = len(d["A"])
        ny = len(d["C"])
        return cls(
            A=np.asarray(d["A"], float).reshape(nx, nx),
            B=np.asarray(d["B"], float).reshape(nx, -1),
            C=np.asarray(d["C"], float).reshape(ny, nx),
            D=np.asarray(d["D"], float).reshape(ny, -1),
            E=np.asarray(d["E"], float).reshape(nx, -1),
            F=np.asarray(d["F"], float).reshape(ny, -1),
            exponents_state=np.asarray(d["exponents_state"], np.int64),
            exponents_output=np.asarray(d["exponents_output"], np.int64),
            u_mean=np.asarray(d["u_mean"]), u_scale=np.asarray(d["u_scale"]),
            y_mean=np.asarray(d["y_mean"]), y_scale=np.asarray(d["y_scale"]),
            fs=d["fs"], degrees=tuple(d["degrees"]), structure=d["structure"],
            n_transient=d.get("n_transient", 0),
            cost_=_from_json_float(d.get("cost")), cost_val_=_from_json_float(d.get("cost_val")),
        )  # fmt: skip


def _json_float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _from_json_float(v: float | None) -> float:
    return float("nan") if v is None else float(v)
