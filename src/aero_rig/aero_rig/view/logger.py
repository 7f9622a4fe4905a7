"""``RigViewLogger``: rig messages (plain objects, no middleware) into Rerun logs.

The event and model topics are aero_rig_interfaces messages; a bag recorded before them
carries the same payloads as std_msgs/String JSON, and each is read through its topic's one
reader (multisine_gen.plan_format.segment_event_from_message,
aero_identification.model_message.model_from_message), which takes both.
"""

import json
import math
import struct
import time
from array import array
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rerun as rr

from aero_identification import model_payload as mm
from aero_identification.model_message import model_from_message
from aero_identification.quality import data_quality_lines
from multisine_gen.plan_format import segment_event_from_message
from pressure_scanner.tap_cloud import read_cloud
from pressure_scanner.wing_geometry import RigGeometry
from rig_runtime import stamp_to_ns
from rig_runtime.interface import (
    IDENTIFICATION_MODEL,
    PITCH_JOINT,
    PRESSURE_TAPS,
    joint_position,
)
from rig_runtime.messages import cdr_stamp_ns, deserialize

from .blueprint import (
    BLUE,
    CLUSTER_COLORS,
    ENTITY,
    GRAY,
    GREEN,
    LEGEND_AT,
    LEGEND_STEP,
    ORANGE,
    PREDICTION_COLORS,
    RED,
    SPARE_COLORS,
    TIMELINE,
    cl_alpha_to_view,
    cp_to_view,
    make_blueprint,
    slug,
)

STATUS_LEVELS = {0: "INFO", 1: "WARN", 2: "ERROR", 3: "WARN"}
STAMPED = ("command", "state", "coefficients", "taps", "taps_drawn")
MAX_WARNED = 100  # subjects the view names on /events/view; more are only counted


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


class RigViewLogger:
    """Logs rig messages to a Rerun recording; no middleware (plain message objects in).

    One ``on_<topic>`` method per topic. Time series are logged at every
    ``series_decimation``-th sample, the Cp distribution and the live C_l–α trail at every
    ``taps_decimation``-th. Model updates replace the FRF, cluster and prediction entities.
    Unparseable input raises ``ValueError``; callers decide whether to go on.

    The time series (pitch command and measurement, C_l: three of every four log calls at the
    rig's rate) are buffered and sent as columns (``rr.send_columns``, each sample at its own
    stamp) once ``series_batch`` samples of a series are waiting, and by :meth:`send_series`,
    which the live node calls on a timer and :meth:`flush` calls: one call per batch instead of
    one ``log`` and one ``set_time`` per sample (docs/design.md §3.9).
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        *,
        taps_decimation: int = 10,
        series_decimation: int = 1,
        series_batch: int = 200,
        trail_s: float = 2.0,
        dynamic_pressure_pa: float | None = None,
        chord_m: float | None = None,
        send_blueprint: bool = True,
    ) -> None:
        if taps_decimation < 1 or series_decimation < 1 or series_batch < 1:
            raise ValueError("taps_decimation, series_decimation and series_batch must be >= 1")
        wing = RigGeometry()
        self.rec = recording
        self.taps_decimation = int(taps_decimation)
        self.series_decimation = int(series_decimation)
        self.series_batch = int(series_batch)
        # Per series entity: the stamps [ns] and values not yet sent.
        self._series: dict[str, tuple[list[int], list[float]]] = {
            key: ([], []) for key in ("command", "measured", "cl")
        }
        self.trail_ns = int(trail_s * 1e9)
        self.q_pa = float(dynamic_pressure_pa or wing.dynamic_pressure_pa)
        self.chord_m = float(chord_m or wing.chord_m)
        self.counts = dict.fromkeys(
            ("command", "state", "taps", "coefficients", "segment", "model", "status"), 0
        )
        self.counts.update(cl_invalid=0, taps_drawn=0, warnings=0)
        # The stamps received per stream (and of the Cp frames drawn), to count at the end what
        # the view missed inside the plan: (t0_ns, samples, fs) from the plan_end event.
        self._stamps = {key: array("q") for key in STAMPED}
        self.plan: tuple[int, int, float] | None = None
        self.last_ns: int | None = None
        self._alpha_by_stamp: OrderedDict[int, float] = OrderedDict()
        self._last_alpha: float | None = None
        self._trail: deque[tuple[int, float, float]] = deque()
        self._send_blueprint = send_blueprint
        self._levels: list[str] = []
        self._series_colors: dict[str, tuple[int, int, int]] = {}  # by model, in order seen
        self._model_entities: set[str] = set()
        self._status_seen: dict[str, tuple[Any, ...]] = {}
        self._quality_line = ""
        self._warned: set[str] = set()
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

    def _stamp(self, t_ns: int | None) -> int:
        """A message's experiment time [ns]; ``None`` or unset: the latest stamp seen (or now,
        before any)."""
        if t_ns is None or t_ns <= 0:
            return self.last_ns if self.last_ns is not None else time.time_ns()
        self.last_ns = t_ns if self.last_ns is None else max(self.last_ns, t_ns)
        return t_ns

    def _set_time(self, t_ns: int | None) -> None:
        """Set the experiment time of the next ``log`` calls (see ``_stamp``)."""
        self.rec.set_time(TIMELINE, timestamp=np.datetime64(int(self._stamp(t_ns)), "ns"))

    def _series_sample(self, key: str, t_ns: int | None, value: float) -> None:
        """Buffer one sample of a time series; send the series once a batch is waiting."""
        times, values = self._series[key]
        times.append(self._stamp(t_ns))
        values.append(value)
        if len(times) >= self.series_batch:
            self._send_series(key)

    def _send_series(self, key: str) -> None:
        times, values = self._series[key]
        if not times:
            return
        self.rec.send_columns(
            ENTITY[key],
            indexes=[rr.TimeColumn(TIMELINE, timestamp=np.array(times, dtype="datetime64[ns]"))],
            columns=rr.Scalars.columns(scalars=np.array(values, dtype=np.float64)),
        )
        times.clear()
        values.clear()

    def send_series(self) -> None:
        """Send every buffered time-series sample now (the live node's timer, and flush)."""
        for key in self._series:
            self._send_series(key)

    @staticmethod
    def _pitch_deg(msg: Any) -> float | None:
        value = joint_position(msg, PITCH_JOINT)
        return None if value is None else math.degrees(value)

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
        self._stamps["command"].append(stamp_to_ns(msg.header.stamp))
        deg = self._pitch_deg(msg)
        if deg is None or n % self.series_decimation:
            return
        self._series_sample("command", stamp_to_ns(msg.header.stamp), deg)

    def on_state(self, msg: Any) -> None:
        n = self.counts["state"]
        self.counts["state"] += 1
        t_ns = stamp_to_ns(msg.header.stamp)
        self._stamps["state"].append(t_ns)
        deg = self._pitch_deg(msg)
        if deg is None:
            return
        self._alpha_by_stamp[t_ns] = deg
        while len(self._alpha_by_stamp) > 4096:
            self._alpha_by_stamp.popitem(last=False)
        self._last_alpha = deg
        if n % self.series_decimation:
            return
        self._series_sample("measured", t_ns, deg)

    def on_coefficients(self, msg: Any) -> None:
        n = self.counts["coefficients"]
        self.counts["coefficients"] += 1
        self._stamps["coefficients"].append(stamp_to_ns(msg.header.stamp))
        cl = float(msg.vector.x)
        if not math.isfinite(cl):  # NaN = invalid sample (docs/design.md §8): a gap, not a value
            self.counts["cl_invalid"] += 1
            return
        t_ns = stamp_to_ns(msg.header.stamp)
        if n % self.series_decimation == 0:
            self._series_sample("cl", t_ns, cl)
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
        self.counts["taps_drawn"] += 1
        self._stamps["taps_drawn"].append(stamp_to_ns(msg.header.stamp))
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

    def on_taps_cdr(self, cdr: bytes | memoryview) -> None:
        """``on_taps`` of a serialized PointCloud2 (CDR, as on the wire and in a bag): only the
        samples it logs (every ``taps_decimation``-th) are deserialized, the others counted."""
        try:
            self._stamps["taps"].append(cdr_stamp_ns(cdr))
        except struct.error:
            pass  # too short for a header: deserialize names it below if it is drawn
        if self.counts["taps"] % self.taps_decimation:
            self.counts["taps"] += 1
            return
        try:
            msg = deserialize(cdr, PRESSURE_TAPS.type)
        except Exception as exc:  # the CDR reader's struct/index errors: the input is bad
            self.counts["taps"] += 1
            raise ValueError(f"{PRESSURE_TAPS.name}: not a {PRESSURE_TAPS.type} ({exc})") from None
        self.on_taps(msg)

    # -- events --------------------------------------------------------------------------------

    def on_segment(self, msg: Any) -> None:
        """A SegmentEvent (or the std_msgs/String JSON of an older bag): a text log line; the
        plan_end event gives the plan's first stamp, samples and rate for :meth:`report`."""
        self.counts["segment"] += 1
        event = segment_event_from_message(msg)  # PlanError (a ValueError) naming the topic
        edge = event.get("event", "?")
        stamp_key = {"start": "start_stamp_s", "end": "end_stamp_s"}.get(edge)
        t_ns = None
        if stamp_key and isinstance(event.get(stamp_key), int | float):
            t_ns = round(event[stamp_key] * 1e9)
        self._set_time(t_ns)
        if edge == "plan_end":
            t0, samples, fs = event.get("t0_ns"), event.get("samples"), event.get("fs")
            if (
                isinstance(t0, int | float)
                and isinstance(samples, int | float)
                and isinstance(fs, int | float)
                and samples > 0 < fs
            ):
                self.plan = (int(t0), int(samples), float(fs))
        level = "WARN" if edge in ("plan_aborted", "refused") else "INFO"
        entity = ENTITY["adaptive"] if edge in ("decision", "refused") else ENTITY["segment"]
        self.rec.log(entity, rr.TextLog(describe_segment(event), level=level))

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
        """A model update: FRFs, clusters, predictions, Table 1, the summary and the data-quality
        line. What cannot be drawn is named once on ``/events/view`` (`model_payload.problems`)
        and left out; the rest is drawn."""
        self.counts["model"] += 1
        model = model_from_message(msg)  # ValueError naming the topic
        stamp = model.get(mm.STAMP_NS)
        header = getattr(msg, "header", None)  # IdentificationModel: the fit's last sample
        if not isinstance(stamp, int | float) and header is not None:
            stamp = stamp_to_ns(header.stamp) or None
        self._set_time(int(stamp) if isinstance(stamp, int | float) else None)
        topic = IDENTIFICATION_MODEL.name
        for field, problem in mm.problems(model):
            self.warn(f"{topic}: {field}", problem)
        levels = model.get(mm.LEVELS)
        if not isinstance(levels, dict):
            levels = {}
        refit = model.get(mm.REFIT, "?")
        summary = [f"# Model refit {refit}", ""]
        frf_paths: set[str] = set()
        cluster_paths: set[str] = set()
        for name, level in sorted(levels.items()):
            if not isinstance(level, dict):
                continue
            try:  # a level that cannot be drawn is named, the others are drawn
                frf_paths |= self._log_frf(name, level.get(mm.BLA) or {})
                paths, text = self._log_clusters(name, level.get(mm.CLUSTERS) or {})
            except (ValueError, TypeError, AttributeError) as exc:
                self.warn(f"{topic}: {mm.LEVELS}.{name}", f"not drawn ({exc})")
                continue
            cluster_paths |= paths
            offset = level.get(mm.OFFSET_DEG)
            where = f" (offset {offset:g}°)" if isinstance(offset, int | float) else ""
            summary.append(f"- level {name}{where}" + (f": {text}" if text else ""))
        self._clear_missing("/frf/", frf_paths)
        self._clear_missing("/clusters/", cluster_paths)
        self._clear_missing("/cl_alpha/predictions/", self._log_predictions(model))
        quality = self._log_data_quality(model.get(mm.DATA_QUALITY))
        summary += ["", quality, ""]
        summary.append(
            "FRF: |G| and the noise and nonlinear-distortion variances as published by the "
            "identifier, per excited line [dB]. C_l–α: α [deg] right, C_l up."
        )
        self.rec.log(
            ENTITY["summary"], rr.TextDocument("\n".join(summary), media_type="text/markdown")
        )
        table = model.get(mm.TABLE1)
        tables = [
            f"## {title}\n\n{table[key]}"
            for key, title in mm.TABLE1_TITLES.items()
            if isinstance(table, dict) and isinstance(table.get(key), str) and table[key].strip()
        ]
        if tables:
            self.rec.log(
                ENTITY["table1"], rr.TextDocument("\n\n".join(tables), media_type="text/markdown")
            )
        predictions = model.get(mm.PREDICTIONS)
        self.rec.log(
            ENTITY["model_event"],
            rr.TextLog(
                f"model refit {refit}: levels {sorted(levels)}, "
                f"{len(predictions) if isinstance(predictions, list) else 0} predictions",
                level="INFO",
            ),
        )
        self._update_blueprint(sorted(str(k) for k in levels))

    def _update_blueprint(self, levels: list[str]) -> None:
        """Send the layout again when the levels have changed (an FRF and a cluster view each)."""
        if self._send_blueprint and levels != self._levels:
            self.rec.send_blueprint(make_blueprint(levels))
        self._levels = levels

    def _log_data_quality(self, quality: Any) -> str:
        """The data-quality line (also on ``/events/data_quality`` when it changes)."""
        samples = quality.get("samples") if isinstance(quality, dict) else None
        if not isinstance(quality, dict) or not isinstance(samples, dict):
            return "data quality: not reported"
        counts = ", ".join(
            f"{name} {c.get('received', '?')} of {c.get('expected', '?')}"
            for name, c in samples.items()
            if isinstance(c, dict)
        )
        try:
            problems = data_quality_lines(quality) if quality.get("clean") is False else []
        except (KeyError, TypeError, AttributeError) as exc:
            problems = [f"the account cannot be read ({exc!r})"]
        line = "data quality: " + ("not clean: " + "; ".join(problems) if problems else "clean")
        line += f" (plan samples received: {counts})" if counts else ""
        if line != self._quality_line:
            self._quality_line = line
            level = "WARN" if problems else "INFO"
            self.rec.log(ENTITY["data_quality"], rr.TextLog(line, level=level))
        return line

    def _log_frf(self, level: str, bla: dict[str, Any]) -> set[str]:
        f = _float_array(bla.get(mm.FREQ_HZ))
        re, im = _float_array(bla.get(mm.G_RE)), _float_array(bla.get(mm.G_IM))
        if f.size == 0 or not f.shape == re.shape == im.shape:
            return set()  # named by model_payload.problems
        g = re + 1j * im
        steps = np.diff(np.sort(f))
        steps = steps[steps > 0]
        df = float(np.median(steps)) if steps.size else 0.04
        base = f"/frf/level_{slug(level)}"
        series = [("G_dB", _db(np.abs(g), power=False), 0.0, BLUE)]
        for key, name, shift, color in (
            (mm.VAR_NOISE, "noise_dB", -0.25, GRAY),
            (mm.VAR_NL, "nl_distortion_dB", 0.25, RED),
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
        labels = clusters.get(mm.LABELS)
        if not labels:
            return set(), ""
        try:
            arr = np.array(labels, dtype=np.int64)
        except (TypeError, ValueError):
            return set(), ""  # named by model_payload.problems
        if arr.ndim != 2:
            return set(), ""
        n_periods, n_real = arr.shape
        dominant = clusters.get(mm.DOMINANT)
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
        text = f"k = {clusters.get(mm.K, '?')}, dominant {dominant}, labels per period {rows}"
        return paths, text + f" ({n_periods} periods x {n_real} realizations)"

    def _series_color(self, model: str) -> tuple[int, int, int]:
        """A model's colour: fixed for the known models, the next free one for a new model; a
        new series redraws the legend."""
        if model not in self._series_colors:
            known = dict(PREDICTION_COLORS)
            spare = [c for c in SPARE_COLORS if c not in self._series_colors.values()]
            self._series_colors[model] = known.get(model) or (spare or SPARE_COLORS)[0]
            self._log_legend()
        return self._series_colors[model]

    def _log_legend(self) -> None:
        """The C_l–α view's legend: one labelled point per series, the known ones in their order
        (PREDICTION_COLORS), then the others as seen, the live trail last, from LEGEND_AT down
        (static: it holds at every time)."""
        known = [name for name, _ in PREDICTION_COLORS]
        order = sorted(self._series_colors, key=lambda n: known.index(n) if n in known else 99)
        entries = [(n, self._series_colors[n]) for n in order] + [("live trail", GREEN)]
        alpha = np.full(len(entries), LEGEND_AT[0])
        cl = LEGEND_AT[1] - LEGEND_STEP * np.arange(len(entries))
        x, y = cl_alpha_to_view(alpha, cl)
        self.rec.log(
            ENTITY["cl_alpha_legend"],
            rr.Points2D(
                np.column_stack([x, y]),
                colors=[color for _, color in entries],
                labels=[name for name, _ in entries],
                show_labels=True,
                radii=-5.0,
            ),
            static=True,
        )

    def _log_predictions(self, model: dict[str, Any]) -> set[str]:
        """Every C_l series of every validation sine, one strip entity per model and sine."""
        paths = set()
        predictions = model.get(mm.PREDICTIONS)
        for i, pred in enumerate(predictions if isinstance(predictions, list) else []):
            if not isinstance(pred, dict):
                continue
            try:
                alpha = _float_array(pred.get(mm.ALPHA_DEG))
            except (TypeError, ValueError):
                continue  # named by model_payload.problems
            base = f"/cl_alpha/predictions/{slug(pred.get(mm.NAME, f'prediction {i}'))}"
            for name, values in mm.prediction_series(pred):
                try:
                    cl = _float_array(values)
                except (TypeError, ValueError):
                    continue  # named by model_payload.problems
                if cl.size == 0 or cl.shape != alpha.shape:
                    continue
                x, y = cl_alpha_to_view(alpha, cl)
                path = f"{base}/{slug(name)}"
                color = self._series_color(name)
                radius = -2.0 if name == mm.MEASURED else -1.0
                strips = finite_runs(x, y)
                labels = [name] * len(strips)  # on hover (the legend names the colours)
                self.rec.log(
                    path,
                    rr.LineStrips2D(
                        strips, colors=color, radii=radius, labels=labels, show_labels=False
                    ),
                )
                paths.add(path)
        return paths

    def warn(self, subject: str, detail: str) -> None:
        """A warning on the view's ``/events/view`` log (``subject: detail``), once per subject
        (a topic, or a topic and a field), for at most MAX_WARNED subjects; every warning is
        counted (``counts["warnings"]``)."""
        self.counts["warnings"] += 1
        if subject in self._warned or len(self._warned) >= MAX_WARNED:
            return
        self._warned.add(subject)
        self.rec.log(ENTITY["view_event"], rr.TextLog(f"{subject}: {detail}", level="WARN"))

    def report(self) -> str:
        """What the view received and drew of the plan's samples (the ``plan_end`` event gives
        the plan's first stamp, samples and rate), also logged on ``/events/view``: the samples
        it missed per stream and the Cp frames it should have drawn but did not. Samples
        outside the plan (the rig at rest before and after) are not counted."""
        c = self.counts
        if self.plan is None:
            line = (
                f"view: received {c['command']} commands, {c['state']} states, "
                f"{c['coefficients']} C_l and {c['taps']} tap samples, drew {c['taps_drawn']} "
                "Cp frames (no plan_end event with t0_ns, samples and fs: nothing to compare "
                "with)"
            )
        else:
            t0, planned, fs = self.plan
            half = 0.5e9 / fs
            first, last = t0 - half, t0 + (planned - 1) * 2 * half + half

            def inside(key: str) -> int:
                stamps = np.frombuffer(self._stamps[key], dtype=np.int64)
                return int(np.unique(stamps[(stamps >= first) & (stamps <= last)]).size)

            missed = {key: planned - inside(key) for key in STAMPED[:4]}
            frames = -(-planned // self.taps_decimation)
            drawn = inside("taps_drawn")
            line = (
                f"view: of {planned} plan samples missed {missed['command']} commands, "
                f"{missed['state']} states, {missed['coefficients']} C_l and "
                f"{missed['taps']} tap samples; drew {drawn} of {frames} Cp frames "
                f"({100.0 * max(frames - drawn, 0) / frames:.2f} % missed)"
            )
        self.rec.log(ENTITY["view_event"], rr.TextLog(line, level="INFO"))
        return line

    def flush(self, timeout_s: float = 10.0) -> None:
        """Send the buffered series, then wait until the recording has written everything."""
        self.send_series()
        self.rec.flush(timeout_sec=timeout_s)


def describe_segment(event: dict[str, Any]) -> str:
    """One line for a segment event: ``start multisine level 0 realization 1 period 2 …``."""
    edge = event.get("event", "?")
    if edge in ("decision", "refused"):
        return describe_decision(event)
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


def describe_decision(event: dict[str, Any]) -> str:
    """One line for an adaptive run's decision (multisine_gen.revision, the generator's answer to
    the identifier's request): ``level 0 after sample 4095: end_realization -> revision 1 …``."""
    edge = event.get("event", "?")
    request = event.get("request", "?")
    head = f"level {event.get('level', '?')} after sample {event.get('after_k', '?')}: {request}"
    reason = f" ({event['reason']})" if event.get("reason") else ""
    if edge == "refused":
        return f"refused {head}{reason}: {event.get('why', '?')}"
    change = event.get("change")
    if not change:
        return f"{head}{reason}: plan unchanged"
    return f"{head}{reason} -> revision {event.get('revision', '?')}: {change}"
