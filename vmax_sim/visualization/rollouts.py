"""Bird's-eye picture of closed-loop rollouts over the scenario they ran on.

The scenario is drawn as `scenariomax inspect --render` draws it (map, paths, logged trajectories,
objects at the first policy step); each policy's simulated SDC path is drawn on top in its own colour.
The reference path (the expert's log replay, by default any name starting with "expert") is a wide
translucent band under the thinner policy lines, so both stay visible where they coincide. A path
ends in a square, or in an X where the episode failed (collision, off-road or red light), with the
failure and its step in the legend. Two legends sit beside the map, inside the saved picture: the
paths, and the map's symbols (lights by state, stop signs, crosswalks, road edges, lanes, agents, the SDC).
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from scenariomax import Scenario, draw_scenario

# Policy colours that none of the map's symbols use (lights are red / yellow / green, vehicles blue,
# the SDC magenta, its route cyan, lane lines white and yellow).
COLOURS = ("#5a189a", "#000000", "#ff6d00", "#6d4c41", "#00897b", "#c51162")
REFERENCE_COLOUR = "#ffb74d"  # the expert's band: light orange under the policy lines
FAILURES = (("overlap", "collision"), ("offroad", "off-road"), ("red_light", "red light"))
LEGEND_WRAP = 34  # characters per legend line: long labels wrap instead of running off the picture
STEP_S = 0.1  # seconds per simulation step
MIN_VIEW_RADIUS_M = 20.0  # the view fits the paths with a margin, at least this far each side of their centre
VIEW_MARGIN_M = 10.0
MAP_LABELS = {"SDC": "SDC (at the first policy step)", "logged trajectory": "logged trajectories",
              "controllable": "controllable agent", "SDC path (on route)": "SDC route"}


def rollout_paths(rollout, index: int = 0) -> dict:
    """The simulated SDC positions of episode `index` of a batched Rollout, valid steps only.

    -> {"xy": (S, 2), "failed_at": step of the first collision / off-road / red light or -1,
        "failure": what failed first ("collision", "off-road", "red light"; "" without a failure)}
    """
    per_step = {k: np.asarray(v)[index] for k, v in rollout.per_step.items()}
    valid = np.asarray(rollout.step_valid)[index]
    xy = np.stack([per_step["sdc_x"], per_step["sdc_y"]], -1)[valid]
    flags = {name: (per_step[key] > 0.5) & valid for key, name in FAILURES if key in per_step}
    failed = np.zeros_like(valid, dtype=bool)
    for flag in flags.values():
        failed |= flag
    failed_steps = np.flatnonzero(failed)
    if not failed_steps.size:
        return {"xy": xy, "failed_at": -1, "failure": ""}
    step = int(failed_steps[0])
    return {"xy": xy, "failed_at": step, "failure": " + ".join(name for name, flag in flags.items() if flag[step])}


def default_reference(names) -> str | None:
    """The first name that is the expert's (log replay), else None."""
    return next((name for name in names if name.lower().startswith("expert")), None)


def path_label(name: str, path: Mapping) -> str:
    """Legend text of one path: its name, then how it ended."""
    step = int(path.get("failed_at", -1))
    if step < 0:
        return f"{name}: no failure in {len(path['xy'])} steps"
    return f"{name}: {path.get('failure') or 'failure'} at step {step} ({step * STEP_S:.1f} s)"


def rollout_view(scenario: Scenario, rollouts: Mapping[str, Mapping]) -> tuple[np.ndarray, float]:
    """Centre and half-width of the picture: the simulated paths and the SDC at the first policy step,
    with a margin (at least MIN_VIEW_RADIUS_M)."""
    from scenariomax.render import default_view

    centre, _ = default_view(scenario, scenario.current_time_index)
    points = [np.asarray(path["xy"], dtype=np.float64).reshape(-1, 2) for path in rollouts.values()]
    points = np.concatenate([centre[None], *points])
    points = points[np.all(np.isfinite(points), axis=-1)]
    low, high = points.min(axis=0), points.max(axis=0)
    return (low + high) / 2, max(MIN_VIEW_RADIUS_M, float((high - low).max()) / 2 + VIEW_MARGIN_M)


def _wrap(label: str) -> str:
    return "\n".join(textwrap.wrap(label, LEGEND_WRAP, break_long_words=True)) or label


def rollout_figure(scenario: Scenario, rollouts: Mapping[str, Mapping], title: str | None = None, *,
                   reference: str | None = "auto"):
    """The matplotlib Figure `render_rollouts` saves (close it with `plt.close(fig)`).

    `reference`: the name of the path drawn as a wide band under the others ("auto": `default_reference`;
    None: none)."""
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D

    from scenariomax.render import BACKGROUND, LEGEND_ORDER, default_view

    if reference == "auto":
        reference = default_reference(rollouts)
    fig = plt.figure(figsize=(11.8, 7.6), layout="constrained")
    grid = fig.add_gridspec(1, 2, width_ratios=(7.6, 3.2))
    ax = fig.add_subplot(grid[0])
    side = fig.add_subplot(grid[1])
    side.set_axis_off()
    centre, radius = rollout_view(scenario, rollouts)
    sdc_centre, sdc_radius = default_view(scenario, scenario.current_time_index)
    # draw_scenario crops the map around the SDC: wide enough to cover this view
    crop = max(sdc_radius, float(np.abs(centre - sdc_centre).max()) + radius)
    handles = draw_scenario(ax, scenario, title=title, legend=False, view_radius=crop)
    ax.set_xlim(centre[0] - radius, centre[0] + radius)
    ax.set_ylim(centre[1] - radius, centre[1] + radius)
    ax.tick_params(labelsize=8)
    ax.set_xlabel("x (m)", fontsize=9)
    ax.set_ylabel("y (m)", fontsize=9)
    if title is not None:
        ax.set_title(title, fontsize=11)

    path_handles, path_labels = [], []
    colours = iter(COLOURS)
    ordered = sorted(rollouts.items(), key=lambda item: item[0] != reference)  # the reference first, underneath
    for name, path in ordered:
        xy = np.asarray(path["xy"])
        if len(xy) == 0:
            continue
        step = int(path.get("failed_at", -1))
        if name == reference:
            colour, style = REFERENCE_COLOUR, dict(lw=7.0, alpha=0.8, zorder=6, solid_capstyle="round")
            edge = "#5d4037"
        else:
            colour, style = next(colours, "#000000"), dict(lw=2.0, zorder=6.5, solid_capstyle="round")
            edge = "#ffffff"
        ax.plot(xy[:, 0], xy[:, 1], "-", color=colour, **style)
        end_handles = [Line2D([], [], color=colour, lw=min(style["lw"], 5.0), alpha=style.get("alpha", 1.0))]
        if step < 0 or step < len(xy) - 1:  # where the path ends, unless it ends at the failure
            ax.plot(*xy[-1], "s", color=colour, ms=8, mec=edge, mew=1.2, zorder=7.5)
            end_handles.append(Line2D([], [], ls="", marker="s", color=colour, ms=7, mec=edge, mew=1.2))
        if step >= 0:
            at = xy[min(step, len(xy) - 1)]
            ax.plot(*at, "X", color=colour, ms=12, mec=edge, mew=1.3, zorder=7.6)
            end_handles.append(Line2D([], [], ls="", marker="X", color=colour, ms=9, mec=edge, mew=1.2))
        path_handles.append(tuple(end_handles))
        path_labels.append(_wrap(path_label(name, path)))

    legend_style = dict(fontsize=8, title_fontsize=9, alignment="left", borderaxespad=0.0)
    paths_legend = side.legend(path_handles, path_labels, loc="upper left", bbox_to_anchor=(0.0, 1.0),
                               title="simulated SDC paths\n(end: square, failure: X)",
                               handler_map={tuple: HandlerTuple(ndivide=None, pad=0.6)}, handlelength=3.2,
                               labelspacing=0.9, **legend_style)
    side.add_artist(paths_legend)
    labels = sorted(handles, key=lambda label: LEGEND_ORDER.index(label) if label in LEGEND_ORDER else 99)
    side.legend([handles[label] for label in labels], [_wrap(MAP_LABELS.get(label, label)) for label in labels],
                loc="lower left", bbox_to_anchor=(0.0, 0.0), ncols=2 if len(labels) > 9 else 1, title="map",
                facecolor=BACKGROUND, framealpha=1.0, handlelength=2.0, columnspacing=1.0, **legend_style)
    return fig


def render_rollouts(scenario: Scenario, rollouts: Mapping[str, Mapping], out_path: str | Path,
                    title: str | None = None, *, reference: str | None = "auto", dpi: int = 120) -> Path:
    """Saves a PNG of `scenario` with each policy's simulated SDC path (`rollout_paths` outputs) and the
    legends of the paths and of the map symbols beside it (see `rollout_figure`)."""
    import matplotlib.pyplot as plt

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig = rollout_figure(scenario, rollouts, title, reference=reference)
    try:
        fig.savefig(out_path, dpi=dpi)
    finally:
        plt.close(fig)
    return out_path
