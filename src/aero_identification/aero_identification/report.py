"""Reports of an identification run: the figures of the paper's Figs. 6–9 and `write_report`,
the one report of every source (tables in report_tables.py).

Figures use matplotlib's object-oriented API on an Agg canvas (no pyplot, no screen, no global
backend switch), so they can be written from nodes and tests alike.
"""

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from aero_identification import model_payload as msg
from aero_identification.bla import BLA
from aero_identification.dataset import QuasiStaticSweep
from aero_identification.identification_result import (
    IdentificationResult,
    bla_summary,
    modal_frequencies,
)
from aero_identification.quality import data_quality_lines
from aero_identification.report_tables import TABLE1_MODELS, clustering_markdown, table1

__all__ = ["TABLE1_MODELS", "clustering_markdown", "table1"]


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=120)
    return path


def _finish(fig: Figure, ax: Any, path: str | Path, xlabel: str, ylabel: str, title: str) -> Path:
    """Labels, legend and grid of a single-axes figure, then save it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)
    return _save(fig, path)


def _db_amplitude(x: np.ndarray) -> np.ndarray:
    return 20 * np.log10(np.maximum(np.abs(x), 1e-300))


def _db_variance(v: np.ndarray) -> np.ndarray:
    # Standard deviation in dB: 10·log10(variance); zeros (no distortion) are not drawn.
    v = np.asarray(v, dtype=float)
    return np.where(v > 0, 10 * np.log10(np.where(v > 0, v, 1.0)), np.nan)


def plot_frf(bla: BLA, path: str | Path, title: str = "Best linear approximation") -> Path:
    """FRF magnitude and phase with noise and nonlinear-distortion levels (paper Fig. 7).

    The levels are standard deviations of the mean BLA: √var_noise, √var_total, √var_nl (dB).
    """
    fig = Figure(figsize=(7, 6), layout="constrained")
    ax_mag, ax_phase = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    ax_mag.plot(bla.freq, _db_amplitude(bla.G), "k-", lw=1.5, label="G BLA")
    ax_mag.plot(bla.freq, _db_variance(bla.var_noise), ".", color="0.5", ms=3, label="noise σ")
    ax_mag.plot(
        bla.freq, _db_variance(bla.var_total), "x", color="tab:orange", ms=3, label="total σ"
    )
    ax_mag.plot(bla.freq, _db_variance(bla.var_nl), ".", color="tab:red", ms=3, label="nonlinear σ")
    ax_mag.set_ylabel("magnitude [dB]")
    ax_mag.set_title(f"{title} (M={bla.M}, P={bla.periods_text}, {bla.method})")
    ax_mag.legend(loc="best", fontsize="small")
    ax_mag.grid(True, alpha=0.3)
    ax_phase.plot(bla.freq, np.degrees(np.unwrap(np.angle(bla.G))), "k-")
    ax_phase.set_ylabel("phase [°]")
    ax_phase.set_xlabel("frequency [Hz]")
    ax_phase.grid(True, alpha=0.3)
    return _save(fig, path)


def plot_output_spectrum(
    bla: BLA, path: str | Path, title: str = "Output spectrum", ylabel: str = "|C_l| [dB]"
) -> Path:
    """Output spectrum at excited, odd and even detection lines and the noise (paper Fig. 6).

    All four are levels of the period-averaged output DFT (RMS over realizations), so a line
    with noise only lies at the noise level.
    """
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(bla.freq, _db_amplitude(bla.excited_level), "k.", ms=4, label="excited")
    for freq, level, marker, color, label in (
        (bla.odd_freq, bla.odd_nl_level, "o", "tab:red", "odd detection"),
        (bla.even_freq, bla.even_nl_level, "s", "tab:blue", "even"),
    ):
        ax.plot(freq, _db_amplitude(level), marker, color=color, ms=3, mfc="none", label=label)
    ax.plot(bla.noise_freq, _db_amplitude(bla.noise_level), "-", color="0.5", lw=1, label="noise σ")
    return _finish(fig, ax, path, "frequency [Hz]", ylabel, title)


def plot_clusters(
    labels: np.ndarray,
    path: str | Path,
    y: np.ndarray | None = None,
    fs: float | None = None,
    title: str = "Clustering of periods",
) -> Path:
    """Cluster of every period over time (paper Fig. 8).

    Args:
        labels: (P, M) cluster label per period (0 = dominant, kept for modelling).
        path: output PNG.
        y: optional (N, P, M) output records: drawn against time, each period coloured by its
            cluster, one panel per realization.
        fs: sampling frequency [Hz] for the time axis of `y` (default: samples).
        title: figure title.
    """
    labels = np.asarray(labels)
    if labels.ndim != 2:
        raise ValueError(f"labels must be a (P, M) array; got shape {labels.shape}")
    P, M = labels.shape
    if y is not None and (np.ndim(y) != 3 or np.shape(y)[1:] != (P, M)):
        raise ValueError(f"y must be (N, P, M) with (P, M)={(P, M)}; got {np.shape(y)}")
    colours = [f"C{i % 10}" for i in range(int(labels.max()) + 1)]
    n_rows = M if y is not None else 0
    fig = Figure(figsize=(8, 2 + 1.8 * n_rows), layout="constrained")
    axes = fig.subplots(n_rows + 1, 1, squeeze=False)[:, 0]
    if y is not None:
        N = y.shape[0]
        dt = 1.0 / fs if fs else 1.0
        for m in range(M):
            ax = axes[m]
            for p in range(P):
                t = (p * N + np.arange(N)) * dt
                ax.plot(t, y[:, p, m], color=colours[labels[p, m]], lw=0.6)
            ax.set_ylabel(f"y, realization {m}")
            ax.grid(True, alpha=0.3)
        axes[M - 1].set_xlabel("time [s]" if fs else "sample")
    ax = axes[-1]
    for m in range(M):
        for p in range(P):
            ax.barh(m, 1, left=p, color=colours[labels[p, m]], edgecolor="white")
            ax.text(p + 0.5, m, str(labels[p, m]), ha="center", va="center", fontsize="small")
    ax.set_yticks(range(M))
    ax.set_ylabel("realization")
    ax.set_xlabel("period")
    ax.set_xlim(0, P)
    axes[0].set_title(f"{title}: cluster 0 kept")
    return _save(fig, path)


def plot_time_series(
    t: np.ndarray,
    y_measured: np.ndarray,
    y_simulated: Mapping[str, np.ndarray],
    path: str | Path,
    ylabel: str = "C_l",
    title: str = "Measured and simulated output",
) -> Path:
    """Measured output against the simulated outputs of one or more models.

    Args:
        t: (T,) time [s].
        y_measured: (T,) measured output.
        y_simulated: {model name: (T,) simulated output}.
    """
    fig = Figure(figsize=(8, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(t, y_measured, "k-", lw=1.2, label="measured")
    for name, y_sim in y_simulated.items():
        ax.plot(t, y_sim, lw=1.0, label=name, color=msg.model_color_hex(name))
    return _finish(fig, ax, path, "time [s]", ylabel, title)


def plot_cl_alpha(
    alpha_deg: np.ndarray,
    cl_measured: np.ndarray,
    path: str | Path,
    cl_simulated: Mapping[str, np.ndarray] | None = None,
    quasi_static: tuple[np.ndarray, np.ndarray] | None = None,
    title: str = "Lift coefficient against angle of attack",
) -> Path:
    """Transfer characteristic C_l–α, measured and simulated (paper Fig. 9).

    Args:
        alpha_deg: (T,) angle of attack [°].
        cl_measured: (T,) measured C_l.
        cl_simulated: {model name: (T,) simulated C_l} on the same α.
        quasi_static: optional (α [°], C_l) baseline lift curve (paper Fig. 5).
    """
    fig = Figure(figsize=(6, 5), layout="constrained")
    ax = fig.subplots()
    if quasi_static is not None:
        ax.plot(quasi_static[0], quasi_static[1], "-", color="0.6", lw=1, label="quasi-static")
    ax.plot(alpha_deg, cl_measured, "k-", lw=1.0, label="measured")
    for name, cl in (cl_simulated or {}).items():
        ax.plot(alpha_deg, cl, lw=1.0, label=name, color=msg.model_color_hex(name))
    return _finish(fig, ax, path, "α [°]", "C_l", title)


def plot_quasi_static(
    sweep: QuasiStaticSweep,
    path: str | Path,
    levels: Sequence[tuple[str, float, float]] = (),
    sines: Sequence[tuple[str, float, float]] = (),
    title: str = "Quasi-static lift and the excitation ranges",
) -> Path:
    """The quasi-static C_l–α curve, pitch-up and pitch-down, with each multisine level's
    α mean ± std as a filled band and each sine's α range as a dashed band (paper Fig. 5).

    Args:
        sweep: the measured sweep; each branch drawn as its mean C_l per 0.25° of α.
        levels: (name, α mean, α std) per multisine level.
        sines: (name, α min, α max) per validation sine.
    """
    fig = Figure(figsize=(7, 5), layout="constrained")
    ax = fig.subplots()
    for i, (name, mean, std) in enumerate(levels):
        ax.axvspan(mean - std, mean + std, color=f"C{i % 10}", alpha=0.18,
                   label=f"multisine {name}: {mean:.1f}° ± {std:.1f}°")  # fmt: skip
    for i, (name, lo, hi) in enumerate(sines):
        for edge in (lo, hi):
            ax.axvline(edge, color=f"C{i % 10}", ls="--", lw=0.9,
                       label=f"{name}: {lo:.1f}°–{hi:.1f}°" if edge == lo else None)  # fmt: skip
    for direction, color in (("up", "k"), ("down", "tab:red")):
        alpha, cl = sweep.branch(direction)
        label = f"quasi-static, pitch-{direction} ({sweep.rate_deg_s:.2g}°/s)"
        if alpha.size:
            ax.plot(alpha, cl, "-", lw=1.3, color=color, label=label)
    return _finish(fig, ax, path, "α [°]", "C_l", title)


def fig5_bands(
    result: IdentificationResult,
) -> tuple[list[tuple[str, float, float]], list[tuple[str, float, float]]]:
    """Fig. 5's bands: (level, α mean, α std) of every level's periods and (sine, α min, α max)
    of every validation sine, from the result's levels and predictions."""
    levels = [
        (lv.name, float(np.mean(lv.record.data.u)), float(np.std(lv.record.data.u)))
        for lv in result.levels.values()
        if lv.record.data is not None
    ]
    sines = []
    for pred in result.predictions:
        alpha = np.asarray(pred[msg.ALPHA_DEG], dtype=float)
        sines.append((str(pred[msg.NAME]), float(alpha.min()), float(alpha.max())))
    return levels, sines


def plot_scan(scan: Any, path: str | Path, title: str = "PNLSS structure scan") -> Path:
    """Validation error against the number of parameters, one marker per candidate
    (scan.ScanResult); the kept candidate circled, the one-standard-error band shaded."""
    fig = Figure(figsize=(7.0, 4.5))
    ax = fig.add_subplot()
    styles = {"state": ("o", "tab:blue"), "state+output": ("s", "tab:orange")}
    ok = [r for r in scan.rows if r.status == "ok" and np.isfinite(r.validation_error)]
    for equations, (marker, color) in styles.items():
        rows = [r for r in ok if r.equations == equations]
        if rows:
            ax.scatter(
                [r.n_params for r in rows],
                [r.validation_error for r in rows],
                marker=marker,
                color=color,
                label=f"monomials in {equations.replace('+', ' and ')}",
            )
            for r in rows:
                ax.annotate(
                    f"nx={r.nx} d={','.join(map(str, r.degrees))}",
                    (r.n_params, r.validation_error),
                    fontsize=6,
                    xytext=(3, 3),
                    textcoords="offset points",
                )
    if ok:
        best = min(ok, key=lambda r: r.validation_error)
        ax.axhspan(
            best.validation_error,
            best.validation_error + best.validation_se,
            color="0.85",
            label="within one standard error of the best",
        )
        kept = scan.best_row
        ax.scatter(
            [kept.n_params], [kept.validation_error], s=160, facecolors="none",
            edgecolors="k", label="kept (one-standard-error rule)",
        )  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    return _finish(fig, ax, path, "parameters", "validation error (relative RMS)", title)


# --- the report of an identification ------------------------------------------------------------


def write_report(
    result: IdentificationResult,
    out_dir: str | Path,
    quasi_static: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, Path]:
    """The one report of `pipeline.identify`, whatever the source: models.json, the tables
    (Table 1 when there were sines, validation_errors when there were held-out levels; Markdown
    and CSV), data_quality.md, summary.md, clustering.md (with the ablation), the structure
    scan, and the figures of the paper's Figs. 5-9 (PNG; Fig. 5, quasi_static_lift.png, when
    the source measured a quasi-static sweep, whose static curve the C_l–α figures then draw
    unless ``quasi_static`` gives another)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    if result.quasi_static is not None:
        levels, sines = fig5_bands(result)
        written["quasi_static"] = plot_quasi_static(
            result.quasi_static, out / "quasi_static_lift.png", levels, sines
        )
        if quasi_static is None:
            quasi_static = result.quasi_static.static_curve()
    path = out / "models.json"
    path.write_text(json.dumps(result.to_json_dict(), indent=1, allow_nan=True))
    written["models"] = path
    for key, (markdown, csv_text) in result.tables().items():
        (out / f"{key}.md").write_text(markdown)
        (out / f"{key}.csv").write_text(csv_text)
        written[key] = out / f"{key}.md"
    path = out / "data_quality.md"
    path.write_text(data_quality_markdown(result.data_quality))
    written["data_quality"] = path
    path = out / "summary.md"
    path.write_text(summary_markdown(result))
    written["summary"] = path
    if result.scan is not None:
        scan_md = (
            "# PNLSS structure scan (all levels)\n\n"
            "Validation error: relative RMS error on the held-out periods of the estimation "
            f"levels ({result.pnlss_held_out}; docs/design.md §7.6).\n\n"
            + result.scan.to_markdown()
        )
        (out / "pnlss_scan.md").write_text(scan_md)
        (out / "pnlss_scan.csv").write_text(result.scan.to_csv())
        written["pnlss_scan"] = out / "pnlss_scan.md"
        written["pnlss_scan_plot"] = plot_scan(result.scan, out / "pnlss_scan.png")
    for lv in result.levels.values():
        tag = lv.name.replace(" ", "_").replace("/", "_")
        where = (
            f"{lv.name} level ({lv.offset_deg:g}°)"
            if lv.record.offset_deg is not None
            else (f"level {lv.name}")
        )
        if lv.bla is not None:
            written[f"frf_{tag}"] = plot_frf(lv.bla, out / f"frf_{tag}.png", f"BLA, {where}")
            written[f"spectrum_{tag}"] = plot_output_spectrum(
                lv.bla, out / f"output_spectrum_{tag}.png", f"Output spectrum, {where}"
            )
        if lv.clusters is not None and lv.record.data is not None:
            written[f"clusters_{tag}"] = plot_clusters(
                lv.clusters.labels,
                out / f"clusters_{tag}.png",
                y=lv.record.data.y,
                fs=result.fs,
                title=f"Clusters, {where} (k = {lv.clusters.k})",
            )
    if result.clustering_effect:
        path = out / "clustering.md"
        path.write_text(clustering_markdown(result.clustering_effect))
        written["clustering"] = path
    for pred in result.predictions:
        name = pred[msg.NAME]
        tag = name.replace(" ", "_").replace(".", "p")
        alpha = np.asarray(pred[msg.ALPHA_DEG])
        series = {model: np.asarray(v) for model, v in msg.prediction_series(pred)}
        measured = series.pop(msg.MEASURED)
        written[f"cl_alpha_{tag}"] = plot_cl_alpha(
            alpha, measured, out / f"cl_alpha_{tag}.png", series, quasi_static, name
        )
        t = np.arange(len(measured)) / result.fs
        written[f"time_{tag}"] = plot_time_series(
            t, measured, series, out / f"time_{tag}.png", title=name
        )
    return written


def data_quality_markdown(quality: Mapping[str, Any]) -> str:
    """data_quality.md: every plan sample (streams) or every record (files) accounted for."""
    text = ["# Data quality", ""]
    text += [
        f"- {name}: {c['received']} of {c['expected']} plan samples received once, "
        f"{c['missing']} missing, {c['duplicated']} duplicated with another value, "
        f"{c.get('redelivered', 0)} delivered twice with the same value (harmless), "
        f"{c['outside_plan']} outside the plan"
        for name, c in quality.get("samples", {}).items()
    ]
    text += [
        f"- level {r['level']}, `{r['file']}`: {r['samples']} samples "
        f"({r['periods_in_file']} periods × {r['realizations']} realization(s) read"
        + (f", the first {r['dropped_periods']} period(s) dropped as asked" if r["dropped_periods"]
           else "")
        + "), every sample finite"
        for r in quality.get("records", [])
    ]  # fmt: skip
    lines = data_quality_lines(dict(quality))
    text += [
        "",
        "Clean: every plan sample arrived once; no anomaly; nothing excluded."
        if not lines and quality.get("samples")
        else "Clean: every record read whole; nothing excluded."
        if not lines
        else "**Not clean**:",
        *[f"- {line}" for line in lines],
    ]
    return "\n".join(text).rstrip() + "\n"


def summary_markdown(result: IdentificationResult) -> str:
    """summary.md: data, BLA levels, linear orders, PNLSS, validation errors, warnings."""
    lines = ["# Identification summary", "", f"Source: {result.source}", "", "## Levels", ""]
    lines += [
        "| level | role | operating point | input RMS | BLA method | M × P | periods used | "
        "clusters | median \\|G\\| [dB] | median noise σ [dB] | median SNR [dB] | "
        "median NL σ [dB] | linear order | modes [Hz] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for lv in result.levels.values():
        rec = lv.record
        op = "–" if rec.offset_deg is None else f"{rec.offset_deg:g}°"
        row = [lv.name, lv.role, op, f"{rec.input_rms:.4g}"]
        if lv.bla is None:
            row += ["–"] * 10
        else:
            s = bla_summary(lv.bla)
            nl = f"{s['nl_db']:.1f}" if "nl_db" in s else "not separable (M = 1)"
            clusters = "–" if lv.clusters is None else f"k = {lv.clusters.k}"
            order, modes = "–", "–"
            if lv.linear is not None:
                order = f"{lv.linear.order}" + (" (scan)" if lv.order_scanned else "")
                modes = ", ".join(f"{f:.2f}" for f in modal_frequencies(lv.linear)) or "–"
            row += [
                lv.bla.method, f"{lv.bla.M} × {lv.bla.periods_text}", str(lv.periods_used),
                clusters,
                f"{s['G_db']:.1f}", f"{s['noise_db']:.1f}", f"{s['snr_db']:.1f}", nl, order,
                modes,
            ]  # fmt: skip
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "## PNLSS (all levels)", ""]
    m = result.pnlss_all
    if m is not None:
        lines.append(
            f"nx = {m.nx}, degrees {list(m.degrees)}, structure {m.structure}, "
            f"{m.parameters.size} parameters, started from the linear model of level "
            f"{result.pnlss_start_level}; iterate chosen on {result.pnlss_held_out}"
            + (f"; structure chosen by the scan ({result.scan.rule})" if result.scan else "")
            + "."
        )
    else:
        lines.append("not fitted")
    lines += ["", "## B-spline LPV (all levels)", ""]
    lpv = result.lpv_all
    if lpv is not None:
        h = lpv.history_
        lines.append(
            f"{lpv.describe()}; started from the linear model of level "
            f"{result.pnlss_start_level}; kept: {h.get('kept')} (error on the held-out periods "
            f"{h.get('kept_error', float('nan')):.4g}, its linear start "
            f"{h.get('linear_start_error', float('nan')):.4g})"
            + (f"; structure chosen by the scan ({result.lpv_scan.rule})" if result.lpv_scan
               else "")
            + "."
        )  # fmt: skip
    else:
        lines.append("not fitted")
    if result.selection:
        sel = result.selection
        errors = ", ".join(f"{n} {v:.4g}" for n, v in sel["validation_errors"].items())
        lines += ["", "## Selected model", "",
                  f"{sel['class']} ({sel['structure']}): the lower error on the held-out periods "
                  f"({sel['held_out']}): {errors}."]  # fmt: skip
    if result.beddoes_leishman is not None:
        how = (
            "; static curves from the quasi-static sweep (Kirchhoff inversion), time constants "
            "fitted on the estimation sets."
        )
        lines += ["", "## Beddoes-Leishman baseline (all levels)", "",
                  result.beddoes_leishman.describe() + how]  # fmt: skip
    if result.lpv_scan is not None:
        lines += ["", "## B-spline LPV structure scan", "", result.lpv_scan.to_markdown().rstrip()]
    for key, (markdown, _) in result.tables().items():
        title = {
            "table1_all_levels": "Table 1, trained on all levels (relative RMS error on sines)",
            "table1_level1": "Table 1, trained on level 1 (the paper's variant)",
            "table1_floor_ratios": "Table 1 divided by the noise floor (1: as good as the data "
            "allow)",
            "table1_no_clustering": "Table 1, all levels, without clustering",
            "validation_errors": "Validation on held-out levels (relative RMS error)",
            "validation_errors_no_clustering": "Held-out levels, without clustering",
        }.get(key, key)
        lines += ["", f"## {title}", "", markdown.rstrip()]
    if result.warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in result.warnings]
    return "\n".join(lines).rstrip() + "\n"
