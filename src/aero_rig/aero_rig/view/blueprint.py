"""The Rerun blueprint of the view: entity paths, colours, view coordinates and the layout."""

import re
from collections.abc import Iterable
from typing import Any

import numpy as np
import rerun.blueprint as rrb

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


def slug(text: Any) -> str:
    """An entity-path part from free text: ``'sine level 2 1.0 Hz'`` -> ``sine_level_2_1_0_hz``."""
    out = re.sub(r"[^0-9a-zA-Z]+", "_", str(text)).strip("_").lower()
    return out or "unnamed"


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
