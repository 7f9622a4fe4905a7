"""Identification of measured level records (CSV/MAT files read by records.py).

Per estimation level: the BLA (`bla.estimate_bla`, method "auto": the robust method with noise
and nonlinear-distortion variances when the level has M ≥ 2 realizations; with M = 1 the Local
Polynomial Method, and the distortion level cannot be separated from the BLA: var_total equals
var_noise) and a linear state-space model of it (`subspace.fit_linear_ss`, at a given order or
at the order its scan selects). Then one PNLSS model over all estimation levels
(`fit_nonlinear`, started from the linear model of the lowest estimation level) and the
validation of every model on the held-out levels (`metrics.relative_rms_error`, the records
simulated in periodic steady state).

The PNLSS step is one function, `fit_nonlinear(data, validation, linear, **options)`, so a
cross-validated structure scan can take its place (`identify_levels(..., fit_nonlinear=...)`).

Held-out data for the PNLSS iterate choice (the divergence guard and the returned model): the
last realization of each estimation level when it has M ≥ 2, otherwise its last period (noise
independent of the training periods, same excitation). The validation levels are never used in
any fit, so their errors are honest test errors.
"""

import csv
import io
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aero_identification.bla import BLA, estimate_bla
from aero_identification.config import IdentificationConfig
from aero_identification.data import PeriodicData, transient_periods
from aero_identification.metrics import relative_rms_error, steady_state_response
from aero_identification.models import LinearStateSpace, PNLSSModel
from aero_identification.monomials import structure_exponents
from aero_identification.pnlss import fit_pnlss, one_blas_thread
from aero_identification.records import LevelRecord, matches_level
from aero_identification.subspace import fit_linear_ss

# Largest Jacobian fit_nonlinear accepts (bytes): LM holds one (samples × parameters) float64
# buffer, and each iteration costs about samples × parameters² flops: beyond 1 GB the fit would
# take hours on the 2-core target machine (the identifier's default, full degrees 2–5, at nx = 6
# on the four F-16 levels needs 1.45 GB).
MAX_JACOBIAN_BYTES = 1_000_000_000

DEFAULT_MAX_ORDER = 12  # highest order of the linear order scan

NonlinearFit = Callable[..., PNLSSModel]


@dataclass
class LevelModel:
    """One level's nonparametric and linear results."""

    record: LevelRecord
    role: str  # "estimation" or "validation"
    bla: BLA | None = None
    linear: LinearStateSpace | None = None
    transient_hint: int | None = None  # data.transient_periods on the kept periods
    order_scanned: bool = False
    seconds: float = 0.0


@dataclass
class LevelFitResult:
    levels: dict[str, LevelModel]
    estimation: list[str]
    validation: list[str]
    linear_start: str | None = None  # level whose linear model starts the PNLSS fit
    pnlss: PNLSSModel | None = None
    pnlss_options: dict[str, Any] = field(default_factory=dict)
    pnlss_seconds: float = 0.0
    pnlss_holdout: str = ""
    errors: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    scan: Any = None  # the ScanResult when the PNLSS came from `scan_nonlinear`


def select_levels(
    records: Sequence[LevelRecord],
    estimation: Sequence[str] | None,
    validation: Sequence[str] | None,
) -> tuple[list[str], list[str]]:
    """Names of the estimation and validation levels from the user's selectors.

    A selector is a level name, file stem or glob (`records.matches_level`). Without
    ``estimation`` every level not selected for validation is estimated; without ``validation``
    every level not estimated is validated. A level in both, or a selector matching nothing,
    raises ValueError.
    """
    names = [r.name for r in records]

    def pick(tokens: Sequence[str], what: str) -> list[str]:
        out: list[str] = []
        for token in tokens:
            hit = [r.name for r in records if matches_level(token, r)]
            if not hit:
                raise ValueError(f"{what} level {token!r} matches no level; levels: {names}")
            out += [h for h in hit if h not in out]
        return out

    est = pick(estimation, "estimation") if estimation else None
    val = pick(validation, "validation") if validation else None
    if est is None:
        est = [n for n in names if n not in (val or [])]
    if val is None:
        val = [n for n in names if n not in est]
    both = sorted(set(est) & set(val))
    if both:
        raise ValueError(f"level(s) {both} are selected for estimation and for validation")
    if not est:
        raise ValueError(f"no estimation level left (levels: {names})")
    return est, val


def _pnlss_size(nx: int, degrees: Sequence[int], structure: str, equations: str) -> int:
    K = structure_exponents(nx, 1, degrees, structure).shape[0]
    Ke = K if equations == "state+output" else 0
    return nx * nx + nx + nx * K + nx + 1 + Ke + 1


def fit_nonlinear(
    data: PeriodicData,
    validation: PeriodicData | None,
    linear: LinearStateSpace,
    **options: Any,
) -> PNLSSModel:
    """The nonlinear model of the estimation records: a PNLSS fit (`pnlss.fit_pnlss`).

    Args:
        data: training periods (N, P, M); each period is one record.
        validation: held-out periods (same N) choosing the returned iterate, or None.
        linear: the initial linear model (stable).
        options: ``degrees``, ``structure``, ``max_iter`` (defaults: IdentificationConfig) and
            any other keyword of `fit_pnlss` (e.g. ``n_transient``, ``weighting``).

    Raises:
        ValueError: when the Levenberg–Marquardt Jacobian would exceed MAX_JACOBIAN_BYTES
            (name smaller settings), or from fit_pnlss.
    """
    config = IdentificationConfig()
    opts = dict(options)
    degrees = tuple(opts.pop("degrees", config.degrees))
    structure = str(opts.pop("structure", config.structure))
    max_iter = int(opts.pop("max_iter", config.max_iter))
    n_par = _pnlss_size(linear.nx, degrees, structure, str(opts.get("equations", "state+output")))
    size = data.N * data.P * data.M * (n_par + 1) * 8
    if max_iter > 0 and size > MAX_JACOBIAN_BYTES:
        raise ValueError(
            f"PNLSS with nx={linear.nx}, degrees {list(degrees)}, structure {structure!r} has "
            f"{n_par} parameters; its Jacobian on {data.N * data.P * data.M} samples would take "
            f"{size / 1e9:.1f} GB (limit {MAX_JACOBIAN_BYTES / 1e9:g} GB). Choose fewer degrees, "
            "structure 'inputsonly' or 'statesonly', or a lower order"
        )
    return fit_pnlss(
        data, linear, degrees=degrees, structure=structure, max_iter=max_iter,
        validation=validation, **opts,
    )  # fmt: skip


class ScanFit:
    """A nonlinear step (`fit_nonlinear`'s signature) that runs the cross-validated structure
    scan (scan.scan_pnlss) at the linear model's order and keeps its ScanResult in `.result`.

    Grid: ``degrees`` (degree sets) × ``equations``, with the given ``structure`` and
    ``max_iter`` (50, as the paper's scan); candidates whose Jacobian would exceed
    MAX_JACOBIAN_BYTES are left out and named in `.skipped`. ``client``: a Dask client;
    ``workers``: local worker processes when no client (None: every core).
    """

    def __init__(
        self,
        degrees: Sequence[Sequence[int]] = ((2,), (2, 3)),
        equations: Sequence[str] = ("state", "state+output"),
        structure: str = "full",
        max_iter: int = 50,
        client: Any = None,
        workers: int | None = None,
    ) -> None:
        self.degrees = [tuple(d) for d in degrees]
        self.equations = tuple(equations)
        self.structure = structure
        self.max_iter = max_iter
        self.client = client
        self.workers = workers
        self.result: Any = None
        self.skipped: list[str] = []

    def __call__(
        self,
        data: PeriodicData,
        validation: PeriodicData | None,
        linear: LinearStateSpace,
        **_options: Any,
    ) -> PNLSSModel:
        from .scan import scan_pnlss

        if validation is None:
            raise ValueError("the structure scan needs held-out periods to score the candidates")
        samples = data.N * data.P * data.M
        fits = [
            (d, eq)
            for d in self.degrees
            for eq in self.equations
            if samples * (_pnlss_size(linear.nx, d, self.structure, eq) + 1) * 8
            <= MAX_JACOBIAN_BYTES
        ]
        self.skipped = [
            f"degrees {list(d)} {eq}" for d in self.degrees for eq in self.equations
            if (d, eq) not in fits
        ]  # fmt: skip
        if not fits:
            raise ValueError(
                f"every scan candidate at nx={linear.nx} exceeds the Jacobian limit "
                f"({MAX_JACOBIAN_BYTES / 1e9:g} GB); choose lower degrees or 'statesonly'"
            )
        degrees = sorted({d for d, _ in fits})
        equations = sorted({eq for _, eq in fits})
        self.result = scan_pnlss(
            data, validation, nx=(linear.nx,), degrees=degrees, equations=equations,
            structures=(self.structure,), max_iter=self.max_iter, client=self.client,
            linear={linear.nx: linear}, workers=self.workers,
        )  # fmt: skip
        return self.result.best


def _record_error(model: Any, data: PeriodicData, centred: bool) -> float:
    """Relative RMS error over every realization's kept periods (steady-state simulation).
    Linear models map deviations: with ``centred`` they are put at the record's means."""
    errors_num, errors_den = 0.0, 0.0
    for m in range(data.M):
        u = data.u[:, :, m].T.reshape(-1)
        y = data.y[:, :, m].T.reshape(-1)
        mod = model.with_operating_point(u.mean(), y.mean()) if centred else model
        y_hat = steady_state_response(mod, u, data.N)
        if not np.all(np.isfinite(y_hat)):
            return math.inf
        e = relative_rms_error(y, y_hat)
        spread2 = float(np.mean((y - y.mean()) ** 2))
        errors_num += e * e * spread2
        errors_den += spread2
    return math.sqrt(errors_num / errors_den)


def _split_for_pnlss(
    records: Sequence[LevelRecord],
) -> tuple[PeriodicData, PeriodicData | None, str]:
    """Training mean periods and held-out mean periods, one record per level and realization."""
    us, ys, uv, yv = [], [], [], []
    M = min(r.data.M for r in records)
    P = min(r.data.P for r in records)
    if M >= 2:
        how = "the last realization of each estimation level"
    elif P >= 2:
        how = "the last period of each estimation level"
    else:
        how = "none (one period, one realization per level)"
    for r in records:
        d = r.data
        if d.M >= 2:
            train_u, train_y = d.u[:, :, :-1], d.y[:, :, :-1]
            us.append(train_u.mean(axis=1))
            ys.append(train_y.mean(axis=1))
            uv.append(d.u[:, :, -1:].mean(axis=1))
            yv.append(d.y[:, :, -1:].mean(axis=1))
        elif d.P >= 2:
            us.append(d.u[:, :-1, :].mean(axis=1))
            ys.append(d.y[:, :-1, :].mean(axis=1))
            uv.append(d.u[:, -1, :])
            yv.append(d.y[:, -1, :])
        else:
            us.append(d.u[:, 0, :])
            ys.append(d.y[:, 0, :])
    lines = records[0].data.excited_lines
    fs = records[0].data.fs
    train = PeriodicData(
        np.concatenate(us, axis=1)[:, None, :], np.concatenate(ys, axis=1)[:, None, :], fs, lines
    )
    if len(uv) != len(records):
        return train, None, "none (a level has one period and one realization)"
    held = PeriodicData(
        np.concatenate(uv, axis=1)[:, None, :], np.concatenate(yv, axis=1)[:, None, :], fs, lines
    )
    return train, held, how


def identify_levels(
    records: Sequence[LevelRecord],
    estimation: Sequence[str] | None = None,
    validation: Sequence[str] | None = None,
    *,
    nx: int | None = None,
    max_order: int = DEFAULT_MAX_ORDER,
    pnlss: bool = True,
    pnlss_options: Mapping[str, Any] | None = None,
    fit_nonlinear: NonlinearFit = fit_nonlinear,
    log: Callable[[str], None] | None = None,
) -> LevelFitResult:
    """BLA and linear model per estimation level, one PNLSS, validation on held-out levels.

    Args:
        records: the levels (records.read_records).
        estimation, validation: level selectors (`select_levels`).
        nx: linear (and PNLSS) order; None: chosen per level by the order scan of
            `fit_linear_ss` (orders 1 … max_order, MDL-type penalty) without refinement, then
            refitted with refinement at the chosen order.
        pnlss: fit the nonlinear model.
        pnlss_options: keywords for ``fit_nonlinear`` (degrees, structure, max_iter, …).
        fit_nonlinear: the nonlinear step (same signature as this module's `fit_nonlinear`).
        log: progress messages (e.g. print to stderr).

    Returns:
        LevelFitResult; `errors` has one row per validation level.
    """
    with one_blas_thread():
        return _identify_levels(
            records, estimation, validation, nx, max_order, pnlss, pnlss_options,
            fit_nonlinear, log,
        )  # fmt: skip


def _identify_levels(
    records: Sequence[LevelRecord],
    estimation: Sequence[str] | None,
    validation: Sequence[str] | None,
    nx: int | None,
    max_order: int,
    pnlss: bool,
    pnlss_options: Mapping[str, Any] | None,
    fit_nonlinear: NonlinearFit,
    log: Callable[[str], None] | None,
) -> LevelFitResult:
    say = log or (lambda _msg: None)
    est, val = select_levels(records, estimation, validation)
    by_name = {r.name: r for r in records}
    result = LevelFitResult(
        levels={}, estimation=est, validation=val, pnlss_options=dict(pnlss_options or {})
    )
    t_all = time.perf_counter()
    for name in [*est, *val]:
        rec = by_name[name]
        lm = LevelModel(rec, "estimation" if name in est else "validation")
        result.levels[name] = lm
        if rec.data.P >= 3:
            lm.transient_hint = transient_periods(rec.data)
            if lm.transient_hint:
                result.warnings.append(
                    f"level {name}: the first {lm.transient_hint} kept period(s) differ from "
                    "the last ones by more than twice the noise (a transient, or slow drift); "
                    "nothing dropped: use --drop-periods K to drop leading periods"
                )
        t0 = time.perf_counter()
        lm.bla = estimate_bla(rec.data, method="auto")
        if rec.data.M < 2:
            result.warnings.append(
                f"level {name}: one realization (M = 1): the nonlinear distortion level cannot "
                "be separated from the BLA (var_total = var_noise, LPM noise estimate)"
            )
        if lm.role != "estimation":
            continue  # its BLA is for the report only; no model is fitted to held-out data
        order = nx
        if order is None:
            order = fit_linear_ss(lm.bla, max_order=max_order, refine_fit=False).order
            lm.order_scanned = True
        lm.linear = fit_linear_ss(lm.bla, nx=order).with_operating_point(
            float(np.mean(rec.data.u)), float(np.mean(rec.data.y))
        )
        lm.seconds = time.perf_counter() - t0
        say(
            f"level {name}: BLA ({lm.bla.method}, M={rec.data.M}, P={rec.data.P}), linear "
            f"order {lm.linear.order}{' (scan)' if lm.order_scanned else ''}, "
            f"{lm.seconds:.1f} s"
        )
    result.timings_s["bla_linear"] = time.perf_counter() - t_all

    est_sorted = sorted(est, key=lambda n: by_name[n].input_rms)
    result.linear_start = est_sorted[0]
    if pnlss:
        start = result.levels[est_sorted[0]].linear
        assert start is not None
        train, held, how = _split_for_pnlss([by_name[n] for n in est_sorted])
        result.pnlss_holdout = how
        t0 = time.perf_counter()
        say(f"PNLSS from the linear model of level {est_sorted[0]}, options {pnlss_options}")
        try:
            result.pnlss = fit_nonlinear(train, held, start, **dict(pnlss_options or {}))
        except (ValueError, np.linalg.LinAlgError) as exc:
            result.warnings.append(f"PNLSS not fitted: {exc}")
        if isinstance(fit_nonlinear, ScanFit):
            result.scan = fit_nonlinear.result
            result.warnings += [
                f"scan candidate left out (Jacobian over the limit): {s}"
                for s in fit_nonlinear.skipped
            ]
        result.pnlss_seconds = time.perf_counter() - t0
        say(f"PNLSS: {result.pnlss_seconds:.1f} s")
        result.timings_s["pnlss"] = result.pnlss_seconds

    lowest = result.levels[est_sorted[0]].linear
    for name in val:
        rec = by_name[name]
        nearest = min(est, key=lambda n: abs(by_name[n].input_rms - rec.input_rms))
        near_model = result.levels[nearest].linear
        row: dict[str, Any] = {
            "level": name,
            "input_rms": rec.input_rms,
            "nearest_estimation_level": nearest,
            "linear_nearest": _record_error(near_model, rec.data, centred=True),
            "linear_lowest": _record_error(lowest, rec.data, centred=True),
            "pnlss": (
                _record_error(result.pnlss, rec.data, centred=False)
                if result.pnlss is not None
                else None
            ),
        }
        result.errors.append(row)
    result.timings_s["total"] = time.perf_counter() - t_all
    return result


# --- report ---------------------------------------------------------------------------------

ERROR_COLUMNS = (
    ("level", "held-out level"),
    ("input_rms", "input RMS"),
    ("nearest_estimation_level", "nearest estimation level"),
    ("linear_nearest", "linear SS (nearest level)"),
    ("linear_lowest", "linear SS (lowest level)"),
    ("pnlss", "PNLSS"),
)


def error_table(result: LevelFitResult, digits: int = 3) -> tuple[str, str]:
    """Validation errors per held-out level as (Markdown, CSV)."""
    header = [title for _, title in ERROR_COLUMNS]
    md = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([key for key, _ in ERROR_COLUMNS])
    for row in result.errors:
        cells = []
        for key, _ in ERROR_COLUMNS:
            v = row[key]
            if v is None:
                cells.append("–")
            elif isinstance(v, float):
                cells.append(f"{v:.{digits}f}" if key != "input_rms" else f"{v:.4g}")
            else:
                cells.append(str(v))
        md.append("| " + " | ".join(cells) + " |")
        writer.writerow(["" if row[k] is None else row[k] for k, _ in ERROR_COLUMNS])
    return "\n".join(md) + "\n", buffer.getvalue()


def bla_summary(bla: BLA) -> dict[str, float]:
    """Median levels over the excited lines [dB]: |G|, noise σ and (M ≥ 2) distortion σ."""

    def db_var(v: np.ndarray) -> float:
        m = float(np.median(v))
        return 10 * math.log10(m) if m > 0 else -math.inf

    out = {
        "G_db": float(20 * np.log10(np.median(np.abs(bla.G)))),
        "noise_db": db_var(bla.var_noise),
        "snr_db": float(10 * np.log10(np.median(bla.snr))),
    }
    if bla.M >= 2:
        out["nl_db"] = db_var(bla.var_nl)
        out["total_db"] = db_var(bla.var_total)
    return out


def modal_frequencies(model: LinearStateSpace) -> list[float]:
    """Natural frequencies [Hz] of the model's complex pole pairs, ascending."""
    p = model.poles()
    p = p[np.imag(p) > 0]
    return sorted(float(f) for f in np.abs(np.log(p)) * model.fs / (2 * math.pi))


def _level_json(lm: LevelModel) -> dict[str, Any]:
    rec = lm.record
    entry: dict[str, Any] = {
        "file": str(rec.path),
        "role": lm.role,
        "N": rec.data.N,
        "P": rec.data.P,
        "M": rec.data.M,
        "periods_in_file": rec.periods_in_file,
        "dropped_periods": rec.dropped_periods,
        "transient_hint": lm.transient_hint,
        "input_rms": rec.input_rms,
        "notes": rec.notes,
    }
    if lm.bla is not None:
        entry["bla"] = {
            "method": lm.bla.method,
            "freq_hz": lm.bla.freq.tolist(),
            "G_re": lm.bla.G.real.tolist(),
            "G_im": lm.bla.G.imag.tolist(),
            "var_noise": lm.bla.var_noise.tolist(),
            "var_total": lm.bla.var_total.tolist(),
            "var_nl": lm.bla.var_nl.tolist() if lm.bla.M >= 2 else None,
            "summary_db": bla_summary(lm.bla),
        }
    if lm.linear is not None:
        entry["linear"] = lm.linear.to_dict()
        entry["linear"]["order_scanned"] = lm.order_scanned
        entry["linear"]["modal_frequencies_hz"] = modal_frequencies(lm.linear)
    return entry


def write_level_report(result: LevelFitResult, out_dir: str | Path) -> dict[str, Path]:
    """models.json, validation_errors.md|csv, summary.md and BLA figures per level."""
    from aero_identification import report

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    md, csv_text = error_table(result)
    (out / "validation_errors.md").write_text(md)
    (out / "validation_errors.csv").write_text(csv_text)
    written["validation_errors"] = out / "validation_errors.md"
    payload = {
        "estimation_levels": result.estimation,
        "validation_levels": result.validation,
        "levels": {name: _level_json(lm) for name, lm in result.levels.items()},
        "pnlss": {
            "model": result.pnlss.to_dict() if result.pnlss is not None else None,
            "initial_linear_level": result.linear_start,
            "options": {k: _jsonable(v) for k, v in result.pnlss_options.items()},
            "held_out": result.pnlss_holdout,
            "fit_seconds": result.pnlss_seconds,
        },
        "errors": result.errors,
        "warnings": result.warnings,
        "timings_s": result.timings_s,
    }
    (out / "models.json").write_text(json.dumps(payload, indent=1, allow_nan=True))
    written["models"] = out / "models.json"
    for name, lm in result.levels.items():
        if lm.bla is None:
            continue
        tag = name.replace(" ", "_").replace("/", "_")
        written[f"frf_{tag}"] = report.plot_frf(
            lm.bla, out / f"frf_{tag}.png", f"BLA, level {name}"
        )
        written[f"spectrum_{tag}"] = report.plot_output_spectrum(
            lm.bla, out / f"output_spectrum_{tag}.png", f"Output spectrum, level {name}", "|Y| [dB]"
        )
    if result.scan is not None:
        (out / "pnlss_scan.md").write_text("# PNLSS structure scan\n\n" + result.scan.to_markdown())
        (out / "pnlss_scan.csv").write_text(result.scan.to_csv())
        written["pnlss_scan"] = out / "pnlss_scan.md"
        written["pnlss_scan_plot"] = report.plot_scan(result.scan, out / "pnlss_scan.png")
    (out / "summary.md").write_text(summary_markdown(result))
    written["summary"] = out / "summary.md"
    return written


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple | list):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    return v


def summary_markdown(result: LevelFitResult) -> str:
    """A readable summary: data, BLA levels, linear orders, PNLSS, validation errors."""
    lines = ["# Identification of level records", "", "## Data", ""]
    for name, lm in result.levels.items():
        rec = lm.record
        lines.append(f"- level {name} ({lm.role}), `{rec.path.name}`: " + "; ".join(rec.notes))
    lines += ["", "## BLA per level and linear models (estimation levels)", ""]
    lines += [
        "| level | input RMS | BLA method | M × P | median |G| [dB] | median noise σ [dB] | "
        "median SNR [dB] | median NL σ [dB] | order | modes [Hz] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, lm in sorted(result.levels.items(), key=lambda kv: kv[1].record.input_rms):
        if lm.bla is None:
            continue
        s = bla_summary(lm.bla)
        nl = f"{s['nl_db']:.1f}" if "nl_db" in s else "not separable (M = 1)"
        modes, order = "–", "– (held out)"
        if lm.linear is not None:
            modes = ", ".join(f"{f:.2f}" for f in modal_frequencies(lm.linear))
            order = f"{lm.linear.order}" + (" (scan)" if lm.order_scanned else "")
        lines.append(
            f"| {name} | {lm.record.input_rms:.4g} | {lm.bla.method} | {lm.bla.M} × {lm.bla.P} | "
            f"{s['G_db']:.1f} | {s['noise_db']:.1f} | {s['snr_db']:.1f} | {nl} | {order} | "
            f"{modes} |"
        )
    lines += ["", "## PNLSS", ""]
    if result.pnlss is not None:
        m = result.pnlss
        lines.append(
            f"nx = {m.nx}, degrees {list(m.degrees)}, structure {m.structure}, "
            f"{m.parameters.size} parameters, started from the linear model of level "
            f"{result.linear_start}; iterate chosen on {result.pnlss_holdout}; "
            f"{len(m.history_) - 1} LM trials in {result.pnlss_seconds:.1f} s."
        )
    else:
        lines.append("not fitted")
    lines += ["", "## Validation on held-out levels (relative RMS error)", ""]
    lines.append(error_table(result)[0])
    if result.warnings:
        lines += ["## Warnings", ""] + [f"- {w}" for w in result.warnings]
    return "\n".join(lines).rstrip() + "\n"
