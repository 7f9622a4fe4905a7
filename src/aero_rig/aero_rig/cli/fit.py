"""``aero-rig fit``: offline fit of a recorded bag, or of measured multisine records (CSV/MAT).

    aero-rig fit BAG [--out DIR] [--scan|--no-scan] [--scheduler ADDRESS]
    aero-rig fit FILE|DIR --format csv|mat --input COL --output COL --period N [--fs HZ] ...

A bag runs the identifier's pipeline (aero_rig.offline); records run the level-by-level fit
(aero_identification.level_fit), with ``--scan`` on a Dask client (``--scheduler``).
"""

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from aero_identification.quality import data_quality_lines

from .common import EXIT_NOT_CLEAN, EXIT_OK, EXIT_USAGE

FIT_DESCRIPTION = """\
Without --format the source is a rosbag2 recording of a campaign (the identifier's pipeline).

With --format csv|mat the source is measured periodic multisine data: one file per level, each
M realizations x P periods of N samples of one input and one output. CSV: a header row, one
sample per row, the realizations one after another; MAT (v5/v7 and v7.3): vectors of M*P*N
samples, (T, M) samples x realizations, or (N, P, M) arrays. Per level: the BLA with its noise
level (and, with M >= 2, the nonlinear distortion level), a linear state-space model of it; one
PNLSS model over the estimation levels; validation errors on the held-out levels. Bad input
(a column not in the file, a record that is not whole periods, NaN or empty cells, conflicting
sampling frequencies) stops with exit code 2 and names the file and column. The PNLSS default
(the identifier's: full structure, degrees 2-5) is refused above a 1 GB Jacobian (a warning;
the rest of the report is written): choose a smaller setting for high orders, as below.

example (F-16 ground vibration test, docs/real_data.md; 25 s on 2 cores):
  aero-rig fit DIR --format csv --input Force --output Acceleration2 --period 8192 \\
      --estimation 1 3 5 7 --validation 2 4 6 --drop-periods 1 \\
      --pnlss-structure statesonly --pnlss-degrees 3 --pnlss-iter 20 --out runs/f16
"""


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "fit",
        help="offline fit of a recorded bag, or of measured multisine records (CSV/MAT)",
        description=FIT_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "bag",
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
        help="bags only: exit 0 even if data were lost or excluded (they are still listed)",
    )
    p.add_argument(
        "--scan",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="choose the PNLSS structure by the cross-validated scan (docs/design.md §7.6). "
        "Bags: on by default, as the identifier (config/identifier.yaml: nx 1-2, degrees 2 | "
        "2,3 | 2..5, monomials in the state or in state and output); --no-scan fits the one "
        "structure. Records: off by default; --scan scans at the linear order, degree sets "
        "2..D for each --pnlss-degrees D (default 2 3), both equation sets. Report: "
        "pnlss_scan.md|csv|png",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="with --scan: run the fits on this Dask scheduler (e.g. tcp://HOST:8786, started "
        "with `dask scheduler` and `dask worker`); default: a local cluster, one worker "
        "process per core",
    )
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
        "--estimation",
        nargs="+",
        metavar="LEVEL",
        help="levels to fit (level names, file stems or globs); default: every level not in "
        "--validation",
    )
    g.add_argument(
        "--validation",
        nargs="+",
        metavar="LEVEL",
        help="held-out levels, used only for the validation errors; default: every level not "
        "in --estimation",
    )
    g.add_argument(
        "--nx",
        type=int,
        metavar="N",
        help="order of the linear models (and the PNLSS); default: chosen per level by the "
        "subspace order scan (MDL-type penalty) over 1 ... --max-order",
    )
    g.add_argument(
        "--max-order",
        type=int,
        default=12,
        metavar="N",
        help="highest order of the order scan without --nx (default 12)",
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
    g.add_argument("--no-pnlss", action="store_true", help="skip the PNLSS model")
    g.add_argument(
        "--pnlss-degrees",
        type=int,
        nargs="+",
        metavar="D",
        help="PNLSS monomial degrees (each >= 2; default 2 3 4 5, the identifier's)",
    )
    g.add_argument(
        "--pnlss-structure",
        choices=("full", "statesonly", "inputsonly"),
        help="monomials of states and input (full, default), of the states only, or of the "
        "input only (cheapest)",
    )
    g.add_argument(
        "--pnlss-iter",
        type=int,
        metavar="K",
        help="Levenberg-Marquardt iterations of the PNLSS fit (default 100)",
    )


def main(args: argparse.Namespace) -> int:
    if args.format is not None:
        return fit_records(args)
    used = [opt for opt, value in _record_options(args).items() if value]
    if used:
        print(
            f"aero-rig fit: {', '.join(used)} apply to measured records; add --format csv|mat "
            "(without --format the source is a bag)",
            file=sys.stderr,
        )
        return EXIT_USAGE
    from aero_identification.config import IdentificationConfig

    from ..offline import BagError, fit_bag

    out = Path(args.out) if args.out else Path(args.bag).resolve().parent / "offline_fit"
    config = IdentificationConfig(scan_scheduler=args.scheduler or "")
    if args.scan is not None:
        config = replace(config, scan=args.scan)
    try:
        result, data = fit_bag(args.bag, out, config)
    except BagError as exc:
        print(f"aero-rig fit: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if result.scan is not None:
        print(f"PNLSS structure scan ({result.scan.workers}, {result.scan.seconds:.1f} s):")
        print(result.scan.to_markdown())
    for warning in result.warnings:
        print(f"aero-rig fit: warning: {warning}", file=sys.stderr)
    tables = result.tables()
    print(f"{data.messages} samples read from {args.bag}")
    print("realizations in the bag (valid periods / periods):")
    for (level, m), block in sorted(data.assembler.blocks.items()):
        valid = int(block.period_valid().sum())
        state = "complete" if valid == block.P else ("incomplete" if valid else "none")
        print(f"  level {level} realization {m}: {valid}/{block.P} ({state})")
    print("\nTable 1, trained on all levels:")
    print(tables["all_levels"][0])
    print("\nTable 1, trained on level 1 only:")
    print(tables["level1"][0])
    if "no_clustering" in tables:
        print("\nTable 1, trained on all levels, without clustering (every valid period):")
        print(tables["no_clustering"][0])
    print(f"\nreport: {out.resolve()}")
    problems = data_quality_lines(result.data_quality)
    if problems:
        print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); Table 1 uses only what was left:")
        for line in problems[:40]:
            print(f"  - {line}")
        if not args.allow_excluded:
            print(
                "aero-rig fit: the bag lost or excluded data (above); exit code 3. Pass "
                "--allow-excluded to accept it.",
                file=sys.stderr,
            )
            return EXIT_NOT_CLEAN
    return EXIT_OK


def _record_options(args: argparse.Namespace) -> dict[str, Any]:
    return {
        "--input": args.input,
        "--output": args.output,
        "--fs": args.fs,
        "--period": args.period,
        "--levels": args.levels,
        "--estimation": args.estimation,
        "--validation": args.validation,
        "--nx": args.nx,
        "--drop-periods": args.drop_periods,
        "--realizations": args.realizations,
        "--band": args.band,
        "--no-pnlss": args.no_pnlss,
        "--pnlss-degrees": args.pnlss_degrees,
        "--pnlss-structure": args.pnlss_structure,
        "--pnlss-iter": args.pnlss_iter,
    }


def fit_records(args: argparse.Namespace) -> int:
    """``aero-rig fit FILE|DIR --format csv|mat``: measured multisine records, level by level."""
    from aero_identification.level_fit import error_table, identify_levels, write_level_report
    from aero_identification.records import read_records

    missing = [o for o, v in (("--input", args.input), ("--output", args.output),
                              ("--period", args.period)) if v is None]  # fmt: skip
    if missing:
        print(f"aero-rig fit: --format {args.format} needs {', '.join(missing)}", file=sys.stderr)
        return EXIT_USAGE
    if args.allow_excluded:
        print("aero-rig fit: --allow-excluded applies to bags only", file=sys.stderr)
        return EXIT_USAGE
    source = Path(args.bag)
    out = Path(args.out) if args.out else source.resolve().parent / f"fit_{source.stem}"
    options: dict[str, Any] = {}
    if args.pnlss_degrees:
        options["degrees"] = tuple(args.pnlss_degrees)
    if args.pnlss_structure:
        options["structure"] = args.pnlss_structure
    if args.pnlss_iter is not None:
        options["max_iter"] = args.pnlss_iter
    nonlinear = _record_scan(args)

    def log(message: str) -> None:
        print(f"aero-rig fit: {message}", file=sys.stderr)

    try:
        records = read_records(
            source, args.format, args.input, args.output, args.period, args.fs,
            patterns=args.levels, realizations=args.realizations or 1,
            drop_periods=args.drop_periods or 0,
            band=tuple(args.band) if args.band else None,
        )  # fmt: skip
        for rec in records:
            log(f"level {rec.name} <- {rec.path.name}: " + "; ".join(rec.notes))
        result = identify_levels(
            records, args.estimation, args.validation, nx=args.nx,
            max_order=args.max_order, pnlss=not args.no_pnlss, pnlss_options=options, log=log,
            **({"fit_nonlinear": nonlinear} if nonlinear is not None else {}),
        )  # fmt: skip
    except ValueError as exc:  # RecordError and bad selections are ValueErrors
        print(f"aero-rig fit: {exc}", file=sys.stderr)
        return EXIT_USAGE
    write_level_report(result, out)
    for warning in result.warnings:
        print(f"aero-rig fit: warning: {warning}", file=sys.stderr)
    print(f"estimation levels {result.estimation}, validation levels {result.validation}")
    print("\nValidation on held-out levels (relative RMS error rms(y - yhat)/rms(y - mean y)):")
    print(error_table(result)[0])
    print(f"report: {out.resolve()}  (summary.md, validation_errors.md|csv, models.json, *.png)")
    return EXIT_OK


def _record_scan(args: argparse.Namespace) -> Any:
    """``--scan`` for measured records: the structure scan at the linear order (ScanFit)."""
    if not args.scan:
        return None
    from aero_identification.level_fit import ScanFit

    client = None
    if args.scheduler:
        from dask.distributed import Client

        client = Client(args.scheduler, timeout="30s")
    return ScanFit(
        degrees=[
            (d,) if d == 2 else tuple(range(2, d + 1)) for d in (args.pnlss_degrees or [2, 3])
        ],
        structure=args.pnlss_structure or "full",
        max_iter=args.pnlss_iter or 50,
        client=client,
    )
