"""The models against what the data allow: a campaign bag's final identification (the
parameters recorded in the bag, as `aero-rig fit BAG`), each all-levels Table 1 cell over its
sine's noise floor, and the targets of issue 59.

    .venv/bin/python bench/models.py BAG [--out DIR]

Prints, per model row of the all-levels Table 1 (PNLSS, B-spline LPV, selected,
Beddoes-Leishman, the own level's BLA SS), its cells and their ratio to the noise floor, the
selection (class, structure, held-out errors) and each stage's fit time; then the targets:

- ``selected_within_1p25_floor``: the selected model within 1.25 × the floor in every cell;
- ``selected_not_worse_than_own_bla_ss``: in no cell worse than the level's own BLA SS by more
  than that cell's ± (the BLA SS's spread over the sine's periods).

Last line: JSON {"cells": {...}, "floor": {...}, "ratios": {...}, "selection": {...},
"timings_s": {...}, "targets": {...}}.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

from aero_identification.pipeline import identify
from aero_identification.report import write_report
from aero_identification.report_tables import FLOOR_ROW
from aero_rig.offline import read_campaign_bag, recorded_config

ROWS = ("BLA SS", "PNLSS", "B-spline LPV", "selected", "Beddoes-Leishman")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", help="a campaign's bag/ directory")
    parser.add_argument("--out", default=None, help="also write the report here")
    args = parser.parse_args()
    from aero_identification.campaign_source import campaign_dataset

    data = read_campaign_bag(args.bag)
    config = recorded_config(data)
    dataset = campaign_dataset(data.assembler, final=True, min_periods=config.min_periods,
                               source=f"bag {args.bag}")  # fmt: skip
    t0 = time.perf_counter()
    result = identify(dataset, config, final=True)
    seconds = time.perf_counter() - t0
    if args.out:
        write_report(result, Path(args.out))
    cells: dict[str, dict[str, float]] = {}
    spreads: dict[str, dict[str, float]] = {}
    for (model, level, f), error in result.errors_all.items():
        if model in ROWS:
            cells.setdefault(model, {})[f"{level} {f:g} Hz"] = error
            spreads.setdefault(model, {})[f"{level} {f:g} Hz"] = result.spreads_all.get(
                (model, level, f), math.nan
            )
    floor = {f"{lv} {f:g} Hz": v for (lv, f), v in result.noise_floor.items()}
    ratios = {
        model: {c: v / floor[c] for c, v in row.items() if floor.get(c)}
        for model, row in cells.items()
    }
    for model in ROWS:
        if model not in cells:
            continue
        line = "  ".join(f"{c}: {v:.3f} ({ratios[model].get(c, math.nan):.2f}×)"
                         for c, v in cells[model].items())  # fmt: skip
        print(f"{model:18s} {line}")
    print(f"{FLOOR_ROW:18s} " + "  ".join(f"{c}: {v:.3f}" for c, v in floor.items()))
    print(f"selection: {json.dumps(result.selection)}")
    selected, own = cells.get("selected", {}), cells.get("BLA SS", {})
    within = bool(selected) and all(ratios["selected"].get(c, math.inf) <= 1.25 for c in floor)
    not_worse = bool(selected) and all(
        selected[c] <= own[c] + spreads["BLA SS"].get(c, 0.0) for c in own if c in selected
    )
    targets = {
        "selected_within_1p25_floor": within,
        "cells_over_1p25_floor": sorted(
            c for c, r in ratios.get("selected", {}).items() if r > 1.25
        ),
        "selected_not_worse_than_own_bla_ss": not_worse,
        "cells_worse_than_own_bla_ss": sorted(
            c for c in own if c in selected and selected[c] > own[c] + spreads["BLA SS"][c]
        ),
    }
    print(f"targets: {targets}")
    timings = {**{k: round(v, 2) for k, v in result.timings_s.items()},
               "identify": round(seconds, 2)}  # fmt: skip
    print(json.dumps({"cells": cells, "floor": floor, "ratios": ratios,
                      "selection": result.selection, "timings_s": timings,
                      "targets": targets}))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
