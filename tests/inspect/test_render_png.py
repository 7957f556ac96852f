"""`render_scenario` / `render_grid` write real PNGs, with and without lights and paths."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from scenariomax.inspect import load_scenario
from scenariomax.render import box_corners, default_view, render_grid, render_scenario
from tests.conftest import realdata_file
from tests.inspect.scenes import make_scenario

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_box_corners_hand_worked():
    corners = box_corners(np.array([1.0]), np.array([2.0]), np.array([np.pi / 2]), np.array([4.0]), np.array([2.0]))
    # Facing +y: front-left is 2 m ahead (+y) and 1 m to the left (-x).
    np.testing.assert_allclose(corners[0], [[0, 4], [0, 0], [2, 0], [2, 4]], atol=1e-9)


def test_default_view_centres_on_sdc_and_fits_its_trajectory():
    centre, radius = default_view(make_scenario(), 10)
    # SDC at step 10 is at x = 5 + 10 * 1.0 = 15; its trajectory ends at x = 103 -> 88 m + 15 m margin.
    np.testing.assert_allclose(centre, [15.0, 0.0], atol=1e-4)
    assert radius == pytest.approx(103.0, abs=1e-3)


@pytest.mark.parametrize("with_extras", [True, False], ids=["lights+paths", "bare"])
def test_render_scenario_writes_png(tmp_path, with_extras):
    scenario = make_scenario(with_lights=with_extras, with_paths=with_extras, with_controllable=with_extras)
    out = render_scenario(scenario, tmp_path / "sub" / "scene.png")
    assert out == tmp_path / "sub" / "scene.png"
    width, height = _png_size(out)
    assert (width, height) == (1290, 1050)  # 8.6 x 7 inches at 150 dpi
    assert out.stat().st_size > 20_000


def test_render_at_a_later_step_with_a_fixed_radius(tmp_path):
    out = render_scenario(make_scenario(), tmp_path / "late.png", time_index=90, view_radius=20.0, title="late")
    assert _png_size(out) == (1290, 1050)


def test_render_rejects_a_step_outside_the_scenario(tmp_path):
    with pytest.raises(ValueError, match="time_index 91 is outside 0..90"):
        render_scenario(make_scenario(), tmp_path / "x.png", time_index=91)


def test_render_grid(tmp_path):
    scenes = [make_scenario("a"), make_scenario("b", with_lights=False, with_paths=False)]
    width, height = _png_size(render_grid(scenes, tmp_path / "grid.png", ncols=3))
    assert width > height  # two panels side by side plus the legend


def test_render_real_womd_example(tmp_path):
    scenario = load_scenario(realdata_file("womd/motion_data_one_example.tfrecord"))
    out = render_scenario(scenario, tmp_path / "womd.png")
    assert _png_size(out) == (1290, 1050)
    assert out.stat().st_size > 100_000  # a busy intersection, not an empty canvas


def test_render_objects_only_scenario_with_sdc_invalid_now(tmp_path):
    from scenariomax import Scenario
    from tests.inspect.scenes import _objects

    objects = _objects()
    objects["valid"] = objects["valid"].copy()
    objects["valid"][0, 5:] = False  # the SDC disappears before the current step
    scenario = Scenario(scenario_id="objects-only", **objects)
    assert _png_size(render_scenario(scenario, tmp_path / "bare.png")) == (1290, 1050)
