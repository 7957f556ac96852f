"""Shared test fixtures: the real-data folder and small hand-made scenarios."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


def realdata_file(relative: str) -> Path:
    """Path of a real sample under ../shared/realdata, or skip the test with the reason."""
    path = REALDATA / relative
    if not path.exists():
        pytest.skip(f"real-data sample {relative} not found under {REALDATA} (the shared folder is absent)")
    return path


def straight_road_scenario(scenario_id: str = "toy-0", num_objects: int = 3, num_timesteps: int = 91,
                           speed: float = 10.0):
    """A straight east-bound road with edges at y = -2 and y = +5.5 and vehicles 20 m apart, SDC first."""
    from scenariomax import Scenario
    from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph

    t = np.arange(num_timesteps) * 0.1
    xs = np.stack([20.0 * i + speed * t for i in range(num_objects)])
    ones = np.ones((num_objects, num_timesteps), np.float32)
    road = polylines_to_roadgraph([
        MapPolyline(1, 2, np.array([[-50, 0, 0], [400, 0, 0]], float), speed_limit=13.4),
        MapPolyline(2, 15, np.array([[-50, -2, 0], [400, -2, 0]], float)),
        MapPolyline(3, 15, np.array([[400, 5.5, 0], [-50, 5.5, 0]], float)),
    ])
    return Scenario(
        scenario_id=scenario_id,
        object_id=np.arange(num_objects) + 100,
        object_type=np.ones(num_objects),
        is_sdc=np.arange(num_objects) == 0,
        x=xs, y=0 * ones, z=0 * ones, bbox_yaw=0 * ones,
        length=4.5 * ones, width=2.0 * ones, height=1.6 * ones,
        velocity_x=speed * ones, velocity_y=0 * ones,
        valid=ones.astype(bool),
        tl_state=np.full((1, num_timesteps), 6), tl_valid=np.ones((1, num_timesteps), bool),
        tl_lane_id=np.ones((1, num_timesteps)), tl_x=np.full((1, num_timesteps), 300.0),
        tl_y=np.zeros((1, num_timesteps)), tl_z=np.zeros((1, num_timesteps)),
        source_dataset="test",
        **road,
        **lane_graph_arrays([LaneLinks(1)]),
    )


@pytest.fixture
def toy_scenario():
    return straight_road_scenario()


@pytest.fixture(scope="session", autouse=True)
def _private_cache_dir(tmp_path_factory):
    """Tests (and the commands they start) cache map indices and synthetic splits in a folder of their own,
    never in the user's ~/.cache/vmax_sim. A VMAX_CACHE_DIR set by the caller is kept."""
    if "VMAX_CACHE_DIR" in os.environ:
        yield
        return
    os.environ["VMAX_CACHE_DIR"] = str(tmp_path_factory.mktemp("vmax-cache"))
    yield
    del os.environ["VMAX_CACHE_DIR"]
