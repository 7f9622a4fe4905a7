"""The second model class against a peer, side by side in one run, on the F-16 ground vibration
test: this project's PNLSS and B-spline LPV (`aero-rig fit`, docs/real_data.md's command) and
freq-statespace 0.1.2's NL-LFR (bench/nllfr_peer.py, in its own venv), on the same estimation
levels (1, 3, 5, 7) and validation levels (2, 4, 6).

    python3.11 -m venv /tmp/fss && /tmp/fss/bin/pip install freq-statespace==0.1.2
    .venv/bin/python bench/peer.py [--data DIR] [--peer-python /tmp/fss/bin/python]
        [--peer-nx 10] [--out DIR]

DIR: the F-16 CSV files (default: ../shared/data/f16-gvt beside the checkout, or $F16_GVT_DIR).
The NL-LFR runs at nx 10: at nx 6, the order of the PNLSS's linear start, the package's own
linear model of these data is unstable and its NL-LFR fit gives no model (bench/nllfr_peer.py).

Prints each model's validation errors and fit time; then the targets of issue 59:
``lpv_as_accurate_as_nllfr`` (on every validation level), ``lpv_10x_faster``. Last line: JSON.
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LEVELS = ("2", "4", "6")
FIT = [
    "--format", "csv", "--input", "Force", "--output", "Acceleration2", "--period", "8192",
    "--estimation", "1", "3", "5", "7", "--validation", *LEVELS, "--drop-periods", "1",
    "--structure", "statesonly", "--degrees", "3", "--max-iter", "20",
    "--lpv", "--lpv-state-degree", "1", "--lpv-intervals", "4",
]  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    default_data = os.environ.get("F16_GVT_DIR") or str(ROOT.parent / "shared/data/f16-gvt")
    parser.add_argument("--data", default=default_data, help="the F-16 CSV directory")
    parser.add_argument("--peer-python", default="/tmp/fss/bin/python",
                        help="a Python with freq-statespace==0.1.2")  # fmt: skip
    parser.add_argument("--peer-nx", type=int, default=10, help="the NL-LFR's state order")
    parser.add_argument("--out", default=None, help="keep the reports here")
    args = parser.parse_args()
    if not Path(args.peer_python).exists():
        print(f"peer: no {args.peer_python}; make it as this script's docstring says",
              file=sys.stderr)  # fmt: skip
        return 2
    out = Path(args.out or tempfile.mkdtemp(prefix="peer_"))
    out.mkdir(parents=True, exist_ok=True)

    # Ours: one aero-rig fit (the BLAs, the linear models, the PNLSS and the B-spline LPV).
    fit = [sys.executable, "-m", "aero_rig.cli", "fit", args.data, *FIT, "--out", str(out / "ours")]
    print("ours:", " ".join(fit[3:]), flush=True)
    subprocess.run(fit, check=True, stdout=subprocess.DEVNULL)
    model = json.loads((out / "ours" / "models.json").read_text())
    with (out / "ours" / "validation_errors.csv").open() as f:
        rows = {r["level"]: r for r in csv.DictReader(f)}
    timings = model["timings_s"]
    ours = {
        "PNLSS": {"fit_s": timings["pnlss"],
                  "errors": {k: float(rows[k]["pnlss"]) for k in LEVELS}},
        "B-spline LPV": {"fit_s": timings["lpv"],
                         "errors": {k: float(rows[k]["lpv"]) for k in LEVELS}},
    }  # fmt: skip

    # The peer, in its own venv, on the same records.
    peer_json = out / "nllfr.json"
    peer = [
        args.peer_python,
        str(ROOT / "bench" / "nllfr_peer.py"),
        "--f16",
        args.data,
        "--data",
        str(out / "f16.npz"),
        "--nx",
        str(args.peer_nx),
        "--out",
        str(peer_json),
    ]
    print("peer:", " ".join(peer[1:]), flush=True)  # fmt: skip
    subprocess.run(peer, check=True, stdout=subprocess.DEVNULL)
    nllfr = json.loads(peer_json.read_text())
    names = dict(zip(LEVELS, ("L2", "L4", "L6"), strict=True))
    theirs = {"fit_s": nllfr["fit_s"], "errors": {k: nllfr["errors"][names[k]] for k in LEVELS}}

    print("| model | fit [s] | level 2 | 4 | 6 |\n|---|---|---|---|---|")
    for name, r in {**ours, f"NL-LFR (freq-statespace, nx {args.peer_nx})": theirs}.items():
        cells = " | ".join("–" if r["errors"][k] is None else f"{r['errors'][k]:.3f}"
                           for k in LEVELS)  # fmt: skip
        print(f"| {name} | {r['fit_s']:.1f} | {cells} |")
    lpv = ours["B-spline LPV"]
    accurate = all(
        theirs["errors"][k] is None or lpv["errors"][k] <= theirs["errors"][k] for k in LEVELS
    )
    targets = {
        "lpv_as_accurate_as_nllfr": accurate,
        "lpv_speedup": theirs["fit_s"] / lpv["fit_s"],
        "lpv_10x_faster": theirs["fit_s"] >= 10 * lpv["fit_s"],
        "pnlss_speedup": theirs["fit_s"] / ours["PNLSS"]["fit_s"],
    }
    print(f"targets: {targets}")
    print(json.dumps({"ours": ours, "nllfr": theirs, "nllfr_settings": nllfr.get("settings"),
                      "targets": targets}))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
