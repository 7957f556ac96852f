"""Hand-made scenarios for the rule-based policies (straight road of tests.integration_sim, a red light,
a curved road) and helpers to run one episode."""

from __future__ import annotations

import dataclasses
import functools

import chex
import jax
import numpy as np

import scenariomax
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.schema import OBJECT_TYPE_VEHICLE, RG_LANE_SURFACE_STREET, RG_ROAD_EDGE_BOUNDARY, TL_GO, TL_STOP
from tests.integration_sim.conftest import DT, NUM_STEPS, road_scenario, small_data_config
from vmax_sim.data import scenarios_to_batch
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.evaluation import make_policy, run_episode
from vmax_sim.metrics import MetricsConfig
from vmax_sim.observation import ObservationConfig

SPEED_LIMIT = 13.4  # m/s on the straight road of tests.integration_sim
LIGHT_X = 50.0  # m, stop point of the red light
LEAD_START_X, LEAD_SPEED = 35.0, 6.0  # the lead car: 35 m ahead of the SDC, 6 m/s
CURVE_RADIUS = 40.0  # m


def empty_road_scenario(scenario_id: str = "empty", speed: float = 5.0) -> scenariomax.Scenario:
    """The SDC alone on the straight road, logged at a constant `speed` (well under the 13.4 m/s limit)."""
    time = np.arange(NUM_STEPS) * DT
    xs = (speed * time)[None]
    return road_scenario(scenario_id, xs, np.full_like(xs, speed))


def lead_car_scenario(scenario_id: str = "lead") -> scenariomax.Scenario:
    """The SDC at 10 m/s behind a car driving 6 m/s; the log has the SDC keep its distance."""
    time = np.arange(NUM_STEPS) * DT
    lead = LEAD_START_X + LEAD_SPEED * time
    sdc = np.minimum(10.0 * time, lead - 20.0)
    xs = np.stack([sdc, lead])
    speeds = np.stack([np.gradient(sdc, DT), np.full(NUM_STEPS, LEAD_SPEED)])
    return road_scenario(scenario_id, xs, speeds)


def red_light_scenario(scenario_id: str = "red") -> scenariomax.Scenario:
    """The SDC at 10 m/s towards a light of its lane at x = 50 m that is red for the whole log."""
    time = np.arange(NUM_STEPS) * DT
    xs = (10.0 * time)[None]
    scenario = road_scenario(scenario_id, xs, np.full_like(xs, 10.0))
    t = NUM_STEPS
    return dataclasses.replace(scenario, tl_state=np.full((1, t), TL_STOP), tl_x=np.full((1, t), LIGHT_X))


def green_light_scenario(scenario_id: str = "green") -> scenariomax.Scenario:
    scenario = red_light_scenario(scenario_id)
    return dataclasses.replace(scenario, tl_state=np.full_like(scenario.tl_state, TL_GO))


def curve_scenario(scenario_id: str = "curve", speed: float = 8.0) -> scenariomax.Scenario:
    """One lane bending left on a circle of CURVE_RADIUS (edges 2 m and 5.5 m off the lane), the SDC
    alone, logged along the lane centre at `speed`."""
    r = CURVE_RADIUS
    angle = np.linspace(-0.3, 2.5, 600)  # radians around the centre (0, r): the lane starts heading east

    def ring(radius):
        return np.stack([radius * np.sin(angle), r - radius * np.cos(angle), 0 * angle], 1)

    road = polylines_to_roadgraph([
        MapPolyline(1, RG_LANE_SURFACE_STREET, ring(r), speed_limit=SPEED_LIMIT),
        MapPolyline(2, RG_ROAD_EDGE_BOUNDARY, ring(r + 2.0)),  # the road on the edge's left
        MapPolyline(3, RG_ROAD_EDGE_BOUNDARY, ring(r - 5.5)[::-1]),
    ])
    time = np.arange(NUM_STEPS) * DT
    theta = speed * time / r  # angle driven from the start point (0, 0)
    ones = np.ones((1, NUM_STEPS), np.float32)
    x, y = (r * np.sin(theta))[None], (r - r * np.cos(theta))[None]
    path_angle = np.arange(0.0, 300.0) / r  # 1 m apart from the start
    path = np.stack([r * np.sin(path_angle), r - r * np.cos(path_angle), 0 * path_angle], 1)[None]
    valid = path_angle < 2.4
    return scenariomax.Scenario(
        scenario_id=scenario_id, object_id=np.array([100]), object_type=np.array([OBJECT_TYPE_VEHICLE]),
        is_sdc=np.array([True]), x=x, y=y, z=0 * ones, bbox_yaw=theta[None], length=4.5 * ones,
        width=2.0 * ones, height=1.6 * ones, velocity_x=speed * np.cos(theta)[None],
        velocity_y=speed * np.sin(theta)[None], valid=ones.astype(bool),
        tl_state=np.full((1, NUM_STEPS), TL_GO), tl_valid=np.zeros((1, NUM_STEPS), bool),
        tl_lane_id=np.ones((1, NUM_STEPS)), tl_x=np.zeros((1, NUM_STEPS)), tl_y=np.zeros((1, NUM_STEPS)),
        tl_z=np.zeros((1, NUM_STEPS)), path_xyz=path, path_valid=valid[None], path_lane_id=np.ones((1, 300)),
        path_arc_length=np.arange(300.0)[None], path_on_route=np.array([True]), source_dataset="test",
        **road, **lane_graph_arrays([LaneLinks(1)]))


ENV_CONFIG = EnvConfig(max_num_objects=8, terminate_on=())  # whole episodes, to see what happens after a hit


@functools.lru_cache(maxsize=8)
def episode_fn(name: str):
    """Jitted unbatched episode of the named policy on states shaped like `small_data_config` (cached:
    one compilation per policy for the whole test session)."""
    env = make_environment(ENV_CONFIG)
    policy = make_policy(name, env)

    def run(state):
        return run_episode(env, policy, state, jax.random.PRNGKey(0), MetricsConfig(), ObservationConfig())

    # every test that runs this policy shares one trace: no recompiles. chex counts traces per (call stack,
    # source, name), so the name carries the policy: two policies first built from one test stay apart
    run.__name__ = f"run_{name}"
    return jax.jit(chex.assert_max_traces(run, n=1))


def as_state(scenario):
    """One unbatched SimulatorState (8 objects, small roadgraph) of a scenario."""
    return jax.tree.map(lambda a: a[0], scenarios_to_batch([scenario], small_data_config("")))


def episode(name: str, scenario):
    """(Rollout, per-step metrics as numpy) of one whole episode (no termination) of a named policy."""
    rollout = jax.device_get(episode_fn(name)(as_state(scenario)))
    return rollout, {k: np.asarray(v) for k, v in rollout.per_step.items()}
