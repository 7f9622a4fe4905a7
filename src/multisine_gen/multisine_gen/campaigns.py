"""Campaign presets: the paper's campaign (`default_plan`), its small version for tests
(`short_plan`), and the designer both use (`build_plan`), each returning an ExperimentPlan."""

import math

import numpy as np

from multisine_gen.crest import reduce_crest_factor
from multisine_gen.multisine import (
    ExcitationError,
    design_line_grid,
    random_phase_multisine,
)
from multisine_gen.plan import (
    BaselineSweep,
    ExperimentPlan,
    MultisineLevel,
    PlanError,
    SineTest,
)
from multisine_gen.sine import design_sine
from rig_runtime.interface import ActuatorLimits

__all__ = ["build_plan", "default_plan", "derived_seed", "short_plan"]


def derived_seed(seed: int, *key: int) -> int:
    """A 32-bit seed for one random part, stable when other parts are added or removed."""
    return int(np.random.SeedSequence(seed, spawn_key=key).generate_state(1)[0])


def build_plan(
    *,
    fs: float = 200.0,
    N: int = 10_000,
    f_min_hz: float = 0.02,
    f_max_hz: float = 1.98,
    group_size: int = 4,
    offsets_deg: tuple[float, ...] = (6.6, 15.7, 19.9),
    std_deg: float = 2.4,
    realizations: int = 2,
    periods: int = 6,
    settle_periods: int = 1,
    crest_factor_reduction: bool = False,
    sine_frequencies_hz: tuple[float, ...] = (0.4, 1.0, 1.6),
    sine_amplitude_deg: float = 4.7,
    sine_offsets_deg: tuple[float, ...] = (5.9, 15.1, 19.3),
    sine_min_periods: int = 10,
    sine_min_duration_s: float = 20.0,
    sine_settle_s: float = 2.0,
    baseline: BaselineSweep | None = None,
    rest_deg: float = 0.0,
    ramp_rate_deg_s: float = 5.0,
    seed: int | None = 0,
    limits: ActuatorLimits | None = None,
) -> ExperimentPlan:
    """Design a campaign: multisine levels at `offsets_deg` (level i), M = `realizations` odd
    random-phase realizations each on one shared line grid, and sines at `sine_offsets_deg[i]`
    (level i) for every frequency, each with max(sine_min_periods, ⌈sine_min_duration_s·f⌉)
    measured periods after ⌈sine_settle_s·f⌉ (≥ 1) settling periods.

    seed: int for a reproducible plan; None draws fresh entropy (recorded in plan.seed).
    Design errors come back as PlanError naming the level / sine concerned.
    """
    entropy = np.random.SeedSequence(seed).entropy
    assert isinstance(entropy, int)
    try:
        grid = design_line_grid(
            fs, N, f_min_hz, f_max_hz, "odd_random", group_size, derived_seed(entropy, 0)
        )
    except ExcitationError as error:
        raise PlanError(f"multisine levels: {error}") from error
    levels = []
    for i, offset in enumerate(offsets_deg):
        realization_list = []
        for m in range(realizations):
            try:
                ms = random_phase_multisine(grid, std_deg, offset, derived_seed(entropy, 1, i, m))
                if crest_factor_reduction:
                    ms = reduce_crest_factor(ms)
            except ExcitationError as error:
                raise PlanError(
                    f"multisine level {i} (offset {offset:g}°), realization {m}: {error}"
                ) from error
            realization_list.append(ms)
        levels.append(
            MultisineLevel(
                i, tuple(realization_list), periods=periods, settle_periods=settle_periods
            )
        )
    sines = []
    for i, offset in enumerate(sine_offsets_deg):
        for f in sine_frequencies_hz:
            try:
                sine = design_sine(fs, f, sine_amplitude_deg, offset)
            except ExcitationError as error:
                raise PlanError(
                    f"sine level {i} (offset {offset:g}°), {f:g} Hz: {error}"
                ) from error
            f_fit = sine.frequency_hz
            n_periods = max(sine_min_periods, math.ceil(sine_min_duration_s * f_fit - 1e-9))
            n_settle = max(1, math.ceil(sine_settle_s * f_fit - 1e-9))
            sines.append(SineTest(i, sine, periods=n_periods, settle_periods=n_settle))
    return ExperimentPlan(
        fs=float(fs),
        rest_deg=float(rest_deg),
        ramp_rate_deg_s=float(ramp_rate_deg_s),
        baseline=baseline,
        levels=tuple(levels),
        sines=tuple(sines),
        seed=entropy,
        limits=limits if limits is not None else ActuatorLimits(),
    )


def default_plan(
    seed: int | None = 0,
    *,
    include_baseline: bool = True,
    crest_factor_reduction: bool = False,
    limits: ActuatorLimits | None = None,
) -> ExperimentPlan:
    """The paper's campaign (§3.2): baseline sweep 0.52 °/s up to 30° and back; odd
    random-phase multisines 0.02–1.98 Hz, fs 200 Hz, N 10,000 (50 s periods), 2.4° std at
    offsets 6.6°, 15.7°, 19.9°, M = 2 realizations × (1 settling + P = 6) periods; sines 0.4,
    1.0, 1.6 Hz of 4.7° at 5.9°, 15.1°, 19.3° (≥ 10 periods and ≥ 20 s, after ≥ 2 s settling);
    ramps at 5 °/s from and back to rest at 0°. About 41 minutes."""
    return build_plan(
        baseline=BaselineSweep(peak_deg=30.0, rate_deg_s=0.52) if include_baseline else None,
        crest_factor_reduction=crest_factor_reduction,
        seed=seed,
        limits=limits,
    )


def short_plan(
    seed: int | None = 0,
    *,
    crest_factor_reduction: bool = False,
    limits: ActuatorLimits | None = None,
) -> ExperimentPlan:
    """The default plan's structure, small enough for tests: N = 2,000 (10 s periods, 0.1 Hz
    resolution), band 0.1–1.98 Hz, levels 6.6° and 19.9° (2.4° std), M = 2 realizations × (1
    settling + P = 4) periods; sines at 1.0 and 1.6 Hz of 4.7° at 5.9° and 19.3°, 5 periods
    after 1 settling period; no baseline; ramps at 10 °/s. About 3.8 minutes of experiment.

    P = 4 rather than 3: at the high level a period deviates from the period mean by ≈ 40-50% of
    the output's standard deviation (stochastic stall), and a PNLSS model trained on the mean of
    3 periods now and then fits that variation instead of the dynamics (simulated plant, 14
    seeds: the worst PNLSS model error on long 19.3° sine records fell from > 7 to 0.45)."""
    return build_plan(
        N=2_000,
        f_min_hz=0.1,
        f_max_hz=1.98,
        offsets_deg=(6.6, 19.9),
        realizations=2,
        periods=4,
        settle_periods=1,
        crest_factor_reduction=crest_factor_reduction,
        sine_frequencies_hz=(1.0, 1.6),
        sine_offsets_deg=(5.9, 19.3),
        sine_min_periods=5,
        sine_min_duration_s=0.0,
        sine_settle_s=0.0,
        baseline=None,
        ramp_rate_deg_s=10.0,
        seed=seed,
        limits=limits,
    )
