"""Clustering of periods: find the dominant flow regime before modelling.

Dynamic stall varies from cycle to cycle, so periods of the same excitation can belong to
different flow regimes. As in the paper (§3.4), the periods are grouped by k-means without prior
physical information or user interaction, and only the dominant (largest) cluster is used for
the BLA and the models. The number of clusters comes from the data (silhouette, Rousseeuw 1987),
including the answer "one cluster" when the periods are homogeneous.
"""

from dataclasses import dataclass

import numpy as np
from sklearn.cluster import KMeans
from sklearn.metrics import silhouette_score

from aero_identification.data import PeriodicData


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


def period_features(data: PeriodicData) -> np.ndarray:
    """Feature vector of every period: its output waveform minus its realization's median period.

    A period's output waveform y[:, p, m] is the natural feature (the paper clusters periods in
    the time domain, §3.4), but another phase realization has another waveform, so raw
    waveforms would split the realizations rather than the flow regimes. Subtracting, per
    realization, the sample-wise median over its periods removes the realization: periods of the
    realization's majority regime sit near zero in every realization, periods of another regime
    stand out by their difference. (A realization wholly in another regime is not detected this
    way; the BLA's var_nl then shows it as a large spread between realizations.)

    The features are divided by one common scale, not z-scored per sample: z-scoring would lift
    the noise-only samples to the same weight as the samples where the regimes differ.

    Returns:
        (P·M, N) array, rows ordered as (p, m) in C order (row p·M + m).
    """
    deviation = data.y - np.median(data.y, axis=1, keepdims=True)
    X = deviation.transpose(1, 2, 0).reshape(data.P * data.M, data.N)
    scale = np.sqrt(np.mean(X**2))
    return X / scale if scale > 0 else X


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
    X = period_features(data)
    n = X.shape[0]
    # Exact rotation onto the (at most n − 1) principal directions: same distances, far fewer
    # columns for k-means than the N samples of a waveform.
    _, s, Vt = np.linalg.svd(X, full_matrices=False)
    rank = int(np.sum(s > s[0] * 1e-12)) if s.size and s[0] > 0 else 0
    if n_components is not None:
        rank = min(rank, n_components)
    Z = X @ Vt[:rank].T if rank else np.zeros((n, 1))
    silhouettes: dict[int, float] = {}
    best_labels = np.zeros(n, dtype=np.int64)
    best_k, best_s = 1, -np.inf
    if rank > 0:
        for k in range(2, min(kmax, n - 1) + 1):
            km = KMeans(n_clusters=k, n_init=n_init, random_state=random_state).fit(Z)
            if np.unique(km.labels_).size < k:
                continue  # fewer distinct points than clusters
            sil = float(silhouette_score(Z, km.labels_))
            silhouettes[k] = sil
            if sil > best_s:
                best_k, best_s, best_labels = k, sil, km.labels_
    if best_s < min_silhouette:
        best_k, best_labels = 1, np.zeros(n, dtype=np.int64)
    labels = _relabel_by_size(Z, best_labels, best_k)
    sizes = np.bincount(labels, minlength=best_k)
    labels_pm = labels.reshape(data.P, data.M)
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
