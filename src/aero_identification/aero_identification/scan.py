"""Cross-validated PNLSS structure scan: every candidate fitted, the simplest adequate one kept.

The paper chooses its model complexity by "cross-validation based model order scanning (using
50 Levenberg–Marquardt iterations)" [PitchingWing]. :func:`scan_pnlss` fits one PNLSS model
per candidate structure (state order nx, monomial degrees, the equations the monomials enter,
the monomial structure), each from the linear model of its order, and scores it on held-out
periodic data.

Score and selection rule (docs/design.md §7.6):

- Validation error of a candidate: for every validation period r, the relative RMS error
  e_r = rms(y_r − ŷ) / std(y_r) of the steady-state simulation ŷ (the input is periodic, so ŷ is
  the same for every period of a realization; the periods differ by noise and by
  cycle-to-cycle variation). The candidate's error is E = √(mean_r w_r e_r² / mean_r w_r)
  (weights: `validation_weights`, default 1). Its standard error SE is the larger of two
  resolutions: the spread of the w_r e_r² over the periods (standard error of their mean,
  delta method for the square root), and what the excitation can resolve at all: the input
  is periodic, so the model-error part of the residual is fixed by the 2·F·M real numbers of
  its spectrum at the F excited lines of the M realizations, and an error estimated from n
  such values has a relative standard error √(2/n) in E² (χ² with n degrees of freedom), i.e.
  SE ≥ E / (2√(F·M)). Without that floor, a validation set of a few periods of one
  realization would claim a precision its noise does not have, and a candidate would win
  only because its best LM iterate was chosen on the same data (a linear system otherwise
  "prefers" a cubic model by 3 %).
- Cross-fit (``splits``; the pipeline's ``scan_splits``, default 1 = off): the SE above measures
  the noise on one held-out set, not how well a structure's extra terms are determined. So
  every candidate is also fitted with another realization held out (with one realization per
  level: another period), and its score is the mean of the K splits' errors with the K-fold
  SE, max(std_k(E_k)/√K, √(Σ_k SE_k²)/K) (Hastie, Tibshirani & Friedman 2009 §7.10.1): a
  structure whose fit depends on which realization it saw has a large spread, and the rule
  below then prefers a simpler one. The kept model is the fit on the first split.
- One-standard-error rule (Breiman et al. 1984 §3.4.3; Hastie, Tibshirani & Friedman 2009
  §7.10): among the candidates whose E is within the best candidate's E + SE, keep the one with
  the fewest parameters (ties: the lower E). A richer model must beat a simpler one by more
  than the data can resolve before it is preferred: on real data the richer structure tends
  to extrapolate worse (issue 12: output-equation terms on the electronic Duffing benchmark).

Parallel: the candidates are independent fits. With `client` (a ``dask.distributed.Client``,
e.g. of a cluster started with ``dask scheduler`` / ``dask worker``) they run on its workers;
otherwise, with ``workers > 1`` (default: every core), on a local Dask cluster of single-
threaded worker processes (numba kernels load from their on-disk cache once per process);
``workers=1`` runs them one after the other in this process. The local workers do not re-run
the caller's script, so a plain script without an ``if __name__ == "__main__":`` guard, a
notebook and the CLI all work with the defaults (`_workers_without_main_script`).
"""

import contextlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from .metrics import steady_state_response
from .monomials import STRUCTURES, check_degrees
from .periodic_data import PeriodicData
from .pnlss import EQUATIONS, PnlssSettings, fit_pnlss, output_equation_start, stress_periods
from .state_space_models import LinearStateSpace, PNLSSModel

__all__ = [
    "Candidate",
    "ScanResult",
    "ScanRow",
    "candidate_grid",
    "fit_candidate",
    "one_standard_error",
    "periodic_error",
    "scan_pnlss",
]

LinearSource = Callable[[int], LinearStateSpace] | Mapping[int, LinearStateSpace] | None


@dataclass(frozen=True)
class Candidate:
    """One PNLSS structure of the scan."""

    nx: int
    degrees: tuple[int, ...]
    equations: str
    structure: str = "full"
    start: str = "linear"


STARTS = ("linear", "output_ls")


@dataclass(frozen=True)
class ScanRow:
    """One row of the scan table (errors are relative RMS, module docstring)."""

    nx: int
    degrees: tuple[int, ...]
    equations: str
    structure: str
    n_params: int
    validation_error: float
    validation_se: float
    training_error: float
    fit_seconds: float
    status: str  # "ok" or what went wrong
    start: str = "linear"
    # Cross-fit (module docs): the validation error of each split, the first the kept model's;
    # validation_error is then their mean. Empty: one split.
    split_errors: tuple[float, ...] = ()

    @property
    def structure_label(self) -> str:
        """The candidate's structure, without its start: "nx 1, degrees 2,3, state, full"."""
        degrees = ",".join(map(str, self.degrees))
        return f"nx {self.nx}, degrees {degrees}, {self.equations}, {self.structure}"

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["degrees"] = list(self.degrees)
        d["split_errors"] = list(self.split_errors)
        return d


@dataclass
class ScanResult:
    """The scan's table, its models and the selected candidate."""

    rows: list[ScanRow]
    models: list[PNLSSModel | None]
    best_index: int
    rule: str
    seconds: float = 0.0
    workers: str = ""

    @property
    def best(self) -> PNLSSModel:
        model = self.models[self.best_index]
        assert model is not None  # the selection only keeps fitted candidates
        return model

    @property
    def best_row(self) -> ScanRow:
        return self.rows[self.best_index]

    @property
    def table(self) -> list[dict[str, Any]]:
        """One dict per candidate, in scan order, with ``selected`` marking the kept one."""
        return [{**r.as_dict(), "selected": i == self.best_index} for i, r in enumerate(self.rows)]

    def to_markdown(self) -> str:
        head = (
            "| nx | degrees | equations | structure | start | parameters | validation error | SE "
            "| per split | training error | fit s | status |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|\n"
        )
        lines = []
        for i, r in enumerate(self.rows):
            mark = " **(selected)**" if i == self.best_index else ""
            per_split = " / ".join(map(_fmt, r.split_errors)) or "–"
            lines.append(
                f"| {r.nx} | {','.join(map(str, r.degrees))} | {r.equations} | {r.structure} "
                f"| {r.start} | {r.n_params} | {_fmt(r.validation_error)}{mark} "
                f"| {_fmt(r.validation_se)} | {per_split} | {_fmt(r.training_error)} "
                f"| {r.fit_seconds:.1f} | {r.status} |"
            )
        return head + "\n".join(lines) + f"\n\nRule: {self.rule}\n"

    def to_csv(self) -> str:
        keys = [*ScanRow.__dataclass_fields__, "selected"]
        out = [",".join(keys)]
        for row in self.table:
            values = [
                " ".join(map(str, row[k])) if k in ("degrees", "split_errors") else str(row[k])
                for k in keys
            ]
            out.append(",".join(values))
        return "\n".join(out) + "\n"


def _fmt(x: float) -> str:
    return f"{x:.4g}" if math.isfinite(x) else "—"


def candidate_grid(
    nx: Iterable[int] = (1, 2, 3),
    degrees: Iterable[Sequence[int]] = ((2,), (2, 3), (2, 3, 4, 5)),
    equations: Iterable[str] = EQUATIONS,
    structures: Iterable[str] = ("full",),
    starts: Iterable[str] = ("linear",),
) -> list[Candidate]:
    """Every combination, checked (orders ≥ 1, valid degrees, equations, structures, starts)."""
    starts = tuple(starts)
    for st in starts:
        if st not in STARTS:
            raise ValueError(f"unknown start {st!r}; choose from {STARTS}")
    out: list[Candidate] = []
    for n in nx:
        if int(n) < 1:
            raise ValueError(f"state orders must be >= 1; got {n}")
        for d in degrees:
            for eq in equations:
                if eq not in EQUATIONS:
                    raise ValueError(f"unknown equations {eq!r}; choose from {EQUATIONS}")
                for s in structures:
                    if s not in STRUCTURES:
                        raise ValueError(f"unknown structure {s!r}; choose from {STRUCTURES}")
                    out.extend(Candidate(int(n), check_degrees(d), eq, s, st) for st in starts)
    if not out:
        raise ValueError("the scan grid is empty")
    return out


def scan_pnlss(
    data: PeriodicData,
    validation: PeriodicData,
    nx: Iterable[int] = (1, 2, 3),
    degrees: Iterable[Sequence[int]] = ((2,), (2, 3), (2, 3, 4, 5)),
    equations: Iterable[str] = EQUATIONS,
    structures: Iterable[str] = ("full",),
    max_iter: int = 50,
    client: Any = None,
    *,
    linear: LinearSource = None,
    workers: int | None = None,
    record_weights: np.ndarray | None = None,
    validation_weights: np.ndarray | None = None,
    starts: Iterable[str] = ("linear",),
    stress: float | None = 1.3,
    splits: Sequence[tuple[PeriodicData, PeriodicData]] = (),
) -> ScanResult:
    """Fit every candidate PNLSS structure and select one by cross-validation (module docs).

    Args:
        data: training periods (N, P, M).
        validation: held-out periods (same N): each LM fit keeps its best iterate on them, and
            the scan scores and selects on them.
        nx, degrees, equations, structures: the grid (every combination is a candidate).
        max_iter: Levenberg–Marquardt iterations per candidate (the paper's scan: 50).
        client: a ``dask.distributed.Client``; None: local (see `workers`).
        linear: the initial linear model of each order: a mapping or a callable nx → model;
            None: the frequency-domain subspace model (fit_linear_ss) of the robust BLA of
            `data` at that order, with the data's operating point.
        workers: local worker processes when no client is given (default: every core; 1: in
            this process, one after the other).
        record_weights, validation_weights: per-period weights of the training cost and of the
            validation score (fit_pnlss); e.g. 1/var(y) per level for records of several levels.
        starts: the LM starts to try for every structure (each a candidate of its own, same
            parameter count, so the rule keeps the better on validation): "linear" (E = F = 0,
            Paduart et al. 2010 §4) and/or "output_ls" (C, D, F and the offset by least
            squares on the linear model's states, pnlss.output_equation_start: the campaign
            pipeline's start, for outputs with a strong static nonlinearity such as lift over
            several offsets).
        stress: every fit keeps only iterates that stay bounded on the validation inputs
            scaled about their mean by this factor (PnlssSettings.stress), and a candidate whose
            steady-state response there diverges or is not periodic is rejected (status
            "unstable at …"; module docs). None: no such check.
        splits: further (training, held-out) splits of the same records, e.g. with another
            realization held out: every candidate is also fitted and scored on each, and its
            validation error and SE become those of the cross-fit (module docs); the kept
            model is the one fitted on (`data`, `validation`). Weights apply to every split.

    Returns:
        A ScanResult: `.best` (the selected PNLSSModel, with `.simulate(u)`), `.table`,
        `.rows`, `.models`, `.rule`; `to_markdown()` / `to_csv()` for the report.

    Raises:
        ValueError: for an empty or invalid grid, mismatched data, or when no candidate could
            be fitted (every row's status says why).
    """
    if validation.u.shape[0] != data.u.shape[0]:
        raise ValueError(
            f"validation periods have {validation.u.shape[0]} samples; training periods have "
            f"{data.u.shape[0]}"
        )
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1; got {max_iter}")
    for k, (train_k, held_k) in enumerate(splits, start=2):  # split 1: data, validation
        if train_k.u.shape[0] != data.u.shape[0] or held_k.u.shape != validation.u.shape:
            raise ValueError(
                f"split {k}: its sets must match the first split's period length and held-out "
                f"shape {validation.u.shape}; got {train_k.u.shape} and {held_k.u.shape}"
            )
    grid = candidate_grid(nx, degrees, equations, structures, starts)
    linears = _linear_models(data, sorted({c.nx for c in grid}), linear)
    sets = [(data, validation), *splits]
    options = {
        "max_iter": int(max_iter),
        "record_weights": record_weights,
        "validation_weights": validation_weights,
        "stress": stress,
    }
    jobs = [
        (c, linears[c.nx], k, _split_options(options, k)) for c in grid for k in range(len(sets))
    ]
    t0 = time.perf_counter()
    results, where = run_fits(jobs, sets, client, workers)
    per = len(sets)
    rows = [cross_fit([r for r, _ in results[i : i + per]]) for i in range(0, len(results), per)]
    models = [results[i][1] for i in range(0, len(results), per)]
    best, why = select_one_se(rows)
    return ScanResult(
        rows=rows,
        models=models,
        best_index=best,
        rule=why,
        seconds=time.perf_counter() - t0,
        workers=where,
    )


def select_one_se(rows: Sequence[ScanRow]) -> tuple[int, str]:
    """Index of the kept candidate by the one-standard-error rule, and the rule as text."""
    ok = [i for i, r in enumerate(rows) if r.status == "ok" and math.isfinite(r.validation_error)]
    if not ok:
        reasons = "; ".join(f"nx={r.nx} {r.degrees} {r.equations}: {r.status}" for r in rows)
        raise ValueError(f"no PNLSS candidate could be fitted: {reasons}")
    best, i_min, bound, within = one_standard_error(
        {i: (rows[i].validation_error, rows[i].validation_se, rows[i].n_params) for i in ok}
    )
    why = (
        f"one-standard-error rule: the lowest validation error is "
        f"{rows[i_min].validation_error:.4g} ± {rows[i_min].validation_se:.4g} "
        f"(nx={rows[i_min].nx}, degrees {list(rows[i_min].degrees)}, "
        f"{rows[i_min].equations}); of the {len(within)} "
        f"candidate(s) within {bound:.4g}, the one with the fewest parameters is kept "
        f"({rows[best].n_params} parameters)."
    )
    return best, why


def one_standard_error(
    scores: Mapping[int, tuple[float, float, int]],
) -> tuple[int, int, float, list[int]]:
    """The one-standard-error rule on {candidate: (validation error, its SE, parameters)} of
    fitted candidates: (the kept candidate, the lowest-error one, the bound error + SE, the
    candidates within it). The kept one has the fewest parameters within the bound (ties: the
    lower error). Every model class's scan selects with it."""
    i_min = min(scores, key=lambda i: scores[i][0])
    bound = scores[i_min][0] + scores[i_min][1]
    within = [i for i in scores if scores[i][0] <= bound]
    best = min(within, key=lambda i: (scores[i][2], scores[i][0]))
    return best, i_min, bound, within


def cross_fit(rows: Sequence[ScanRow]) -> ScanRow:
    """One candidate's row from its fits on K splits (the first: the kept model's).

    E = mean of the K validation errors E_k. SE = max(std(E_k)/√K, √(Σ SE_k²)/K): the spread
    of the K-fold estimate (Hastie, Tibshirani & Friedman 2009 §7.10.1), which holds the model's
    own variability (a different fit per split), and never less than the noise resolution of
    the mean of K errors. A split whose fit failed, diverged or lost stability rejects the
    candidate, naming the split.
    """
    first = rows[0]
    if len(rows) == 1:
        return first
    errors = tuple(r.validation_error for r in rows)
    bad = next(
        (
            (k, r)
            for k, r in enumerate(rows)
            if r.status != "ok" or not math.isfinite(r.validation_error)
        ),
        None,
    )
    if bad is not None:
        k, r = bad
        status = r.status if r.status != "ok" else "diverges on the validation data"
        status = status if k == 0 else f"split {k + 1}: {status}"
        return replace(first, status=status, validation_error=math.nan, split_errors=errors)
    K = len(rows)
    mean = float(np.mean(errors))
    spread = float(np.std(errors, ddof=1)) / math.sqrt(K)
    noise = math.sqrt(sum(r.validation_se**2 for r in rows)) / K
    return replace(
        first,
        validation_error=mean,
        validation_se=max(spread, noise),
        fit_seconds=sum(r.fit_seconds for r in rows),
        split_errors=errors,
    )


def _linear_models(
    data: PeriodicData, orders: list[int], linear: LinearSource
) -> dict[int, LinearStateSpace]:
    if linear is None:
        from .bla import estimate_bla
        from .subspace import fit_linear_ss

        bla = estimate_bla(data, method="auto")
        u0, y0 = float(np.mean(data.u)), float(np.mean(data.y))
        return {n: fit_linear_ss(bla, nx=n).with_operating_point(u0, y0) for n in orders}
    if callable(linear):
        return {n: linear(n) for n in orders}
    missing = [n for n in orders if n not in linear]
    if missing:
        raise ValueError(f"no initial linear model of order(s) {missing} given")
    return {n: linear[n] for n in orders}


# A fit to run: the candidate, its start, the index of its (training, held-out) set, and
# fit_candidate's options.
Job = tuple[Candidate, LinearStateSpace, int, dict[str, Any]]


def run_fits(
    jobs: Sequence[Job],
    sets: Sequence[tuple[PeriodicData, PeriodicData]],
    client: Any = None,
    workers: int | None = None,
) -> tuple[list[tuple[ScanRow, PNLSSModel | None]], str]:
    """Every job's ``fit_candidate`` (in the jobs' order), and where they ran: in this process
    (``workers`` 1, or a single job), on a local Dask cluster of ``workers`` single-threaded
    worker processes (None: every core), or on ``client``. The scan's fits and the estimation
    bootstrap's refits (pipeline.py) both run here."""
    if client is None:
        n = workers if workers is not None else (os.cpu_count() or 1)
        if n < 1:
            raise ValueError(f"workers must be >= 1; got {n}")
        if n == 1 or len(jobs) == 1:
            fits = [fit_candidate(c, lin, *sets[k], opts) for c, lin, k, opts in jobs]
            return fits, "serial"
        from dask.distributed import Client, LocalCluster

        with (
            _workers_without_main_script(),
            LocalCluster(
                n_workers=min(n, len(jobs)),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                host="127.0.0.1",
            ) as cluster,
            Client(cluster) as local,
        ):
            return _on_client(local, jobs, sets), (
                f"local Dask cluster, {min(n, len(jobs))} worker processes"
            )
    return _on_client(client, jobs, sets), f"Dask client {client}"


@contextlib.contextmanager
def _workers_without_main_script() -> Iterator[None]:
    """Start local worker processes without re-running the caller's script.

    Dask's local workers are started with multiprocessing's "spawn", which re-imports the
    parent's ``__main__`` in every child (by path for ``python script.py``, by name for
    ``python -m``; multiprocessing.spawn.get_preparation_data). A script without an
    ``if __name__ == "__main__":`` guard would then call scan_pnlss again inside each
    worker while it bootstraps, and the worker fails ("Nanny failed to start"). The scan's
    tasks need only this package, never the script, so while the workers are spawned the
    main module shows neither a file nor a spec: the children skip it, as they do for an
    interactive session or a notebook.
    """
    main = sys.modules.get("__main__")
    path, spec = getattr(main, "__file__", None), getattr(main, "__spec__", None)
    if main is None or (path is None and spec is None):
        yield
        return
    if path is not None:
        del main.__file__
    main.__spec__ = None
    try:
        yield
    finally:
        if path is not None:
            main.__file__ = path
        main.__spec__ = spec


def _on_client(
    client: Any,
    jobs: Sequence[Job],
    sets: Sequence[tuple[PeriodicData, PeriodicData]],
) -> list[tuple[ScanRow, PNLSSModel | None]]:
    # Data once per worker, not once per task; the largest candidates first, so the last
    # task to finish is a small one. One numba thread per fit: the workers are the
    # parallelism (the kernels' own prange over records would oversubscribe the cores).
    scattered = client.scatter([x for pair in sets for x in pair], broadcast=True)
    order = sorted(range(len(jobs)), key=lambda i: -_size(jobs[i][0]))
    futures = {}
    for i in order:
        c, lin, k, options = jobs[i]
        data_f, val_f = scattered[2 * k], scattered[2 * k + 1]
        options = {**options, "numba_threads": 1}
        futures[i] = client.submit(fit_candidate, c, lin, data_f, val_f, options, pure=False)
    return [futures[i].result() for i in range(len(jobs))]


def _split_options(options: dict[str, Any], k: int) -> dict[str, Any]:
    """A job's options: only the first split's fits are kept (ScanResult.models); the further
    splits' fits give their row only, so their models are not shipped back from the workers."""
    return options if k == 0 else {**options, "keep_model": False}


def _size(c: Candidate) -> int:  # relative cost, for the order of submission
    return c.nx * (c.nx + 1) * sum(c.degrees) * (2 if c.equations == "state+output" else 1)


def fit_candidate(
    candidate: Candidate,
    lin: LinearStateSpace,
    data: PeriodicData,
    validation: PeriodicData,
    options: Mapping[str, Any],
) -> tuple[ScanRow, PNLSSModel | None]:
    """Fit one candidate and score it; a failed fit is a row with its reason, never a crash."""
    threads = options.get("numba_threads")
    if threads is not None:
        import numba

        numba.set_num_threads(int(threads))  # this thread's kernels (a Dask worker's task)
    t0 = time.perf_counter()
    try:
        settings = PnlssSettings(
            degrees=candidate.degrees, structure=candidate.structure,
            equations=candidate.equations, max_iter=int(options.get("max_iter", 50)),
            stress=options.get("stress"),
        )  # fmt: skip
        rw, vw = options.get("record_weights"), options.get("validation_weights")
        initial = None
        if candidate.start == "output_ls":
            initial = output_equation_start(
                data, lin, settings, validation=validation, record_weights=rw, validation_weights=vw
            )
        model = fit_pnlss(
            data, lin, settings, validation=validation, initial_model=initial, record_weights=rw,
            validation_weights=vw,
        )  # fmt: skip
        val, se = periodic_error(model, validation, options.get("validation_weights"))
        train, _ = periodic_error(model, data, options.get("record_weights"))
        status = "ok" if math.isfinite(val) else "diverges on the validation data"
        stress = options.get("stress")
        if status == "ok" and stress is not None and not periodic_at(model, validation, stress):
            status = f"unstable at {stress:g}× the validation amplitude"
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        model, val, se, train, status = None, math.nan, math.nan, math.nan, f"failed: {exc}"
    n_params = _n_params(model) if model is not None else 0
    row = ScanRow(
        candidate.nx,
        candidate.degrees,
        candidate.equations,
        candidate.structure,
        n_params,
        val,
        se,
        train,
        time.perf_counter() - t0,
        status,
        candidate.start,
    )
    return row, (model if options.get("keep_model", True) else None)


def _n_params(model: PNLSSModel) -> int:
    offset = model.C.shape[0]  # the fitted output offset
    return int(sum(getattr(model, k).size for k in "ABCDEF") + offset)


def periodic_at(model: PNLSSModel, data: PeriodicData, scale: float) -> bool:
    """Whether the model reaches a bounded periodic steady state on each realization's input
    scaled about its mean by `scale`, and on two random-phase periods of the same amplitude
    spectrum per realization (pnlss.stress_periods, the inputs PnlssSettings.stress checks).

    A stable system driven by a periodic input settles to a periodic response (the premise of
    the BLA framework, Pintelon & Schoukens 2012 §3.4); a model that diverges, or whose last
    two simulated periods still differ by more than 1 % of the output's RMS deviation after
    twenty periods' warm-up, has lost that property at this amplitude (a sub-harmonic or chaotic
    regime) and would not extrapolate there.
    """
    N = data.u.shape[0]
    for u in stress_periods(data.u.mean(axis=1), scale).T:
        # Twenty periods' warm-up (states only), then the two periods compared.
        x = model.state_after(np.tile(u, 20))
        if x is None:
            return False
        y = np.asarray(model.simulate(np.tile(u, 2), x0=x))
        if not np.all(np.isfinite(y)):
            return False
        last, before = y[-N:], y[:N]
        spread = float(np.std(last))
        if spread == 0 or float(np.sqrt(np.mean((last - before) ** 2))) > 0.01 * spread:
            return False
    return True


def periodic_error(
    model: Any, data: PeriodicData, weights: np.ndarray | None = None
) -> tuple[float, float]:
    """Relative RMS error over steady-state periods and its standard error (module docs), of
    any model with ``simulate(u)`` (every class's scan scores with it)."""
    N, P, M = data.u.shape
    e2 = np.empty((M, P))
    for m in range(M):
        u_period = data.u[:, :, m].mean(axis=1)  # the periods of a realization share the input
        y_hat = steady_state_response(model, u_period, N)
        if not np.all(np.isfinite(y_hat)):
            return math.inf, math.nan
        for p in range(P):
            y = data.y[:, p, m]
            e2[m, p] = np.mean((y - y_hat) ** 2) / np.var(y)
    w = np.ones(M * P) if weights is None else np.asarray(weights, float).reshape(-1)
    x = e2.reshape(-1) * w / np.mean(w)  # record r = m·P + p
    mse = float(np.mean(x))
    se_mse = float(np.std(x, ddof=1) / math.sqrt(x.size)) if x.size > 1 else 0.0
    err = math.sqrt(mse)
    if err == 0:
        return 0.0, 0.0
    floor = err / (2 * math.sqrt(max(1, data.excited_lines.size) * M))  # module docstring
    return err, max(se_mse / (2 * err), floor)
