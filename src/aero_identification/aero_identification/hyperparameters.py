"""Hyperparameters of the identification pipeline (pipeline.py), declared once.

Each field of :class:`IdentificationConfig` carries its default, description and range
(:func:`hyper`). Everything else is generated from that declaration: the identifier node's
parameters (:func:`config_parameters`, read back by :func:`config_from_parameters`), the
command-line flags (:func:`add_config_arguments`, :func:`config_from_args`) and the JSON form
(:meth:`IdentificationConfig.to_dict`, :meth:`IdentificationConfig.from_dict`). aero_rig's
``config/identifier.yaml`` is tested equal to the defaults (test_hyperparameters.py).

A module of its own, standard library and ``rig_runtime.params`` only, so that the identifier
node can hold the config without loading the numerical stack.
"""

import argparse
import dataclasses
import typing
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rig_runtime.params import Parameter, ParameterError

# Value kinds of the fields, from their annotations: scalars, tuples of scalars (list
# parameters), and tuples of integer tuples (lists of strings "2,3", e.g. degree sets).
_SCALARS: tuple[type, ...] = (bool, int, float, str)


def hyper(
    default: Any,
    description: str,
    *,
    min: float | None = None,
    max: float | None = None,
    choices: Sequence[str] | None = None,
) -> Any:
    """A hyperparameter field: its default, one-line description and range.

    ``min``/``max`` bound every number of the value (the elements of a tuple, the integers of
    a degree set); ``choices`` restrict every string of it.
    """
    return dataclasses.field(
        default=default,
        metadata={
            "description": description,
            "min": min,
            "max": max,
            "choices": None if choices is None else tuple(choices),
        },
    )


@dataclass(frozen=True)
class IdentificationConfig:
    """Hyperparameters of the pipeline (the identifier node's parameters).

    Values are checked on construction (ValueError naming the field); lists are accepted for
    tuples, and degree sets may be written as strings ("2,3").
    """

    nx: int = hyper(
        1,
        "states of the BLA state-space and PNLSS models (paper: 1); 0: chosen per level by the "
        "subspace order scan over 1..max_order",
        min=0,
        max=12,
    )
    max_order: int = hyper(
        12, "highest order of the subspace order scan when nx = 0", min=1, max=30
    )
    degrees: tuple[int, ...] = hyper(
        (2, 3, 4, 5), "PNLSS monomial degrees (paper: 2..5)", min=2, max=7
    )
    structure: str = hyper(
        "full",
        "PNLSS monomials: of states and input (full), of the states only, or of the input only",
        choices=("full", "statesonly", "inputsonly"),
    )
    # The paper used 50 iterations for its order scan.
    max_iter: int = hyper(100, "Levenberg-Marquardt iterations per PNLSS fit", min=0, max=1000)
    pnlss: bool = hyper(True, "fit the PNLSS models (false: clustering, BLA and linear models)")
    # The second nonlinear model class (bspline_lpv.py): a state-space model whose
    # coefficients are cubic B-splines of α, polynomial in the state; trained on the PNLSS's
    # sets, its iterate chosen on the same held-out periods, and (with ``scan``) its structure
    # by the same cross-validation over lpv_scan_intervals × lpv_scan_state_degrees. Table 1's
    # "selected" row is whichever of it and the all-levels PNLSS is lower on the held-out
    # periods. "relative" weighting: each training record by 1 / its output's variance, so the
    # low offset counts as much as the stall (docs/results.md, "The second model class").
    lpv: bool = hyper(True, "fit the B-spline LPV state-space model beside the PNLSS")
    lpv_intervals: int = hyper(
        8, "B-spline LPV: knot intervals over the training angles (single-structure fits)", min=1,
        max=40,
    )  # fmt: skip
    lpv_state_degree: int = hyper(
        3, "B-spline LPV: highest degree of the state monomials (1: linear in the state)", min=1,
        max=5,
    )  # fmt: skip
    lpv_max_iter: int = hyper(60, "B-spline LPV: Levenberg-Marquardt iterations", min=0,
                              max=1000)  # fmt: skip
    lpv_weighting: str = hyper(
        "relative", "B-spline LPV: weights of the training records", choices=("none", "relative")
    )
    lpv_scan_intervals: tuple[int, ...] = hyper(
        (4, 8), "B-spline LPV scan: knot intervals", min=1, max=40
    )
    lpv_scan_state_degrees: tuple[int, ...] = hyper(
        (1, 3), "B-spline LPV scan: highest state monomial degrees", min=1, max=5
    )
    # The semi-empirical baseline (beddoes_leishman.py): a Table 1 row, never a candidate of
    # the selected model; fitted only when the source measured a quasi-static sweep.
    semi_empirical: bool = hyper(
        True,
        "fit the Beddoes-Leishman baseline (static curves from the quasi-static sweep, time "
        "constants on the estimation data)",
    )
    # The estimation sets' held-out realization (estimation_sets.py): it chooses every model's
    # iterate and scores the scans' candidates and the selection; every other one trains.
    validation_realization: int = hyper(
        1,
        "realization whose periods choose the PNLSS iterate (the last one if a level has "
        "fewer); every other realization trains it",
        min=0,
    )
    min_periods: int = hyper(
        2,
        "fewest valid periods a realization needs for its level to be fitted (and to be kept "
        "by the clustering)",
        min=1,
    )
    # Period clustering (clustering.py): the BLA and the models use each level's dominant
    # cluster only. clustering_ablation: the final identification also runs the whole pipeline
    # without clustering (every valid period), for table1_no_clustering and clustering.md.
    clustering: bool = hyper(True, "model each level's dominant cluster of periods only")
    clustering_ablation: bool = hyper(
        True,
        "final identification also without clustering (table1_no_clustering, clustering.md)",
    )
    # How the levels weigh in the all-levels PNLSS cost and in the choice of its iterate:
    # "none": absolute errors (the largest level dominates); "relative": each level's record
    # by 1 / var(its output), the sum of the levels' squared relative errors that Table 1
    # reports; "noise": by 1 / the noise variance of its mean period (the scatter of its kept
    # periods, stall cycle-to-cycle variation included): maximum likelihood under level-
    # dependent noise. Chosen by cross-validation (bench/level_weighting.py; docs/results.md,
    # "Level weighting"): RMS over the levels of the held-out realizations' relative errors on
    # three plant seeds' default campaigns 0.215/0.292/0.163 none, 0.228/0.279/0.165 relative,
    # 0.328/0.580/0.226 noise (best at low and medium, worst at high), so "none" stays.
    level_weighting: str = hyper(
        "none",
        "weights of the levels in the all-levels PNLSS cost",
        choices=("none", "relative", "noise"),
    )
    # Cross-validated structure scan (scan.py) for the final all-levels PNLSS instead of the
    # one structure above: every (nx, degrees, equations) of the grid is fitted from the
    # level-1 BLA's subspace model of that order and scored on the validation realization;
    # the one-standard-error rule keeps the simplest adequate model. Online refits keep the
    # single structure (they must stay fast). Default grid: nx ≤ 2, since an nx = 3 candidate
    # with degrees 2-5 costs 15-30 s alone on two cores (docs/results.md, the scan). Each
    # structure is tried from two LM starts (scan.STARTS).
    scan: bool = hyper(True, "final all-levels PNLSS by the cross-validated structure scan")
    scan_nx: tuple[int, ...] = hyper(
        (1, 2), "scan: state orders (0: the lowest level's linear model order)", min=0, max=12
    )
    scan_degrees: tuple[tuple[int, ...], ...] = hyper(
        ((2,), (2, 3), (2, 3, 4, 5)), "scan: degree sets, e.g. '2,3' (degrees 2..7)", min=2, max=7
    )
    scan_equations: tuple[str, ...] = hyper(
        ("state", "state+output"),
        "scan: where monomials enter",
        choices=("state", "state+output"),
    )
    # The paper's scan: 50 Levenberg–Marquardt iterations.
    scan_max_iter: int = hyper(50, "scan: Levenberg-Marquardt iterations per fit", min=1)
    scan_workers: int = hyper(
        1, "scan: local worker processes (0 = every core, 1 = in this process)", min=0
    )
    scan_scheduler: str = hyper(
        "", "scan: Dask scheduler address, e.g. tcp://HOST:8786 ('' = local processes)"
    )
    # Stability beyond the validated amplitudes (issue 22; docs/design.md §7.6): every scan
    # fit rejects LM iterates whose simulation diverges on the held-out inputs scaled about
    # their mean by this factor, and the scan rejects candidates that diverge or reach no
    # periodic steady state there (the recorded periods and two random-phase periods of the
    # same spectrum, pnlss.stress_periods). It should cover the amplitudes the model will be
    # used at. Measured (docs/results.md, "Selection that extrapolates"): F-16 fitted on levels 1-5,
    # tested on level 7 (1.33× level 5): without the rule every candidate diverged there, with
    # 1.2 the kept one did, with 1.3 and 1.5 each is bounded and the kept one is the best there;
    # the short campaign loses its 3× high-offset target at 1.5 (a 12-parameter candidate is
    # rejected), not at 1.3; on the default campaign 0 and 1.5 keep a 19-parameter model within
    # the spreads of 1.3's 41-parameter one.
    # The single-structure fits (online refits, records without --scan) do not use it.
    scan_stress: float = hyper(
        1.3, "scan: held-out input scale a candidate must stay stable at (0: no check)", min=0.0
    )
    # Cross-fit of the scan (issue 22; scan.py, docs/design.md §7.6): every candidate is fitted
    # on this many (training, held-out) splits, each with another realization of every level
    # held out (one realization per level: another period), and scored by the splits' mean
    # error with the K-fold SE, so that a structure whose fit depends on the realization it saw
    # loses to a simpler one. Capped at the realizations (periods) there are; each split adds
    # the scan's cost once more. Default 1 (one split, the SE the held-out noise only): with 2,
    # the default campaign's Table 1 was worse on each of three plant seeds (docs/results.md,
    # "Cross-fit"), F-16's pick unchanged.
    scan_splits: int = hyper(
        1, "scan: cross-fit splits per candidate (1 = one held-out realization)", min=1
    )
    # Table 1's estimation spread (issues 22, 23; bootstrap.py, docs/design.md §7.7): the final
    # identification refits the level models and the kept PNLSS structure on this many
    # replicates of the estimation periods, drawn with replacement within each realization, and
    # adds each cell's std over them. 0: off. Each replicate costs about one PNLSS fit of the
    # kept structure and one of level 1 (default campaign: about 10 s on 2 cores).
    bootstrap: int = hyper(
        0, "Table 1: bootstrap replicates over the estimation periods (0 = off)", min=0
    )
    # The whole procedure in each replicate (Efron 2014, "Estimation and accuracy after model
    # selection", JASA 109: the bootstrap of a selected model reruns the selection): the
    # structure scan runs again on every replicate, so the spread includes which structure the
    # scan keeps, not only the kept structure's estimation scatter. Costs the scan's time per
    # replicate (default campaign: about 50 s on 2 cores), so it is off by default.
    bootstrap_scan: bool = hyper(
        False, "Table 1's bootstrap: rerun the structure scan in every replicate"
    )

    def __post_init__(self) -> None:
        for spec in _SPECS:
            object.__setattr__(self, spec.name, spec.coerce(getattr(self, spec.name)))

    def to_dict(self) -> dict[str, Any]:
        """Every field by name, JSON-able (tuples as lists, degree sets as lists of ints)."""
        return {spec.name: _jsonable(getattr(self, spec.name)) for spec in _SPECS}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "IdentificationConfig":
        """The config of :meth:`to_dict`'s form; missing keys take their defaults, an unknown
        key or an invalid value raises ValueError (ParameterError) naming it."""
        known = {spec.name for spec in _SPECS}
        unknown = sorted(str(k) for k in values if k not in known)
        if unknown:
            raise ParameterError(
                f"unknown identification parameter(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(sorted(known))}"
            )
        return cls(**dict(values))


@dataclass(frozen=True)
class _Spec:
    """One field of the declaration: name, default, range and value kind."""

    name: str
    default: Any
    description: str
    min: float | None
    max: float | None
    choices: tuple[str, ...] | None
    kind: str  # "scalar", "list" (tuple of scalars) or "sets" (tuple of integer tuples)
    element: type  # the scalar type (of the elements)

    def coerce(self, value: Any) -> Any:
        """``value`` as the field's type (lists as tuples, "2,3" as (2, 3)), checked by the
        runtime's own parameter rule (rig_runtime.params.Parameter.validate); ParameterError
        naming the field when it is not one."""
        if self.kind == "scalar":
            return self._checker().validate(value, SOURCE)
        if not isinstance(value, list | tuple) or not value:
            raise self._error(value, "expected a non-empty list")
        if self.kind == "list":
            return tuple(self._checker().validate(list(value), SOURCE))
        sets = []
        for item in value:
            if isinstance(item, str):
                try:
                    item = parse_degrees(item)
                except ValueError as exc:
                    raise self._error(value, str(exc)) from None
            if not isinstance(item, list | tuple) or not item:
                raise self._error(value, "expected a list of integer sets such as '2,3' or [2, 3]")
            sets.append(tuple(self._checker().validate(list(item), SOURCE)))
        return tuple(sets)

    def _checker(self) -> Parameter:
        """The range check of a value (scalar) or of one list / degree set."""
        return Parameter(
            self.name,
            self.default if self.kind == "scalar" else [self.element()],
            self.description,
            min=self.min,
            max=self.max,
            choices=self.choices,
            element_type=None if self.kind == "scalar" else self.element,
        )

    def _error(self, value: Any, reason: str) -> ParameterError:
        return ParameterError(
            f"identification parameter {self.name!r} = {value!r} is invalid: {reason} — "
            f"{self.description}"
        )

    def parameter(self) -> Parameter:
        """The node parameter: lists for tuples, degree sets as strings "2,3"."""
        if self.kind == "sets":  # the numbers' range is checked by coerce (parse: strings)
            text = [",".join(map(str, s)) for s in self.default]
            return Parameter(self.name, text, self.description, element_type=str)
        return Parameter(
            self.name,
            list(self.default) if self.kind == "list" else self.default,
            self.description,
            min=self.min,
            max=self.max,
            choices=self.choices,
            element_type=self.element if self.kind == "list" else None,
        )


def _read_specs() -> tuple[_Spec, ...]:
    """The declaration: IdentificationConfig's fields, their metadata and annotations."""
    hints = typing.get_type_hints(IdentificationConfig)
    specs = []
    for f in dataclasses.fields(IdentificationConfig):
        kind, element = _kind(f.name, hints[f.name])
        meta = f.metadata
        specs.append(
            _Spec(
                f.name,
                f.default,
                meta["description"],
                meta["min"],
                meta["max"],
                meta["choices"],
                kind,
                element,
            )
        )
    return tuple(specs)


def _kind(name: str, annotation: Any) -> tuple[str, type]:
    if annotation in _SCALARS:
        return "scalar", annotation
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is tuple and len(args) == 2 and args[1] is Ellipsis:
        if args[0] in _SCALARS:
            return "list", args[0]
        if typing.get_args(args[0]) == (int, Ellipsis):
            return "sets", int
    raise TypeError(f"IdentificationConfig.{name}: unsupported annotation {annotation!r}")


_SPECS = _read_specs()
SOURCE = "the identification config"  # where a value came from, in error messages


def _jsonable(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    return value


def config_parameters() -> list[Parameter]:
    """The identifier node's identification parameters, one per field, in declaration order
    (tuples as list parameters; degree sets as strings "2,3")."""
    return [spec.parameter() for spec in _SPECS]


def config_from_parameters(values: Mapping[str, Any]) -> IdentificationConfig:
    """The config from node parameter values (:func:`config_parameters`'s form). Names that
    are not fields (the node's own parameters) are ignored, missing fields take their
    defaults; an invalid value raises ValueError (ParameterError) naming the parameter."""
    return IdentificationConfig(
        **{spec.name: values[spec.name] for spec in _SPECS if spec.name in values}
    )


def _format_default(spec: _Spec) -> str:
    value = spec.default
    if isinstance(value, bool):
        return "true" if value else "false"
    if spec.kind == "list":
        return " ".join(map(str, value))
    if spec.kind == "sets":
        return " ".join(",".join(map(str, s)) for s in value)
    return repr(value) if value == "" else str(value)


def _cli_type(spec: _Spec) -> Any:
    """argparse ``type``: one element, checked against the declaration (argparse reports the
    message); ``coerce`` checks the whole value again in config_from_args."""

    def convert(text: str) -> Any:
        try:
            if spec.kind == "sets":
                value: Any = parse_degrees(text)
                return tuple(spec._checker().validate(list(value), "the command line"))
            value = spec.element(text)
            if spec.kind == "list":
                return spec._checker().validate([value], "the command line")[0]
            return spec._checker().validate(value, "the command line")
        except ValueError as exc:  # ParameterError too
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = spec.name  # argparse's "invalid <name> value" for other errors
    return convert


def add_config_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    only: Iterable[str] | None = None,
) -> None:
    """Add a flag per field (or per field named in ``only``): ``--max-iter N``, ``--degrees 2
    3 4 5``, ``--scan-degrees 2 2,3 2,3,4,5``, ``--clustering/--no-clustering``. Every
    default is None, so :func:`config_from_args` sees only the flags that were given."""
    specs = {spec.name: spec for spec in _SPECS}
    names = list(specs) if only is None else list(only)
    unknown = [n for n in names if n not in specs]
    if unknown:
        raise ValueError(f"not identification parameters: {unknown}; known: {sorted(specs)}")
    for name in names:
        spec = specs[name]
        flag = "--" + name.replace("_", "-")
        text = f"{spec.description} (default {_format_default(spec)})".replace("%", "%%")
        if spec.kind == "scalar" and spec.element is bool:
            parser.add_argument(
                flag, dest=name, action=argparse.BooleanOptionalAction, default=None, help=text
            )
            continue
        options: dict[str, Any] = {"dest": name, "default": None, "help": text}
        options["type"] = _cli_type(spec)
        if spec.kind != "scalar":
            options["nargs"] = "+"
        if spec.choices:
            options["metavar"] = "{" + ",".join(spec.choices) + "}"
        elif spec.kind == "sets":
            options["metavar"] = "D[,D...]"
        elif spec.element is str:
            options["metavar"] = "TEXT"
        else:
            options["metavar"] = "N" if spec.element is int else "X"
        parser.add_argument(flag, **options)


def config_from_args(
    args: argparse.Namespace, base: IdentificationConfig | None = None
) -> tuple[IdentificationConfig, dict[str, Any]]:
    """``base`` (default: the declared defaults) with the flags of :func:`add_config_arguments`
    that were given, and those overrides by name (JSON-able, for the caller to print or
    record). ValueError (ParameterError) naming the parameter when the result is invalid."""
    base = base if base is not None else IdentificationConfig()
    given = {
        spec.name: getattr(args, spec.name)
        for spec in _SPECS
        if getattr(args, spec.name, None) is not None
    }
    config = dataclasses.replace(base, **given)
    return config, {name: _jsonable(getattr(config, name)) for name in given}


def parse_degrees(text: str) -> tuple[int, ...]:
    """A degree set written as a parameter string ("2,3") as a tuple; ValueError when bad."""
    try:
        degrees = tuple(int(part) for part in text.replace(" ", "").split(",") if part)
    except ValueError:
        raise ValueError(
            f"a degree set is integers separated by commas, e.g. '2,3'; got {text!r}"
        ) from None
    if not degrees or min(degrees) < 2:
        raise ValueError(f"PNLSS degrees are integers >= 2, e.g. '2,3'; got {text!r}")
    return degrees
