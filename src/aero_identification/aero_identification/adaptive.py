"""The adaptive experiment's stop and extend rules (docs/design.md §7.9).

After each measured multisine period the identifier judges the level's periods so far and sends
the generator one request (multisine_gen.revision). The rules use only what the identification
estimates anyway; every threshold is a parameter (:class:`AdaptiveRules`).

- **Floor**: a realization keeps at least ``min_periods`` measured periods and a level at least
  ``min_realizations`` realizations (the generator's bounds, in the plan message), so the
  noise and the nonlinear distortions stay separable (the robust BLA's total variance needs
  M >= 2 realizations, Pintelon & Schoukens 2012, §4.3.1).
- **Periods (end the realization)**: the noise variance of the FRF of the realization so far,
  relative to |G|² and averaged over the excited lines, is below ``noise_db``. The robust BLA's
  noise variance of the mean over P periods falls as 1/P (Pintelon & Schoukens 2012, §4.3.1);
  once it is below the threshold a further period adds little that another realization would
  not give too. A split needs at least ``CLUSTER_PERIODS`` (3) periods to show (k-means on
  fewer cannot tell one regime from two, clustering.py): with fewer, a realization whose
  nonlinear distortion at the detection lines (noise taken out) is above ``distortion_db`` goes
  on. Dynamic stall, whose cycle-to-cycle variation the clustering looks for, is a strong
  nonlinearity; a level whose odd and even detection lines hold (almost) only noise has no
  regime to split (odd random-phase multisines, Pintelon & Schoukens 2012, §4.3.2). The
  default campaign's low level shows −32 to −39 dB there after 2 periods, its medium level −8
  to −10 dB and its high level about −7 dB (where its noise is too large for an estimate, the
  noise rule keeps it going anyway). Never below the valid periods of the level's earlier
  realizations: the estimators take the same P from each, so the earlier ones' extra periods
  would be lost; and for the same reason never beyond them: once it has as many it ends, and
  the level's rule below decides whether another realization is needed. Otherwise, while the
  realization's periods split into clusters (the cycle-to-cycle variation of dynamic stall,
  clustering.py), it goes on.
- **Realizations (finish the level, or add one)**, when a realization has ended:
  - BLA convergence: the total variance (noise and stochastic nonlinear distortions, over the
    realizations) relative to |G|² is below ``total_db`` (§4.3.1);
  - clustering: when the clustering splits the level's periods into regimes, its dominant
    cluster holds at least ``min_cluster_periods`` periods (a level in one regime has all its
    periods in it, and the variance rule judges them);
  - model convergence: the error of the level's BLA from the earlier realizations on the newest
    one (relative RMS on the excited lines) improved on the previous such error by no more than
    its own spread (the newest realization's noise level), or there is no previous error yet.
  All three and the floor met: the level is finished after this realization; otherwise another
  realization is added while the budget (``max_realizations``) allows.

Pure functions on PeriodicData; no ROS.
"""

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from rig_runtime.params import Parameter

from .bla import detection_lines, estimate_bla, frf_noise_variance
from .periodic_data import PeriodicData

# clustering.py (scikit-learn) is imported where it is used: the identifier node imports this
# module, and loads it only in an adaptive run (bla.py needs numpy only).

Action = Literal["go_on", "end_realization", "finish_level", "add_realization"]


@dataclass(frozen=True)
class AdaptiveRules:
    """Thresholds of the rules (the identifier's ``adaptive_*`` parameters, PARAMETERS).

    noise_db, total_db: for the low, medium and high levels (AdaptiveRules.at; one value for
    all). The noise threshold is one for every level. The total variance holds the stochastic
    nonlinear distortions too, which only more realizations average out (1/M), and at the high
    offset dynamic stall's cycle-to-cycle variation makes them large: the default campaign's
    two realizations end near −13 dB there, the low level near −37 dB (docs/design.md §7.9).
    At −20 dB the high level would take every realization the budget allows and still not
    converge, so its default is −10 dB and the period clustering decides there.

    distortion_db: the nonlinear distortion (dB of the output, `distortion_db`) beyond which
    a realization of fewer than CLUSTER_PERIODS periods goes on.
    """

    noise_db: tuple[float, ...] = (-20.0,)
    total_db: tuple[float, ...] = (-20.0, -20.0, -10.0)
    min_cluster_periods: int = 8
    distortion_db: float = -20.0

    @staticmethod
    def at(values: tuple[float, ...], rank: int, levels: int) -> float:
        """The threshold of the level of offset rank ``rank`` (0 = lowest) of ``levels``: the
        values are for the low, medium and high levels as campaign_source.level_names names
        them (two levels are low and high), the last one for any level beyond."""
        position = {1: [0], 2: [0, 2]}.get(levels, list(range(levels)))[rank]
        return float(values[min(position, len(values) - 1)])

    @classmethod
    def from_parameters(cls, values: dict[str, Any]) -> "AdaptiveRules":
        return cls(
            tuple(values["adaptive_noise_db"]),
            tuple(values["adaptive_total_db"]),
            int(values["adaptive_min_cluster_periods"]),
            float(values["adaptive_distortion_db"]),
        )


# Periods k-means needs to tell one regime from two (dominant_periods, clustering.py).
CLUSTER_PERIODS = 3

_DEFAULT = AdaptiveRules()
PARAMETERS = [
    Parameter(
        "adaptive",
        False,
        "steer the generator: end realizations and levels that converged, add realizations "
        "where they did not (aero-rig campaign --adaptive)",
    ),
    Parameter(
        "adaptive_noise_db",
        list(_DEFAULT.noise_db),
        "adaptive: a realization ends once its FRF noise variance / |G|^2 is below this [dB], "
        "for the low, medium and high levels",
        element_type=float,
    ),
    Parameter(
        "adaptive_total_db",
        list(_DEFAULT.total_db),
        "adaptive: a level ends once its FRF total variance / |G|^2 is below this [dB], per "
        "the low, medium and high levels",
        element_type=float,
    ),
    Parameter(
        "adaptive_min_cluster_periods",
        _DEFAULT.min_cluster_periods,
        "adaptive: periods a level's dominant cluster must hold before it ends",
        min=1,
    ),
    Parameter(
        "adaptive_distortion_db",
        _DEFAULT.distortion_db,
        f"adaptive: a realization of fewer than {CLUSTER_PERIODS} periods (too few to show a "
        "split into regimes) goes on while its nonlinear distortion at the detection lines, "
        "noise taken out, is above this [dB of the output]",
    ),
]


@dataclass(frozen=True)
class Bounds:
    """The generator's bounds on requests (multisine_gen.revision.Adaptation, from the plan
    message)."""

    min_periods: int = 2
    min_realizations: int = 2
    max_realizations: int = 4

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "Bounds":
        return cls(**values) if values else cls()


@dataclass(frozen=True)
class Verdict:
    """What the rules say about a level after one period: the request and its reason, with the
    figures it was taken on (logged, recorded in the request and in models.json)."""

    action: Action
    reason: str
    figures: dict[str, float] = field(default_factory=dict)


def relative_variance_db(var: np.ndarray, G: np.ndarray) -> float:
    """10·log10 of mean over the excited lines of var / |G|² (the band's relative variance)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.asarray(var, float) / np.abs(G) ** 2
    ratio = ratio[np.isfinite(ratio)]
    if ratio.size == 0:
        return math.inf
    mean = float(np.mean(ratio))
    return 10.0 * math.log10(mean) if mean > 0 else -math.inf


def _excited(data: PeriodicData) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, M) input and output spectra at the excited lines."""
    return data.U[data.excited_lines], data.Y[data.excited_lines]


def noise_db(data: PeriodicData) -> float:
    """Relative noise variance (dB) of the FRF of one realization, the mean over its P >= 2
    periods: the robust estimate with M = 1 (Pintelon & Schoukens 2012, §4.3.1)."""
    U, Y = _excited(data)
    G_mp = Y[:, :, -1:] / U[:, :, -1:]
    return relative_variance_db(frf_noise_variance(G_mp), G_mp.mean(axis=(1, 2)))


def distortion_db(data: PeriodicData) -> float:
    """The nonlinear distortion of the realization so far (M = 1, P >= 2), in dB of its
    output: the larger of the odd and even non-excited lines' mean power |Ȳ|²
    (bla.detection_lines), less the noise variance of the mean over the periods (σ²/P,
    averaged over the band), over the mean power at the excited lines. The paper's §3.3
    distortion levels with the noise taken out (Pintelon & Schoukens 2012, §4.3.1-4.3.2);
    -inf where the detection lines hold noise only."""
    lines = data.excited_lines
    max_line = int(lines.max())
    odd, even = detection_lines(lines, max_line)
    Y = data.Y[: max_line + 1, :, -1:]  # (lines, P, 1) of the newest realization
    Ybar = Y.mean(axis=1)[:, 0]
    # σ²/P of the period mean: the robust BLA's noise variance, here of Y (M = 1).
    noise = float(np.mean(frf_noise_variance(Y[1:])))
    power = max(float(np.mean(np.abs(Ybar[k]) ** 2)) if k.size else 0.0 for k in (odd, even))
    output = float(np.mean(np.abs(Ybar[lines]) ** 2))
    if not (power > noise and output > 0.0):
        return -math.inf
    return 10.0 * math.log10((power - noise) / output)


def dominant_periods(data: PeriodicData) -> tuple[int, np.ndarray]:
    """Periods in the dominant cluster, and the (P, M) mask of them (all when too few)."""
    if data.P * data.M < CLUSTER_PERIODS:
        return data.P * data.M, np.ones((data.P, data.M), dtype=bool)
    from .clustering import period_clusters

    result = period_clusters(data)
    return int(result.sizes[0]), result.keep


def bla_error(earlier: PeriodicData, newest: PeriodicData) -> tuple[float, float]:
    """Relative RMS error of the earlier realizations' BLA on the newest realization's mean
    period, on the excited lines, and its spread (the newest realization's noise level
    relative to its output, the error a perfect model would show)."""
    U0, Y0 = _excited(earlier)
    G = np.mean(Y0 / U0, axis=(1, 2))
    U, Y = _excited(newest)
    Ubar, Ybar = U.mean(axis=1)[:, 0], Y.mean(axis=1)[:, 0]
    scale = float(np.sqrt(np.sum(np.abs(Ybar) ** 2)))
    error = float(np.sqrt(np.sum(np.abs(Ybar - G * Ubar) ** 2))) / scale
    noise = float(np.sum(frf_noise_variance(Y))) if Y.shape[1] > 1 else 0.0  # σ²/P, summed
    return error, float(np.sqrt(noise)) / scale


@dataclass(frozen=True)
class PeriodPosition:
    """Where a judged period stands in its level and in the plan."""

    periods_done: int  # measured periods of this realization so far
    last_period: bool  # the plan ends the realization here
    realization: int  # 0-based
    planned_realizations: int  # realizations the plan has for the level now
    rank: tuple[int, int]  # the level's offset rank (0 = lowest) and the number of levels
    earlier_periods: int = 0  # fewest valid periods among the earlier realizations (0: none)


def judge_period(
    current: PeriodicData,
    level_data: PeriodicData | None,
    position: PeriodPosition,
    rules: AdaptiveRules,
    bounds: Bounds,
    errors: list[float],
) -> Verdict:
    """The verdict after a measured period: on the realization (:func:`judge_realization`)
    until the plan ends it, then on the level (:func:`judge_level`).

    current: the valid periods of this realization so far (M = 1); level_data: every
    realization's valid periods so far (the newest last; the same count per realization;
    None when fewer than two realizations have two valid periods); errors: the level's BLA
    validation errors on its earlier newest realizations (the newest is appended when a
    realization ends).
    """
    noise_limit = rules.at(rules.noise_db, *position.rank)
    total_limit = rules.at(rules.total_db, *position.rank)
    if not position.last_period:
        return judge_realization(current, position, noise_limit, rules, bounds)
    return judge_level(level_data, position, total_limit, rules, bounds, errors)


def judge_realization(
    current: PeriodicData,
    position: PeriodPosition,
    noise_limit: float,
    rules: AdaptiveRules,
    bounds: Bounds,
) -> Verdict:
    """End the realization here, or go on: the floor, the earlier realizations' period count,
    the noise (below ``noise_limit`` dB, the level's threshold), the regimes, and the
    distortion where the periods are too few to show them."""
    figures: dict[str, float] = {}
    periods_done, earlier_periods = position.periods_done, position.earlier_periods
    if periods_done < bounds.min_periods or current.P < 2:
        return Verdict("go_on", f"{periods_done} of at least {bounds.min_periods} periods")
    if current.P < earlier_periods:
        # The nonparametric estimators take the same P from every realization
        # (campaign_source.equal_periods): ending here would discard the earlier realizations'
        # periods.
        return Verdict(
            "go_on",
            f"{current.P} of the {earlier_periods} periods the earlier realizations have",
        )
    figures["noise_db"] = noise_db(current)
    clusters, _ = dominant_periods(current)
    figures["cluster_periods"] = clusters
    if 0 < earlier_periods <= current.P:
        # Further periods would be discarded by the same equal-P rule: the level's
        # realizations decide from here (another one if it has not converged).
        return Verdict(
            "end_realization",
            f"{current.P} periods, as many as the earlier realizations have (noise "
            f"{figures['noise_db']:.1f} dB of |G|²)",
            figures,
        )
    if figures["noise_db"] >= noise_limit:
        return Verdict(
            "go_on",
            f"noise {figures['noise_db']:.1f} dB of |G|² ≥ {noise_limit:g} dB",
            figures,
        )
    if clusters < current.P:
        return Verdict(
            "go_on",
            f"its periods split into regimes (dominant cluster {clusters} of {current.P})",
            figures,
        )
    if current.P < CLUSTER_PERIODS:
        figures["distortion_db"] = distortion_db(current)
        if figures["distortion_db"] > rules.distortion_db:
            return Verdict(
                "go_on",
                f"nonlinear distortion {figures['distortion_db']:.1f} dB of the output > "
                f"{rules.distortion_db:g} dB, and {current.P} periods are too few to "
                f"show a split into regimes (at least {CLUSTER_PERIODS})",
                figures,
            )
    return Verdict(
        "end_realization",
        f"noise {figures['noise_db']:.1f} dB of |G|² < {noise_limit:g} dB after "
        f"{periods_done} periods",
        figures,
    )


def judge_level(
    level_data: PeriodicData | None,
    position: PeriodPosition,
    total_limit: float,
    rules: AdaptiveRules,
    bounds: Bounds,
    errors: list[float],
) -> Verdict:
    """The realization ended: finish the level, add a realization, or go on with the plan
    (BLA convergence: total variance below ``total_limit`` dB, the level's threshold; the
    dominant cluster; the model's convergence; the floor and budget). Appends the newest
    realization's BLA error to ``errors``."""
    figures: dict[str, float] = {}
    done = position.realization + 1
    more = position.planned_realizations - done  # realizations the plan still has for the level
    if level_data is None or level_data.M < 2:
        if done < bounds.min_realizations:
            return Verdict(
                "go_on", f"{done} realization(s): the floor is {bounds.min_realizations}"
            )
        return Verdict("go_on", "too few valid periods to judge the level")
    bla = estimate_bla(level_data, method="robust")
    figures["total_db"] = relative_variance_db(bla.var_total, bla.G)
    figures["noise_db"] = relative_variance_db(bla.var_noise, bla.G)
    size, _ = dominant_periods(level_data)
    split = size < level_data.P * level_data.M
    figures["cluster_periods"] = size
    earlier = level_data.select_realizations(list(range(level_data.M - 1)))
    newest = level_data.select_realizations([level_data.M - 1])
    error, spread = bla_error(earlier, newest)
    figures["bla_error"], figures["bla_error_spread"] = error, spread
    improving = bool(errors) and errors[-1] - error > spread
    errors.append(error)
    problems = []
    if figures["total_db"] >= total_limit:
        problems.append(f"total variance {figures['total_db']:.1f} dB ≥ {total_limit:g} dB")
    if split and size < rules.min_cluster_periods:
        problems.append(
            f"periods split into regimes: dominant cluster {size} < "
            f"{rules.min_cluster_periods} periods"
        )
    if improving:
        problems.append(f"BLA error on the newest realization still improving ({error:.3g})")
    if done < bounds.min_realizations:
        return Verdict("go_on", f"{done} realization(s): the floor is {bounds.min_realizations}")
    if not problems:
        reason = (
            f"converged: total variance {figures['total_db']:.1f} dB, dominant cluster {size}, "
            f"BLA error {error:.3g} (spread {spread:.2g})"
        )
        return Verdict("finish_level" if more > 0 else "go_on", reason, figures)
    if more > 0:
        return Verdict("go_on", "; ".join(problems), figures)
    if done >= bounds.max_realizations:
        return Verdict(
            "go_on",
            "; ".join(problems) + f"; the budget ({bounds.max_realizations}) is spent",
            figures,
        )
    return Verdict("add_realization", "; ".join(problems), figures)
