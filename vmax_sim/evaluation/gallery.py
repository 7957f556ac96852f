"""Failure gallery: an animated GIF and a PNG of the first failing step for each failed episode (and a
few passed ones), with an `index.html` listing them by policy.

`GalleryCollector` is an evaluation `on_batch` hook (see `compare_policies` / `evaluate`): the rollout
already records the simulated boxes of every object (`Rollout.trajectory`, one compilation for all
batches), and the collector keeps, on the host, only the episodes it will draw (the first
`max_failed` failed and `max_passed` passed ones of each policy), each cropped to its view. After the
evaluation, `write` renders them (matplotlib, Pillow's GIF writer) with a progress bar.

An episode fails when it is not accurate (collision, off-road or red light: the step metrics
`overlap`, `offroad`, `red_light`) or when its V-Max score is 0 (also: an at-fault collision, no
progress, driving against the lane). The failing metric of the picture is the first one to fire;
from that step on the SDC is drawn red with a yellow outline.
"""

from __future__ import annotations

import dataclasses
import html
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenariomax import render as scene_render

# per-step failures (metric key, label), checked in this order at each step
STEP_FAILURES = (("overlap", "collision"), ("at_fault_collision", "at-fault collision"), ("offroad", "off-road"),
                 ("red_light", "red light"))
# episode multipliers of the V-Max score that fail an episode when 0 (metric key, label)
EPISODE_FAILURES = (("making_progress", "no progress"), ("driving_direction", "against the lane"))
FAIL_COLOR, FAIL_EDGE = "#ff1f1f", "#ffe600"
LOG_SDC_EDGE = "#ffffff"
DT = 0.1
MIN_RADIUS_M, MAX_RADIUS_M, MARGIN_M = 25.0, 150.0, 12.0


@dataclasses.dataclass(frozen=True)
class Failure:
    metric: str  # episode metric key, e.g. "overlap"
    label: str  # words for people, e.g. "collision"
    step: int | None  # policy step index (0-based) where it first fired; None for an episode-level failure

    def describe(self) -> str:
        if self.step is None:
            return f"{self.label} ({self.metric} = 0)"
        return f"{self.label} ({self.metric}) at step {self.step + 1} ({(self.step + 1) * DT:.1f} s)"


def episode_failures(per_step: dict, step_valid: np.ndarray, episode: dict) -> list[Failure]:
    """The failures of one episode: per-step ones by first step, then the episode-level ones.

    per_step: name -> (S,); step_valid (S,); episode: name -> float. Empty for a passed episode.
    """
    valid = np.asarray(step_valid, bool)
    failures = []
    for key, label in STEP_FAILURES:
        if key in per_step and float(episode.get(key, 0.0)) > 0.5:
            fired = np.flatnonzero(valid & (np.asarray(per_step[key]) > 0.5))
            failures.append(Failure(key, label, int(fired[0]) if fired.size else None))
    failures.sort(key=lambda f: (f.step is None, f.step if f.step is not None else 0))
    if float(episode.get("vmax_score", 1.0)) <= 0.0:
        failures += [Failure(key, label, None) for key, label in EPISODE_FAILURES
                     if key in episode and float(episode[key]) <= 0.0]
    return failures


def is_failed(episode: dict) -> bool:
    return float(episode.get("accurate", 1.0)) < 0.5 or float(episode.get("vmax_score", 1.0)) <= 0.0


@dataclasses.dataclass
class EpisodeCapture:
    """What drawing one episode needs (numpy, cropped to its view)."""

    column: int
    scenario_id: str
    failed: bool
    failures: list[Failure]
    metrics: dict  # episode metric -> float
    first_timestep: int  # the timestep of frame 0; policy step k lands at first_timestep + k + 1
    num_valid_steps: int  # policy steps in the episode (up to and including the terminating one)
    highlight_step: int | None  # policy step index from which the SDC is drawn failing
    sdc: int  # row of the SDC
    sim: dict  # x, y, yaw, length, width (N, T) float32; valid (N, T) bool: the simulated boxes
    log_x: np.ndarray  # (N, T) logged positions (for the logged trajectories and the logged SDC box)
    log_y: np.ndarray
    log_yaw: np.ndarray
    log_valid: np.ndarray
    object_types: np.ndarray  # (N,)
    roadgraph: dict  # xy (R, 2), types (R,), ids (R,): the points in view
    lights: dict  # x, y, state (L, T), valid (L, T)
    paths: list  # [(xy (Q, 2), on_route bool)] of the valid SDC paths
    centre: np.ndarray  # (2,) view centre
    radius: float  # view half-size (m)


def _view(points: np.ndarray) -> tuple[np.ndarray, float]:
    if len(points) == 0:
        return np.zeros(2), MIN_RADIUS_M
    lo, hi = points.min(0), points.max(0)
    centre = 0.5 * (lo + hi)
    radius = float(np.clip(0.5 * np.max(hi - lo) + MARGIN_M, MIN_RADIUS_M, MAX_RADIUS_M))
    return centre, radius


def capture_episode(column: int, scenario_id: str, batch, rollout, index: int) -> EpisodeCapture:
    """Pulls episode `index` of a host batch and its host Rollout (with `trajectory`) into an EpisodeCapture."""
    i = index
    per_step = {k: np.asarray(v[i]) for k, v in rollout.per_step.items()}
    episode = {k: float(np.asarray(v[i])) for k, v in rollout.episode.items()}
    step_valid = np.asarray(rollout.step_valid[i], bool)
    failures = episode_failures(per_step, step_valid, episode)
    num_valid = int(step_valid.sum())
    traj = rollout.trajectory
    sim = {k: np.asarray(traj[k][i]) for k in ("x", "y", "yaw", "length", "width", "valid")}
    first = int(np.asarray(traj["first_timestep"][i]))
    sdc = int(np.argmax(np.asarray(batch.object_metadata.is_sdc[i])))
    log = batch.log_trajectory
    log_x, log_y = np.asarray(log.x[i]), np.asarray(log.y[i])
    log_valid = np.asarray(log.valid[i], bool)
    last = min(first + num_valid, sim["x"].shape[-1] - 1)
    window = slice(first, last + 1)
    sim_sdc = np.stack([sim["x"][sdc, window], sim["y"][sdc, window]], -1)[sim["valid"][sdc, window]]
    log_sdc = np.stack([log_x[sdc, window], log_y[sdc, window]], -1)[log_valid[sdc, window]]
    centre, radius = _view(np.concatenate([sim_sdc, log_sdc]))
    highlight = None
    if failures:
        highlight = failures[0].step if failures[0].step is not None else max(num_valid - 1, 0)

    rg = batch.roadgraph_points
    rg_xy = np.stack([np.asarray(rg.x[i]), np.asarray(rg.y[i])], -1)
    keep = np.asarray(rg.valid[i], bool) & np.all(np.abs(rg_xy - centre) <= radius * 1.2 + 5.0, axis=-1)
    lights = batch.log_traffic_light
    paths = batch.sdc_paths
    path_list = []
    for p in range(np.asarray(paths.x[i]).shape[0]):
        valid = np.asarray(paths.valid[i][p], bool)
        if valid.sum() >= 2:
            path_list.append((np.stack([np.asarray(paths.x[i][p]), np.asarray(paths.y[i][p])], -1)[valid],
                              bool(np.asarray(paths.on_route[i][p]))))
    return EpisodeCapture(
        column=column, scenario_id=scenario_id, failed=bool(failures), failures=failures,
        metrics={k: v for k, v in episode.items()}, first_timestep=first, num_valid_steps=num_valid,
        highlight_step=highlight, sdc=sdc, sim=sim, log_x=log_x, log_y=log_y, log_yaw=np.asarray(log.yaw[i]),
        log_valid=log_valid, object_types=np.asarray(batch.object_metadata.object_types[i]),
        roadgraph={"xy": rg_xy[keep], "types": np.asarray(rg.types[i])[keep], "ids": np.asarray(rg.ids[i])[keep]},
        lights={"x": np.asarray(lights.x[i]), "y": np.asarray(lights.y[i]), "state": np.asarray(lights.state[i]),
                "valid": np.asarray(lights.valid[i], bool)},
        paths=path_list, centre=centre, radius=radius)


class GalleryCollector:
    """An evaluation `on_batch` hook keeping the episodes to draw: per policy column, the first `max_failed`
    failed and the first `max_passed` passed ones (memory bounded by those counts)."""

    def __init__(self, max_failed: int = 50, max_passed: int = 5):
        if max_failed < 0 or max_passed < 0:
            raise ValueError("the gallery's episode limits must not be negative")
        self.max_failed, self.max_passed = max_failed, max_passed
        self.captures: dict[int, list[EpisodeCapture]] = {}
        self.num_failed: dict[int, int] = {}
        self.num_episodes: dict[int, int] = {}

    def __call__(self, column: int, ids: Sequence[str], batch, rollout, real: int) -> None:
        kept = self.captures.setdefault(column, [])
        for i in range(real):
            self.num_episodes[column] = self.num_episodes.get(column, 0) + 1
            failed = is_failed({k: float(np.asarray(v[i])) for k, v in rollout.episode.items()})
            self.num_failed[column] = self.num_failed.get(column, 0) + int(failed)
            shown = sum(capture.failed == failed for capture in kept)
            if shown < (self.max_failed if failed else self.max_passed):
                kept.append(capture_episode(column, ids[i], batch, rollout, i))

    def write(self, out_dir: str | Path, runs, *, progress: bool = True, title: str = "V-Max failure gallery",
              note: str = "") -> Path:
        """Renders every kept episode into out_dir/<policy>/ and writes out_dir/index.html. -> its path.

        runs: the PolicyRun columns (names and summaries) in column order.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        folders = _folder_names([run.name for run in runs])
        jobs = []
        for column, run in enumerate(runs):
            captures = sorted(self.captures.get(column, []), key=lambda c: not c.failed)  # failed first
            for number, capture in enumerate(captures):
                stem = f"{number:03d}-{_safe(capture.scenario_id)}"
                jobs.append((run.name, folders[column], stem, capture))
        iterator = jobs
        if progress and jobs:
            from tqdm import tqdm

            iterator = tqdm(jobs, unit="episode", desc="rendering the gallery", leave=False, disable=None)
        entries: dict[int, list[tuple[EpisodeCapture, str, str]]] = {}
        for name, folder, stem, capture in iterator:
            (out / folder).mkdir(parents=True, exist_ok=True)
            gif, png = f"{folder}/{stem}.gif", f"{folder}/{stem}.png"
            render_episode_gif(capture, out / gif, policy=name)
            render_episode_png(capture, out / png, policy=name)
            entries.setdefault(capture.column, []).append((capture, gif, png))
        index = out / "index.html"
        index.write_text(gallery_html(runs, entries, self.num_failed, self.num_episodes, self.max_failed,
                                      title=title, note=note))
        return index


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:80] or "scenario"


def _folder_names(names: Sequence[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for name in names:
        base = _safe(name)
        seen[base] = seen.get(base, 0) + 1
        out.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return out


# --- drawing ---------------------------------------------------------------------------------------

def _headless_pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed: servers, worker processes)."""
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


class EpisodeFigure:
    """A matplotlib figure of one episode. The map, paths, logged trajectories and legend are drawn once
    (the background); `image(frame)` restores it and draws only the moving artists (boxes, lights, the
    simulated SDC trail, the title) at frame f = timestep first_timestep + f, so a frame costs a few ms."""

    def __init__(self, capture: EpisodeCapture, policy: str, figsize: tuple[float, float] = (7.2, 6.0),
                 dpi: float = 72):
        plt = _headless_pyplot()
        from matplotlib.collections import LineCollection, PolyCollection

        self.c, self.policy, self.plt = capture, policy, plt
        self.fig, self.ax = plt.subplots(figsize=figsize, dpi=dpi)
        ax, c = self.ax, capture
        handles: dict = {}
        ax.set_facecolor(scene_render.BACKGROUND)
        self._draw_map(handles)
        sdc = c.sdc
        log_sdc = c.log_valid[sdc]
        ax.plot(c.log_x[sdc, log_sdc], c.log_y[sdc, log_sdc], color=scene_render.SDC_COLOR, lw=1.4, alpha=0.55,
                ls="--", zorder=3.6)
        others = np.arange(len(c.object_types)) != sdc
        segments = scene_render.trajectory_segments(c.log_x[others], c.log_y[others], c.log_valid[others])
        if len(segments):
            ax.add_collection(LineCollection(segments, colors="#1a1a1a", linewidths=0.6, alpha=0.25, zorder=3.4))
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        handles["logged SDC"] = Line2D([], [], color=scene_render.SDC_COLOR, lw=1.4, ls="--", alpha=0.7)
        (self.trail,) = ax.plot([], [], color=scene_render.SDC_COLOR, lw=2.4, zorder=5.2, solid_capstyle="round")
        handles["simulated SDC"] = Line2D([], [], color=scene_render.SDC_COLOR, lw=2.4)
        self.boxes = {}
        for obj_type, colour in scene_render.OBJECT_COLORS.items():
            self.boxes[obj_type] = ax.add_collection(PolyCollection([], facecolors=colour, edgecolors="#1a1a1a",
                                                                    linewidths=0.6, alpha=0.9, zorder=5))
            if np.any((c.object_types == obj_type) & others & c.sim["valid"].any(-1)):
                handles[scene_render.OBJECT_LABELS[obj_type]] = Patch(facecolor=colour, edgecolor="#1a1a1a")
        self.log_box = ax.add_collection(PolyCollection([], facecolors="none", edgecolors=LOG_SDC_EDGE,
                                                        linewidths=1.0, linestyles="--", zorder=5.3))
        handles["logged SDC box"] = Patch(facecolor="none", edgecolor=LOG_SDC_EDGE, linestyle="--")
        self.sdc_box = ax.add_collection(PolyCollection([], linewidths=1.8, zorder=5.6))
        handles["SDC"] = Patch(facecolor=scene_render.SDC_COLOR, edgecolor="#000000")
        if c.failed:
            handles["SDC, failing"] = Patch(facecolor=FAIL_COLOR, edgecolor=FAIL_EDGE, linewidth=2.0)
        self.ticks = ax.add_collection(LineCollection([], colors="#111111", linewidths=0.9, zorder=5.8))
        self.lights = ax.scatter(np.zeros(0), np.zeros(0), s=55, edgecolors="#000000", linewidths=1.0, zorder=7)
        if c.lights["valid"].any():
            for name, colour in scene_render.LIGHT_GROUPS:
                handles[f"light {name}"] = Line2D([], [], marker="o", ls="", color=colour, markeredgecolor="#000000")
        # where the failure happened, once the SDC has moved on from it (episodes run on without termination)
        self.marker = ax.scatter(np.zeros(0), np.zeros(0), marker="X", s=110, c=FAIL_EDGE, edgecolors="#000000",
                                 linewidths=1.0, zorder=8)
        self.hit = ax.add_collection(PolyCollection([], facecolors="none", edgecolors=FAIL_COLOR, linewidths=2.4,
                                                    zorder=5.7))
        self.hit_rows = colliding_objects(c)
        if self.hit_rows.size:
            handles["hit object"] = Patch(facecolor="none", edgecolor=FAIL_COLOR, linewidth=2.0)
        ax.set_xlim(c.centre[0] - c.radius, c.centre[0] + c.radius)
        ax.set_ylim(c.centre[1] - c.radius, c.centre[1] + c.radius)
        ax.set_aspect("equal", adjustable="box")
        ax.tick_params(labelsize=7)
        ax.legend(list(handles.values()), list(handles), loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                  facecolor=scene_render.BACKGROUND, framealpha=1.0, borderaxespad=0.0)
        self.title = ax.set_title("policy\nstatus", fontsize=8.5, loc="left")  # two lines, for the layout
        self.fig.tight_layout()
        self.dynamic = sorted([self.trail, *self.boxes.values(), self.log_box, self.sdc_box, self.ticks, self.lights,
                               self.marker, self.hit, self.title], key=lambda artist: artist.get_zorder())
        for artist in self.dynamic:
            artist.set_animated(True)
        self.fig.canvas.draw()
        self.background = self.fig.canvas.copy_from_bbox(self.fig.bbox)

    def _draw_map(self, handles: dict) -> None:
        from matplotlib.collections import LineCollection
        from matplotlib.lines import Line2D
        from matplotlib.patches import Polygon

        ax, rg = self.ax, self.c.roadgraph
        xy, types, ids = rg["xy"], rg["types"], rg["ids"]
        for rg_type, style in scene_render.ROADGRAPH_LINE_STYLES.items():
            is_type = types == rg_type
            segments = scene_render.polyline_runs(xy[is_type], ids[is_type])
            if segments:
                ax.add_collection(LineCollection(segments, colors=style.color, linewidths=style.linewidth,
                                                 linestyles=[style.linestyle], zorder=style.zorder, capstyle="butt"))
                handles.setdefault(style.label, Line2D([], [], color=style.color, lw=max(style.linewidth, 1.2)))
        for rg_type, (_, colour, hatch) in scene_render.POLYGON_STYLES.items():
            is_type = types == rg_type
            for feature in np.unique(ids[is_type]):
                points = xy[is_type][ids[is_type] == feature]
                if len(points) >= 3:
                    ax.add_patch(Polygon(points, closed=True, facecolor="none", edgecolor=colour, hatch=hatch,
                                         linewidth=0.8, alpha=0.9, zorder=1.5))
        stops = xy[types == scene_render.sch.RG_STOP_SIGN]
        if len(stops):
            ax.scatter(stops[:, 0], stops[:, 1], marker="8", s=60, c="#d7191c", edgecolors="white", zorder=6)
        for points, on_route in self.c.paths:
            colour = scene_render.ON_ROUTE_COLOR if on_route else scene_render.PATH_COLOR
            ax.plot(points[:, 0], points[:, 1], color=colour, lw=3.2 if on_route else 1.0,
                    alpha=0.5 if on_route else 0.6, ls="-" if on_route else (0, (1, 2)), zorder=3)
        if any(on_route for _, on_route in self.c.paths):
            handles["SDC path (on route)"] = Line2D([], [], color=scene_render.ON_ROUTE_COLOR, lw=3.0, alpha=0.6)

    @property
    def num_frames(self) -> int:
        """Frames 0 (the start) .. the last valid policy step, within the log."""
        c = self.c
        return max(1, min(c.num_valid_steps, c.sim["x"].shape[-1] - 1 - c.first_timestep) + 1)

    def show(self, frame: int) -> None:
        """Updates the artists to frame `frame` (after `frame` policy steps)."""
        c, sdc = self.c, self.c.sdc
        t = c.first_timestep + frame
        sim = c.sim
        valid = sim["valid"][:, t]
        corners = scene_render.box_corners(sim["x"][:, t], sim["y"][:, t], sim["yaw"][:, t],
                                           np.maximum(sim["length"][:, t], 0.5), np.maximum(sim["width"][:, t], 0.5))
        others = valid & (np.arange(len(valid)) != sdc)
        for obj_type, collection in self.boxes.items():
            collection.set_verts(list(corners[others & (c.object_types == obj_type)]))
        failing = c.highlight_step is not None and frame >= c.highlight_step + 1
        self.sdc_box.set_verts([corners[sdc]] if valid[sdc] else [])
        self.sdc_box.set_facecolor(FAIL_COLOR if failing else scene_render.SDC_COLOR)
        self.sdc_box.set_edgecolor(FAIL_EDGE if failing else "#000000")
        self.sdc_box.set_linewidth(2.6 if failing else 1.8)
        now = slice(t, t + 1)
        size = np.maximum(sim["length"][sdc, now], 0.5), np.maximum(sim["width"][sdc, now], 0.5)
        logged = scene_render.box_corners(c.log_x[sdc, now], c.log_y[sdc, now], c.log_yaw[sdc, now], *size)
        self.log_box.set_verts(list(logged) if c.log_valid[sdc, t] else [])
        front = corners[:, [0, 3]].mean(axis=1)
        centre = np.stack([sim["x"][:, t], sim["y"][:, t]], -1)
        self.ticks.set_segments(list(np.stack([centre[valid], front[valid]], axis=1)))
        steps = slice(c.first_timestep, t + 1)
        trail = sim["valid"][sdc, steps]
        self.trail.set_data(sim["x"][sdc, steps][trail], sim["y"][sdc, steps][trail])
        lights = c.lights
        on = lights["valid"][:, t]
        self.lights.set_offsets(np.stack([lights["x"][on, t], lights["y"][on, t]], -1).reshape(-1, 2))
        self.lights.set_facecolors([scene_render.LIGHT_COLORS.get(int(s), scene_render.LIGHT_UNKNOWN_COLOR)
                                    for s in lights["state"][on, t]] or ["none"])
        at = c.highlight_step + 1 if c.highlight_step is not None else None
        if failing and frame > at and c.failures[0].step is not None:
            self.marker.set_offsets([[sim["x"][sdc, c.first_timestep + at], sim["y"][sdc, c.first_timestep + at]]])
        else:
            self.marker.set_offsets(np.zeros((0, 2)))
        hit = self.hit_rows[valid[self.hit_rows]] if failing else self.hit_rows[:0]
        self.hit.set_verts(list(corners[hit]))
        self.title.set_text(self._title(frame, failing))

    def _title(self, frame: int, failing: bool) -> str:
        c = self.c
        head = f"{self.policy}  |  {c.scenario_id}  |  step {frame} ({frame * DT:.1f} s)"
        if not c.failed:
            return head + f"\npassed  |  V-Max score {c.metrics.get('vmax_score', math.nan):.3f}"
        first = c.failures[0]
        state = "FAILED" if failing else "fails"
        return head + f"\n{state}: {first.describe()}  |  V-Max score {c.metrics.get('vmax_score', math.nan):.3f}"

    def image(self, frame: int):
        """The figure at `frame` as a PIL RGB image."""
        from PIL import Image

        canvas = self.fig.canvas
        canvas.restore_region(self.background)
        self.show(frame)
        for artist in self.dynamic:
            self.ax.draw_artist(artist)
        return Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy())

    def close(self) -> None:
        self.plt.close(self.fig)


def colliding_objects(capture: EpisodeCapture) -> np.ndarray:
    """Rows of the objects whose simulated boxes overlap the SDC's at a collision failure step (else empty)."""
    from shapely.geometry import Polygon

    c = capture
    if not c.failures or c.failures[0].metric not in ("overlap", "at_fault_collision") or c.highlight_step is None:
        return np.zeros(0, int)
    t = min(c.first_timestep + c.highlight_step + 1, c.sim["x"].shape[-1] - 1)
    sim = c.sim
    corners = scene_render.box_corners(sim["x"][:, t], sim["y"][:, t], sim["yaw"][:, t],
                                       np.maximum(sim["length"][:, t], 0.1), np.maximum(sim["width"][:, t], 0.1))
    ego = Polygon(corners[c.sdc])
    rows = [n for n in np.flatnonzero(sim["valid"][:, t]) if n != c.sdc and ego.intersects(Polygon(corners[n]))]
    return np.asarray(rows, int)


def render_episode_gif(capture: EpisodeCapture, path: str | Path, policy: str = "", *, fps: int = 10,
                       dpi: int = 72, hold_seconds: float = 1.5) -> Path:
    """An animated GIF of the episode, one frame per policy step (real time at fps=10), looping, the last
    frame held `hold_seconds`. Frames drawn by matplotlib, written by Pillow."""
    path = Path(path)
    figure = EpisodeFigure(capture, policy, dpi=dpi)
    try:
        frames = [figure.image(frame) for frame in range(figure.num_frames)]
    finally:
        figure.close()
    step_ms = int(round(1000 / fps))
    durations = [step_ms] * (len(frames) - 1) + [max(step_ms, int(1000 * hold_seconds))]
    frames = _shared_palette(frames, [0, failure_frame(capture), len(frames) - 1])
    frames[0].save(path, format="GIF", save_all=True, append_images=frames[1:], duration=durations, loop=0)
    return path


def _shared_palette(frames: list, samples: Sequence[int], colours: int = 128) -> list:
    """Frames quantised, without dithering, to one palette taken from a few sample frames: flat colours and
    an unchanged background let the GIF store only what moves (5-6x smaller than a palette per frame)."""
    from PIL import Image

    samples = sorted({min(max(i, 0), len(frames) - 1) for i in samples})
    width, height = frames[0].size
    montage = Image.new("RGB", (width, height * (len(samples) + 1)))
    for row, i in enumerate(samples):
        montage.paste(frames[i], (0, row * height))
    # a strip of the picture's key colours, each over a large area, so that each keeps a palette entry even
    # where it covers a few pixels only (a legend patch, a cyclist)
    key = (list(scene_render.OBJECT_COLORS.values()) + [scene_render.SDC_COLOR, FAIL_COLOR, FAIL_EDGE]
           + [colour for _, colour in scene_render.LIGHT_GROUPS] + [scene_render.ON_ROUTE_COLOR, "#000000", "#ffffff"])
    block = max(1, width // len(key))
    for k, colour in enumerate(key):
        montage.paste(colour, (k * block, len(samples) * height, (k + 1) * block, (len(samples) + 1) * height))
    palette = montage.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    return [frame.quantize(palette=palette, dither=Image.Dither.NONE) for frame in frames]


def failure_frame(capture: EpisodeCapture) -> int:
    """The frame of the first failing step (the last frame of a passed episode)."""
    last = max(1, min(capture.num_valid_steps, capture.sim["x"].shape[-1] - 1 - capture.first_timestep))
    return last if capture.highlight_step is None else min(capture.highlight_step + 1, last)


def render_episode_png(capture: EpisodeCapture, path: str | Path, policy: str = "", *, dpi: int = 110) -> Path:
    """A PNG at the first failing step (the last step of a passed episode)."""
    path = Path(path)
    figure = EpisodeFigure(capture, policy, dpi=dpi)
    try:
        figure.image(failure_frame(capture)).save(path, format="PNG")
    finally:
        figure.close()
    return path


# --- index.html ------------------------------------------------------------------------------------

_STYLE = """body{font-family:system-ui,sans-serif;margin:1.5em;background:#fafafa;color:#222}
h2{border-bottom:2px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
.episode{display:inline-block;vertical-align:top;margin:.5em;padding:.6em;background:#fff;border:1px solid #ddd;
border-radius:6px;max-width:540px}
.episode.failed{border-left:6px solid #d62728}.episode.passed{border-left:6px solid #2ca02c}
.episode img{max-width:520px;display:block;margin:.3em 0}
table.metrics{border-collapse:collapse;font-size:.85em}table.metrics td,table.metrics th{padding:.1em .5em;
text-align:left;border-bottom:1px solid #eee}.fail{color:#d62728;font-weight:600}
img.missing{outline:3px dashed #d62728;min-height:2em}"""
_ONERROR = " onerror=\"this.classList.add('missing')\""  # an image that fails to load is outlined (and findable)


def _fmt(value) -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else f"{float(value):.3f}"


def gallery_html(runs, entries: dict, num_failed: dict, num_episodes: dict, max_failed: int,
                 title: str = "V-Max failure gallery", note: str = "") -> str:
    """The index page: one section per policy, one card per drawn episode (images linked relatively)."""
    esc = html.escape
    folders = _folder_names([run.name for run in runs])
    parts = [f"<!doctype html>\n<html><head><meta charset='utf-8'><title>{esc(title)}</title>"
             f"<style>{_STYLE}</style></head><body>", f"<h1>{esc(title)}</h1>"]
    if note:
        parts.append(f"<p>{esc(note)}</p>")
    parts.append("<p>Policies: " + ", ".join(f"<a href='#policy-{esc(f)}'>{esc(run.name)}</a>"
                                            for run, f in zip(runs, folders)) + "</p>")
    for column, (run, folder) in enumerate(zip(runs, folders)):
        summary = run.result.summary
        cards = entries.get(column, [])
        failed, total = num_failed.get(column, 0), num_episodes.get(column, 0)
        shown = sum(c.failed for c, _, _ in cards)
        parts.append(f"<section id='policy-{esc(folder)}' class='policy'><h2>{esc(run.name)}</h2>")
        mode = esc(str(summary.get("mode", "")))
        parts.append(f"<p>Mode {mode}: {total} episodes, <b>{failed} failed</b> (showing {shown}"
                     f"{f', limit {max_failed}' if failed > shown else ''}) and {len(cards) - shown} passed for "
                     f"comparison. Accuracy {100 * summary['accuracy']:.2f}%, V-Max score "
                     f"{100 * summary['vmax_score']:.2f}, nuPlan score {100 * summary['nuplan_score']:.2f}.</p>")
        if not cards:
            parts.append("<p>No episode to show.</p>")
        for capture, gif, png in cards:
            status = "failed" if capture.failed else "passed"
            failing = "; ".join(f.describe() for f in capture.failures) or "none"
            metrics = capture.metrics
            rows = [("scenario id", esc(capture.scenario_id)), ("policy", esc(run.name)),
                    ("failing metrics", f"<span class='fail'>{esc(failing)}</span>" if capture.failed else "none"),
                    ("accuracy", "accurate" if metrics.get("accurate", 0.0) > 0.5 else "not accurate"),
                    ("V-Max score", _fmt(metrics.get("vmax_score"))),
                    ("nuPlan score", _fmt(metrics.get("nuplan_score"))),
                    ("ego progress", _fmt(metrics.get("ego_progress"))),
                    ("log divergence (m)", _fmt(metrics.get("log_divergence")))]
            table = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
            step_note = ("first failing step" if capture.failed else "last step")
            parts.append(
                f"<div class='episode {status}' data-scenario='{esc(capture.scenario_id)}'>"
                f"<h3>{esc(capture.scenario_id)} <small>({status})</small></h3><table class='metrics'>{table}</table>"
                f"<a href='{esc(gif)}'><img src='{esc(gif)}' alt='rollout of {esc(capture.scenario_id)}'{_ONERROR}></a>"
                f"<a href='{esc(png)}'><img src='{esc(png)}' alt='{step_note} of {esc(capture.scenario_id)}'"
                f"{_ONERROR}></a>"
                f"<small>GIF: the whole episode; PNG: the {step_note}.</small></div>")
        parts.append("</section>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
