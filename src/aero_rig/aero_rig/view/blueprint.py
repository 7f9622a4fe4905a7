"""The Rerun blueprint of the view: entity paths, colours, view coordinates and the layout."""

import re
from collections.abc import Iterable
from typing import Any

import numpy as np
import rerun.blueprint as rrb

from aero_identification import model_payload as mm

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
    "cl_alpha_legend": "/cl_alpha/legend",
    "segment": "/events/segment",
    "model_event": "/events/model",
    "status": "/events/status",
    "adaptive": "/events/adaptive",
    "data_quality": "/events/data_quality",
    "view_event": "/events/view",
    "table1": "/model/table1",
    "summary": "/model/summary",
}

BLUE = (31, 119, 180)
ORANGE = (255, 127, 14)
GREEN = (44, 160, 44)
RED = (214, 39, 40)
GRAY = (127, 127, 127)
PURPLE = (148, 103, 189)
BROWN = (140, 86, 75)
PINK = (227, 119, 194)
OLIVE = (188, 189, 34)
CYAN = (23, 190, 207)
CLUSTER_COLORS = [BLUE, ORANGE, GREEN, RED, PURPLE, BROWN, PINK]
# The C_l–α view's series (model_payload.prediction_series): the measured loop and the models
# of validation.validate_sine; a model added later takes the first spare colour. A legend (points
# with the series' names) stands at the top left of the view, from LEGEND_AT down.
PREDICTION_COLORS = ((mm.MEASURED, GRAY), *mm.MODEL_COLORS.items())  # the models' as the report's
SPARE_COLORS = (PINK, OLIVE, CYAN, RED)
LEGEND_AT = (6.5, 2.15)  # (α [deg], C_l) of the first entry: above the low-α loops
LEGEND_STEP = 0.13  # C_l between entries


def slug(text: Any) -> str:
    """An entity-path part from free text: ``'sine level 2 1.0 Hz'`` -> ``sine_level_2_1_0_hz``."""
    out = re.sub(r"[^0-9a-zA-Z]+", "_", str(text)).strip("_").lower()
    return out or "unnamed"


def cp_to_view(x_c: np.ndarray, cp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return CP_X_SCALE * np.asarray(x_c), np.asarray(cp)


def cl_alpha_to_view(alpha_deg: np.ndarray, cl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(alpha_deg), -CL_SCALE * np.asarray(cl)


TABS = ("Clusters", "Model", "Table 1")  # the tabs under the C_l–α view


def make_blueprint(levels: Iterable[str] = (), active_tab: str = TABS[0]) -> rrb.Blueprint:
    """The layout: time series and events | Cp and the FRF of each level | C_l–α, and tabs with
    the clusters of each level, the model summary and Table 1. ``levels``: the model's levels;
    ``active_tab``: the tab shown (one of TABS).

    The time panel follows the newest data: live, the views show the latest samples, and a
    finished recording opened as a file shows its end state with no clicks. The blueprint and
    selection panels start collapsed so the views get the window."""
    levels = list(levels)
    frf_views: list[Any] = [
        rrb.BarChartView(
            origin=f"/frf/level_{slug(lv)}",
            name=f"FRF level {lv} [dB] over f [Hz]: |G| blue, noise gray, distortion red",
        )
        for lv in levels
    ] or [rrb.BarChartView(origin="/frf", name="FRF [dB] (after the first refit)")]
    cluster_views: list[Any] = [
        rrb.BarChartView(
            origin=f"/clusters/level_{slug(lv)}",
            name=f"Clusters level {lv}: a bar per period, the dominant cluster tallest",
        )
        for lv in levels
    ] or [rrb.BarChartView(origin="/clusters", name="Clusters (after the first refit)")]
    cp_x, cp_y = cp_to_view(np.array([-0.05, 1.05]), np.array([-3.2, 1.2]))
    ca_x, ca_y = cl_alpha_to_view(np.array([-6.0, 36.0]), np.array([-0.4, 2.2]))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(
                    origin="/series/pitch", name="Pitch [deg]: command (gray), measured (blue)"
                ),
                rrb.TimeSeriesView(origin="/series/cl", name="C_l"),
                rrb.TextLogView(
                    origin="/events",
                    name="Events: segments, adaptive decisions, status, data quality, view",
                ),
                row_shares=[2, 2, 1],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin="/cp",
                    name="−Cp over x/c, decimated (upper blue, lower orange)",
                    visual_bounds=rrb.VisualBounds2D(
                        x_range=sorted(cp_x.tolist()), y_range=sorted(cp_y.tolist())
                    ),
                ),
                *frf_views,
                row_shares=[2] + [1] * len(frf_views),
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin="/cl_alpha",
                    name="C_l–α of the validation sines: each model against the measured loop "
                    "(legend top left), live trail green",
                    visual_bounds=rrb.VisualBounds2D(
                        x_range=sorted(ca_x.tolist()), y_range=sorted(ca_y.tolist())
                    ),
                ),
                rrb.Tabs(
                    rrb.Vertical(*cluster_views, name=TABS[0]),
                    rrb.TextDocumentView(origin="/model/summary", name=TABS[1]),
                    rrb.TextDocumentView(origin="/model/table1", name=TABS[2]),
                    active_tab=TABS.index(active_tab),  # by name, rerun finds views only
                    name="Identification",
                ),
                row_shares=[3, 2],
            ),
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIMELINE, play_state="following", state="collapsed"),
    )
