"""``aero-rig fit SOURCE``: the identification pipeline on a recorded bag or on measured
multisine records (CSV/MAT), one report for both.

    aero-rig fit BAG [--estimation L...] [--validation L...] [identification flags] [--out DIR]
    aero-rig fit FILE|DIR --format csv|mat --input COL --output COL --period N [--fs HZ]
                 [--levels PATTERN...] [--drop-periods K] [--realizations M] [--band F1 F2] ...

The source adapter (a bag: aero_rig.offline and aero_identification.campaign_source; records:
aero_identification.records) yields a Dataset; aero_identification.pipeline.identify runs on
it with the parameters below and aero_identification.report.write_report writes the report.
The identification flags are generated from the one declaration of the parameters
(aero_identification.hyperparameters); those given on the command line are printed as overrides.
"""

import argparse
import sys
from pathlib import Path
from typing import Any

from aero_identification.hyperparameters import (
    IdentificationConfig,
    add_config_arguments,
    config_from_args,
)
from aero_identification.quality import data_quality_lines

from .common import EXIT_NOT_CLEAN, EXIT_OK, EXIT_USAGE

# Records carry no recorded parameters and no sines; where the identifier's defaults (a
# one-state model of a pitching wing, the final structure scan) do not fit an arbitrary
# measured system, records start from these instead (then the user's flags apply):
RECORD_DEFAULTS: dict[str, Any] = {
    "nx": 0,  # the linear order from the subspace order scan, per level
    "scan": False,  # one PNLSS structure unless --scan
    "scan_nx": (0,),  # with --scan: at the linear model's order
}

FIT_DESCRIPTION = """\
The source is a rosbag2 recording of a campaign (without --format), or measured periodic
multisine data (--format csv|mat): one file per level, each M realizations x P periods of N
samples of one input and one output. CSV: a header row, one sample per row, the realizations
one after another; MAT (v5/v7 and v7.3): vectors of M*P*N samples, (T, M) samples x
realizations, or (N, P, M) arrays.

Both go through the one pipeline and get the same report: per level the period clustering, the
BLA with its noise level (and, with M >= 2, the nonlinear distortion level; with M = 1 the LPM)
and a linear state-space model; one PNLSS model over the estimation levels (or the structure
scan's choice); Table 1 on the sine records (bags) and the errors on held-out levels
(--validation); the same pipeline without clustering; data_quality.md, summary.md, figures.

Parameters: a bag is fitted with the identifier's parameters recorded in it (its
/identification/model messages; the defaults for a bag without them); records start from the
defaults with nx 0 (order scan) and --no-scan. Flags override either, and are printed. Bad
input (a column not in the file, a record that is not whole periods, NaN or empty cells,
conflicting sampling frequencies, a bad parameter) stops with exit code 2 and names it; a bag
that lost or excluded data exits 3 unless --allow-excluded. A PNLSS setting whose
Levenberg-Marquardt Jacobian would exceed 1 GB is refused with a warning (the rest of the
report is written).

example (F-16 ground vibration test, docs/real_data.md; about 25 s on 2 cores):
  aero-rig fit DIR --format csv --input Force --output Acceleration2 --period 8192 \\
      --estimation 1 3 5 7 --validation 2 4 6 --drop-periods 1 \\
      --structure statesonly --degrees 3 --max-iter 20 --out runs/f16
"""


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "fit",
        help="identify a recorded bag or measured multisine records (CSV/MAT)",
        description=FIT_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "source",
        metavar="BAG|FILE|DIR",
        help="rosbag2 directory; with --format: one record file (one level) or a directory of "
        "them (one level per file)",
    )
    p.add_argument(
        "--out",
        default=None,
        help="report directory (default: <bag>/../offline_fit; for records <source>/../fit_<name>)",
    )
    p.add_argument(
        "--allow-excluded",
        action="store_true",
        help="exit 0 even if data were lost or excluded (they are still listed)",
    )
    p.add_argument(
        "--estimation",
        nargs="+",
        metavar="LEVEL",
        help="levels to fit (names such as 'low' or '3', plan level numbers, file stems or "
        "globs); default: every level not in --validation",
    )
    p.add_argument(
        "--validation",
        nargs="+",
        metavar="LEVEL",
        help="held-out levels, kept out of every fit and used only for validation errors "
        "(validation_errors.md|csv); default: none",
    )
    add_config_arguments(p.add_argument_group("identification parameters (hyperparameters.py)"))
    _add_record_options(p)
    p.set_defaults(func=main)


def _add_record_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("measured records (with --format)")
    g.add_argument(
        "--format",
        choices=("csv", "mat"),
        default=None,
        help="read measured records instead of a bag: csv (header row, one sample per row) or "
        "mat (Matlab v5/v7 via scipy, v7.3 via h5py)",
    )
    g.add_argument("--input", metavar="COL", help="input column (CSV) or variable (MAT) name")
    g.add_argument("--output", metavar="COL", help="output column (CSV) or variable (MAT) name")
    g.add_argument(
        "--fs",
        type=float,
        metavar="HZ",
        help="sampling frequency [Hz]; default: the file's 'fs' column (CSV, any case, "
        "non-empty cells must agree) or scalar variable fs/Fs/FS (MAT); if both are given "
        "they must agree",
    )
    g.add_argument(
        "--period",
        type=int,
        metavar="N",
        help="samples per period of the multisine (required); each record must hold a whole "
        "number of periods",
    )
    g.add_argument(
        "--levels",
        nargs="+",
        metavar="PATTERN",
        help="with a directory: glob patterns of the level files (default *.csv or *.mat). A "
        "level is named k when its file stem contains 'Level<k>', else by the stem",
    )
    g.add_argument(
        "--drop-periods",
        type=int,
        metavar="K",
        help="drop the first K periods of every realization (a start-up transient); nothing "
        "is dropped unless asked, and the drop is reported. A transient the fit detects is "
        "only reported",
    )
    g.add_argument(
        "--realizations",
        type=int,
        metavar="M",
        help="number of consecutive realizations in a record stored as one column/vector "
        "(default 1)",
    )
    g.add_argument(
        "--band",
        type=float,
        nargs=2,
        metavar=("FMIN", "FMAX"),
        help="restrict the excited-line detection to FMIN ... FMAX Hz (default: every bin "
        "within 20 dB of the median strong input line)",
    )


RECORD_OPTIONS = ("input", "output", "fs", "period", "levels", "drop_periods", "realizations",
                  "band")  # fmt: skip


def _say(message: str) -> None:
    print(f"aero-rig fit: {message}", file=sys.stderr)


def main(args: argparse.Namespace) -> int:
    if args.format is None:
        used = [f"--{o.replace('_', '-')}" for o in RECORD_OPTIONS if getattr(args, o)]
        if used:
            _say(
                f"{', '.join(used)} apply to measured records; add --format csv|mat (without "
                "--format the source is a bag)"
            )
            return EXIT_USAGE
    try:
        loaded = _load_bag(args) if args.format is None else _load_records(args)
    except ValueError as exc:  # BagError, RecordError, bad selections and parameters
        _say(str(exc))
        return EXIT_USAGE
    dataset, held_out, config, out, warnings = loaded
    from aero_identification.pipeline import identify
    from aero_identification.report import write_report

    result = identify(dataset, config, final=True, held_out=held_out, log=_say)
    result.warnings[:0] = warnings
    write_report(result, out)
    return _print_result(result, out, args.allow_excluded)


def _overrides(args: argparse.Namespace, base: IdentificationConfig, where: str) -> Any:
    config, given = config_from_args(args, base)
    shown = ", ".join(f"{k}={v}" for k, v in given.items()) or "none"
    _say(f"parameters: {where}; command-line overrides: {shown}")
    return config


def _load_bag(args: argparse.Namespace) -> Any:
    from aero_identification.campaign_source import campaign_dataset
    from aero_identification.dataset import select_levels

    from ..offline import read_campaign_bag, recorded_config

    data = read_campaign_bag(args.source)
    base = recorded_config(data)
    where = (
        "as recorded with the run (/identification/model in the bag)"
        if data.recorded_config is not None
        else "the identifier's defaults (the bag holds no /identification/model)"
    )
    config = _overrides(args, base, where)
    print(f"{data.messages} samples read from {args.source}")
    print("realizations in the bag (valid periods / periods):")
    for (level, m), block in sorted(data.assembler.blocks.items()):
        valid = int(block.period_valid().sum())
        state = "complete" if valid == block.P else ("incomplete" if valid else "none")
        print(f"  level {level} realization {m}: {valid}/{block.P} ({state})")
    dataset = campaign_dataset(
        data.assembler, final=True, min_periods=config.min_periods, source=f"bag {args.source}"
    )
    dataset, held_out = select_levels(dataset, args.estimation, args.validation)
    out = Path(args.out) if args.out else Path(args.source).resolve().parent / "offline_fit"
    return dataset, held_out, config, out, data.warnings


def _load_records(args: argparse.Namespace) -> Any:
    from aero_identification.dataset import select_levels
    from aero_identification.records import read_records, records_dataset

    missing = [f"--{o}" for o in ("input", "output", "period") if getattr(args, o) is None]
    if missing:
        raise ValueError(f"--format {args.format} needs {', '.join(missing)}")
    base = IdentificationConfig.from_dict(RECORD_DEFAULTS)
    config = _overrides(args, base, "the defaults for records (nx 0: order scan; no scan)")
    source = Path(args.source)
    records = read_records(
        source, args.format, args.input, args.output, args.period, args.fs,
        patterns=args.levels, realizations=args.realizations or 1,
        drop_periods=args.drop_periods or 0, band=tuple(args.band) if args.band else None,
    )  # fmt: skip
    for rec in records:
        where = rec.path.name if rec.path is not None else rec.name
        _say(f"level {rec.name} <- {where}: " + "; ".join(rec.notes))
    dataset, held_out = select_levels(
        records_dataset(records, source=str(source)), args.estimation, args.validation
    )
    out = Path(args.out) if args.out else source.resolve().parent / f"fit_{source.stem}"
    return dataset, held_out, config, out, []


TITLES = {
    "table1_all_levels": "Table 1, trained on all levels (estimation: one realization per level):",
    "table1_level1": "Table 1, trained on level 1 only (the paper's variant):",
    "table1_floor_ratios": "Table 1 divided by each sine's noise floor (1: as good as the data "
    "allow):",
    "table1_no_clustering": "Table 1, trained on all levels, without clustering (every valid "
    "period):",
    "validation_errors": "Validation on held-out levels (relative RMS error "
    "rms(y - yhat)/rms(y - mean y)):",
    "validation_errors_no_clustering": "Held-out levels, without clustering:",
}


def _print_result(result: Any, out: Path, allow_excluded: bool) -> int:
    if result.scan is not None:
        print(f"PNLSS structure scan ({result.scan.workers}, {result.scan.seconds:.1f} s):")
        print(result.scan.to_markdown())
    for warning in result.warnings:
        _say(f"warning: {warning}")
    estimation = [n for n, lv in result.levels.items() if lv.role == "estimation"]
    held = [n for n, lv in result.levels.items() if lv.role != "estimation"]
    print(f"estimation levels {estimation}, held-out levels {held}")
    for key, (markdown, _) in result.tables().items():
        print(f"\n{TITLES.get(key, key)}")
        print(markdown)
    print(f"report: {out.resolve()}  (summary.md, models.json, data_quality.md, tables, *.png)")
    problems = data_quality_lines(result.data_quality)
    if problems:
        print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); the tables use only what was left:")
        for line in problems[:40]:
            print(f"  - {line}")
        if not allow_excluded:
            _say("the source lost or excluded data (above); exit code 3. Pass --allow-excluded "
                 "to accept it.")  # fmt: skip
            return EXIT_NOT_CLEAN
    return EXIT_OK
