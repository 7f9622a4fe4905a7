"""Rerun view of a pitching-wing experiment, live (DDS) or from a rosbag.

Shows, on the ``experiment_time`` timeline (the message stamps): commanded and measured pitch
[deg] and C_l over time; the Cp distribution over the chord (−Cp up, upper and lower surface,
decimated); on each ``/identification/model`` update the FRF |G| [dB] with its noise and
nonlinear-distortion variances [dB] per level, the cluster label of every period, the models'
C_l–α predictions against the measured sine records and the validation table; segment events and
identification status as text logs. A blueprint lays these out.

Modes: ``save`` writes ``rrd_path``; ``spawn`` starts a Rerun Viewer; ``serve`` runs a gRPC
server a viewer connects to; ``connect`` streams to a running viewer at ``url``; ``none`` only
counts messages (not ``off``: YAML reads that as false). With ``rrd_path`` set, every mode
also saves to that file.

This module imports rerun (numpy >= 2): run it from the project's virtual environment on the
Cyclone DDS backend, never in an rclpy process (DESIGN.md §3). ``RigViewLogger`` has no
middleware and takes plain messages; ``view_bag`` replays a recorded bag through it.
"""

import json
import math
import os
import re
import sys
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from pressure_scanner.tap_cloud import read_cloud
from pressure_scanner.wing_params import WingParams
from rig_runtime.node import BACKEND_ENV, EXIT_CONFIG_ERROR

from rig_runtime import Node, Parameter, run_node, stamp_to_ns

TIMELINE = "experiment_time"

# Rerun's 2D views draw +y downwards (rerun-io/rerun#1387), so the two x–y plots are laid out in
# view coordinates: Cp plot at (CP_X_SCALE·x/c, Cp), i.e. −Cp up; C_l–α plot at
# (α [deg], −CL_SCALE·C_l), i.e. C_l up, one unit of C_l as tall as CL_SCALE degrees. Labelled
# axes are drawn into both views (entities .../axes).
CP_X_SCALE = 4.0
CL_SCALE = 10.0

ENTITY = {
    "command": "/series/pitch/command",
    "measured": "/series/pitch/measured",
    "cl": "/series/cl",
    "cp_upper": "/cp/upper",
    "cp_lower": "/cp/lower",
    "cp_taps": "/cp/taps",
    "cp_axes": "/cp/axes",
    "cl_alpha_live": "/cl_alpha/live",
    "cl_alpha_axes": "/cl_alpha/axes",
    "segment": "/events/segment",
    "model_event": "/events/model",
    "status": "/events/status",
    "table1": "/model/table1",
    "summary": "/model/summary",
}

BLUE = (31, 119, 180)
ORANGE = (255, 127, 14)
GREEN = (44, 160, 44)
RED = (214, 39, 40)
GRAY = (127, 127, 127)
PURPLE = (148, 103, 189)
CLUSTER_COLORS = [BLUE, ORANGE, GREEN, RED, PURPLE, (140, 86, 75), (227, 119, 194)]
PREDICTION_SERIES = (("cl_measured", "measured", GRAY), ("cl_bla_ss", "bla_ss", BLUE))
PREDICTION_SERIES += (("cl_pnlss", "pnlss", ORANGE),)
STATUS_LEVELS = {0: "INFO", 1: "WARN", 2: "ERROR", 3: "WARN"}


def slug(text: Any) -> str:
    """An entity-path part from free text: ``'sine level 2 1.0 Hz'`` -> ``sine_level_2_1_0_hz``."""
    out = re.sub(r"[^0-9a-zA-Z]+", "_", str(text)).strip("_").lower()
    return out or "unnamed"


def _float_array(values: Any) -> np.ndarray:
    """A float64 array from a JSON list (None -> NaN)."""
    if values is None:
        return np.zeros(0)
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


def _db(values: np.ndarray, power: bool) -> np.ndarray:
    """20·log10|x| (amplitude) or 10·log10(x) (power/variance); NaN where not positive."""
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (10.0 if power else 20.0) * np.log10(values)
    out[~np.isfinite(out)] = np.nan
    return out


def json_object(text: str, topic: str) -> dict[str, Any]:
    """The JSON object a std_msgs/String of ``topic`` carries; ValueError naming the topic."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{topic}: not JSON ({exc})") from None
    if not isinstance(value, dict):
        raise ValueError(f"{topic}: expected a JSON object")
    return value


def finite_runs(x: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
    """(n, 2) strips of the consecutive finite (x, y) points (a NaN breaks the line)."""
    ok = np.isfinite(x) & np.isfinite(y)
    strips, start = [], None
    for i, good in enumerate(np.append(ok, False)):
        if good and start is None:
            start = i
        elif not good and start is not None:
            if i - start >= 2:
                strips.append(np.column_stack([x[start:i], y[start:i]]))
            start = None
    return strips


def _axes(
    x_ticks: Sequence[float],
    y_ticks: Sequence[float],
    to_view: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    x_label: str,
    y_label: str,
) -> tuple[rr.LineStrips2D, rr.Points2D]:
    """Axis lines through the origin with labelled ticks, in view coordinates."""
    x0, x1, y0, y1 = min(x_ticks), max(x_ticks), min(y_ticks), max(y_ticks)
    xa, ya = to_view(np.array([x0, x1]), np.array([0.0, 0.0]))
    xb, yb = to_view(np.array([0.0, 0.0]), np.array([y0, y1]))
    tx, ty = to_view(np.asarray(x_ticks, float), np.zeros(len(x_ticks)))
    ux, uy = to_view(np.zeros(len(y_ticks)), np.asarray(y_ticks, float))
    labels = [f"{v:g}" for v in x_ticks] + [f"{v:g}" for v in y_ticks]
    labels[-1] = f"{y_ticks[-1]:g} {y_label}"
    labels[len(x_ticks) - 1] = f"{x_ticks[-1]:g} {x_label}"
    lines = rr.LineStrips2D(
        [np.column_stack([xa, ya]), np.column_stack([xb, yb])], colors=GRAY, radii=-0.5
    )
    ticks = rr.Points2D(
        np.column_stack([np.concatenate([tx, ux]), np.concatenate([ty, uy])]),
        labels=labels,
        show_labels=True,
        colors=GRAY,
        radii=-2.0,
    )
    return lines, ticks


def cp_to_view(x_c: np.ndarray, cp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return CP_X_SCALE * np.asarray(x_c), np.asarray(cp)


def cl_alpha_to_view(alpha_deg: np.ndarray, cl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(alpha_deg), -CL_SCALE * np.asarray(cl)


def make_blueprint(levels: Iterable[str] = ()) -> rrb.Blueprint:
    """The layout: time series and events | Cp and FRFs | C_l–α, clusters and model tables."""
    levels = list(levels)
    frf_views: list[Any] = [
        rrb.BarChartView(origin=f"/frf/level_{slug(lv)}", name=f"FRF level {lv} [dB]")
        for lv in levels
    ] or [rrb.BarChartView(origin="/frf", name="FRF [dB]")]
    cluster_views: list[Any] = [
        rrb.BarChartView(origin=f"/clusters/level_{slug(lv)}", name=f"Clusters level {lv}")
        for lv in levels
    ] or [rrb.BarChartView(origin="/clusters", name="Clusters")]
    cp_x, cp_y = cp_to_view(np.array([-0.05, 1.05]), np.array([-3.2, 1.2]))
    ca_x, ca_y = cl_alpha_to_view(np.array([-6.0, 36.0]), np.array([-0.4, 2.2]))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/series/pitch", name="Pitch [deg]"),
                rrb.TimeSeriesView(origin="/series/cl", name="C_l"),
                rrb.TextLogView(origin="/events", name="Events"),
                row_shares=[2, 2, 1],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin="/cp",
                    name="−Cp over x/c (upper blue, lower orange)",
                    visual_bounds=rrb.VisualBounds2D(
                        x_range=sorted(cp_x.tolist()), y_range=sorted(cp_y.tolist())
                    ),
                ),
                rrb.Tabs(*frf_views),
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin="/cl_alpha",
                    name="C_l–α: measured (gray), BLA SS (blue), PNLSS (orange), live (green)",
                    visual_bounds=rrb.VisualBounds2D(
                        x_range=sorted(ca_x.tolist()), y_range=sorted(ca_y.tolist())
                    ),
                ),
                rrb.Tabs(
                    *cluster_views,
                    rrb.TextDocumentView(origin="/model/summary", name="Model"),
                    rrb.TextDocumentView(origin="/model/table1", name="Table 1"),
                ),
            ),
        ),
        collapse_panels=False,
    )


class RigViewLogger:
    """Logs rig messages to a Rerun recording; no middleware (plain message objects in).

    One ``on_<topic>`` method per topic. Time series are logged at every
    ``series_decimation``-th sample, the Cp distribution and the live C_l–α trail at every
    ``taps_decimation``-th. Model updates replace the FRF, cluster and prediction entities.
    Unparseable input raises ``ValueError``; callers decide whether to go on.
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        *,
        taps_decimation: int = 10,
        series_decimation: int = 1,
        trail_s: float = 2.0,
        dynamic_pressure_pa: float | None = None,
        chord_m: float | None = None,
        send_blueprint: bool = True,
    ) -> None:
        if taps_decimation < 1 or series_decimation < 1:
            raise ValueError("taps_decimation and series_decimation must be >= 1")
        wing = WingParams()
        self.rec = recording
        self.taps_decimation = int(taps_decimation)
        self.series_decimation = int(series_decimation)
        self.trail_ns = int(trail_s * 1e9)
        self.q_pa = float(dynamic_pressure_pa or wing.dynamic_pressure_pa)
        self.chord_m = float(chord_m or wing.chord_m)
        self.counts = dict.fromkeys(
            ("command", "state", "taps", "coefficients", "segment", "model", "status"), 0
        )
        self.counts["cl_invalid"] = 0
        self.last_ns: int | None = None
        self._alpha_by_stamp: OrderedDict[int, float] = OrderedDict()
        self._last_alpha: float | None = None
        self._trail: deque[tuple[int, float, float]] = deque()
        self._levels: list[str] = []
        self._send_blueprint = send_blueprint
        self._model_entities: set[str] = set()
        self._status_seen: dict[str, tuple[Any, ...]] = {}
        self._log_static()
        if send_blueprint:
            self.rec.send_blueprint(make_blueprint())

    # -- helpers -------------------------------------------------------------------------------

    def _log_static(self) -> None:
        log = self.rec.log
        log(ENTITY["command"], rr.SeriesLines(colors=GRAY, names="command [deg]"), static=True)
        log(ENTITY["measured"], rr.SeriesLines(colors=BLUE, names="measured [deg]"), static=True)
        log(ENTITY["cl"], rr.SeriesLines(colors=RED, names="C_l"), static=True)
        lines, ticks = _axes(
            [0.0, 0.25, 0.5, 0.75, 1.0], [-1.0, 0.0, 1.0, 2.0, 3.0],
            lambda x, y: cp_to_view(x, -y), "x/c", "−Cp",
        )  # fmt: skip
        log(ENTITY["cp_axes"], lines, ticks, static=True)
        lines, ticks = _axes(
            [0.0, 10.0, 20.0, 30.0], [0.0, 0.5, 1.0, 1.5, 2.0], cl_alpha_to_view, "α [deg]", "C_l"
        )
        log(ENTITY["cl_alpha_axes"], lines, ticks, static=True)

    def _set_time(self, t_ns: int | None) -> None:
        """Set the experiment time; ``None``: the latest stamp seen (or now, before any)."""
        if t_ns is None or t_ns <= 0:
            t_ns = self.last_ns if self.last_ns is not None else time.time_ns()
        else:
            self.last_ns = t_ns if self.last_ns is None else max(self.last_ns, t_ns)
        self.rec.set_time(TIMELINE, timestamp=np.datetime64(int(t_ns), "ns"))

    @staticmethod
    def _pitch_deg(msg: Any) -> float | None:
        names = list(msg.name)
        i = names.index("pitch") if "pitch" in names else 0
        if i >= len(msg.position):
            return None
        value = float(msg.position[i])
        return math.degrees(value) if math.isfinite(value) else None

    def _clear_missing(self, prefix: str, present: set[str]) -> None:
        """Clear entities under ``prefix`` logged by an earlier model but absent now."""
        for path in sorted(p for p in self._model_entities if p.startswith(prefix)):
            if path not in present:
                self.rec.log(path, rr.Clear(recursive=True))
                self._model_entities.discard(path)
        self._model_entities |= present

    # -- sample streams ------------------------------------------------------------------------

    def on_command(self, msg: Any) -> None:
        n = self.counts["command"]
        self.counts["command"] += 1
        deg = self._pitch_deg(msg)
        if deg is None or n % self.series_decimation:
            return
        self._set_time(stamp_to_ns(msg.header.stamp))
        self.rec.log(ENTITY["command"], rr.Scalars(deg))

    def on_state(self, msg: Any) -> None:
        n = self.counts["state"]
        self.counts["state"] += 1
        deg = self._pitch_deg(msg)
        if deg is None:
            return
        t_ns = stamp_to_ns(msg.header.stamp)
        self._alpha_by_stamp[t_ns] = deg
        while len(self._alpha_by_stamp) > 4096:
            self._alpha_by_stamp.popitem(last=False)
        self._last_alpha = deg
        if n % self.series_decimation:
            return
        self._set_time(t_ns)
        self.rec.log(ENTITY["measured"], rr.Scalars(deg))

    def on_coefficients(self, msg: Any) -> None:
        n = self.counts["coefficients"]
        self.counts["coefficients"] += 1
        cl = float(msg.vector.x)
        if not math.isfinite(cl):  # NaN = invalid sample (DESIGN.md §8): a gap, not a value
            self.counts["cl_invalid"] += 1
            return
        t_ns = stamp_to_ns(msg.header.stamp)
        if n % self.series_decimation == 0:
            self._set_time(t_ns)
            self.rec.log(ENTITY["cl"], rr.Scalars(cl))
        if n % self.taps_decimation:
            return
        # The live C_l–α trail: decimated samples of the last trail_s seconds, as one strip.
        alpha = self._alpha_by_stamp.get(t_ns, self._last_alpha)
        if alpha is None:
            return
        self._trail.append((t_ns, alpha, cl))
        while self._trail and self._trail[0][0] < t_ns - self.trail_ns:
            self._trail.popleft()
        if len(self._trail) >= 2:
            trail = np.array([(a, c) for _, a, c in self._trail])
            x, y = cl_alpha_to_view(trail[:, 0], trail[:, 1])
            self._set_time(t_ns)
            self.rec.log(
                ENTITY["cl_alpha_live"],
                rr.LineStrips2D([np.column_stack([x, y])], colors=GREEN, radii=-1.5),
            )

    def on_taps(self, msg: Any) -> None:
        n = self.counts["taps"]
        self.counts["taps"] += 1
        if n % self.taps_decimation:
            return
        xyz, pressures = read_cloud(msg)
        x_c = xyz[:, 0] / self.chord_m
        cp = pressures / self.q_pa
        self._set_time(stamp_to_ns(msg.header.stamp))
        z = xyz[:, 2]
        upper = z >= -1e-9  # the leading-edge tap (z = 0) closes both surfaces
        lower = z <= 1e-9
        for key, mask, color in (("cp_upper", upper, BLUE), ("cp_lower", lower, ORANGE)):
            order = np.argsort(x_c[mask], kind="stable")
            vx, vy = cp_to_view(x_c[mask][order], cp[mask][order])
            self.rec.log(ENTITY[key], rr.LineStrips2D(finite_runs(vx, vy), colors=color))
        ok = np.isfinite(cp)
        vx, vy = cp_to_view(x_c[ok], cp[ok])
        colors = np.where((z[ok] > 1e-9)[:, None], BLUE, ORANGE).astype(np.uint8)
        self.rec.log(
            ENTITY["cp_taps"], rr.Points2D(np.column_stack([vx, vy]), colors=colors, radii=-3.0)
        )

    # -- events --------------------------------------------------------------------------------

    def on_segment(self, msg: Any) -> None:
        self.counts["segment"] += 1
        event = json_object(msg.data, "/experiment/segment")
        edge = event.get("event", "?")
        stamp_key = {"start": "start_stamp_s", "end": "end_stamp_s"}.get(edge)
        t_ns = None
        if stamp_key and isinstance(event.get(stamp_key), int | float):
            t_ns = round(event[stamp_key] * 1e9)
        self._set_time(t_ns)
        level = "WARN" if edge == "plan_aborted" else "INFO"
        self.rec.log(ENTITY["segment"], rr.TextLog(describe_segment(event), level=level))

    def on_status(self, msg: Any) -> None:
        self.counts["status"] += 1
        self._set_time(stamp_to_ns(msg.header.stamp))
        for status in msg.status:
            values = tuple((kv.key, kv.value) for kv in status.values)
            key = (int(status.level), status.message, values)
            if self._status_seen.get(status.name) == key:
                continue  # only changes reach the log
            self._status_seen[status.name] = key
            text = f"{status.name}: {status.message}"
            if values:
                text += " (" + ", ".join(f"{k}={v}" for k, v in values) + ")"
            level = STATUS_LEVELS.get(int(status.level), "WARN")
            self.rec.log(ENTITY["status"], rr.TextLog(text, level=level))

    # -- model ---------------------------------------------------------------------------------

    def on_model(self, msg: Any) -> None:
        self.counts["model"] += 1
        model = json_object(msg.data, "/identification/model")
        stamp = model.get("stamp_ns")
        self._set_time(int(stamp) if isinstance(stamp, int | float) else None)
        levels = model.get("levels") or {}
        if not isinstance(levels, dict):
            levels = {}
        summary = [f"# Model refit {model.get('refit', '?')}", ""]
        frf_paths: set[str] = set()
        cluster_paths: set[str] = set()
        for name, level in sorted(levels.items()):
            if not isinstance(level, dict):
                continue
            frf_paths |= self._log_frf(name, level.get("bla") or {})
            paths, text = self._log_clusters(name, level.get("clusters") or {})
            cluster_paths |= paths
            offset = level.get("offset_deg")
            head = f"- level {name}" + (f" (offset {offset:g}°)" if offset is not None else "")
            summary.append(head + (f": {text}" if text else ""))
        self._clear_missing("/frf/", frf_paths)
        self._clear_missing("/clusters/", cluster_paths)
        self._clear_missing("/cl_alpha/predictions/", self._log_predictions(model))
        summary.append("")
        summary.append(
            "FRF variances as published by the identifier (var_noise, var_nl); "
            "C_l–α plot: α [deg] right, C_l up."
        )
        self.rec.log(
            ENTITY["summary"], rr.TextDocument("\n".join(summary), media_type="text/markdown")
        )
        table = (model.get("table1") or {}).get("markdown")
        if isinstance(table, str) and table.strip():
            self.rec.log(ENTITY["table1"], rr.TextDocument(table, media_type="text/markdown"))
        self.rec.log(
            ENTITY["model_event"],
            rr.TextLog(
                f"model refit {model.get('refit', '?')}: levels {sorted(levels)}, "
                f"{len(model.get('predictions') or [])} predictions",
                level="INFO",
            ),
        )
        names = sorted(str(k) for k in levels)
        if self._send_blueprint and names != self._levels:
            self.rec.send_blueprint(make_blueprint(names))
        self._levels = names

    def _log_frf(self, level: str, bla: dict[str, Any]) -> set[str]:
        f = _float_array(bla.get("freq_hz"))
        if f.size == 0:
            return set()
        g = _float_array(bla.get("G_re")) + 1j * _float_array(bla.get("G_im"))
        if g.shape != f.shape:
            raise ValueError(f"level {level}: G_re/G_im length differs from freq_hz")
        steps = np.diff(np.sort(f))
        steps = steps[steps > 0]
        df = float(np.median(steps)) if steps.size else 0.04
        base = f"/frf/level_{slug(level)}"
        series = [("G_dB", _db(np.abs(g), power=False), 0.0, BLUE)]
        for key, name, shift, color in (
            ("var_noise", "noise_dB", -0.25, GRAY),
            ("var_nl", "nl_distortion_dB", 0.25, RED),
        ):
            v = _float_array(bla.get(key))
            if v.shape == f.shape:
                series.append((name, _db(v, power=True), shift, color))
        paths = set()
        for name, values, shift, color in series:
            ok = np.isfinite(values) & np.isfinite(f)
            path = f"{base}/{name}"
            self.rec.log(
                path,
                rr.BarChart(
                    values[ok], abscissa=f[ok] + shift * df, widths=[0.22 * df], color=color
                ),
            )
            paths.add(path)
        return paths

    def _log_clusters(self, level: str, clusters: dict[str, Any]) -> tuple[set[str], str]:
        labels = clusters.get("labels")
        if not labels:
            return set(), ""
        arr = np.array(labels, dtype=np.int64)
        if arr.ndim != 2:
            raise ValueError(f"level {level}: clusters.labels must be P x M, got {arr.shape}")
        n_periods, n_real = arr.shape
        dominant = clusters.get("dominant")
        # Periods in time order: realization by realization, period by period.
        order = arr.T.reshape(-1)
        index = np.arange(1, order.size + 1)
        paths = set()
        base = f"/clusters/level_{slug(level)}"
        for c in np.unique(order):
            path = f"{base}/cluster_{c}" if c >= 0 else f"{base}/excluded"
            height = 1.0 if c == dominant else (0.6 if c >= 0 else 0.3)
            color = CLUSTER_COLORS[c % len(CLUSTER_COLORS)] if c >= 0 else GRAY
            sel = order == c
            self.rec.log(
                path,
                rr.BarChart(
                    np.full(int(sel.sum()), height), abscissa=index[sel], widths=[0.8], color=color
                ),
            )
            paths.add(path)
        rows = "; ".join(f"r{m}: {' '.join(map(str, arr[:, m]))}" for m in range(n_real))
        text = f"k = {clusters.get('k', '?')}, dominant {dominant}, labels per period {rows}"
        return paths, text + f" ({n_periods} periods x {n_real} realizations)"

    def _log_predictions(self, model: dict[str, Any]) -> set[str]:
        paths = set()
        for i, pred in enumerate(model.get("predictions") or []):
            if not isinstance(pred, dict):
                continue
            alpha = _float_array(pred.get("alpha_deg"))
            base = f"/cl_alpha/predictions/{slug(pred.get('name', f'prediction {i}'))}"
            for key, name, color in PREDICTION_SERIES:
                cl = _float_array(pred.get(key))
                if cl.size == 0 or cl.shape != alpha.shape:
                    continue
                x, y = cl_alpha_to_view(alpha, cl)
                path = f"{base}/{name}"
                radius = -2.0 if name == "measured" else -1.0
                self.rec.log(path, rr.LineStrips2D(finite_runs(x, y), colors=color, radii=radius))
                paths.add(path)
        return paths

    def flush(self, timeout_s: float = 10.0) -> None:
        self.rec.flush(timeout_sec=timeout_s)


def describe_segment(event: dict[str, Any]) -> str:
    """One line for a segment event: ``start multisine level 0 realization 1 period 2 …``."""
    edge = event.get("event", "?")
    if edge not in ("start", "end"):
        extra = {k: v for k, v in event.items() if k != "event"}
        return f"{edge} {json.dumps(extra, sort_keys=True)}"
    parts = [edge, str(event.get("kind", "?"))]
    for key in ("level", "realization", "period"):
        if event.get(key) is not None:
            parts.append(f"{key} {event[key]}")
    if event.get("kind") in ("sine",) or event.get("excitation") == "sine":
        if event.get("frequency_hz") is not None:
            parts.append(f"{event['frequency_hz']:g} Hz")
    if event.get("offset_deg") is not None:
        parts.append(f"(offset {event['offset_deg']:g}°)")
    if event.get("index") is not None:
        parts.append(f"[segment {event['index']}]")
    return " ".join(parts)


# -- recordings ------------------------------------------------------------------------------

MODES = ("save", "spawn", "serve", "connect", "none")


def open_recording(
    application_id: str,
    mode: str,
    rrd_path: str | Path | None = None,
    *,
    port: int = 0,
    url: str = "",
    bind_ip: str = "127.0.0.1",
    blueprint: rrb.Blueprint | None = None,
) -> tuple[rr.RecordingStream, str]:
    """A recording stream with its sinks for ``mode``; returns it and a line saying where to."""
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}: expected one of {list(MODES)}")
    if mode == "save" and not rrd_path:
        raise ValueError(
            "mode 'save' needs rrd_path (e.g. -p rrd_path:=run.rrd), or use -p mode:=spawn"
        )
    rec = rr.RecordingStream(application_id, default_enabled=mode != "none")
    if mode == "none":
        return rec, "rerun off: counting messages only"
    sinks: list[Any] = []
    where = []
    if mode == "spawn":
        rr.spawn(port=port or 9876, connect=False, recording=rec)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{port or 9876}/proxy"))
        where.append(f"spawned viewer on port {port or 9876}")
    elif mode == "serve":
        server = rr.GrpcServerSink(bind_ip, port or 9876)
        sinks.append(server)
        where.append(f"serving at {server.uri}")
    elif mode == "connect":
        sinks.append(rr.GrpcSink(url or None))
        where.append(f"streaming to {url or 'the default viewer address'}")
    if rrd_path:
        path = Path(rrd_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(path)))
        where.append(f"saving to {path}")
    rec.set_sinks(*sinks, default_blueprint=blueprint)
    return rec, ", ".join(where)


def close_recording(rec: rr.RecordingStream, timeout_s: float = 10.0) -> None:
    """Flush everything logged so far and finalise the sinks (an .rrd gets its footer)."""
    rec.flush(timeout_sec=timeout_s)
    rec.disconnect()


# -- offline ---------------------------------------------------------------------------------

TOPICS: dict[str, tuple[str, str]] = {
    # topic: (type, handler). QoS for the live node in View.QOS.
    "/pitch/command": ("sensor_msgs/msg/JointState", "on_command"),
    "/pitch/state": ("sensor_msgs/msg/JointState", "on_state"),
    "/pressure/taps": ("sensor_msgs/msg/PointCloud2", "on_taps"),
    "/wing/coefficients": ("geometry_msgs/msg/Vector3Stamped", "on_coefficients"),
    "/experiment/segment": ("std_msgs/msg/String", "on_segment"),
    "/identification/model": ("std_msgs/msg/String", "on_model"),
    "/identification/status": ("diagnostic_msgs/msg/DiagnosticArray", "on_status"),
}


def _route(topic: str) -> str | None:
    """The known topic a bag topic is (exactly, or under a namespace: ``/rig/pitch/state``)."""
    if topic in TOPICS:
        return topic
    return next((t for t in TOPICS if topic.endswith(t)), None)


def view_bag(
    bag_path: str | Path,
    rrd_path: str | Path | None = None,
    spawn: bool = False,
    *,
    application_id: str = "aero_rig",
    taps_decimation: int = 10,
    series_decimation: int = 1,
) -> Path | None:
    """Replay a rosbag2 directory (MCAP or sqlite3) through :class:`RigViewLogger`.

    Writes ``rrd_path`` (default: ``<bag>.rrd`` beside the bag unless ``spawn``), and/or streams
    to a spawned viewer. Returns the .rrd path (None when only spawning). Messages go in bag
    order; an unreadable message is skipped and reported on ``/events/view``.
    """
    from rig_runtime.messages import typestore
    from rosbags.highlevel import AnyReader

    bag = Path(bag_path)
    if not bag.exists():
        raise FileNotFoundError(f"no bag at {bag}")
    if rrd_path is None and not spawn:
        rrd_path = bag.with_name(bag.name + ".rrd") if bag.is_dir() else bag.with_suffix(".rrd")
    rec, _ = open_recording(application_id, "spawn" if spawn else "save", rrd_path)
    try:
        view = RigViewLogger(
            rec, taps_decimation=taps_decimation, series_decimation=series_decimation
        )
        with AnyReader([bag], default_typestore=typestore()) as reader:
            conns = []
            for conn in reader.connections:
                topic = _route(conn.topic)
                if topic is not None and conn.msgtype == TOPICS[topic][0]:
                    conns.append((conn, getattr(view, TOPICS[topic][1])))
            handlers = {c.id: h for c, h in conns}
            errors = 0
            for conn, _t, raw in reader.messages(connections=[c for c, _ in conns]):
                try:
                    handlers[conn.id](reader.deserialize(raw, conn.msgtype))
                except ValueError as exc:
                    errors += 1
                    if errors <= 20:
                        rec.log("/events/view", rr.TextLog(f"{conn.topic}: {exc}", level="WARN"))
    finally:
        close_recording(rec)
    return Path(rrd_path) if rrd_path else None


# -- node ------------------------------------------------------------------------------------

PARAMETERS = [
    Parameter("mode", "save", "where the view goes", choices=MODES),
    Parameter("rrd_path", "", ".rrd file to write (needed by 'save'; other modes also save)"),
    Parameter("application_id", "aero_rig", "Rerun application id (groups recordings)"),
    Parameter("taps_decimation", 10, "log every n-th Cp distribution / C_l–α trail", min=1),
    Parameter("series_decimation", 1, "log every n-th pitch / C_l sample", min=1),
    Parameter("trail_s", 2.0, "length of the live C_l–α trail [s]", min=0.0),
    Parameter("port", 0, "spawn: viewer port; serve: gRPC port (0 = 9876)", min=0, max=65535),
    Parameter("bind_ip", "127.0.0.1", "serve: address to listen on (0.0.0.0 = all)"),
    Parameter("url", "", "connect: viewer gRPC URL (empty: rerun+http://127.0.0.1:9876/proxy)"),
    Parameter("stats_period_s", 10.0, "log message counts every … s (0 = never)", min=0.0),
]


class View:
    """The view node: subscribes the rig topics and feeds a :class:`RigViewLogger`.

    High-rate streams are read best effort (a slow viewer drops samples, it never holds back
    the experiment; best effort matches reliable and best-effort publishers); segment events
    reliable and deep; model and status latched, so a late view still gets the current model.
    """

    QOS: ClassVar[dict[str, tuple[str, int | None]]] = {
        "/pitch/command": ("sensor", 1000),
        "/pitch/state": ("sensor", 1000),
        "/pressure/taps": ("sensor", 200),
        "/wing/coefficients": ("sensor", 1000),
        "/experiment/segment": ("events", None),
        "/identification/model": ("latched", None),
        "/identification/status": ("latched", 100),
    }

    def __init__(self, node: Node) -> None:
        p = node.params
        self.node = node
        self.rec, where = open_recording(
            p["application_id"],
            p["mode"],
            p["rrd_path"] or None,
            port=p["port"],
            url=p["url"],
            bind_ip=p["bind_ip"],
        )
        self.logger = RigViewLogger(
            self.rec,
            taps_decimation=p["taps_decimation"],
            series_decimation=p["series_decimation"],
            trail_s=p["trail_s"],
        )
        self.errors = 0
        for topic, (type_name, handler) in TOPICS.items():
            qos, depth = self.QOS[topic]
            node.create_subscription(
                type_name, topic, self._guard(topic, getattr(self.logger, handler)), qos, depth
            )
        if p["stats_period_s"] > 0:
            node.create_timer(p["stats_period_s"], self.log_stats)
        node.logger.info("view: %s", where)

    def _guard(self, topic: str, handler: Callable[[Any], None]) -> Callable[[Any], None]:
        def call(msg: Any) -> None:
            try:
                handler(msg)
            except (ValueError, KeyError, TypeError) as exc:
                self.errors += 1
                if self.errors <= 20 or self.errors % 1000 == 0:
                    self.node.logger.warning("%s: %s (%d bad messages)", topic, exc, self.errors)

        return call

    def log_stats(self) -> None:
        counts = " ".join(f"{k}={v}" for k, v in self.logger.counts.items())
        self.node.logger.info("received %s errors=%d", counts, self.errors)

    def close(self) -> None:
        self.log_stats()
        close_recording(self.rec)


def main(argv: Sequence[str] | None = None) -> int:
    # rerun and rclpy's numpy 1.26 extensions cannot share a process (DESIGN.md §3).
    previous = os.environ.get(BACKEND_ENV)
    if (previous or "").strip().lower() == "rclpy":
        print(
            f"[FATAL] [view]: {BACKEND_ENV}=rclpy: the Rerun view runs on the Cyclone DDS "
            "backend only (rerun needs numpy >= 2)",
            file=sys.stderr,
        )
        return EXIT_CONFIG_ERROR
    os.environ[BACKEND_ENV] = "dds"
    try:
        return run_node(View, "view", PARAMETERS, argv, description=__doc__)
    finally:
        if previous is None:
            os.environ.pop(BACKEND_ENV, None)
        else:
            os.environ[BACKEND_ENV] = previous


if __name__ == "__main__":
    raise SystemExit(main())
