"""``aero-rig``: run the pitching-wing campaign, live graphs, offline fits and views.

    aero-rig campaign [--plan default|short|FILE] [--real-time-factor X] [--out DIR]
                      [--rerun spawn|save|serve|off] [--seed N] [--allow-excluded]
    aero-rig run sim|rig [--graph FILE] [--duration S]
    aero-rig fit BAG [--out DIR]
    aero-rig fit FILE|DIR --format csv|mat --input COL --output COL --period N [--fs HZ]
                 [--levels PATTERN...] [--estimation L...] [--validation L...] [--nx N]
                 [--drop-periods K] [--out DIR]
    aero-rig view BAG|live [--save FILE.rrd]
    aero-rig bag recover BAG

``campaign`` launches the simulated graph (generator, simulated actuator, simulated wing, lift,
identifier, recorder, optionally the Rerun view) as processes on the Cyclone DDS backend, runs
the plan to its end, waits for the final identification, stops everything and prints Table 1
and the run directory (bag, models, report, .rrd). A run that lost or excluded data (missing or
duplicated samples, anomalies such as a free-running actuator, excluded periods or sine records,
a bag short of samples) lists what on its last lines and exits with code 3, unless
``--allow-excluded`` is given.
"""

import argparse
import json
import os
import signal
import sys
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

from aero_identification.quality import data_quality_lines
from rig_runtime import ros_environment
from rig_runtime.graph import GraphError, GraphSpec, load_graph, package_share
from rig_runtime.interface import EXPERIMENT_PLAN, EXPERIMENT_SEGMENT, IDENTIFICATION_STATUS
from rig_runtime.launcher import Launcher, parse_overrides

from .verdict import run_problems

EXIT_NOT_CLEAN = 3  # the campaign finished but lost or excluded data
VIEW_MODES = ("spawn", "save", "serve", "off")  # "off": no view node (the node calls it "none")


def _config(name: str) -> Path:
    return package_share("aero_rig") / "config" / name


def _with_view(graph: GraphSpec, mode: str, rrd: Path | None) -> GraphSpec:
    if mode == "off":
        return graph
    view = load_graph(_config("live_view.yaml")).nodes[0]
    overrides = {"mode": mode}
    if rrd is not None:
        overrides["rrd_path"] = str(rrd)
    view = replace(
        view, parameter_overrides={**view.parameter_overrides, **overrides}, stops_graph=False
    )
    return GraphSpec(graph.name, (*graph.nodes, view), graph.source)


def _run_dir(out: str | None) -> Path:
    if out:
        path = Path(out)
    else:
        path = Path("runs") / datetime.now().strftime("%Y%m%d-%H%M%S")
    if path.exists() and any(path.iterdir()):
        raise SystemExit(f"aero-rig: run directory {path} exists and is not empty; use --out NEW")
    path.mkdir(parents=True, exist_ok=True)
    return path.resolve()


class CampaignMonitor:
    """In-process observer: progress from segment events, end from the identifier's status."""

    def __init__(self) -> None:
        from rig_runtime.node import Node

        self.node = Node("aero_rig_campaign", argv=[])  # the graph's backend (the env's)
        self.total = 0
        self.fs = 0.0  # the plan's sample rate [Hz]
        self.k = 0
        self.state = ""
        self.model: dict[str, Any] | None = None
        self.node.create_subscription(
            EXPERIMENT_PLAN.type, EXPERIMENT_PLAN.name, self._plan, EXPERIMENT_PLAN.qos
        )
        self.node.create_subscription(
            EXPERIMENT_SEGMENT.type, EXPERIMENT_SEGMENT.name, self._segment, EXPERIMENT_SEGMENT.qos
        )
        self.node.create_subscription(
            IDENTIFICATION_STATUS.type,
            IDENTIFICATION_STATUS.name,
            self._status,
            IDENTIFICATION_STATUS.qos,
        )

    def _plan(self, msg: Any) -> None:
        plan = json.loads(msg.data)
        self.total = int(plan["total_samples"])
        self.fs = float(plan["fs"])

    def _segment(self, msg: Any) -> None:
        event = json.loads(msg.data)
        if event.get("event") == "end":
            self.k = int(event["start_k"]) + int(event["length"])
        elif event.get("event") == "plan_end":
            self.k = self.total

    def _status(self, msg: Any) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key == "state":
                    self.state = kv.value

    def spin(self, seconds: float) -> None:
        self.node.spin_until(lambda: False, seconds)

    def close(self) -> None:
        self.node.close()


def backend_label(backend: str) -> str:
    return "rclpy (Fast DDS)" if backend == "rclpy" else "the Cyclone DDS backend"


def checked_backend() -> str:
    """The runtime backend of the graph to start, or SystemExit(2) with one clear line."""
    try:
        backend = ros_environment.check()
    except ros_environment.RosEnvironmentError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    if backend == "dds" and not os.environ.get(ros_environment.BACKEND_ENV):
        print(
            "aero-rig: rclpy does not import here; the graph runs on the Cyclone DDS backend "
            f"(for rclpy: {ros_environment.INSTALL_RCLPY})",
            file=sys.stderr,
        )
    return backend


def cmd_campaign(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    backend = checked_backend()
    user_overrides = parse_overrides(args.overrides)
    graph = load_graph(Path(args.graph) if args.graph else _config("sim.yaml"))
    run_dir = _run_dir(args.out)
    rrd = run_dir / "campaign.rrd" if args.rerun == "save" else None
    graph = _with_view(graph, args.rerun, rrd)
    plan = args.plan
    if plan not in ("default", "short"):
        plan = str(Path(plan).resolve())
    overrides = _merge(
        {
            "generator": {
                "plan": plan,
                "seed": args.seed,
                "real_time_factor": args.real_time_factor,
            },
            "recorder": {"output": str(run_dir / "bag")},
            "identifier": {"output_dir": str(run_dir), "exit_after_final": True},
        },
        user_overrides,
    )
    # Every node, and the monitor in this process, on one backend; a simulated campaign stays
    # on this machine unless a discovery range was chosen (ros_environment.py).
    env = {"RIG_RUNTIME_BACKEND": backend}
    os.environ.update(env)
    ros_environment.localhost_by_default(os.environ)
    print(
        f"aero-rig: campaign '{args.plan}' on {backend_label(backend)} -> {run_dir}",
        file=sys.stderr,
    )
    try:
        launcher = Launcher(
            graph,
            env=env,
            overrides=overrides,
            log_dir=run_dir / "logs",
            backends=parse_node_backends(args.node_backend),
        )
    except (KeyError, GraphError) as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return 2
    monitor = CampaignMonitor()
    started = time.monotonic()
    stopped_by: list[str] = []

    def _on_signal(signum: int, _frame: Any) -> None:
        # kill, a job scheduler's time limit or a closed terminal: stop the graph as Ctrl-C does
        # (the nodes are in their own process groups and would otherwise run on).
        stopped_by.append(signal.Signals(signum).name)
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGTERM, signal.SIGHUP)}
    launcher.start()
    reason: str | None = None
    progress = tqdm(total=1, unit="sample", unit_scale=True, desc="experiment", disable=args.quiet)
    try:
        while reason is None:
            monitor.spin(0.2)
            if monitor.total and progress.total != monitor.total:
                progress.total = monitor.total
            progress.n = monitor.k
            progress.set_postfix_str(monitor.state or "starting")
            progress.refresh()
            reason = launcher.poll()
            if args.timeout and time.monotonic() - started > args.timeout:
                reason = f"timeout after {args.timeout:g} s"
                launcher.failure = reason
    except KeyboardInterrupt:
        reason = "interrupted"
        launcher.failure = (
            f"stopped by {stopped_by[0]}" if stopped_by else "interrupted by the user"
        )
    finally:
        previous[signal.SIGINT] = signal.getsignal(signal.SIGINT)
        for sig in previous:  # the graph is being stopped (bounded): let that finish
            signal.signal(sig, signal.SIG_IGN)
        progress.close()
        monitor.close()
        codes = launcher.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    wall = time.monotonic() - started
    if launcher.failure:
        print(f"aero-rig: campaign failed: {launcher.failure}", file=sys.stderr)
        print(
            f"aero-rig: node logs in {run_dir / 'logs'}; the bag so far: {run_dir / 'bag'}",
            file=sys.stderr,
        )
        return 1
    bad = {n: c for n, c in codes.items() if c not in (0, -2, 130)}
    table = run_dir / "table1_all_levels.md"
    if not table.exists():
        print(
            f"aero-rig: the identifier produced no report ({reason}); exit codes {codes}",
            file=sys.stderr,
        )
        return 1
    problems = run_problems(run_dir, monitor.total)
    summary = {
        "wall_s": round(wall, 1),
        "backend": backend,
        "experiment_s": round(monitor.total / monitor.fs, 1) if monitor.total else None,
        "real_time_factor": round(monitor.total / monitor.fs / wall, 1) if monitor.total else None,
        "exit_codes": codes,
        "clean": not problems,
        "problems": problems,
    }
    (run_dir / "campaign.json").write_text(json.dumps(summary, indent=1))
    print("\nTable 1, trained on all levels (estimation: one realization per level):")
    print(table.read_text())
    level1 = run_dir / "table1_level1.md"
    if level1.exists():
        print("\nTable 1, trained on level 1 only (the paper's variant):")
        print(level1.read_text())
    clustering = run_dir / "clustering.md"
    if clustering.exists():
        print("\nWhat the period clustering changed (clustering.md, table1_no_clustering.md):")
        print("\n".join(x for x in clustering.read_text().splitlines() if x.startswith("|")))
    print(
        f"\nwall time {summary['wall_s']} s for {summary['experiment_s']} s of experiment "
        f"({summary['real_time_factor']}x real time)"
    )
    print(f"run directory: {run_dir}  (bag/, models.json, table1_*.md|csv, *.png, logs/)")
    if bad:
        print(f"aero-rig: warning: nodes stopped uncleanly: {bad}", file=sys.stderr)
    if problems:
        print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); Table 1 uses only what was left:")
        for line in problems[:40]:
            print(f"  - {line}")
        if len(problems) > 40:
            print(f"  - … {len(problems) - 40} more in {run_dir / 'data_quality.md'}")
        if not args.allow_excluded:
            print(
                "aero-rig: the campaign lost or excluded data (above); exit code 3. Pass "
                "--allow-excluded to accept such a run.",
                file=sys.stderr,
            )
            return EXIT_NOT_CLEAN
    else:
        print("data clean: every plan sample arrived and was recorded once, no anomaly")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    backend = checked_backend()
    if args.which == "sim":
        ros_environment.localhost_by_default(os.environ)
    print(f"aero-rig: {args.which} graph on {backend_label(backend)}", file=sys.stderr)
    graph = load_graph(Path(args.graph) if args.graph else _config(f"{args.which}.yaml"))
    graph = _with_view(graph, args.rerun, None)
    overrides: dict[str, dict[str, Any]] = {}
    if any(n.name == "recorder" for n in graph.nodes):
        out = _run_dir(args.out)
        overrides["recorder"] = {"output": str(out / "bag")}
        overrides["identifier"] = {"output_dir": str(out)}
        print(f"aero-rig: recording to {out / 'bag'}", file=sys.stderr)
    overrides = _merge(overrides, parse_overrides(args.overrides))
    try:
        launcher = Launcher(
            graph, overrides=overrides, backends=parse_node_backends(args.node_backend)
        )
    except (KeyError, GraphError) as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return 2
    return launcher.run(args.duration)


def _merge(
    base: dict[str, dict[str, Any]], extra: dict[str, dict[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Per-node parameter overrides, ``extra`` (the user's -p) winning."""
    out = {name: dict(values) for name, values in base.items()}
    for name, values in extra.items():
        out.setdefault(name, {}).update(values)
    return out


def cmd_fit(args: argparse.Namespace) -> int:
    if args.format is not None:
        return cmd_fit_records(args)
    used = [opt for opt, value in _record_options(args).items() if value]
    if used:
        print(
            f"aero-rig fit: {', '.join(used)} apply to measured records; add --format csv|mat "
            "(without --format the source is a bag)",
            file=sys.stderr,
        )
        return 2
    from aero_identification.config import IdentificationConfig

    from .offline import BagError, fit_bag

    out = Path(args.out) if args.out else Path(args.bag).resolve().parent / "offline_fit"
    config = IdentificationConfig(scan_scheduler=args.scheduler or "")
    if args.scan is not None:
        config = replace(config, scan=args.scan)
    try:
        result, data = fit_bag(args.bag, out, config)
    except BagError as exc:
        print(f"aero-rig fit: {exc}", file=sys.stderr)
        return 2
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
    return 0


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


def cmd_fit_records(args: argparse.Namespace) -> int:
    """``aero-rig fit FILE|DIR --format csv|mat``: measured multisine records, level by level."""
    from aero_identification.level_fit import error_table, identify_levels, write_level_report
    from aero_identification.records import read_records

    missing = [o for o, v in (("--input", args.input), ("--output", args.output),
                              ("--period", args.period)) if v is None]  # fmt: skip
    if missing:
        print(f"aero-rig fit: --format {args.format} needs {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.allow_excluded:
        print("aero-rig fit: --allow-excluded applies to bags only", file=sys.stderr)
        return 2
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
        return 2
    write_level_report(result, out)
    for warning in result.warnings:
        print(f"aero-rig fit: warning: {warning}", file=sys.stderr)
    print(f"estimation levels {result.estimation}, validation levels {result.validation}")
    print("\nValidation on held-out levels (relative RMS error rms(y - yhat)/rms(y - mean y)):")
    print(error_table(result)[0])
    print(f"report: {out.resolve()}  (summary.md, validation_errors.md|csv, models.json, *.png)")
    return 0


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


def cmd_view(args: argparse.Namespace) -> int:
    if args.source == "live":
        graph = _with_view(
            load_graph(_config("live_view.yaml")),
            "save" if args.save else "spawn",
            Path(args.save) if args.save else None,
        )
        graph = GraphSpec(graph.name, graph.nodes[-1:], graph.source)
        return Launcher(graph).run(None)
    from .view import view_bag

    view_bag(args.source, rrd_path=args.save, spawn=not args.save)
    return 0


def cmd_bag_recover(args: argparse.Namespace) -> int:
    """``aero-rig bag recover BAG``: footers and metadata.yaml back after a recorder crash."""
    from rig_runtime.bag_recover import describe, format_stamp, last_readable_ns, recover_bag

    try:
        reports = recover_bag(args.bag)
    except (OSError, ValueError) as exc:
        print(f"aero-rig bag recover: {exc}", file=sys.stderr)
        return 2
    for line in describe(reports):
        print(line)
    damaged = [r for r in reports if not r.intact]
    print(
        f"{args.bag}: {len(damaged)} of {len(reports)} file(s) recovered; "
        f"{sum(r.stats.count for r in reports)} messages; last readable time "
        f"{format_stamp(last_readable_ns(reports))}; metadata.yaml rewritten"
    )
    return 0


def _add_override_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-p",
        dest="overrides",
        action="append",
        default=[],
        metavar="NODE.PARAM:=VALUE",
        help="set a node parameter, as rig-launch -p (e.g. -p sim_wing.seed:=3); repeatable",
    )


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


def _add_backend_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--node-backend",
        action="append",
        default=[],
        metavar="NODE=BACKEND",
        help="run NODE on rclpy or dds, the others on RIG_RUNTIME_BACKEND's (default: rclpy "
        "where it imports): a mixed graph, as a lab with ROS PCs and a venv laptop; repeatable",
    )


def parse_node_backends(items: list[str]) -> dict[str, str]:
    """``["lift=dds", ...]`` -> ``{"lift": "dds"}``; SystemExit(2) on a malformed item."""
    out = {}
    for item in items:
        name, sep, backend = item.partition("=")
        if not sep or backend not in ("rclpy", "dds") or not name:
            print(f"aero-rig: --node-backend {item!r}: expected NODE=rclpy|dds", file=sys.stderr)
            raise SystemExit(2)
        if backend == "rclpy" and not ros_environment.rclpy_available():
            print(
                f"aero-rig: --node-backend {item}: rclpy does not import here; install it with "
                f"`{ros_environment.INSTALL_RCLPY}`",
                file=sys.stderr,
            )
            raise SystemExit(2)
        out[name] = backend
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aero-rig", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("campaign", help="run the simulated campaign end to end")
    p.add_argument("--plan", default="default", help="default | short | plan JSON file")
    p.add_argument("--seed", type=int, default=0, help="plan seed (phases, detection lines)")
    p.add_argument(
        "--real-time-factor",
        type=float,
        default=0.0,
        help="experiment s per wall s; 0 = as fast as the graph takes (default)",
    )
    p.add_argument("--out", default=None, help="run directory (default runs/<date-time>)")
    p.add_argument("--rerun", choices=VIEW_MODES, default="off", help="live Rerun view")
    p.add_argument("--graph", default=None, help="graph YAML (default aero_rig config/sim.yaml)")
    p.add_argument("--timeout", type=float, default=0.0, help="give up after S wall seconds")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--allow-excluded",
        action="store_true",
        help="exit 0 even if data were lost or excluded (they are still listed)",
    )
    _add_backend_option(p)
    _add_override_option(p)
    p.set_defaults(func=cmd_campaign)

    p = sub.add_parser("run", help="run the sim or rig graph until Ctrl-C")
    p.add_argument("which", choices=("sim", "rig"))
    p.add_argument("--graph", default=None, help="graph YAML instead of config/<which>.yaml")
    p.add_argument("--duration", type=float, default=None, help="stop after S seconds")
    p.add_argument("--out", default=None, help="run directory for the bag and the report")
    p.add_argument("--rerun", choices=VIEW_MODES, default="off", help="live Rerun view")
    _add_backend_option(p)
    _add_override_option(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser(
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
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("view", help="Rerun view of a bag or of the live graph")
    p.add_argument("source", help="BAG directory or 'live'")
    p.add_argument("--save", default=None, help="write an .rrd instead of spawning a viewer")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser("bag", help="bag maintenance (recover a bag after a recorder crash)")
    bag_sub = p.add_subparsers(dest="bag_command", required=True)
    p = bag_sub.add_parser(
        "recover",
        help="rewrite the MCAP files that lost their footer (kill -9, power loss) up to their "
        "last complete chunk, and metadata.yaml (like ros2 bag reindex)",
    )
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory (MCAP storage)")
    p.set_defaults(func=cmd_bag_recover)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except GraphError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
