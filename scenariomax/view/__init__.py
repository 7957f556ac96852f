"""Offline web viewer of shards (`scenariomax view`): one self-contained HTML file, or a small local server.

The page (viewer.html / viewer.css / viewer.js, package data, no build step) draws a scene on a
canvas: map layers, objects as oriented boxes with trails, traffic-light states, SDC and agent paths,
a timeline, and, for `vmax-sim view`, policies' simulated SDCs with per-step metrics. Scenes travel
as compact quantised binary (`scenariomax.view.scene`); see docs/viewer.md.
"""

from scenariomax.view.index import ShardIndex, compact_summary
from scenariomax.view.page import DEFAULT_MAX_SCENARIOS, ViewResult, render_page, write_page, write_view
from scenariomax.view.scene import SimTrack, error_scene, pack_scene, scene_from_scenario, unpack_scene
from scenariomax.view.server import make_server, serve_view

__all__ = [
    "DEFAULT_MAX_SCENARIOS", "ShardIndex", "SimTrack", "ViewResult", "compact_summary", "error_scene", "make_server",
    "pack_scene", "render_page", "scene_from_scenario", "serve_view", "unpack_scene", "write_page", "write_view",
]
