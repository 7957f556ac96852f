"""Bird's-eye PNG pictures of scenarios (matplotlib, Agg backend, imported only when drawing).

`render_scenario` draws one scenario at one step: roadgraph by type, logged trajectories, object
boxes with heading ticks (the SDC highlighted), traffic lights by state, and the SDC paths.
`render_grid` puts several scenarios side by side. The map is drawn with line/patch collections
cropped to the view, so a 30000-point roadgraph renders in well under a second.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenariomax import schema as sch
from scenariomax.scenario import Scenario

DPI = 150
BACKGROUND = "#8f9499"  # asphalt grey: white and yellow lines stay visible, black edges too
MIN_VIEW_RADIUS_M = 30.0
VIEW_MARGIN_M = 15.0
MAX_POINT_GAP_M = 5.0  # consecutive points of one feature further apart than this are not joined

OBJECT_COLORS = {
    sch.OBJECT_TYPE_VEHICLE: "#2a6fdb",
    sch.OBJECT_TYPE_PEDESTRIAN: "#f28e2b",
    sch.OBJECT_TYPE_CYCLIST: "#3cb44b",
    sch.OBJECT_TYPE_OTHER: "#8c6d4f",
}
OBJECT_LABELS = {sch.OBJECT_TYPE_VEHICLE: "vehicle", sch.OBJECT_TYPE_PEDESTRIAN: "pedestrian",
                 sch.OBJECT_TYPE_CYCLIST: "cyclist", sch.OBJECT_TYPE_OTHER: "other"}
SDC_COLOR = "#e6007e"
LIGHT_COLORS = {
    sch.TL_STOP: "#e8281e", sch.TL_ARROW_STOP: "#e8281e", sch.TL_FLASHING_STOP: "#e8281e",
    sch.TL_CAUTION: "#ffd21f", sch.TL_ARROW_CAUTION: "#ffd21f", sch.TL_FLASHING_CAUTION: "#ffd21f",
    sch.TL_GO: "#2fd24a", sch.TL_ARROW_GO: "#2fd24a",
}
LIGHT_UNKNOWN_COLOR = "#c8c8c8"
LIGHT_GROUPS = (("red", "#e8281e"), ("yellow", "#ffd21f"), ("green", "#2fd24a"), ("unknown", LIGHT_UNKNOWN_COLOR))
PATH_COLOR = "#9be7ff"
LEGEND_ORDER = ("lane centre", "bike lane", "white line", "yellow line", "road edge", "crosswalk", "speed bump",
                "driveway", "stop sign", "SDC path (on route)", "SDC path", "logged trajectory", "SDC", "vehicle",
                "pedestrian", "cyclist", "other", "controllable", "light red", "light yellow", "light green",
                "light unknown")
ON_ROUTE_COLOR = "#00c8ff"


@dataclasses.dataclass(frozen=True)
class LineStyle:
    label: str
    color: str
    linewidth: float
    linestyle: object = "-"
    zorder: float = 1.0
    alpha: float = 1.0


_WHITE, _YELLOW = "#ffffff", "#ffd700"
ROADGRAPH_LINE_STYLES = {
    sch.RG_LANE_FREEWAY: LineStyle("lane centre", "#5f646a", 0.6, (0, (5, 4)), 1.0),
    sch.RG_LANE_SURFACE_STREET: LineStyle("lane centre", "#5f646a", 0.6, (0, (5, 4)), 1.0),
    sch.RG_LANE_BIKE: LineStyle("bike lane", "#3d7a3d", 0.6, (0, (2, 3)), 1.0),
    sch.RG_BROKEN_SINGLE_WHITE: LineStyle("white line", _WHITE, 0.9, (0, (6, 5)), 2.0),
    sch.RG_SOLID_SINGLE_WHITE: LineStyle("white line", _WHITE, 0.9, "-", 2.0),
    sch.RG_SOLID_DOUBLE_WHITE: LineStyle("white line", _WHITE, 1.8, "-", 2.0),
    sch.RG_BROKEN_SINGLE_YELLOW: LineStyle("yellow line", _YELLOW, 0.9, (0, (6, 5)), 2.0),
    sch.RG_BROKEN_DOUBLE_YELLOW: LineStyle("yellow line", _YELLOW, 1.8, (0, (6, 5)), 2.0),
    sch.RG_SOLID_SINGLE_YELLOW: LineStyle("yellow line", _YELLOW, 0.9, "-", 2.0),
    sch.RG_SOLID_DOUBLE_YELLOW: LineStyle("yellow line", _YELLOW, 1.8, "-", 2.0),
    sch.RG_PASSING_DOUBLE_YELLOW: LineStyle("yellow line", _YELLOW, 1.8, (0, (6, 2, 1, 2)), 2.0),
    sch.RG_ROAD_EDGE_BOUNDARY: LineStyle("road edge", "#111111", 1.8, "-", 2.5),
    sch.RG_ROAD_EDGE_MEDIAN: LineStyle("road edge", "#111111", 1.8, "-", 2.5),
}
POLYGON_STYLES = {  # type: (label, face colour, hatch)
    sch.RG_CROSSWALK: ("crosswalk", "#ffffff", "////"),
    sch.RG_SPEED_BUMP: ("speed bump", "#ff9f1c", "xx"),
    sch.RG_DRIVEWAY: ("driveway", "#b9bcc0", None),
}


# --- geometry (pure numpy) -------------------------------------------------------------------------

def box_corners(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, length: np.ndarray,
                width: np.ndarray) -> np.ndarray:
    """Corners of oriented boxes, counter-clockwise from front-left. (B,) each -> (B, 4, 2)."""
    local = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])  # (4, 2) in (length, width) units
    dx = local[None, :, 0] * length[:, None]
    dy = local[None, :, 1] * width[:, None]
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return np.stack([x[:, None] + dx * cos - dy * sin, y[:, None] + dx * sin + dy * cos], axis=-1)


def polyline_runs(xy: np.ndarray, feature_id: np.ndarray, max_gap: float = MAX_POINT_GAP_M) -> list[np.ndarray]:
    """Splits points into polylines: a new one starts where the feature id changes or at a gap.

    (R, 2), (R,) -> list of (k, 2) arrays with k >= 2. Whole polylines (not 2-point segments) keep
    dash patterns continuous along broken lines.
    """
    if len(xy) < 2:
        return []
    breaks = (feature_id[1:] != feature_id[:-1]) | (np.linalg.norm(np.diff(xy, axis=0), axis=-1) > max_gap)
    return [run for run in np.split(xy, np.flatnonzero(breaks) + 1) if len(run) >= 2]


def trajectory_segments(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Segments between consecutive valid steps of each object. (N, T) each -> (S, 2, 2)."""
    joined = valid[:, :-1] & valid[:, 1:]
    start = np.stack([x[:, :-1][joined], y[:, :-1][joined]], axis=-1)
    end = np.stack([x[:, 1:][joined], y[:, 1:][joined]], axis=-1)
    return np.stack([start, end], axis=1)


def default_view(scenario: Scenario, time_index: int) -> tuple[np.ndarray, float]:
    """Centre (the SDC at `time_index`) and radius fitting its whole logged trajectory plus a margin.

    Falls back to the centre of the valid objects (or of the map) when there is no valid SDC.
    """
    s = scenario
    sdc = np.flatnonzero(s.is_sdc)
    if sdc.size and s.valid[sdc[0]].any():
        row, valid = sdc[0], s.valid[sdc[0]]
        at = time_index if valid[time_index] else int(np.flatnonzero(valid)[0])
        centre = np.array([s.x[row, at], s.y[row, at]], dtype=np.float64)
        trajectory = np.stack([s.x[row, valid], s.y[row, valid]], axis=-1)
    elif s.valid.any():
        trajectory = np.stack([s.x[s.valid], s.y[s.valid]], axis=-1)
        centre = trajectory.mean(axis=0)
    elif s.roadgraph_valid.any():
        trajectory = s.roadgraph_xyz[s.roadgraph_valid, :2]
        centre = trajectory.mean(axis=0)
    else:
        return np.zeros(2), MIN_VIEW_RADIUS_M
    reach = float(np.abs(trajectory - centre).max()) if len(trajectory) else 0.0
    return centre, max(MIN_VIEW_RADIUS_M, reach + VIEW_MARGIN_M)


def _in_view(xy: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    return np.all(np.abs(xy - centre) <= radius, axis=-1)


# --- drawing ---------------------------------------------------------------------------------------

def _import_pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")  # headless: works on servers and in worker processes
    import matplotlib.pyplot as plt

    return plt


def _draw_roadgraph(ax, s: Scenario, centre: np.ndarray, radius: float, handles: dict) -> None:
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Polygon

    valid = s.roadgraph_valid & np.all(np.isfinite(s.roadgraph_xyz), axis=-1)
    xy, types, ids = s.roadgraph_xyz[valid, :2], s.roadgraph_type[valid], s.roadgraph_id[valid]
    # Crop with slack so lines entering the view keep their segments.
    near = _in_view(xy, centre, radius * 1.2 + MAX_POINT_GAP_M)
    xy, types, ids = xy[near], types[near], ids[near]
    for rg_type, style in ROADGRAPH_LINE_STYLES.items():
        is_type = types == rg_type
        segments = polyline_runs(xy[is_type], ids[is_type])
        if not segments:
            continue
        ax.add_collection(LineCollection(segments, colors=style.color, linewidths=style.linewidth,
                                         linestyles=[style.linestyle], zorder=style.zorder, alpha=style.alpha,
                                         capstyle="butt"))
        handles.setdefault(style.label, Line2D([], [], color=style.color, lw=max(style.linewidth, 1.2),
                                               ls=style.linestyle if style.linestyle != "-" else "-"))
    for rg_type, (label, color, hatch) in POLYGON_STYLES.items():
        is_type = types == rg_type
        polygons = [Polygon(xy[is_type][ids[is_type] == feature], closed=True)
                    for feature in np.unique(ids[is_type])]
        polygons = [p for p in polygons if len(p.get_xy()) >= 3]
        if not polygons:
            continue
        ax.add_collection(PatchCollection(polygons, facecolor="none", edgecolor=color, hatch=hatch,
                                          linewidth=0.8, alpha=0.9, zorder=1.5))
        handles.setdefault(label, Patch(facecolor="none", edgecolor=color, hatch=hatch, label=label))
    stops = xy[types == sch.RG_STOP_SIGN]
    if len(stops):
        ax.scatter(stops[:, 0], stops[:, 1], marker="8", s=60, c="#d7191c", edgecolors="white",
                   linewidths=0.8, zorder=6)
        handles.setdefault("stop sign", Line2D([], [], marker="8", color="#d7191c", markeredgecolor="white",
                                               ls="", markersize=7))


def _draw_paths(ax, s: Scenario, handles: dict) -> None:
    from matplotlib.lines import Line2D

    for p in range(s.path_xyz.shape[0]):
        points = s.path_xyz[p][s.path_valid[p]]
        if len(points) < 2:
            continue
        on_route = bool(s.path_on_route[p])
        ax.plot(points[:, 0], points[:, 1], color=ON_ROUTE_COLOR if on_route else PATH_COLOR,
                lw=3.2 if on_route else 1.2, alpha=0.55 if on_route else 0.7,
                ls="-" if on_route else (0, (1, 2)), zorder=3 if on_route else 2.8, solid_capstyle="round")
        label = "SDC path (on route)" if on_route else "SDC path"
        handles.setdefault(label, Line2D([], [], color=ON_ROUTE_COLOR if on_route else PATH_COLOR,
                                         lw=3.0 if on_route else 1.2, ls="-" if on_route else ":"))


def _draw_trajectories(ax, s: Scenario, handles: dict) -> None:
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    valid = s.valid & np.isfinite(s.x) & np.isfinite(s.y)
    is_sdc = s.is_sdc.astype(bool)
    for obj_type, color in OBJECT_COLORS.items():
        rows = (s.object_type == obj_type) & ~is_sdc
        segments = trajectory_segments(s.x[rows], s.y[rows], valid[rows])
        if len(segments):
            ax.add_collection(LineCollection(segments, colors=color, linewidths=0.9, alpha=0.45, zorder=3.5))
    segments = trajectory_segments(s.x[is_sdc], s.y[is_sdc], valid[is_sdc])
    if len(segments):
        ax.add_collection(LineCollection(segments, colors=SDC_COLOR, linewidths=1.6, alpha=0.7, zorder=3.6))
        handles.setdefault("logged trajectory", Line2D([], [], color="#333333", lw=1.0, alpha=0.6))


def _draw_objects(ax, s: Scenario, t: int, handles: dict) -> None:
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.patches import Patch

    valid = s.valid[:, t] & np.isfinite(s.x[:, t]) & np.isfinite(s.y[:, t]) & np.isfinite(s.bbox_yaw[:, t])
    length = np.where(np.isfinite(s.length[:, t]) & (s.length[:, t] > 0), s.length[:, t], 1.0)
    width = np.where(np.isfinite(s.width[:, t]) & (s.width[:, t] > 0), s.width[:, t], 1.0)
    corners = box_corners(s.x[:, t], s.y[:, t], s.bbox_yaw[:, t], length, width)  # (N, 4, 2)
    front = corners[:, [0, 3]].mean(axis=1)  # (N, 2) middle of the front edge
    centre = np.stack([s.x[:, t], s.y[:, t]], axis=-1)
    is_sdc = s.is_sdc.astype(bool)
    for obj_type, color in OBJECT_COLORS.items():
        rows = valid & (s.object_type == obj_type) & ~is_sdc
        if not rows.any():
            continue
        ax.add_collection(PolyCollection(corners[rows], facecolors=color, edgecolors="#1a1a1a",
                                         linewidths=0.6, alpha=0.9, zorder=5))
        handles.setdefault(OBJECT_LABELS[obj_type], Patch(facecolor=color, edgecolor="#1a1a1a",
                                                           label=OBJECT_LABELS[obj_type]))
    controllable = valid & s.is_controllable & ~is_sdc
    if controllable.any():
        ax.add_collection(PolyCollection(corners[controllable], facecolors="none", edgecolors="#ffffff",
                                         linewidths=1.2, linestyles="--", zorder=5.2))
        handles.setdefault("controllable", Patch(facecolor="none", edgecolor="#ffffff", linestyle="--"))
    sdc_rows = valid & is_sdc
    if sdc_rows.any():
        ax.add_collection(PolyCollection(corners[sdc_rows], facecolors=SDC_COLOR, edgecolors="#000000",
                                         linewidths=1.8, zorder=5.5))
        handles["SDC"] = Patch(facecolor=SDC_COLOR, edgecolor="#000000", linewidth=1.5)
    ticks = np.stack([centre[valid], front[valid]], axis=1)
    if len(ticks):
        ax.add_collection(LineCollection(ticks, colors="#111111", linewidths=0.9, zorder=5.8))


def _draw_lights(ax, s: Scenario, t: int, handles: dict) -> None:
    from matplotlib.lines import Line2D

    if not s.tl_state.shape[0]:
        return
    valid = s.tl_valid[:, t] & np.isfinite(s.tl_x[:, t]) & np.isfinite(s.tl_y[:, t])
    if not valid.any():
        return
    states = s.tl_state[valid, t]
    colors = [LIGHT_COLORS.get(int(state), LIGHT_UNKNOWN_COLOR) for state in states]
    ax.scatter(s.tl_x[valid, t], s.tl_y[valid, t], c=colors, s=55, edgecolors="#000000", linewidths=1.0, zorder=7)
    for name, color in LIGHT_GROUPS:
        if color in colors:
            handles.setdefault(f"light {name}", Line2D([], [], marker="o", ls="", color=color,
                                                       markeredgecolor="#000000", markersize=7))


def _ordered(handles: dict) -> tuple[list, list[str]]:
    labels = sorted(handles,
                    key=lambda label: LEGEND_ORDER.index(label) if label in LEGEND_ORDER else len(LEGEND_ORDER))
    return [handles[label] for label in labels], labels


def _title(s: Scenario, t: int, title: str | None) -> str:
    if title is not None:
        return title
    seconds = (t - s.current_time_index) / 10.0
    source = s.source_dataset or "unknown source"
    return f"{s.scenario_id or '(no id)'}  |  {source}  |  step {t} ({seconds:+.1f} s)"


def draw_scenario(ax, scenario: Scenario, *, time_index: int | None = None, title: str | None = None,
                  view_radius: float | None = None, legend: bool = True) -> dict:
    """Draws `scenario` on a matplotlib Axes; returns the legend handles by label."""
    s = scenario
    t = s.current_time_index if time_index is None else int(time_index)
    if not 0 <= t < s.num_timesteps:
        raise ValueError(f"time_index {t} is outside 0..{s.num_timesteps - 1}")
    centre, radius = default_view(s, t)
    if view_radius is not None:
        radius = float(view_radius)
    handles: dict = {}
    ax.set_facecolor(BACKGROUND)
    _draw_roadgraph(ax, s, centre, radius, handles)
    _draw_paths(ax, s, handles)
    _draw_trajectories(ax, s, handles)
    _draw_objects(ax, s, t, handles)
    _draw_lights(ax, s, t, handles)
    ax.set_xlim(centre[0] - radius, centre[0] + radius)
    ax.set_ylim(centre[1] - radius, centre[1] + radius)
    ax.set_aspect("equal", adjustable="box")
    ax.tick_params(labelsize=7)
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.set_title(_title(s, t, title), fontsize=9)
    if legend and handles:
        ax.legend(*_ordered(handles), loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  fontsize=7, frameon=True, facecolor=BACKGROUND, framealpha=1.0, borderaxespad=0.0)
    return handles


def render_scenario(scenario: Scenario, out_path: str | os.PathLike, *, time_index: int | None = None,
                    title: str | None = None, view_radius: float | None = None) -> Path:
    """Saves a bird's-eye PNG of `scenario` at `time_index` (default: the current step)."""
    plt = _import_pyplot()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8.6, 7.0))
    try:
        draw_scenario(ax, scenario, time_index=time_index, title=title, view_radius=view_radius)
        fig.tight_layout()
        fig.savefig(out_path, dpi=DPI, format="png")
    finally:
        plt.close(fig)
    return out_path


def render_grid(scenarios: Sequence[Scenario], out_path: str | os.PathLike, ncols: int = 3, *,
                time_index: int | None = None) -> Path:
    """Saves several scenarios in one PNG, one panel each, with one shared legend."""
    scenarios = list(scenarios)
    if not scenarios:
        raise ValueError("render_grid needs at least one scenario")
    plt = _import_pyplot()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    ncols = max(1, min(ncols, len(scenarios)))
    nrows = -(-len(scenarios) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols + 1.6, 4.6 * nrows), squeeze=False)
    try:
        handles: dict = {}
        for ax, scenario in zip(axes.ravel(), scenarios):
            handles.update(draw_scenario(ax, scenario, time_index=time_index, legend=False,
                                         title=f"{scenario.scenario_id or '(no id)'}"))
        for ax in axes.ravel()[len(scenarios):]:
            ax.set_visible(False)
        fig.legend(*_ordered(handles), loc="center right", fontsize=7,
                   facecolor=BACKGROUND)
        fig.tight_layout(rect=(0, 0, 1 - 1.4 / fig.get_figwidth(), 1))
        fig.savefig(out_path, dpi=DPI, format="png")
    finally:
        plt.close(fig)
    return out_path


__all__ = ["box_corners", "default_view", "draw_scenario", "render_grid", "render_scenario"]
