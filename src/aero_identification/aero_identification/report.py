"""Reports of an identification run: the paper's Table 1 and its figures (Figs. 6–9).

Figures use matplotlib's object-oriented API on an Agg canvas (no pyplot, no screen, no global
backend switch), so they can be written from nodes and tests alike.
"""

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from aero_identification.bla import BLA

TABLE1_MODELS = ("BLA FRF", "BLA SS", "PNLSS")


def _column_name(level: str, freq: float) -> str:
    return f"{level} {freq:g} Hz"


def table1(
    errors: Mapping[tuple[str, str, float], float],
    levels: Sequence[str],
    freqs: Sequence[float],
    models: Sequence[str] = TABLE1_MODELS,
    digits: int = 2,
) -> tuple[str, str]:
    """The paper's Table 1: relative RMS errors, rows = models, columns = levels × frequencies.

    Args:
        errors: {(model, level, freq_hz): relative RMS error}; missing cells are left blank
            ("–" in Markdown, empty in CSV).
        levels: excitation levels in column order, e.g. ["low", "medium", "high"].
        freqs: sine frequencies [Hz] in column order within each level, e.g. [0.4, 1.0, 1.6].
        models: row order.
        digits: decimals in the Markdown table (the CSV keeps full precision).

    Returns:
        (markdown, csv_text). Columns: "model", then "<level> <freq> Hz" for each level, and
        each frequency within it.

    Raises:
        ValueError: for a key whose model, level or frequency is not in the layout (a typo
            would otherwise drop a result silently).
    """
    freqs_arr = np.asarray(freqs, dtype=float)
    cells: dict[tuple[str, str, int], float] = {}
    for (model, level, freq), value in errors.items():
        match = np.flatnonzero(np.isclose(freqs_arr, float(freq), rtol=1e-9, atol=1e-12))
        if model not in models or level not in levels or match.size != 1:
            raise ValueError(
                f"result key {(model, level, freq)} is not in the table layout (models "
                f"{list(models)}, levels {list(levels)}, freqs {list(freqs)})"
            )
        cells[(model, level, int(match[0]))] = float(value)
    header = ["model"] + [_column_name(lv, f) for lv in levels for f in freqs_arr]
    rows_md: list[list[str]] = []
    rows_csv: list[list[str]] = []
    for model in models:
        md, cs = [model], [model]
        for level in levels:
            for i in range(freqs_arr.size):
                cell = cells.get((model, level, i))
                md.append("–" if cell is None else f"{cell:.{digits}f}")
                cs.append("" if cell is None else repr(cell))
        rows_md.append(md)
        rows_csv.append(cs)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows_md]
    markdown = "\n".join(lines) + "\n"
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows_csv)
    return markdown, buffer.getvalue()


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
    ax_mag.set_title(f"{title} (M={bla.M}, P={bla.P}, {bla.method})")
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
        ax.plot(t, y_sim, lw=1.0, label=name)
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
        ax.plot(alpha_deg, cl, lw=1.0, label=name)
    return _finish(fig, ax, path, "α [°]", "C_l", title)


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


def clustering_markdown(effect: Mapping[str, Any]) -> str:
    """clustering.md: what the period clustering changed, per level (pipeline.clustering_effect)."""

    def num(value: Any, fmt: str) -> str:
        return "–" if value is None or not np.isfinite(value) else format(value, fmt)

    lines = [
        "# What the period clustering changed",
        "",
        "The same pipeline with clustering (each level's dominant cluster) and without it (every",
        "valid period; `table1_no_clustering.md`). BLA figures near 1.02 Hz as in the paper's",
        "§3.3 (SNR, SNLR: |G|² against the noise and nonlinear variance of the BLA estimate);",
        "var_nl, var_noise: mean over the excited lines of the nonlinear variance of one",
        "realization's FRF and the noise variance of one period's FRF, relative to |G|² (so BLAs",
        "from different numbers of periods compare); PNLSS (all levels): relative RMS",
        "error on the validation realization's dominant-cluster periods (both models on the same",
        "periods).",
        "",
        "| level | k | sizes | periods used (with / without) | SNR dB (with / without) "
        "| SNLR dB | var_nl dB | var_noise dB | PNLSS validation error |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, e in effect.items():
        w, wo = e.get("bla_with", {}), e.get("bla_without", {})

        def pair(
            key: str, fmt: str = ".1f", a: Mapping[str, Any] = w, b: Mapping[str, Any] = wo
        ) -> str:
            return f"{num(a.get(key), fmt)} / {num(b.get(key), fmt)}"

        sizes = e.get("sizes")
        lines.append(
            f"| {name} | {e.get('k', '–')} | {sizes if sizes is not None else '–'} "
            f"| {e.get('periods_used')} / {e.get('periods_used_without')} "
            f"| {pair('snr_db')} | {pair('snlr_db')} | {pair('var_nl_db')} "
            f"| {pair('var_noise_db')} "
            f"| {num(e.get('pnlss_validation_with'), '.3f')} / "
            f"{num(e.get('pnlss_validation_without'), '.3f')} |"
        )
    return "\n".join(lines) + "\n"
