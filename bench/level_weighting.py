"""Benchmark: which level weighting of the all-levels PNLSS cross-validates better?

    .venv/bin/python bench/level_weighting.py BAG [BAG ...] [--weightings none relative noise]

For each campaign bag (e.g. ``runs/<date-time>/bag`` of ``make campaign``), the final
identification's all-levels PNLSS (the structure scan with the bag's recorded parameters,
without the clustering ablation) is fitted once per ``level_weighting``: "none" (the default:
the cost is the absolute error, the levels count by their output variance), "relative"
(each level's records weighted by 1 / var(its output)) and "noise" (by 1 / the noise
variance of its mean period: the maximum-likelihood weighting). All are judged on one criterion,
the held-out multisine realization of each level, as Table 1 judges the sines: the relative
RMS error per level (scan.periodic_error) and the RMS of the three. The weighting is chosen by
that cross-validation, never by the sines (issue 22, item 5); the sines' PNLSS row is printed
beside it for the record.

Last line: JSON {bag: {weighting: {"validation": [...], "validation_rms": x, "sines": [...],
"kept": "..."}}}.
"""

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

from aero_identification.campaign_source import campaign_dataset
from aero_identification.estimation_sets import estimation_sets
from aero_identification.pipeline import identify
from aero_identification.scan import periodic_error
from aero_rig.offline import read_campaign_bag, recorded_config

WEIGHTINGS = ("none", "relative", "noise")


def judge(bag: Path, weightings: list[str]) -> dict[str, Any]:
    data = read_campaign_bag(bag)
    base = recorded_config(data)
    out: dict[str, Any] = {}
    for weighting in weightings:
        config = dataclasses.replace(base, level_weighting=weighting, clustering_ablation=False)
        dataset = campaign_dataset(data.assembler, final=True, min_periods=config.min_periods,
                                   source=f"bag {bag}")  # fmt: skip
        result = identify(dataset, config, final=True)
        model = result.pnlss_all
        if model is None:
            out[weighting] = {"error": "; ".join(result.warnings)}
            continue
        _, held, _ = estimation_sets(list(result.levels.values()), config)
        assert held is not None
        per_level = []
        for k in range(held.M):  # one held-out realization per level, the levels along M
            per_level.append(round(periodic_error(model, held.select_realizations([k]))[0], 4))
        rows = result.to_json_dict()["errors"]["all_levels"]
        row = result.scan.best_row if result.scan is not None else None
        out[weighting] = {
            "validation": per_level,
            "validation_rms": round(math.sqrt(sum(e * e for e in per_level) / len(per_level)), 4),
            "sines": [round(r[3], 3) for r in rows if r[0] == "PNLSS"],
            "kept": (f"nx {row.nx}, degrees {list(row.degrees)}, {row.equations}, "
                     f"{row.n_params} parameters") if row else "single structure",
        }  # fmt: skip
        print(f"{bag} {weighting}: validation per level {per_level} (RMS "
              f"{out[weighting]['validation_rms']}), kept {out[weighting]['kept']}; PNLSS on "
              f"the sines {out[weighting]['sines']}", flush=True)  # fmt: skip
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bags", nargs="+", type=Path, help="rosbag2 directories of campaigns")
    parser.add_argument(
        "--weightings", nargs="+", choices=WEIGHTINGS, default=list(WEIGHTINGS),
        help="the level weightings to compare (default: all)",
    )  # fmt: skip
    args = parser.parse_args()
    results = {str(bag): judge(bag, args.weightings) for bag in args.bags}
    print(json.dumps(results))


if __name__ == "__main__":
    main()
