"""Hand-worked values for every metric, batched == unbatched, no recompiles, float32 outputs."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.schema import TL_GO, TL_STOP
from tests.metrics.helpers import LANE_WIDTH, road_index, step_inputs, straight_road
from vmax_sim.map_index import build_map_index, lane_candidates
from vmax_sim.metrics import (
    MetricsConfig,
    aggregate_episodes,
    at_fault_collisions,
    comfort_score,
    comfort_signals,
    driving_direction_score,
    episode_metrics,
    multiple_lanes_score,
    nuplan_score,
    off_route,
    on_multiple_lanes,
    red_light_violation,
    speed_limit_compliance,
    step_metrics,
    time_to_collision,
    vmax_score,
    wrong_way,
)

CONFIG = MetricsConfig()


@pytest.fixture(scope="module")
def index():
    return road_index()


STEP_METRICS = jax.jit(step_metrics)
EPISODE_METRICS = jax.jit(episode_metrics)


@pytest.fixture(scope="module")
def metrics_fn():
    return STEP_METRICS


def test_clean_driving_has_no_event(index, metrics_fn):
    out = metrics_fn(index, step_inputs())
    for key in ("overlap", "offroad", "wrong_way", "off_route", "at_fault_collision", "ttc_violation",
                "red_light", "multiple_lanes", "kinematic_infeasibility"):
        assert float(out[key]) == 0.0, key
    assert float(out["speed"]) == pytest.approx(10.0, abs=1e-4)  # 1 m per 0.1 s step
    assert float(out["speed_limit"]) == pytest.approx(10.0)
    assert float(out["lane_progress"]) == pytest.approx(1.0, abs=1e-5)
    assert float(out["progress_ratio"]) == pytest.approx(1.0 / 80.0, abs=1e-4)  # at x=1 of the logged 80 m
    assert all(v.dtype == jnp.float32 and v.shape == () for v in out.values())


def test_overlap_touching_and_separated(index, metrics_fn):
    sdc = ((-1.0, 0.0), (0.0, 0.0), (1.0, 0.0))
    hit = metrics_fn(index, step_inputs(sdc_xy=sdc, objects=[(4.9, 0.0, 4.0, 2.0, 0.0)]))
    touch = metrics_fn(index, step_inputs(sdc_xy=sdc, objects=[(5.0, 0.0, 4.0, 2.0, 0.0)]))
    apart = metrics_fn(index, step_inputs(sdc_xy=sdc, objects=[(6.0, 0.0, 4.0, 2.0, 0.0)]))
    assert [float(o["overlap"]) for o in (hit, touch, apart)] == [1.0, 0.0, 0.0]
    # moving ego hits a stopped car with its front bumper: at fault
    assert float(hit["at_fault_collision"]) == 1.0


def test_offroad_when_a_corner_crosses_the_right_edge(index, metrics_fn):
    # width 2 m: corners at y - 1; right edge at -1.85 -> off road when y < -0.85
    on = metrics_fn(index, step_inputs(sdc_xy=((-1.0, -0.6), (0.0, -0.6), (1.0, -0.6))))
    off = metrics_fn(index, step_inputs(sdc_xy=((-1.0, -1.35), (0.0, -1.35), (1.0, -1.35))))
    assert float(on["offroad"]) == 0.0 and float(on["offroad_distance"]) == pytest.approx(-0.25, abs=1e-4)
    assert float(off["offroad"]) == 1.0 and float(off["offroad_distance"]) == pytest.approx(0.5, abs=1e-4)


def test_ttc_of_two_cars_closing_at_10_mps_5_m_apart():
    ego = jnp.array([0.0, 0.0, 4.0, 2.0, 0.0])
    boxes = jnp.array([[9.0, 0.0, 4.0, 2.0, 0.0], [-9.0, 0.0, 4.0, 2.0, 0.0]])
    vels = jnp.zeros((2, 2))
    ttc = time_to_collision(ego, jnp.array([10.0, 0.0]), boxes, vels, jnp.array([True, True]), 0.95)
    assert float(ttc) == pytest.approx(0.5, abs=1e-5)
    # the same car behind the ego (ego reversing into it) is not counted: agents ahead only
    ttc_behind = time_to_collision(ego, jnp.array([-10.0, 0.0]), boxes, vels, jnp.array([False, True]), 0.95)
    assert np.isinf(float(ttc_behind))


def test_ttc_violation_in_step_metrics(index, metrics_fn):
    out = metrics_fn(index, step_inputs(objects=[(11.0, 0.0, 4.0, 2.0, 0.0)]))  # 6 m gap at 10 m/s -> 0.6 s
    assert float(out["ttc"]) == pytest.approx(0.6, abs=1e-4) and float(out["ttc_violation"]) == 1.0
    far = metrics_fn(index, step_inputs(objects=[(16.0, 0.0, 4.0, 2.0, 0.0)]))  # 1.1 s
    assert float(far["ttc_violation"]) == 0.0


@pytest.mark.parametrize("name, obj, obj_speed, ego_speed, multiple, expected", [
    ("front bumper hit", (3.9, 0.0, 4.0, 2.0, 0.0), 5.0, 10.0, False, True),
    ("rear hit never", (-3.9, 0.0, 4.0, 2.0, 0.0), 5.0, 10.0, False, False),
    ("stopped ego never", (3.9, 0.0, 4.0, 2.0, 0.0), 0.0, 0.0, False, False),
    ("lateral, one lane", (-0.5, 1.9, 4.0, 2.0, 0.0), 5.0, 10.0, False, False),
    ("lateral, several lanes", (-0.5, 1.9, 4.0, 2.0, 0.0), 5.0, 10.0, True, True),
    ("lateral into a stopped object", (-0.5, 1.9, 4.0, 2.0, 0.0), 0.0, 10.0, False, True),
])
def test_at_fault_rules(name, obj, obj_speed, ego_speed, multiple, expected):
    got = at_fault_collisions(jnp.array([0.0, 0.0, 4.0, 2.0, 0.0]), jnp.asarray(ego_speed), jnp.array([obj]),
                              jnp.array([obj_speed]), jnp.array([True]), jnp.asarray(multiple),
                              jnp.asarray(False), CONFIG.stopped_speed)
    assert bool(got[0]) is expected, name


def test_speed_limit_compliance_formula():
    # 11 steps (duration 1 s); overspeed 1.115 m/s on 4 steps: loss = 0.1 * 4.46 / (2.23 * 1.0) = 0.2
    violation = jnp.array([0, 0, 1.115, 1.115, 1.115, 1.115, 0, 0, 0, 0, 0], jnp.float32)
    score = speed_limit_compliance(violation, jnp.ones(11, bool))
    assert float(score) == pytest.approx(0.8, abs=1e-5)
    assert float(speed_limit_compliance(violation * 10, jnp.ones(11, bool))) == 0.0


def test_speed_violation_against_the_lane_limit(index, metrics_fn):
    fast = metrics_fn(index, step_inputs(sdc_xy=((-2.4, 0.0), (-1.2, 0.0), (0.0, 0.0))))  # 12 m/s on a 10 m/s lane
    assert float(fast["speed_violation"]) == pytest.approx(2.0, abs=1e-3)


def test_comfort_bounds():
    t = jnp.arange(40) * 0.1
    valid = jnp.ones(40, bool)
    zero = jnp.zeros(40)
    cruising = comfort_signals(10.0 * t, zero, zero, valid)
    assert float(comfort_score(cruising)) == 1.0
    np.testing.assert_allclose(cruising["lon_accel"], 0.0, atol=1e-3)
    braking = comfort_signals(10.0 * t - 0.5 * 5.0 * t ** 2, zero, zero, valid)  # -5 m/s^2 < -4.05
    assert float(comfort_score(braking)) == 0.0
    np.testing.assert_allclose(braking["lon_accel"], -5.0, atol=1e-2)
    gentle = comfort_signals(10.0 * t - 0.5 * 3.0 * t ** 2, zero, zero, valid)  # -3 m/s^2 is fine
    assert float(comfort_score(gentle)) == 1.0
    spinning = comfort_signals(zero, zero, 1.2 * t, valid)  # yaw rate 1.2 > 0.95 rad/s
    assert float(comfort_score(spinning)) == 0.0
    np.testing.assert_allclose(spinning["yaw_rate"], 1.2, atol=1e-3)


def test_driving_direction_thresholds():
    valid = jnp.ones(20, bool)
    forward = driving_direction_score(jnp.full(20, 1.0), valid)
    reverse_4m = driving_direction_score(jnp.full(20, -0.4), valid)  # 4 m against the lane in 1 s
    reverse_7m = driving_direction_score(jnp.full(20, -0.7), valid)
    assert [float(s) for s, _ in (forward, reverse_4m, reverse_7m)] == [1.0, 0.5, 0.0]
    assert float(reverse_4m[1]) == pytest.approx(4.0, abs=1e-4)


def _road_index_with(oncoming_lane_2=False, extra_lanes=()):
    """The straight two-lane road, lane 2 running -x when `oncoming_lane_2`, plus extra lanes (id, (n, 2) points)."""
    r = straight_road()
    xyz, dirs, types, ids, limit = r["xyz"].copy(), r["dir"].copy(), r["types"], r["ids"], r["speed_limit"]
    if oncoming_lane_2:
        xyz[ids == 2] = xyz[ids == 2][::-1]
        dirs[ids == 2, 0] = -1.0
    for lane_id, points in extra_lanes:
        points = np.asarray(points, np.float32)
        step = np.diff(points, axis=0) / np.linalg.norm(np.diff(points, axis=0), axis=1, keepdims=True)
        xyz = np.concatenate([xyz, np.pad(points, ((0, 0), (0, 1)))])
        dirs = np.concatenate([dirs, np.pad(np.concatenate([step, step[-1:]]), ((0, 0), (0, 1)))])
        types = np.concatenate([types, np.full(len(points), types[ids == 1][0])])
        ids = np.concatenate([ids, np.full(len(points), lane_id)])
        limit = np.concatenate([limit, np.full(len(points), 10.0, np.float32)])
    return build_map_index(xyz, dirs, types, ids, np.ones(len(xyz), bool), None, np.zeros(2), speed_limit=limit)


def test_lane_progress_follows_the_lane_the_sdc_is_in(metrics_fn):
    """nuPlan judges the direction of the lane the ego is in. A junction connector of the crossing traffic
    over the SDC's lane is not it, even where it is the nearest centreline (the Nocturne expert crossed two
    such connectors 0-1 m away while 1.1 m off its own lane's centre); an oncoming lane the SDC drives in
    is, even with a lane of its own direction 3.2 m away; beyond half a lane width of every lane, nothing is."""
    angle = np.radians(150.0)  # oncoming traffic turning across the SDC's path, through (0, 1)
    along = np.arange(-20.0, 20.5, 1.0)[:, None]
    connector = np.array([0.0, 1.0]) + along * np.array([np.cos(angle), np.sin(angle)])
    crossing = _road_index_with(extra_lanes=[(9, connector)])
    sdc = ((-2.0, 1.0), (-1.0, 1.0), (0.0, 1.0))  # +x at 1 m per step, 1 m left of lane 1's centre
    assert float(lane_candidates(crossing, jnp.array([0.0, 1.0])).distance.min()) < 0.01  # the connector is nearest
    assert float(metrics_fn(crossing, step_inputs(sdc_xy=sdc))["lane_progress"]) == pytest.approx(1.0, abs=1e-4)

    oncoming = _road_index_with(oncoming_lane_2=True)
    wrong_way = ((-2.0, 3.2), (-1.0, 3.2), (0.0, 3.2))  # +x inside lane 2, which runs -x
    assert float(metrics_fn(oncoming, step_inputs(sdc_xy=wrong_way))["lane_progress"]) == pytest.approx(-1.0, abs=1e-4)

    outside = ((-2.0, -2.2), (-1.0, -2.2), (0.0, -2.2))  # 2.2 m right of lane 1, the nearest centreline
    assert float(metrics_fn(oncoming, step_inputs(sdc_xy=outside))["lane_progress"]) == 0.0


@pytest.mark.parametrize("seconds, expected", [(0.0, 1.0), (3.4, 1.0), (3.5, 0.5), (5.7, 0.5), (5.8, 0.0)])
def test_multiple_lanes_thresholds(seconds, expected):
    assert float(multiple_lanes_score(jnp.asarray(seconds))) == expected


def test_on_multiple_lanes_when_straddling_the_line(index):
    centred = lane_candidates(index, jnp.array([0.0, 0.0]))
    straddle = lane_candidates(index, jnp.array([0.0, 0.5 * LANE_WIDTH]))
    assert not bool(on_multiple_lanes(centred, jnp.array([0.0, 0.0]), jnp.asarray(0.0), 2.0, 1.85, 30.0))
    assert bool(on_multiple_lanes(straddle, jnp.array([0.0, 0.5 * LANE_WIDTH]), jnp.asarray(0.0), 2.0, 1.85, 30.0))


def test_off_centre_in_a_narrow_lane_is_not_on_two_lanes(index):
    # The boundary is LANE_WIDTH / 2 from the centre; a 2 m wide box whose centre is d from it crosses it by
    # 1 - d metres, which counts only beyond the 0.3 m tolerance: d = 0.8 (crosses 0.2 m) no, d = 0.6 (0.4 m) yes.
    inside = jnp.array([0.0, 0.5 * LANE_WIDTH - 0.8])
    across = jnp.array([0.0, 0.5 * LANE_WIDTH - 0.6])
    assert not bool(on_multiple_lanes(lane_candidates(index, inside), inside, jnp.asarray(0.0), 2.0, 1.85, 30.0))
    assert bool(on_multiple_lanes(lane_candidates(index, across), across, jnp.asarray(0.0), 2.0, 1.85, 30.0))


def test_red_light_crossing(index, metrics_fn):
    # the front bumper (2 m ahead of the centre) passes x = 2.5 between the last two steps
    sdc = ((-1.0, 0.0), (0.0, 0.0), (1.0, 0.0))
    red = metrics_fn(index, step_inputs(sdc_xy=sdc, lights=[(2.5, 0.0, 1, TL_STOP)]))
    green = metrics_fn(index, step_inputs(sdc_xy=sdc, lights=[(2.5, 0.0, 1, TL_GO)]))
    other_lane = metrics_fn(index, step_inputs(sdc_xy=sdc, lights=[(2.5, 0.0, 2, TL_STOP)]))
    not_yet = metrics_fn(index, step_inputs(sdc_xy=sdc, lights=[(3.5, 0.0, 1, TL_STOP)]))
    assert [float(o["red_light"]) for o in (red, green, other_lane, not_yet)] == [1.0, 0.0, 0.0, 0.0]


def test_red_light_function_directly():
    args = {"lane_id": jnp.asarray(7), "lane_dir": jnp.array([1.0, 0.0]), "light_xy": jnp.array([[5.0, 0.3]]),
                "light_lane_id": jnp.array([7]), "light_state": jnp.array([TL_STOP]), "light_valid": jnp.array([True]),
                "red_states": CONFIG.red_light_states, "max_lateral": 2.5}
    assert bool(red_light_violation(jnp.array([4.5, 0.0]), jnp.array([5.5, 0.0]), **args))
    assert not bool(red_light_violation(jnp.array([5.5, 0.0]), jnp.array([6.5, 0.0]), **args))


def test_wrong_way_and_off_route_rules():
    assert not bool(wrong_way(jnp.asarray(3.0), 3.5)) and bool(wrong_way(jnp.asarray(3.6), 3.5))
    assert not bool(wrong_way(jnp.asarray(jnp.inf), 3.5))  # no paths: no verdict
    assert bool(off_route(jnp.asarray(5.5), jnp.asarray(jnp.inf), 5.0, 2.0))
    assert bool(off_route(jnp.asarray(3.7), jnp.asarray(0.2), 5.0, 2.0))  # clearly on another path
    assert not bool(off_route(jnp.asarray(1.0), jnp.asarray(2.7), 5.0, 2.0))


def test_off_route_on_the_neighbour_lane(index, metrics_fn):
    y = LANE_WIDTH
    out = metrics_fn(index, step_inputs(sdc_xy=((-1.0, y), (0.0, y), (1.0, y))))
    assert float(out["off_route"]) == 1.0 and float(out["wrong_way"]) == 0.0


def test_progress_and_log_divergence(index, metrics_fn):
    out = metrics_fn(index, step_inputs(sdc_xy=((38.0, 0.0), (39.0, 0.0), (40.0, 0.0)), sdc_log_xy=(37.0, 4.0)))
    assert float(out["progress_ratio"]) == pytest.approx(0.5, abs=1e-4)  # 40 of the logged 80 m
    assert float(out["ego_progress"]) == pytest.approx(40.0, abs=1e-3)
    assert float(out["log_divergence"]) == pytest.approx(5.0, abs=1e-4)


def test_kinematic_infeasibility(index, metrics_fn):
    # speed 10 -> 20 m/s in one step: 100 m/s^2
    out = metrics_fn(index, step_inputs(sdc_xy=((-3.0, 0.0), (-2.0, 0.0), (0.0, 0.0))))
    assert float(out["kinematic_infeasibility"]) == 1.0


def _episode(**overrides):
    base = {"at_fault_collision": 0.0, "offroad": 0.0, "red_light": 0.0, "making_progress": 1.0,
                "driving_direction": 1.0, "ttc_within_bound": 1.0, "ego_progress": 1.0, "speed_limit_compliance": 1.0,
                "comfort": 1.0, "multiple_lanes_score": 1.0}
    base.update(overrides)
    return {k: jnp.asarray(v, jnp.float32) for k, v in base.items()}


def test_score_products():
    assert float(nuplan_score(_episode())) == pytest.approx(1.0)
    # (5 * 1 + 5 * 0.5 + 4 * 0.8 + 2 * 0) / 16 = 0.66875, times the 0.5 driving-direction multiplier
    ep = _episode(ego_progress=0.5, speed_limit_compliance=0.8, comfort=0.0, driving_direction=0.5)
    assert float(nuplan_score(ep)) == pytest.approx(0.5 * 10.7 / 16)
    # V-Max adds the lanes score with weight 3: (10.7 + 3 * 0.5) / 19
    assert float(vmax_score(dict(ep, multiple_lanes_score=jnp.asarray(0.5)))) == pytest.approx(0.5 * 12.2 / 19)
    assert float(nuplan_score(_episode(at_fault_collision=1.0))) == 0.0
    assert float(nuplan_score(_episode(red_light=1.0))) == 1.0  # red light only multiplies the V-Max score
    assert float(vmax_score(_episode(red_light=1.0))) == 0.0


def _rollout_per_step(index, num_steps=30, objects=()):
    """Per-step metrics of an SDC driving 1 m per step along lane 1 (x from 0)."""
    outs = []
    fn = STEP_METRICS
    for t in range(num_steps):
        x = float(t)
        outs.append(fn(index, step_inputs(sdc_xy=((x - 2, 0.0), (x - 1, 0.0), (x, 0.0)), objects=objects,
                                          log_end=(float(num_steps - 1), 0.0))))
    return {k: jnp.stack([o[k] for o in outs]) for k in outs[0]}


def test_episode_metrics_of_a_clean_drive(index):
    per_step = _rollout_per_step(index)
    ep = EPISODE_METRICS(per_step)
    assert float(ep["nuplan_score"]) == pytest.approx(1.0)
    assert float(ep["vmax_score"]) == pytest.approx(1.0)
    assert float(ep["progress_ratio"]) == pytest.approx(1.0, abs=1e-4)
    assert float(ep["accurate"]) == 1.0
    assert all(v.dtype == jnp.float32 for v in ep.values())
    # an invalid tail is ignored
    valid = jnp.arange(30) < 20
    assert float(EPISODE_METRICS(per_step, valid)["ego_progress"]) == pytest.approx(19 / 29, abs=1e-3)


def test_accuracy_aggregation():
    episodes = {"accurate": jnp.array([1.0, 0.0, 1.0, 1.0]), "accurate_at_fault": jnp.array([1.0, 1.0, 1.0, 1.0]),
                "vmax_score": jnp.array([1.0, 0.0, 0.5, 0.5])}
    agg = aggregate_episodes(episodes)
    assert float(agg["accuracy"]) == 0.75 and float(agg["accuracy_at_fault"]) == 1.0
    assert float(agg["vmax_score"]) == 0.5


def test_batched_equals_unbatched_and_no_recompiles(index):
    cases = [step_inputs(), step_inputs(objects=[(4.9, 0.0, 4.0, 2.0, 0.0)]),
             step_inputs(sdc_xy=((-1.0, -1.35), (0.0, -1.35), (1.0, -1.35)))]
    batch = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *cases)
    indexes = jax.tree_util.tree_map(lambda x: jnp.stack([x] * len(cases)), index)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def batched(indexes, batch):
        return jax.vmap(step_metrics)(indexes, batch)

    got = batched(indexes, batch)
    for i, case in enumerate(cases):
        single = STEP_METRICS(index, case)
        for key, value in single.items():
            np.testing.assert_allclose(got[key][i], value, rtol=1e-5, atol=1e-5, err_msg=key)
    shifted = jax.tree_util.tree_map(lambda x: x + 0.5 if x.dtype == jnp.float32 else x, batch)
    batched(indexes, shifted)  # new values, same shapes: no retrace (assert_max_traces would raise)
