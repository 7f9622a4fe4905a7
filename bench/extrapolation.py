"""Benchmark: does the structure scan's pick extrapolate above the amplitudes it was chosen on?

    .venv/bin/python bench/extrapolation.py              # F-16 GVT data from $F16_GVT_DIR
    .venv/bin/python bench/extrapolation.py --stress 0   # without the stability check

Issue 22's F-16 check, on real measured data (docs/real_data.md; kept out of the repo:
``$F16_GVT_DIR``, default ``../shared/data/f16-gvt``):

- estimation levels 1, 3 and 5 (12, 37 and 74 N RMS); the scan trains on the mean of each
  level's periods but the last and selects on the last period of each (the pipeline's split
  for one realization per level, estimation_sets.estimation_sets);
- candidates: nx = the level-1 linear order (subspace order scan), statesonly monomials of
  degree 3 or 2–3, in the state equation or in both, each from the linear and the
  output-equation start (the campaign's scan grid on these data), 20 LM iterations;
- test: level 7 (98 N RMS), above the range: every candidate's relative RMS error there.

Target: the kept candidate's level-7 error within 10 % of the best candidate's. Prints the scan
table with each candidate's level-7 error and the rule's text. Last line: JSON.
"""

import json
import math
import os
import time
from pathlib import Path

from aero_identification.hyperparameters import IdentificationConfig
from aero_identification.pipeline import identify
from aero_identification.records import read_records, records_dataset
from aero_identification.validation import record_error

HERE = Path(__file__).resolve().parent


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stress", type=float, default=1.3,
                        help="config.scan_stress (default 1.3; 0: off)")  # fmt: skip
    parser.add_argument("--splits", type=int, default=1,
                        help="config.scan_splits (default 1; 2: the cross-fit)")  # fmt: skip
    args = parser.parse_args()
    directory = os.environ.get("F16_GVT_DIR", str(HERE.parent.parent / "shared/data/f16-gvt"))
    patterns = [f"*Level{k}.csv" for k in (1, 3, 5, 7)]
    records = read_records(directory, "csv", "Force", "Acceleration2", 8192, patterns=patterns,
                           drop_periods=1)  # fmt: skip
    dataset = records_dataset(records, source=directory)
    config = IdentificationConfig(
        nx=0, structure="statesonly", degrees=(3,), max_iter=20, scan=True, scan_nx=(0,),
        scan_degrees=((3,), (2, 3)), scan_equations=("state", "state+output"), scan_max_iter=20,
        clustering_ablation=False, scan_stress=args.stress, scan_splits=args.splits,
    )  # fmt: skip
    t0 = time.perf_counter()
    result = identify(dataset, config, final=True, held_out=("7",), log=print)
    seconds = time.perf_counter() - t0
    scan = result.scan
    if scan is None:
        raise SystemExit(f"no structure scan ran: {result.warnings}")
    level7 = result.levels["7"].record.data
    assert level7 is not None
    test = [math.nan if m is None else record_error(m, level7, centred=False) for m in scan.models]
    finite = [e for e in test if math.isfinite(e)]
    best = min(finite) if finite else math.inf
    kept = test[scan.best_index]
    print("| nx | degrees | equations | start | parameters | validation | SE | status | "
          "level 7 |\n|---|---|---|---|---|---|---|---|---|")  # fmt: skip
    for i, (row, e7) in enumerate(zip(scan.rows, test, strict=True)):
        mark = " **kept**" if i == scan.best_index else ""
        print(f"| {row.nx} | {','.join(map(str, row.degrees))} | {row.equations} | {row.start} "
              f"| {row.n_params} | {row.validation_error:.4f} | {row.validation_se:.4f} "
              f"({' / '.join(f'{e:.4f}' for e in row.split_errors)}) "
              f"| {row.status} | {e7:.4f}{mark} |")  # fmt: skip
    print(scan.rule)
    ratio = kept / best if math.isfinite(best) else math.nan
    print(f"kept candidate's level-7 error {kept:.4f}, best candidate's {best:.4f}: "
          f"{100 * (ratio - 1):.1f} % above ({'within' if ratio <= 1.10 else 'OVER'} the 10 % "
          f"target); identification {seconds:.1f} s")  # fmt: skip
    print(json.dumps({
        "scan_stress": args.stress, "scan_splits": args.splits, "kept_level7": kept,
        "best_level7": best, "ratio": ratio, "seconds": seconds,
        "rows": [{**r.as_dict(), "level7": e} for r, e in zip(scan.rows, test, strict=True)],
    }))  # fmt: skip


if __name__ == "__main__":
    main()
