"""An .rrd read back with Rerun's own reader (``rerun.chunk.RrdReader``, rerun 0.41): rows per
entity path, as a viewer loads them, and the views of each blueprint sent. For tests and
``bench/`` (what a recording holds), not for the live path."""

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

from .blueprint import TIMELINE


class Rrd:
    """Rows per entity of an .rrd's recording (temporal and static), and its blueprint."""

    def __init__(self, path: Path) -> None:
        reader = RrdReader(path)
        self.rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
        self.static: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for chunk in reader.stream().to_chunks():
            batch = chunk.to_record_batch()
            names = batch.schema.names
            columns = {}
            for name in names:
                column = batch.column(name)
                if pa.types.is_timestamp(column.type):
                    column = column.cast(pa.int64())
                columns[name] = column.to_pylist()
            target = self.static if chunk.is_static else self.rows
            for i in range(batch.num_rows):
                target[chunk.entity_path].append({n: columns[n][i] for n in names})
        for rows in self.rows.values():
            rows.sort(key=lambda r: (r.get(TIMELINE) or 0, r["rerun.controls.RowId"]))
        # Plain dicts from here: looking an entity up must not add it.
        self.rows, self.static = dict(self.rows), dict(self.static)
        # The views' names of each blueprint sent, in the order sent (a row id is a TUID: its
        # first 8 bytes are its time, big-endian), and of all of them.
        # The time panel's settings of each (``TimePanelBlueprint:<field>`` -> value).
        sent: list[tuple[bytes, set[str], dict[str, Any]]] = []
        for bp in reader.blueprints():
            views: set[str] = set()
            panel: dict[str, Any] = {}
            first = b"\xff" * 16
            for chunk in reader.stream(store=bp).to_chunks():
                batch = chunk.to_record_batch()
                first = min(first, *batch.column("rerun.controls.RowId").to_pylist())
                if "ViewBlueprint:display_name" in batch.schema.names:
                    for value in batch.column("ViewBlueprint:display_name").to_pylist():
                        views.update(value or [])
                for name in batch.schema.names:
                    if name.startswith("TimePanelBlueprint:"):
                        (value,) = batch.column(name).to_pylist()[-1]
                        panel[name.split(":", 1)[1]] = value
            sent.append((first, views, panel))
        sent.sort(key=lambda item: item[0])
        self.blueprints = [views for _, views, _ in sent]
        self.time_panels = [panel for _, _, panel in sent]
        self.view_names: set[str] = set().union(*self.blueprints)

    def column(self, entity: str, name: str) -> list[Any]:
        return [row[name] for row in self.rows.get(entity, []) if row.get(name) is not None]

    def scalars(self, entity: str) -> tuple[np.ndarray, np.ndarray]:
        rows = [r for r in self.rows.get(entity, []) if r.get("Scalars:scalars") is not None]
        times = np.array([r[TIMELINE] for r in rows], dtype=np.int64)
        return times, np.array([r["Scalars:scalars"][0] for r in rows])

    def bars(self, entity: str, row: int = -1) -> tuple[np.ndarray, np.ndarray]:
        rows = [r for r in self.rows.get(entity, []) if r.get("BarChart:values") is not None]
        r = rows[row]
        return (
            np.array(r["BarChart:abscissa"][0]["buffer"]),
            np.array(r["BarChart:values"][0]["buffer"]),
        )


def entity_rows(path: Path) -> dict[str, int]:
    """Rows per entity path of a recording (temporal and static), from the chunks' sizes: a
    large recording is counted without reading its rows."""
    rows: dict[str, int] = defaultdict(int)
    for chunk in RrdReader(path).stream().to_chunks():
        rows[str(chunk.entity_path)] += chunk.num_rows
    return dict(sorted(rows.items()))
