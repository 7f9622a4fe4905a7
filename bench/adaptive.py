"""The experiment that steers itself (issue 23): adaptive against fixed default campaigns.

For each plant seed, runs ``aero-rig campaign`` (default plan) once
with the fixed plan and once with ``--adaptive``, both with ``-p sim_wing.seed:=S -p
sim_actuator.seed:=S``, and compares:

- multisine time (settling and measured periods) executed against the fixed plan's, per level
  and in total (models.json ``experiment``), and the measured periods of each realization;
- Table 1 (all levels): each adaptive cell against the fixed run's, within the fixed cell's
  spread (its ``± s``, the std over the sine's periods) or not, and the largest difference in
  units of that spread;
- the decisions the identifier took, and the wall time of each run.

    .venv/bin/python bench/adaptive.py [--seeds 0 1 2] [--out DIR] [--reuse]
                                       [--plan default] [-p NODE.PARAM:=VALUE ...]
                                       [--bootstrap B [--bootstrap-scan] [--fixed-only]]
                                       [--common-sines]

``--bootstrap B`` refits every run's bag with ``aero-rig fit BAG --bootstrap B`` (into
``<run>/fit_bootstrap``; reused with ``--reuse``) and compares those tables: each cell's spread
is then sqrt(s² + b²), s the std over the sine's periods and b the std over B bootstrap refits
on the estimation periods (docs/design.md §7.7), so that "within its spread" includes the
models' estimation scatter. ``--bootstrap-scan`` reruns the structure scan in every replicate
(``aero-rig fit --bootstrap-scan``, into ``<run>/fit_bootstrap_scan``), so that b includes
which structure the scan keeps; ``--fixed-only`` refits only the fixed runs' bags, the
reference spreads that ``--common-sines`` compares against.

``--common-sines`` also identifies each adaptive run again from its bag and scores its models
on the fixed run's sine records (``identify(..., models_from=...)``): both tables then rest on
the same validation data, and a difference is the models'. With ``--bootstrap`` it compares
them a second time against the fixed run's bootstrap mean per cell (same spread): the fixed
run's cell is one draw of its fitting procedure, the mean what the procedure gives on other
draws of the periods. It then also counts the fixed run's own cells against that mean: how
often one draw of the same procedure is outside "its spread", the rate to read the adaptive
run's count against.

``--reuse`` reads the runs already in DIR (``fixed_<seed>``, ``adaptive_<seed>``) instead of
running them again, and runs only the missing ones. ``-p`` is passed to both runs of every
seed (e.g. ``-p generator.adaptive_min_periods:=3``). Last line: JSON {seed: {...},
"summary": {...}}.
"""

import argparse
import csv
import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

CLI = (sys.executable, "-m", "aero_rig.cli", "campaign")


def run(out: Path, seed: int, adaptive: bool, plan: str, extra: list[str]) -> float:
    """Run one campaign into ``out``; its wall time [s]. Raises on a failed run."""
    args = [*CLI, "--plan", plan, "--quiet", "--out", str(out)]
    args += ["-p", f"sim_wing.seed:={seed}", "-p", f"sim_actuator.seed:={seed}"]
    for item in extra:
        args += ["-p", item]
    if adaptive:
        args.append("--adaptive")
    t0 = time.monotonic()
    proc = subprocess.run(args, capture_output=True, text=True)
    (out.parent / f"{out.name}.out").write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        raise RuntimeError(f"{out.name}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return time.monotonic() - t0


# <run>/fit_bootstrap: the bag refitted with --bootstrap; fit_bootstrap_scan: with
# --bootstrap-scan too (each replicate reruns the structure scan).
BOOTSTRAP_DIRS = {False: "fit_bootstrap", True: "fit_bootstrap_scan"}


def refit(run_dir: Path, replicates: int, reuse: bool, scan: bool = False) -> float:
    """``aero-rig fit <run>/bag --bootstrap B [--bootstrap-scan]`` into <run>/fit_bootstrap
    (fit_bootstrap_scan); its wall time [s] (0 when reused)."""
    boot = BOOTSTRAP_DIRS[scan]
    out = run_dir / boot
    if reuse and (out / "table1_all_levels.csv").exists():
        return 0.0
    args = [sys.executable, "-m", "aero_rig.cli", "fit", str(run_dir / "bag"), "--out", str(out)]
    t0 = time.monotonic()
    args += ["--bootstrap", str(replicates), *(["--bootstrap-scan"] if scan else [])]
    proc = subprocess.run(args, capture_output=True, text=True)
    (run_dir / f"{boot}.out").write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        raise RuntimeError(f"{run_dir.name}: fit exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return time.monotonic() - t0


def _table1_csv(directory: Path) -> list[list[str]]:
    """The rows of <directory>/table1_all_levels.csv, the header first."""
    with (directory / "table1_all_levels.csv").open() as f:
        return list(csv.reader(f))


def table1(
    run_dir: Path, boot: str = BOOTSTRAP_DIRS[False]
) -> dict[tuple[str, str], tuple[float, float]]:
    """{(model, column): (error, spread)} of table1_all_levels.csv: the bootstrap refit's
    (<run>/<boot>) when there is one, its spread sqrt(std² + estimation std²)."""
    source = run_dir / boot if (run_dir / boot).is_dir() else run_dir
    rows = _table1_csv(source)
    header = rows[0]
    index = {name: i for i, name in enumerate(header)}
    cells = {}
    for row in rows[1:]:
        for i, name in enumerate(header):
            if i == 0 or name.endswith((" std", " estimation mean")):
                continue
            value = float(row[i]) if row[i] else math.nan
            parts = [row[j] for j in (index.get(f"{name} std"), index.get(f"{name} estimation std"))
                     if j is not None]  # fmt: skip
            spread = math.sqrt(sum(float(p) ** 2 for p in parts)) if all(parts) else math.nan
            cells[(row[0], name)] = (value, spread)
    return cells


def procedure_means(run_dir: Path, boot: str) -> dict[tuple[str, str], float]:
    """{(model, column): the bootstrap refits' mean error} of <run>/<boot>'s
    table1_all_levels.csv (its "<column> estimation mean"; empty without one): what the
    fitting procedure gives on other draws of the run's periods, not only on the run's own
    (docs/design.md §7.7)."""
    if not (run_dir / boot / "table1_all_levels.csv").exists():
        return {}
    rows = _table1_csv(run_dir / boot)
    suffix = " estimation mean"
    return {
        (row[0], name.removesuffix(suffix)): float(row[i]) if row[i] else math.nan
        for row in rows[1:]
        for i, name in enumerate(rows[0])
        if name.endswith(suffix)
    }


def on_common_sines(fixed: Path, adaptive: Path) -> dict[tuple[str, str], float]:
    """Table 1 (all levels) of the adaptive run's models, identified again from its bag with
    its recorded parameters, scored on the fixed run's sine records: the same validation data
    as the fixed run's table, so that a difference is the models' and not the sines' (the
    adaptive plan's shorter levels move the sines to other stall episodes of the plant)."""
    import dataclasses

    from aero_identification.campaign_source import campaign_dataset
    from aero_identification.pipeline import identify
    from aero_rig.offline import read_campaign_bag, recorded_config

    def load(run: Path) -> Any:
        data = read_campaign_bag(run / "bag")
        config = dataclasses.replace(recorded_config(data), bootstrap=0, clustering_ablation=False)
        dataset = campaign_dataset(data.assembler, final=True, min_periods=config.min_periods)
        return dataset, config

    adaptive_data, config = load(adaptive)
    fixed_data, _ = load(fixed)
    models = identify(adaptive_data, config, final=True)
    scored = identify(fixed_data, config, final=True, models_from=models)
    return {(m, f"{lv} {f:g} Hz"): e for (m, lv, f), e in scored.errors_all.items()}


def within(
    values: dict[tuple[str, str], float], reference: dict[tuple[str, str], tuple[float, float]]
) -> tuple[list[str], float]:
    """The cells of ``values`` outside the reference cell's spread, and the largest difference
    in units of that spread."""
    outside, worst = [], 0.0
    for key, value in values.items():
        ref, spread = reference[key]
        if not (math.isfinite(value) and math.isfinite(ref)):
            continue
        units = abs(value - ref) / spread if spread > 0 else math.inf
        worst = max(worst, units)
        if units > 1.0:
            outside.append(f"{key[0]} {key[1]}: {value:.3f} vs {ref:.3f} ± {spread:.3f}")
    return outside, worst


def counted(
    label: str,
    values: dict[tuple[str, str], float],
    reference: dict[tuple[str, str], tuple[float, float]],
    spread_name: str,
) -> dict[str, Any]:
    """`within` of ``values`` against ``reference``, printed under ``label``: the JSON entry."""
    off, worst = within(values, reference)
    print(f"{label}: {len(values) - len(off)} of {len(values)} cells within {spread_name} "
          f"(worst {worst:.2f} spreads)")  # fmt: skip
    for line in off:
        print(f"  outside: {line}")
    return {"cells_outside_spread": off, "worst_difference_in_spreads": round(worst, 2)}


def compare(fixed: Path, adaptive: Path, boot: str) -> dict[str, Any]:
    account = json.loads((adaptive / "models.json").read_text())["experiment"]
    planned = json.loads((fixed / "models.json").read_text())["experiment"]
    a, f = table1(adaptive, boot), table1(fixed, boot)
    outside, worst = within({k: v for k, (v, _) in a.items()}, f)
    return {
        "multisine_s": account["multisine_executed_s"],
        "fixed_multisine_s": planned["multisine_executed_s"],
        "fraction": account["multisine_executed_s"] / planned["multisine_executed_s"],
        "levels": {
            name: {
                "executed_s": lv["executed_s"],
                "fixed_s": planned["levels"][name]["executed_s"],
                "periods": lv["executed_periods"],
            }
            for name, lv in account["levels"].items()
        },
        "cells": len(a),
        "cells_outside_spread": outside,
        "worst_difference_in_spreads": round(worst, 2),
        "decisions": [
            f"{d.get('request')} level {d.get('level')}: {d.get('change') or d.get('why')}"
            for d in account["decisions"]
            if d.get("request") != "go_on"
        ],
        "table1_adaptive": {f"{m} | {c}": round(v, 3) for (m, c), (v, _) in a.items()},
        "table1_fixed": {f"{m} | {c}": f"{v:.3f} ± {s:.3f}" for (m, c), (v, s) in f.items()},
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--out", default="runs/bench_adaptive")
    parser.add_argument("--plan", default="default")
    parser.add_argument(
        "--reuse", action="store_true", help="read the runs already in --out, run the missing"
    )
    parser.add_argument("-p", dest="params", action="append", default=[], metavar="NODE.P:=V")
    parser.add_argument(
        "--common-sines", action="store_true",
        help="also score the adaptive run's models on the fixed run's sine records",
    )  # fmt: skip
    parser.add_argument(
        "--bootstrap", type=int, default=0, metavar="B",
        help="refit each bag with `aero-rig fit --bootstrap B` and compare with its spreads",
    )  # fmt: skip
    parser.add_argument(
        "--bootstrap-scan", action="store_true",
        help="with --bootstrap: rerun the structure scan in every replicate (fit_bootstrap_scan)",
    )  # fmt: skip
    parser.add_argument(
        "--fixed-only", action="store_true",
        help="with --bootstrap: refit only the fixed runs' bags (what --common-sines needs)",
    )  # fmt: skip
    args = parser.parse_args()
    boot = BOOTSTRAP_DIRS[args.bootstrap_scan]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {}
    for seed in args.seeds:
        walls = {}
        for mode in ("fixed", "adaptive"):
            run_dir = out / f"{mode}_{seed}"
            if not (args.reuse and (run_dir / "models.json").exists()):
                walls[mode] = round(run(run_dir, seed, mode == "adaptive", args.plan, args.params))
            if args.bootstrap > 0 and not (args.fixed_only and mode == "adaptive"):
                wall = refit(run_dir, args.bootstrap, args.reuse, args.bootstrap_scan)
                walls[f"{mode}_fit"] = round(wall)
        result = compare(out / f"fixed_{seed}", out / f"adaptive_{seed}", boot)
        result["wall_s"] = walls
        if args.common_sines:
            common = on_common_sines(out / f"fixed_{seed}", out / f"adaptive_{seed}")
            spreads = table1(out / f"fixed_{seed}", boot)
            result["common_sines"] = {
                **counted(f"seed {seed}, the adaptive run's models on the fixed run's sines",
                          common, spreads, "the fixed run's spread"),
                "table1_adaptive": {f"{m} | {c}": round(v, 3) for (m, c), v in common.items()},
            }  # fmt: skip
            # The same cells against the fixed procedure's bootstrap mean (same spread): the
            # fixed run's own cell is one draw of its procedure, the mean is what it gives on
            # other draws of the periods (a lean high, docs/design.md §7.7).
            means = procedure_means(out / f"fixed_{seed}", boot)
            if means:
                reference = {k: (means[k], spreads[k][1]) for k in spreads}
                result["common_sines"]["against_bootstrap_mean"] = counted(
                    f"seed {seed}, the same against the fixed run's bootstrap mean",
                    common, reference, "the spread",
                )  # fmt: skip
                # The rate to read that count against: the fixed run's own cells, one draw of
                # the same procedure, against the same mean and spreads (optimistic: the cell
                # and the mean rest on the same periods).
                own = {k: v for k, (v, _) in spreads.items()}
                result["common_sines"]["fixed_against_its_bootstrap_mean"] = counted(
                    f"seed {seed}, the fixed run's own cells against that mean",
                    own, reference, "the spread",
                )  # fmt: skip
        results[str(seed)] = result
        print(
            f"seed {seed}: multisine {result['multisine_s']:.0f} s of "
            f"{result['fixed_multisine_s']:.0f} s ({100 * result['fraction']:.0f} %); periods "
            + ", ".join(f"{n} {lv['periods']}" for n, lv in result["levels"].items())
            + f"; Table 1: {result['cells'] - len(result['cells_outside_spread'])} of "
            f"{result['cells']} cells within the fixed run's spread (worst "
            f"{result['worst_difference_in_spreads']} spreads)"
        )
        for line in result["cells_outside_spread"]:
            print(f"  outside: {line}")
    # The reference for "within its spread": two fixed runs of the same plan whose plants
    # differ only in their random draws (seed s against the next seed) are not within the
    # within-record spread either, since that spread leaves out run-to-run variability.
    baseline = {}
    seeds = list(args.seeds)
    for a, b in zip(seeds, seeds[1:] + seeds[:1], strict=True):
        if a == b:
            continue
        fa, fb = table1(out / f"fixed_{a}", boot), table1(out / f"fixed_{b}", boot)
        outside = [key for key, (value, _) in fa.items() if abs(value - fb[key][0]) > fb[key][1]]
        baseline[f"fixed_{a} vs fixed_{b}"] = len(outside)
        print(f"fixed seed {a} against fixed seed {b}: {len(fa) - len(outside)} of {len(fa)} "
              "cells within the other's spread")  # fmt: skip
    # Across the seeds: each cell's mean and run-to-run std (plant draws, the scan's pick),
    # fixed against adaptive; "within" when the means differ by less than the fixed runs' std.
    across: dict[str, Any] = {}
    if len(seeds) >= 2:
        fixed = [table1(out / f"fixed_{s}", boot) for s in seeds]
        adapt = [table1(out / f"adaptive_{s}", boot) for s in seeds]
        for key in fixed[0]:
            f = np.array([t[key][0] for t in fixed])
            a = np.array([t[key][0] for t in adapt])
            across[f"{key[0]} | {key[1]}"] = {
                "fixed": [round(float(f.mean()), 3), round(float(f.std(ddof=1)), 3)],
                "adaptive": [round(float(a.mean()), 3), round(float(a.std(ddof=1)), 3)],
                "within": bool(abs(a.mean() - f.mean()) <= f.std(ddof=1)),
            }
        inside = sum(v["within"] for v in across.values())
        print(f"across seeds {seeds}: {inside} of {len(across)} cells' adaptive mean within "
              "the fixed runs' run-to-run std of their mean")  # fmt: skip
        for name, v in across.items():
            mark = "" if v["within"] else "  (outside)"
            print(f"  {name}: fixed {v['fixed'][0]} ± {v['fixed'][1]}, adaptive "
                  f"{v['adaptive'][0]} ± {v['adaptive'][1]}{mark}")  # fmt: skip
    fractions = [r["fraction"] for r in results.values()]
    results["summary"] = {
        "max_fraction": round(max(fractions), 3),
        "cells_outside_spread": sum(len(r["cells_outside_spread"]) for r in results.values()),
        "fixed_against_fixed_outside_spread": baseline,
        "across_seeds": across,
    }
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
