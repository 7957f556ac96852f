"""The viewer page in a real headless Chromium: it loads without console errors, draws the map and the boxes
where the data puts them, the frame changes with `?frame=N`, layers toggle from the URL (test_view_serve.py:
the served page).

The screenshots are kept under the test's tmp_path (e.g. .../test_the_page_draws_.../frame-10.png).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import scenariomax
from scenariomax.view import write_view
from tests.integration_sim.conftest import CAR_AHEAD_X, SMALL_SIZES, braking_scenario, cruising_scenario
from tests.view.browser import colour_mask, needs_browser, rgb, run_chromium, status

pytestmark = needs_browser
SDC, VEHICLE, EDGE = "#e6007e", "#2a6fdb", "#111111"


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("browser_shards")
    scenariomax.write_shards([cruising_scenario("cruise"), braking_scenario("brake")], out, sizes=SMALL_SIZES)
    return out


@pytest.fixture(scope="module")
def page(shards, tmp_path_factory) -> Path:
    return write_view(shards, tmp_path_factory.mktemp("page") / "view.html").out


VIEW = (15.0, 0.0, 10.0)  # ?view= centre x, y (m) and pixels per metre
BACKGROUND = "#8f9499"


def _canvas(image: np.ndarray) -> tuple[int, int, int, int]:
    """(left, top, width, height) of the map canvas in a screenshot: the asphalt-grey block right of the sidebar.
    (Found in the picture itself: a --dump-dom run may lay the page out with another viewport height.)"""
    grey = colour_mask(image, BACKGROUND, 6)
    rows = np.flatnonzero(grey[:, -40])
    cols = np.flatnonzero(grey[rows[len(rows) // 2]])
    return int(cols[0]), int(rows[0]), int(cols[-1] - cols[0] + 1), int(rows[-1] - rows[0] + 1)


def _screen(image: np.ndarray, x: float, y: float) -> tuple[int, int]:
    """Screenshot pixel of world point (x, y) under VIEW."""
    left, top, width, height = _canvas(image)
    cx, cy, k = VIEW
    return round(left + (x - cx) * k + width / 2), round(top + height / 2 - (y - cy) * k)


def _load(url: str, png: Path, dom: bool = True) -> tuple[dict, np.ndarray]:
    """(the page's #status after load, or {} without `dom`; the screenshot as RGB). Asserts a silent console."""
    state = {}
    if dom:
        text, console = run_chromium(url)
        assert console == [], console  # the page logs nothing: any console line is an error or a warning
        state = status(text)
        assert state["ready"] == "1" and state["errors"] == "", state
    _, console = run_chromium(url, screenshot=png)
    assert console == [] and png.is_file(), console
    return state, rgb(png)


def _map_only(image: np.ndarray) -> np.ndarray:
    """The canvas without the legend (top right), where colours mean drawn data."""
    left, top, width, height = _canvas(image)
    canvas = image[top:top + height, left:left + width].copy()
    canvas[:130, -240:] = 0  # the legend's corner
    return canvas


def test_the_page_draws_boxes_and_road_edges_where_the_data_says_and_the_frame_changes(page, tmp_path):
    states, images = {}, {}
    view = ",".join(str(v) for v in VIEW)
    for frame in (10, 40):
        url = f"{page.as_uri()}?scenario=brake&frame={frame}&view={view}"
        states[frame], images[frame] = _load(url, tmp_path / f"frame-{frame}.png", dom=frame == 10)
    assert states[10]["scenario"] == "brake" and states[10]["frame"] == "10"
    assert states[10]["drawn"] == "2" and states[10]["view"].startswith("15.000,0.000,10.00000,")  # SDC + stopped car
    scenario = braking_scenario("brake")
    for frame, image in images.items():
        sdc_x = float(scenario.x[0, frame])
        bx, by = _screen(image, sdc_x - 1.0, 0.0)  # inside the box, off its heading tick
        assert colour_mask(image[by - 2:by + 3, bx - 2:bx + 3], SDC).mean() > 0.8, f"no SDC colour at frame {frame}"
        cx_, cy_ = _screen(image, CAR_AHEAD_X - 1.0, 0.0)
        assert colour_mask(image[cy_ - 2:cy_ + 3, cx_ - 2:cx_ + 3], VEHICLE).mean() > 0.8, "no vehicle colour"
        for edge_y in (-2.0, 5.5):  # road edges: dark lines along the road
            ex, ey = _screen(image, sdc_x - 8.0, edge_y)
            assert colour_mask(image[ey - 2:ey + 3, ex - 1:ex + 2], EDGE, 60).any(), f"no road edge at y={edge_y}"
        gx, gy = _screen(image, sdc_x - 1.0, 12.0)  # off the road: asphalt background only
        assert colour_mask(image[gy - 2:gy + 3, gx - 2:gx + 3], BACKGROUND, 6).all()
    old_x, _ = _screen(images[40], float(scenario.x[0, 10]) - 1.0, 0.0)  # where the SDC was at frame 10
    assert not colour_mask(images[40][by - 2:by + 3, old_x - 2:old_x + 3], SDC).any() or old_x == bx
    changed = np.any(images[10] != images[40], axis=-1)
    assert changed.sum() > 500 and (tmp_path / "frame-40.png").stat().st_size > 5_000


def test_the_default_view_fits_the_sdc_and_url_layers_hide_the_objects(page, tmp_path):
    _, image = _load(f"{page.as_uri()}?scenario=brake&frame=10", tmp_path / "fit.png", dom=False)
    assert colour_mask(_map_only(image), SDC).sum() > 200 and colour_mask(_map_only(image), VEHICLE).sum() > 200
    dom, console = run_chromium(f"{page.as_uri()}?scenario=brake&frame=10&hover={CAR_AHEAD_X + 1.5},0.5")
    tooltip = re.search(r'<div id="tooltip"[^>]*>([^<]*)</div>', dom)
    assert console == [] and tooltip and "hidden" not in tooltip.group(0)
    assert tooltip.group(1).split("\n") == ["id 101", "type vehicle", "size 4.50 x 2.00 m", "speed 0.00 m/s"]
    state, image = _load(f"{page.as_uri()}?scenario=brake&frame=10&layers=edges,lanes", tmp_path / "no-objects.png")
    assert state["drawn"] == "0" and colour_mask(_map_only(image), SDC).sum() == 0
    assert colour_mask(_map_only(image), VEHICLE).sum() == 0 and colour_mask(_map_only(image), EDGE, 60).sum() > 500
