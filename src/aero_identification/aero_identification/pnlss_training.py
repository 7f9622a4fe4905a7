"""The all-levels PNLSS on the estimation sets (estimation_sets.py): level weights, one fit and
the structure scan's driver (step 3 of `pipeline.identify`; [PitchingWing] §4.1)."""

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from .estimation_sets import EstimationSets, validation_realization
from .hyperparameters import IdentificationConfig
from .identification_result import IdentificationResult, LevelResult, Log
from .level_identification import kept_periods
from .monomials import structure_exponents
from .periodic_data import PeriodicData
from .pnlss import PnlssSettings, fit_pnlss, output_equation_start
from .scan import ScanResult, scan_pnlss
from .state_space_models import PNLSSModel
from .subspace import fit_linear_ss

__all__ = [
    "MAX_JACOBIAN_BYTES",
    "fit_client",
    "fit_levels",
    "level_signature",
    "level_weights",
    "noise_variance",
    "pnlss_parameters",
    "scan_levels",
]

# Largest Levenberg–Marquardt Jacobian a PNLSS fit may hold (bytes): one (samples × parameters)
# float64 buffer, each iteration about samples × parameters² flops: beyond 1 GB a fit takes hours
# on the 2-core target machine (full degrees 2–5 at nx = 6 on the four F-16 levels: 1.45 GB).
MAX_JACOBIAN_BYTES = 1_000_000_000

SCHEDULER_CONNECT_S = 30.0  # how long a scan or bootstrap tries to reach scan_scheduler


def pnlss_parameters(nx: int, degrees: Sequence[int], structure: str, equations: str) -> int:
    """Parameters of a PNLSS model (A, B, E, C, D, F, offset; docs/design.md §7.5)."""
    K = structure_exponents(nx, 1, degrees, structure).shape[0]
    Ke = K if equations == "state+output" else 0
    return nx * nx + nx + nx * K + nx + 1 + Ke + 1


def jacobian_bytes(data: PeriodicData, n_par: int) -> int:
    return data.N * data.P * data.M * (n_par + 1) * 8


def fit_levels(
    sets: EstimationSets,
    result: IdentificationResult,
    config: IdentificationConfig,
    label: str,
    say: Log,
) -> PNLSSModel | None:
    """One PNLSS structure (config.degrees, config.structure), started from the lowest level's
    linear model with its output equation solved by least squares (`output_equation_start`)."""
    data, validation = sets.train, sets.held
    result.pnlss_held_out = sets.how
    lin = result.linear_level1
    assert lin is not None
    n_par = pnlss_parameters(lin.nx, config.degrees, config.structure, "state+output")
    size = jacobian_bytes(data, n_par)
    if config.max_iter > 0 and size > MAX_JACOBIAN_BYTES:
        result.warnings.append(
            f"PNLSS ({label}) not fitted: nx={lin.nx}, degrees {list(config.degrees)}, structure "
            f"{config.structure!r} has {n_par} parameters; its Jacobian on "
            f"{data.N * data.P * data.M} samples would take {size / 1e9:.1f} GB (limit "
            f"{MAX_JACOBIAN_BYTES / 1e9:g} GB). Choose fewer degrees, structure 'inputsonly' or "
            "'statesonly', or a lower order"
        )
        return None
    t0 = time.perf_counter()
    try:
        weights, val_weights = level_weights(sets.levels, config, data, validation)
        settings = PnlssSettings(
            degrees=config.degrees, structure=config.structure, max_iter=config.max_iter
        )
        start = output_equation_start(
            data, lin, settings, validation=validation, record_weights=weights,
            validation_weights=val_weights,
        )  # fmt: skip
        model = fit_pnlss(
            data, lin, settings, validation=validation, initial_model=start,
            record_weights=weights, validation_weights=val_weights,
        )  # fmt: skip
    except (ValueError, np.linalg.LinAlgError) as exc:
        result.warnings.append(f"PNLSS ({label}) failed: {exc}")
        return None
    say(f"PNLSS ({label}): {n_par} parameters, {time.perf_counter() - t0:.1f} s")
    return model


def scan_levels(
    sets: EstimationSets,
    result: IdentificationResult,
    config: IdentificationConfig,
    client: Any,
    say: Log,
) -> ScanResult | None:
    """The all-levels PNLSS by the cross-validated structure scan (scan.py) on `fit_levels`'s
    sets: every order of ``config.scan_nx`` (0: the lowest level's linear order) started from the
    lowest level's BLA; candidates whose Jacobian would exceed MAX_JACOBIAN_BYTES are left out
    and named."""
    data, validation = sets.train, sets.held
    result.pnlss_held_out = sets.how
    low = sets.levels[0]
    lin = result.linear_level1
    if validation is None:
        result.warnings.append("PNLSS structure scan: no held-out periods to score candidates")
        return None
    if low.bla is None or lin is None:
        return None
    splits = sets.folds(config)
    grid = _grid_within_limit(data, lin.nx, config, result.warnings)
    if grid is None:
        return None
    orders, degree_sets = grid
    equations = tuple(config.scan_equations)
    u0, y0 = float(lin.u_mean[0]), float(lin.y_mean[0])
    try:
        linear = {
            n: (lin if n == lin.nx and 0 in config.scan_nx else
                fit_linear_ss(low.bla, nx=n).with_operating_point(u0, y0))
            for n in orders
        }  # fmt: skip
        weights, val_weights = level_weights(sets.levels, config, data, validation)
        t0 = time.perf_counter()
        with fit_client(config, client) as executor:
            scan = scan_pnlss(
                data,
                validation,
                nx=tuple(orders),
                degrees=tuple(degree_sets),
                equations=equations,
                structures=(config.structure,),
                max_iter=config.scan_max_iter,
                client=executor,
                linear=linear,
                workers=config.scan_workers or None,
                record_weights=weights,
                validation_weights=val_weights,
                starts=("linear", "output_ls"),  # the latter: the single-structure fit's start
                stress=config.scan_stress or None,
                splits=splits,
            )
        say(
            f"PNLSS structure scan: {len(scan.rows)} candidates × {1 + len(splits)} split(s), "
            f"{time.perf_counter() - t0:.1f} s"
        )
        return scan
    except (ValueError, OSError) as exc:  # OSError: the Dask scheduler cannot be reached
        result.warnings.append(f"PNLSS structure scan failed: {exc}")
        return None


def _grid_within_limit(
    data: PeriodicData, nx: int, config: IdentificationConfig, warnings: list[str]
) -> tuple[list[int], list[tuple[int, ...]]] | None:
    """The scan's orders and degree sets (``config.scan_nx``, 0: ``nx``; ``scan_degrees``)
    without those whose Jacobian would exceed MAX_JACOBIAN_BYTES, each left out named in
    ``warnings``; None when every candidate is over the limit."""
    orders = sorted({nx if n == 0 else n for n in config.scan_nx})
    degree_sets = sorted({tuple(d) for d in config.scan_degrees}, key=lambda d: (len(d), d))
    equations = tuple(config.scan_equations)

    def over(n: int, d: tuple[int, ...], eq: str) -> bool:
        n_par = pnlss_parameters(n, d, config.structure, eq)
        return jacobian_bytes(data, n_par) > MAX_JACOBIAN_BYTES

    # The scan fits the whole grid nx × degrees × equations: drop the largest degree sets,
    # then the highest orders, until no candidate is over the limit.
    while (
        degree_sets
        and orders
        and any(over(n, d, eq) for n in orders for d in degree_sets for eq in equations)
    ):
        dropped = degree_sets.pop() if len(degree_sets) > 1 else None
        if dropped is None:
            warnings.append(
                f"scan order nx {orders[-1]} left out: even degrees {list(degree_sets[0])} are "
                f"over the {MAX_JACOBIAN_BYTES / 1e9:g} GB Jacobian limit"
            )
            orders.pop()
        else:
            warnings.append(
                f"scan degrees {list(dropped)} left out: over the "
                f"{MAX_JACOBIAN_BYTES / 1e9:g} GB Jacobian limit at nx {orders[-1]}"
            )
    if not orders or not degree_sets:
        warnings.append("PNLSS structure scan: every candidate is over the Jacobian limit")
        return None
    return orders, [d for d in (tuple(x) for x in config.scan_degrees) if d in degree_sets]


def relative_weights(data: PeriodicData) -> np.ndarray:
    """1 / var(each record's output) (level_weighting "relative"); record r = m·P + p."""
    var = np.var(data.y, axis=0).T.reshape(-1)
    if not np.all(var > 0):
        raise ValueError("a level's output is constant: relative weighting is undefined")
    return 1.0 / var


def noise_variance(res: LevelResult) -> float:
    """Noise variance of the level's mean period: the sample variance over the kept periods
    of each realization (ddof 1), averaged over time and divided by the number of periods
    averaged (the mean of P periods has variance σ²/P), then averaged over the realizations.
    The stall's cycle-to-cycle scatter counts as noise here: no periodic model predicts it."""
    data = res.record.data
    assert data is not None
    per_realization = []
    for m in range(data.M):
        cols = kept_periods(res, m)
        if len(cols) >= 2:
            var = np.var(data.y[:, cols, m], axis=1, ddof=1).mean()
            per_realization.append(var / len(cols))
    if not per_realization:
        raise ValueError(
            f"level {res.record.name}: level_weighting 'noise' needs two kept periods of a "
            "realization to estimate the noise; use 'none' or 'relative'"
        )
    var = float(np.mean(per_realization))
    if not var > 0:
        raise ValueError(f"level {res.record.name}: the output repeats exactly, noise variance 0")
    return var


def level_weights(
    levels: Sequence[LevelResult],
    config: IdentificationConfig,
    data: PeriodicData,
    validation: PeriodicData | None,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Record weights of the estimation sets' training and held-out records
    (config.level_weighting).

    "noise": each level's records by 1 / the noise variance of its mean period
    (`noise_variance`), the weighted least squares that is the maximum-likelihood output-error
    estimator under Gaussian noise of level-dependent variance [Pintelon2012]
    [Paduart2010: the PNLSS cost weighted by the inverse noise variance]. The records follow
    `estimation_sets`' order: per level, its training realizations (or its one training mean)."""
    weighting = config.level_weighting
    if weighting == "none":
        return None, None
    if weighting == "relative":
        return relative_weights(data), (relative_weights(validation) if validation else None)
    if weighting != "noise":
        raise ValueError(
            f"level_weighting must be 'none', 'relative' or 'noise'; got {weighting!r}"
        )
    w = np.array([1.0 / noise_variance(res) for res in levels])
    counts = []
    for res in levels:
        d = res.record.data
        assert d is not None
        counts.append(d.M - 1 if validation_realization(d, config) is not None else 1)
    train = np.repeat(w, counts)
    if train.size != data.y.shape[2]:  # estimation_sets' record order changed: fail loudly
        raise ValueError(f"noise weighting: {train.size} weights for {data.y.shape[2]} records")
    return train, (w if validation is not None else None)


def level_signature(res: LevelResult, config: IdentificationConfig) -> bytes:
    """The periods a level's PNLSS fit would use, as bytes."""
    data = res.record.data
    assert data is not None
    parts = []
    for m in range(data.M):
        cols = kept_periods(res, m)
        parts.append(
            cols.astype(np.int64).tobytes()
            + data.period_index[cols, m].astype(np.int64).tobytes()
            + data.u[:, cols, m].tobytes()
            + data.y[:, cols, m].tobytes()
        )
    return b"|".join(parts)


@contextmanager
def fit_client(config: IdentificationConfig, client: Any) -> Iterator[Any]:
    """The Dask client the scan's and the bootstrap's fits run on: identify's ``client``, else
    one of the scheduler at ``config.scan_scheduler`` for the duration (OSError if it cannot be
    reached within SCHEDULER_CONNECT_S), else None (scan.run_fits: ``scan_workers`` local
    processes or this one)."""
    if client is not None or not config.scan_scheduler:
        yield client
        return
    from dask.distributed import Client

    with Client(config.scan_scheduler, timeout=f"{SCHEDULER_CONNECT_S:g}s") as remote:
        yield remote
