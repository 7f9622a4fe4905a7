"""Clustering of periods: find the dominant flow regime before modelling.

Dynamic stall varies from cycle to cycle, so periods of the same excitation can belong to
different flow regimes. As in the paper (§3.4), the periods are grouped by k-means without prior
physical information or user interaction, and only the dominant (largest) cluster is used for
the BLA and the models. The number of clusters comes from the data (silhouette, Rousseeuw 1987),
including the answer "one cluster" when the periods are homogeneous or differ only by
independent cycle-to-cycle events. The features are each period's lift curve C_l(α)
(`period_features`).
"""

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.cluster import KMeans
from sklearn.metrics import silhouette_score

from aero_identification.bla import weak_lines
from aero_identification.periodic_data import PeriodicData


@dataclass(frozen=True, eq=False)
class ClusterResult:
    """Cluster assignment of the periods of a PeriodicData.

    Labels are renumbered by decreasing cluster size, so label 0 is the dominant cluster (ties:
    the cluster whose periods are closest to their centre, then the earliest period).

    Attributes:
        labels: (P, M) int cluster label of each period, 0 … k-1.
        keep: (P, M) bool, True for the periods of the dominant cluster (accepted by
            `PeriodicData.select`).
        k: number of clusters chosen (1 when the periods are homogeneous).
        silhouette: mean silhouette coefficient for each tried k (k = 2 … kmax); empty when
            there were too few periods to try any.
        sizes: (k,) number of periods per label.
        dominant: label of the kept cluster (always 0, stated for readers of status messages).
        period_index: (P, M) original period index of each period (from the data).
        realization_index: (M,) original realization index (from the data).
    """

    labels: np.ndarray
    keep: np.ndarray
    k: int
    silhouette: dict[int, float]
    sizes: np.ndarray
    dominant: int
    period_index: np.ndarray
    realization_index: np.ndarray


FEATURE_BINS = 20  # equal-count angle-of-attack bins of the lift-curve features


def _lift_curves(data: PeriodicData, values: np.ndarray, bins: int) -> np.ndarray:
    """(P, M, bins) mean of `values` (N, P, M) in each of `bins` equal-count bins of the input
    (edges: quantiles of the input over all periods and realizations)."""
    if bins < 2:
        raise ValueError(f"bins must be >= 2; got {bins}")
    edges = np.quantile(data.u, np.linspace(0.0, 1.0, bins + 1)[1:-1])
    # One bincount over all periods: sample (n, p, m) goes to slot (p·M + m)·bins + its bin.
    period = np.arange(data.P * data.M).reshape(data.P, data.M)
    slot = (np.searchsorted(edges, data.u, side="right") + bins * period).ravel()
    size = data.P * data.M * bins
    counts = np.bincount(slot, minlength=size).reshape(data.P, data.M, bins)
    sums = np.bincount(slot, weights=values.ravel(), minlength=size).reshape(counts.shape)
    with np.errstate(invalid="ignore"):
        curves = sums / counts  # NaN in a bin a period never visits
    # A bin a period never visits takes its realization's mean there (or zero deviation).
    if np.isnan(curves).any():
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # bins no period visits
            fill = np.nanmean(curves, axis=0, keepdims=True)
        curves = np.nan_to_num(np.where(np.isnan(curves), fill, curves))
    return curves


def _scaled(X: np.ndarray) -> np.ndarray:
    """Features divided by one common scale (not z-scored per bin: bins where nothing differs
    keep a small weight)."""
    scale = np.sqrt(np.mean(X**2))
    return X / scale if scale > 0 else X


def period_features(
    data: PeriodicData, bins: int = FEATURE_BINS, reference: np.ndarray | None = None
) -> np.ndarray:
    """Feature vector of every period: its lift curve C_l(α) minus its realization's reference
    curve, the median lift curve of the realization's `reference` periods.

    A period's lift curve is the mean output in each of `bins` equal-count bins of the input
    (bin edges: quantiles of the input over all periods and realizations). The periods of a
    level all sweep the same angles, so a flow regime shows up in the same bins in every
    realization: a regime with less stall (the simulated wing's light-stall regime) lifts the
    high-α bins, whichever phase realization is running. Each bin averages N/bins samples, so
    the independent cycle-to-cycle events of one regime (a stall that comes a little earlier or
    later) average out while a regime that lasts a large part of the period does not.

    The features were the period's output waveform minus its realization's median period
    before (the paper's §3.4 clusters in the time domain). Measured on the simulated wing with
    stall-type regimes (docs/plant.md §2; the default plan through `aero_rig.simulation`, plant
    seeds 0, 1 and 4, each with light-stall periods at 19.9°), the waveform features gave a best
    silhouette of 0.33-0.45, below the 0.5 of structure, so the regimes went undetected: the
    same regime deviates differently under another phase realization, and the stall events that
    differ at random between periods spread over all N samples. The lift-curve features give
    0.62-0.72 on the same data, with the light-stall periods in the minority clusters, and stay
    below 0.5 at 6.6° and 15.7° (0.84 on the default campaign's high level).

    A reference curve per realization is subtracted because the lift curve of a multisine also
    depends on its phase realization (dynamics, hysteresis). The reference must be the same
    regime in every realization, or a regime that is the majority in one realization and the
    minority in another ends up in the dominant cluster of both (`common_regime` gives such
    periods; default: every period, each realization's median).

    Args:
        data: periodic records (N, P, M).
        bins: angle-of-attack bins.
        reference: (P, M) bool, the periods whose median lift curve is their realization's
            reference; a realization without any takes all its periods.

    Returns:
        (P·M, bins) array, rows ordered as (p, m) in C order (row p·M + m).
    """
    curves = _lift_curves(data, data.y, bins)
    refs = []
    for m in range(data.M):
        rows = reference[:, m] if reference is not None else np.ones(data.P, dtype=bool)
        refs.append(np.median(curves[rows if rows.any() else slice(None), m, :], axis=0))
    deviation = curves - np.stack(refs)[None, :, :]
    return _scaled(deviation.reshape(data.P * data.M, bins))


def residual_features(data: PeriodicData, bins: int = FEATURE_BINS) -> np.ndarray:
    """Features that need no reference per realization: each period's lift curve of what the
    level's best linear approximation leaves unexplained, minus the median over all periods.

    The residual is y − ŷ with ŷ = G_BLA·U at the excited lines and the mean output of the level
    at DC (G_BLA: the mean of Y/U over every period and realization, Pintelon & Schoukens 2012
    §3.4), so the linear dynamics, which differ between phase realizations, are taken out by
    one model for all of them. A regime shifts the residual's lift curve (the level of C_l, the
    high-α bins) in every realization alike. What is left of the realization in it (the
    nonlinear distortion, which depends on the phases) can still split the periods by
    realization; `common_regime` therefore never accepts such a split.

    Returns:
        (P·M, bins) array, rows ordered as (p, m) in C order (row p·M + m).
    """
    U, Y = data.U, data.Y  # (N//2+1, P, M), unitary scaling
    # Lines the input does not excite in every period carry no estimate of G (their ratio
    # would be noise over nothing): they are left to the residual.
    lines = data.excited_lines[~weak_lines(np.abs(U[data.excited_lines]))]
    Y_hat = np.zeros_like(Y)
    Y_hat[lines] = np.mean(Y[lines] / U[lines], axis=(1, 2))[:, None, None] * U[lines]
    Y_hat[0] = np.mean(Y[0])
    residual = data.y - np.fft.irfft(Y_hat, n=data.N, axis=0) * np.sqrt(data.N)
    curves = _lift_curves(data, residual, bins).reshape(data.P * data.M, bins)
    return _scaled(curves - np.median(curves, axis=0))


def common_regime(
    data: PeriodicData,
    kmax: int = 6,
    min_silhouette: float = 0.5,
    random_state: int = 0,
    n_init: int = 10,
) -> np.ndarray:
    """(P, M) bool: the periods of the regime that every realization shares, for the reference
    curves of `period_features`.

    k-means on `residual_features`, k chosen by the silhouette as in `period_clusters`, among the
    k whose dominant cluster holds periods of every realization: a dominant cluster of one
    realization cannot be told from that realization's own signature. Every period when no k
    qualifies or the level has one realization.

    Why: with each realization's median as its reference, a level whose regimes are the
    majority of different realizations (plant seed 1 of the default campaign: realization 0 in
    light stall for 4 of its 6 periods at 19.9°, realization 1 in deep stall for 5) kept light
    stall from one realization and deep stall from the other as one "dominant" cluster, and the
    PNLSS was trained on one regime and validated on the other (validation error 0.9, high-offset
    sines 0.85-0.93 against the BLA SS's 0.49-0.56). On the default plan simulated with plant
    seeds 0-23 (`aero_rig.simulation`, light-stall truth per period), the high level's kept
    periods mixed the two regimes for seeds 1, 8 and 11 before, and for none with these
    references; the low and medium levels cluster exactly as before (docs/design.md §7.3).
    """
    everything = np.ones((data.P, data.M), dtype=bool)
    if data.M < 2:
        return everything
    Z = _principal_coordinates(residual_features(data), None)
    realization = np.tile(np.arange(data.M), data.P)  # of row p·M + m
    silhouettes, k, labels = _best_kmeans(Z, kmax, n_init, random_state, realization)
    if silhouettes.get(k, -np.inf) < min_silhouette:
        return everything
    return (labels == 0).reshape(data.P, data.M)


def period_clusters(
    data: PeriodicData,
    kmax: int = 6,
    min_silhouette: float = 0.5,
    random_state: int = 0,
    n_init: int = 10,
    n_components: int | None = None,
) -> ClusterResult:
    """Cluster the periods with k-means and choose k from the data.

    k = 2 … min(kmax, P·M − 1) are tried (scikit-learn KMeans, `n_init` restarts, fixed
    `random_state`, so the result is deterministic); the k with the highest mean silhouette
    wins. One cluster is returned instead when even that silhouette is below `min_silhouette`:
    k-means always splits data, also homogeneous data, and the silhouette then measures whether
    the split is real — its between-cluster separation relative to the within-cluster spread.
    Below 0.5 the structure is "weak and could be artificial" (Kaufman & Rousseeuw 1990,
    Finding Groups in Data, §2.2), which is what noise-only differences between periods give.

    Args:
        data: periodic records (N, P, M).
        kmax: largest number of clusters tried.
        min_silhouette: least mean silhouette for accepting more than one cluster.
        random_state, n_init: KMeans seed and number of restarts (n_init >= 10).
        n_components: keep only this many principal components of the features (PCA); default
            all, an exact rotation that changes no distance.

    Returns:
        ClusterResult.
    """
    if kmax < 2:
        raise ValueError(f"kmax must be >= 2; got {kmax}")
    if n_init < 10:
        raise ValueError(f"n_init must be >= 10 restarts for a stable k-means; got {n_init}")
    if not 0.0 < min_silhouette < 1.0:
        raise ValueError(f"min_silhouette must lie in (0, 1); got {min_silhouette}")
    if n_components is not None and n_components < 1:
        raise ValueError(f"n_components must be >= 1 or None; got {n_components}")
    reference = common_regime(data, kmax, min_silhouette, random_state, n_init)
    X = period_features(data, reference=reference)
    n = X.shape[0]
    Z = _principal_coordinates(X, n_components)
    silhouettes, best_k, best_labels = _best_kmeans(Z, kmax, n_init, random_state)
    if silhouettes.get(best_k, -np.inf) < min_silhouette:
        best_k, best_labels = 1, np.zeros(n, dtype=np.int64)
    sizes = np.bincount(best_labels, minlength=best_k)
    labels_pm = best_labels.reshape(data.P, data.M)
    return ClusterResult(
        labels=labels_pm,
        keep=labels_pm == 0,
        k=best_k,
        silhouette=silhouettes,
        sizes=sizes,
        dominant=0,
        period_index=data.period_index.copy(),
        realization_index=data.realization_index.copy(),
    )


def _principal_coordinates(X: np.ndarray, n_components: int | None) -> np.ndarray:
    """Exact rotation onto the (at most n − 1) principal directions (the same distances), cut
    to `n_components` if given."""
    _, s, Vt = np.linalg.svd(X, full_matrices=False)
    rank = int(np.sum(s > s[0] * 1e-12)) if s.size and s[0] > 0 else 0
    if n_components is not None:
        rank = min(rank, n_components)
    return X @ Vt[:rank].T if rank else np.zeros((X.shape[0], 1))


def _best_kmeans(
    Z: np.ndarray,
    kmax: int,
    n_init: int,
    random_state: int,
    realization: np.ndarray | None = None,
) -> tuple[dict[int, float], int, np.ndarray]:
    """k-means for k = 2 … min(kmax, n − 1): (silhouette per k, best k, its labels numbered by
    `_relabel_by_size`); best k is 1 with all-zero labels when no k could be tried. With
    `realization` (of each row), only a k whose dominant cluster holds every realization can be
    best (`common_regime`)."""
    n = Z.shape[0]
    silhouettes: dict[int, float] = {}
    best_k, best_s, best_labels = 1, -np.inf, np.zeros(n, dtype=np.int64)
    if not np.any(Z):
        return silhouettes, best_k, best_labels
    for k in range(2, min(kmax, n - 1) + 1):
        km = KMeans(n_clusters=k, n_init=n_init, random_state=random_state).fit(Z)
        if np.unique(km.labels_).size < k:
            continue  # fewer distinct points than clusters
        sil = float(silhouette_score(Z, km.labels_))
        labels = _relabel_by_size(Z, km.labels_, k)
        if (
            realization is not None
            and np.unique(realization[labels == 0]).size < np.unique(realization).size
        ):
            continue  # the dominant cluster misses a realization
        silhouettes[k] = sil
        if sil > best_s:
            best_k, best_s, best_labels = k, sil, labels
    return silhouettes, best_k, best_labels


def _relabel_by_size(Z: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """Renumber clusters: largest first; ties by tighter spread, then earliest member."""
    keys = []
    for c in range(k):
        members = np.flatnonzero(labels == c)
        spread = float(np.mean(np.sum((Z[members] - Z[members].mean(axis=0)) ** 2, axis=1)))
        keys.append((-members.size, spread, int(members[0]), c))
    order = [key[-1] for key in sorted(keys)]
    new = np.empty(k, dtype=np.int64)
    new[order] = np.arange(k)
    return new[labels]


def cluster_periods(
    data: PeriodicData,
    kmax: int = 6,
    min_silhouette: float = 0.5,
    random_state: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Cluster the periods; return (labels, keep), both (P, M).

    labels: int cluster label per period, 0 = dominant cluster. keep: boolean mask of the
    dominant cluster, ready for `data.select(keep)`. See `period_clusters` for the method and
    for the richer ClusterResult.
    """
    result = period_clusters(
        data, kmax=kmax, min_silhouette=min_silhouette, random_state=random_state
    )
    return result.labels, result.keep
