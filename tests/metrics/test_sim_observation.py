"""Observation: SDC frame, normalisation, fixed shapes with masks, map box, lights, route, noise."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from scenariomax.schema import OBJECT_TYPE_PEDESTRIAN, OBJECT_TYPE_VEHICLE, TL_GO, TL_STOP
from tests.metrics.helpers import road_index, route_paths
from vmax_sim.observation import (
    LIGHT_FEATURES,
    OBJECT_FEATURES,
    ROADGRAPH_FEATURES,
    NoiseConfig,
    ObservationConfig,
    ObservationInputs,
    object_feature_count,
    observe,
)
from vmax_sim.observation.features import compact, route_frame

K = 5


def obs_inputs(objects=((10.0, 0.0, 0.0, 5.0),), sdc_yaw=0.0, lights=()):
    """SDC at the origin; objects (x, y, yaw, speed) static in the history, all vehicles."""
    n = 6
    xy = np.zeros((n, K, 2), np.float32)
    yaw = np.zeros((n, K), np.float32)
    vel = np.zeros((n, K, 2), np.float32)
    valid = np.zeros((n, K), bool)
    for i, (x, y, heading, speed) in enumerate(objects):
        xy[i], yaw[i], valid[i] = (x, y), heading, True
        vel[i] = speed * np.array([np.cos(heading), np.sin(heading)])
    types = np.full(n, OBJECT_TYPE_VEHICLE, np.int32)
    types[1] = OBJECT_TYPE_PEDESTRIAN
    light_xy = np.zeros((8, 2), np.float32)
    light_state = np.zeros(8, np.int32)
    light_valid = np.zeros(8, bool)
    for i, (x, y, state) in enumerate(lights):
        light_xy[i], light_state[i], light_valid[i] = (x, y), state, True
    path_xy, path_valid, path_arc, on_route = route_paths()
    sdc_xy = np.stack([np.arange(-K + 1, 1, dtype=np.float32), np.zeros(K, np.float32)], -1)
    return ObservationInputs(
        sdc_xy=jnp.asarray(sdc_xy), sdc_yaw=jnp.full(K, sdc_yaw, jnp.float32),
        sdc_vel=jnp.tile(jnp.array([[10.0, 0.0]]), (K, 1)), sdc_valid=jnp.ones(K, bool),
        sdc_size=jnp.array([4.5, 2.0], jnp.float32),
        object_xy=jnp.asarray(xy), object_yaw=jnp.asarray(yaw), object_vel=jnp.asarray(vel),
        object_size=jnp.tile(jnp.array([[4.5, 2.0]]), (n, 1)), object_type=jnp.asarray(types),
        object_valid=jnp.asarray(valid), light_xy=jnp.asarray(light_xy), light_state=jnp.asarray(light_state),
        light_valid=jnp.asarray(light_valid), path_xy=jnp.asarray(path_xy), path_valid=jnp.asarray(path_valid),
        path_arc=jnp.asarray(path_arc), path_on_route=jnp.asarray(on_route))


@pytest.fixture(scope="module")
def index():
    return road_index()


OBSERVE = jax.jit(observe, static_argnames=("config",))


def test_shapes_and_object_features(index):
    config = ObservationConfig(num_objects=4, num_history=K)
    obs = OBSERVE(index, obs_inputs(objects=[(10.0, 0.0, np.pi / 2, 5.0), (0.0, 25.0, 0.0, 0.0)]), config)
    assert obs.objects.shape == (4, K, OBJECT_FEATURES) and obs.objects_valid.shape == (4, K)
    assert obs.roadgraph.shape[1] == ROADGRAPH_FEATURES and obs.lights.shape == (5, LIGHT_FEATURES)
    assert obs.path_targets.shape == (10, 2)
    first = np.asarray(obs.objects[0, -1])
    # 10 m ahead / 50 m; velocity 5 m/s along +y / 30; heading +90 deg; size / 10; vehicle one-hot
    np.testing.assert_allclose(first[:8], [0.2, 0.0, 0.0, 5 / 30, 0.0, 1.0, 0.45, 0.2], atol=1e-5)
    np.testing.assert_allclose(first[8:], [1, 0, 0, 0])
    assert np.asarray(obs.objects_valid).sum(axis=1).tolist() == [K, K, 0, 0]
    assert np.all(np.asarray(obs.objects[2:]) == 0)
    assert all(x.dtype in (jnp.float32, jnp.bool_) for x in jax.tree_util.tree_leaves(obs))


def test_features_rotate_into_the_sdc_frame(index):
    obs = OBSERVE(index, obs_inputs(objects=[(0.0, 10.0, np.pi / 2, 0.0)], sdc_yaw=np.pi / 2), ObservationConfig())
    # an object 10 m along +y is straight ahead of an SDC heading +y (SDC at the origin now)
    np.testing.assert_allclose(obs.objects[0, -1, :2], [0.2, 0.0], atol=1e-5)
    np.testing.assert_allclose(obs.objects[0, -1, 4:6], [1.0, 0.0], atol=1e-5)


def test_sdc_history_hides_the_older_steps_of_the_sdc_only(index):
    full = OBSERVE(index, obs_inputs(), ObservationConfig())
    now_only = OBSERVE(index, obs_inputs(), ObservationConfig(sdc_history=1))
    assert np.asarray(now_only.sdc_valid).tolist() == [False] * (K - 1) + [True]
    assert np.all(np.asarray(now_only.sdc[:-1]) == 0)
    np.testing.assert_array_equal(now_only.sdc[-1], full.sdc[-1])  # now: speed and heading still seen
    np.testing.assert_array_equal(now_only.objects, full.objects)  # the others keep their history
    np.testing.assert_array_equal(now_only.objects_valid, full.objects_valid)
    np.testing.assert_array_equal(OBSERVE(index, obs_inputs(), ObservationConfig(sdc_history=K + 3)).sdc, full.sdc)
    with pytest.raises(ValueError, match="sdc_history"):
        ObservationConfig(sdc_history=0)


def test_sdc_size_adds_the_sdc_box_beside_its_history_and_changes_nothing_else(index):
    plain = OBSERVE(index, obs_inputs(), ObservationConfig())
    sized = OBSERVE(index, obs_inputs(), ObservationConfig(sdc_size=True))
    assert plain.sdc.shape == (K, 6) and sized.sdc.shape == (K, 8)
    np.testing.assert_array_equal(sized.sdc[:, :6], plain.sdc)
    np.testing.assert_allclose(sized.sdc[:, 6:], np.tile([[0.45, 0.2]], (K, 1)), atol=1e-6)  # 4.5 x 2.0 over 10 m
    bigger = OBSERVE(index, obs_inputs().replace(sdc_size=jnp.array([5.29, 2.33])), ObservationConfig(sdc_size=True))
    assert not np.allclose(bigger.sdc[:, 6:], sized.sdc[:, 6:])
    np.testing.assert_array_equal(sized.objects, plain.objects)


def test_roadgraph_points_lie_in_the_box_ahead(index):
    config = ObservationConfig()
    obs = OBSERVE(index, obs_inputs(), config)
    pts = np.asarray(obs.roadgraph)[np.asarray(obs.roadgraph_valid)] * config.max_distance
    assert len(pts) > 20
    assert pts[:, 0].min() >= -5.0 and pts[:, 0].max() <= 50.0 and np.abs(pts[:, 1]).max() <= 20.0
    assert set(np.round(pts[:, 1].astype(np.float64), 2).tolist()) <= {0.0, 3.7, 1.85, -1.85, 5.55}
    edges_only = OBSERVE(index, obs_inputs(), ObservationConfig(roadgraph_types="edges"))
    kinds = np.asarray(edges_only.roadgraph)[np.asarray(edges_only.roadgraph_valid)][:, 5:]
    assert len(kinds) > 0 and np.all(kinds == [1, 0, 0])


def test_packed_roadgraph_keeps_a_fixed_number_of_points(index):
    config = ObservationConfig(num_roadgraph_points=16)
    obs = OBSERVE(index, obs_inputs(), config)
    assert obs.roadgraph.shape == (16, ROADGRAPH_FEATURES)
    assert 8 <= int(obs.roadgraph_valid.sum()) <= 16  # evenly thinned: every stride-th in-box point
    source, filled = compact(jnp.array([True, False, True, True, False, True]), 3)
    # 4 valid entries into 3 slots: stride 2 keeps the 1st and 3rd valid entries
    assert (np.asarray(source)[np.asarray(filled)].tolist() == [0, 3]
            and np.asarray(filled).tolist() == [True, True, False])


def test_closest_lights_and_path_targets(index):
    lights = [(30.0, 0.0, TL_GO), (8.0, 1.0, TL_STOP), (200.0, 0.0, TL_STOP)]
    obs = OBSERVE(index, obs_inputs(lights=lights), ObservationConfig(num_lights=2))
    np.testing.assert_allclose(obs.lights[0], [8 / 50, 1 / 50, 1, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(obs.lights[1], [30 / 50, 0, 0, 0, 1, 0], atol=1e-6)
    # route along lane 1 from the SDC at x = 0: targets every 5 m ahead
    np.testing.assert_allclose(obs.path_targets[:, 0] * 50, 5.0 * np.arange(1, 11), atol=1e-3)
    assert bool(jnp.all(obs.path_targets_valid))


def test_noise_is_driven_by_the_key(index):
    config = ObservationConfig(noise=NoiseConfig(position_std=0.5))
    inputs = obs_inputs()
    a = OBSERVE(index, inputs, config, jax.random.PRNGKey(0))
    b = OBSERVE(index, inputs, config, jax.random.PRNGKey(0))
    c = OBSERVE(index, inputs, config, jax.random.PRNGKey(1))
    np.testing.assert_array_equal(a.objects, b.objects)
    assert not np.allclose(a.objects, c.objects)


def test_dropout_and_occlusion(index):
    far_drop = ObservationConfig(noise=NoiseConfig(dropout_start=5.0, dropout_max_prob=1.0))
    inputs = obs_inputs(objects=[(49.0, 0.0, 0.0, 0.0), (3.0, 0.0, 0.0, 0.0)])
    dropped = OBSERVE(index, inputs, far_drop, jax.random.PRNGKey(0))
    assert np.asarray(dropped.objects_valid[:, -1]).tolist()[:2] == [True, False]  # sorted by distance: near, far
    occluding = ObservationConfig(noise=NoiseConfig(occlusion=True))
    hidden = OBSERVE(index, obs_inputs(objects=[(20.0, 0.0, 0.0, 0.0), (10.0, 0.0, 0.0, 0.0), (10.0, 8.0, 0.0, 0.0)]),
                     occluding, jax.random.PRNGKey(0))
    # the car at 20 m is behind the one at 10 m; the one off to the side stays visible
    assert int(hidden.objects_valid[:, -1].sum()) == 2


def test_map_dropout_hides_a_fresh_share_of_the_map_points_and_only_with_a_key(index):
    config = ObservationConfig(noise=NoiseConfig(map_dropout=0.5))
    inputs = obs_inputs()
    clean = OBSERVE(index, inputs, ObservationConfig())
    shown = [np.asarray(OBSERVE(index, inputs, config, jax.random.PRNGKey(seed)).roadgraph_valid) for seed in range(4)]
    total = int(clean.roadgraph_valid.sum())
    assert total > 20
    for valid in shown:
        assert not np.any(valid & ~np.asarray(clean.roadgraph_valid))  # only hides
        assert 0.3 * total < valid.sum() < 0.7 * total
    assert not np.array_equal(shown[0], shown[1])  # another sample each step
    hidden = OBSERVE(index, inputs, config, jax.random.PRNGKey(0))
    np.testing.assert_array_equal(np.asarray(hidden.roadgraph)[~shown[0]], 0.0)
    # the objects are untouched, and without a key (evaluation) the map is whole
    np.testing.assert_array_equal(hidden.objects, clean.objects)
    np.testing.assert_array_equal(OBSERVE(index, inputs, config).roadgraph_valid, clean.roadgraph_valid)
    # training environments hand the observation a key when any noise is on
    assert config.noise.active and not config.noise.on_objects and not NoiseConfig().active
    with pytest.raises(ValueError, match="map_dropout"):
        NoiseConfig(map_dropout=1.0)


def test_sdc_history_dropout_hides_the_whole_past_at_a_fresh_share_of_the_steps_and_only_with_a_key(index):
    config = ObservationConfig(noise=NoiseConfig(sdc_history_dropout=0.5))
    inputs = obs_inputs()
    clean = OBSERVE(index, inputs, ObservationConfig())
    assert bool(np.all(clean.sdc_valid))
    seen = [np.asarray(OBSERVE(index, inputs, config, jax.random.PRNGKey(seed)).sdc_valid) for seed in range(40)]
    hidden = [valid for valid in seen if not valid.all()]
    assert 8 < len(hidden) < 32  # about half the steps
    for valid in hidden:  # all of the past goes, never the present
        assert valid[-1] and not valid[:-1].any()
    past_hidden = OBSERVE(index, inputs, config, jax.random.PRNGKey(next(i for i, v in enumerate(seen) if not v.all())))
    np.testing.assert_array_equal(np.asarray(past_hidden.sdc)[:-1], 0.0)
    np.testing.assert_array_equal(past_hidden.sdc[-1], clean.sdc[-1])
    np.testing.assert_array_equal(past_hidden.roadgraph_valid, clean.roadgraph_valid)  # the rest untouched
    # without a key (evaluation) the past is always shown; training environments hand a key when it is on
    np.testing.assert_array_equal(OBSERVE(index, inputs, config).sdc_valid, clean.sdc_valid)
    assert config.noise.active and not config.noise.on_objects
    with pytest.raises(ValueError, match="sdc_history_dropout"):
        NoiseConfig(sdc_history_dropout=1.0)


def test_batched_equals_unbatched_and_no_recompiles(index):
    config = ObservationConfig()
    cases = [obs_inputs(), obs_inputs(objects=[(5.0, 3.0, 0.3, 2.0)], sdc_yaw=0.4)]
    batch = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *cases)
    indexes = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), index)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def batched(indexes, batch):
        return jax.vmap(lambda i, b: observe(i, b, config))(indexes, batch)

    got = batched(indexes, batch)
    for i, case in enumerate(cases):
        single = OBSERVE(index, case, config)
        for a, b in zip(jax.tree_util.tree_leaves(single), jax.tree_util.tree_leaves(got)):
            np.testing.assert_allclose(b[i], a, rtol=1e-5, atol=1e-5)
    batched(indexes, jax.tree_util.tree_map(lambda x: x + 0.1 if x.dtype == jnp.float32 else x, batch))


def test_route_selection_keeps_the_car_ahead_that_parked_cars_push_out(index):
    # four cars parked 4.5 m to the sides of the SDC, one follower behind it, a car 30 m ahead on its route
    objects = [(2.0, 4.5, 0.0, 0.0), (-2.0, 4.5, 0.0, 0.0), (5.0, -4.5, 0.0, 0.0), (-5.0, -4.5, 0.0, 0.0),
               (30.0, 0.0, 0.0, 0.0), (-20.0, 0.0, 0.0, 8.0)]
    inputs = obs_inputs(objects=objects)
    nearest = OBSERVE(index, inputs, ObservationConfig(num_objects=3, num_history=K))
    route = OBSERVE(index, inputs, ObservationConfig(num_objects=3, num_history=K, object_selection="route"))
    ahead_x = 30.0 / 50.0
    assert not np.any(np.isclose(np.asarray(nearest.objects[:, -1, 0]), ahead_x))  # the nearest three are parked
    np.testing.assert_allclose(route.objects[0, -1, :2], [ahead_x, 0.0], atol=1e-5)  # on the route: first
    np.testing.assert_allclose(route.objects[1:, -1, :2], nearest.objects[:2, -1, :2], atol=1e-5)  # then nearest
    # with room for everyone both choose the same objects
    wide = [OBSERVE(index, inputs, ObservationConfig(num_objects=8, num_history=K, object_selection=choice))
            for choice in ("nearest", "route")]
    as_set = [sorted(map(tuple, np.round(np.asarray(o.objects[:, -1, :2])[np.asarray(o.objects_valid[:, -1])], 4)))
              for o in wide]
    assert as_set[0] == as_set[1] and len(as_set[0]) == 6
    with pytest.raises(ValueError, match="object_selection"):
        ObservationConfig(object_selection="closest")


def test_route_selection_reach_shows_a_car_standing_beyond_the_path_targets(index):
    # a car at rest 75 m ahead on the route (beyond the 50 m the path targets span: the distance at which a teacher
    # starts braking for it at 14 m/s) and four cars parked beside the SDC, three slots
    objects = [(2.0, 4.5, 0.0, 0.0), (-2.0, 4.5, 0.0, 0.0), (5.0, -4.5, 0.0, 0.0), (-5.0, -4.5, 0.0, 0.0),
               (75.0, 0.0, 0.0, 0.0)]
    inputs = obs_inputs(objects=objects)
    shown = {reach: np.asarray(OBSERVE(index, inputs, ObservationConfig(
        num_objects=3, num_history=K, object_selection="route", route_selection_m=reach)).objects[:, -1, :2])
        for reach in (None, 50.0, 100.0)}
    far = [75.0 / 50.0, 0.0]
    assert not np.any(np.all(np.isclose(shown[None], far, atol=1e-5), axis=1))  # the parked cars fill the slots
    np.testing.assert_array_equal(shown[50.0], shown[None])  # the targets' own span: the default choice
    np.testing.assert_allclose(shown[100.0][0], far, atol=1e-5)  # reached: on the route, first
    np.testing.assert_allclose(shown[100.0][1:], shown[None][:2], atol=1e-5)  # then the nearest, as before
    with pytest.raises(ValueError, match="route_selection_m"):
        ObservationConfig(route_selection_m=0.0)


def test_route_far_slots_add_the_far_car_without_taking_a_near_slot(index):
    # the scene above with a pedestrian-sized object crossing 8 m ahead off the route: the 100 m route-first choice
    # gives the far car a slot and drops a near object; a far slot keeps every near one and adds the far car
    objects = [(2.0, 4.5, 0.0, 0.0), (-2.0, 4.5, 0.0, 0.0), (5.0, -4.5, 0.0, 0.0), (8.0, 6.0, 0.0, 0.0),
               (75.0, 0.0, 0.0, 0.0)]
    inputs = obs_inputs(objects=objects)

    def shown(**options):
        observation = OBSERVE(index, inputs, ObservationConfig(num_objects=3, num_history=K, object_selection="route",
                                                               **options))
        xy, valid = np.asarray(observation.objects[:, -1, :2]), np.asarray(observation.objects_valid[:, -1])
        return xy, valid

    near, _ = shown()
    reach, _ = shown(route_selection_m=100.0)
    extra, extra_valid = shown(route_selection_m=100.0, route_far_slots=2)
    far = [75.0 / 50.0, 0.0]
    assert np.allclose(reach[0], far, atol=1e-5) and len(reach) == 3  # a near object lost its slot
    assert extra.shape == (5, 2) and extra_valid.tolist() == [True, True, True, True, False]
    np.testing.assert_allclose(extra[:3], near, atol=1e-5)  # the near slots as without the reach
    np.testing.assert_allclose(extra[3], far, atol=1e-5)  # the far car in the first far slot; nothing else that far
    assert ObservationConfig(route_far_slots=2).num_object_slots == 8  # nearest-first: no far slots
    with pytest.raises(ValueError, match="route_far_slots"):
        ObservationConfig(route_far_slots=-1)


def test_route_forecast_gives_a_slot_to_the_car_crossing_into_the_route_before_it_is_in_the_way(index):
    # three cars parked beside the SDC; 20 m ahead a car 12 m left of the route drives across it at 5 m/s (in the
    # corridor from 1.8 s on) and one 12 m right of it drives away from it; a car follows 10 m behind the SDC at 8 m/s
    # (its forecast runs up the route); three slots
    objects = [(2.0, 4.5, 0.0, 0.0), (-2.0, 4.5, 0.0, 0.0), (5.0, -4.5, 0.0, 0.0),
               (20.0, 12.0, -np.pi / 2, 5.0), (20.0, -12.0, -np.pi / 2, 5.0), (-10.0, 0.0, 0.0, 8.0)]
    inputs = obs_inputs(objects=objects)

    def shown(seconds):
        config = ObservationConfig(num_objects=3, num_history=K, object_selection="route", route_forecast_s=seconds)
        return np.asarray(OBSERVE(index, inputs, config).objects[:, -1, :2])

    crossing = [20.0 / 50.0, 12.0 / 50.0]
    now_only = shown(0.0)
    assert not np.any(np.all(np.isclose(now_only, crossing, atol=1e-5), axis=1))  # the parked cars fill the slots
    np.testing.assert_array_equal(shown(1.5), now_only)  # not on the route within 1.5 s: the same choice
    ahead = shown(4.0)
    np.testing.assert_allclose(ahead[0], crossing, atol=1e-5)  # heading onto the route: first
    np.testing.assert_allclose(ahead[1:], now_only[:2], atol=1e-5)  # then the nearest; not the follower, not the other
    assert ObservationConfig(route_forecast_s=2.0).route_forecast_times == (0.5, 1.0, 1.5, 2.0)
    with pytest.raises(ValueError, match="route_forecast_s"):
        ObservationConfig(route_forecast_s=-1.0)


def test_object_route_frame_reads_a_car_on_a_bend_as_in_the_way_and_one_beside_it_as_not():
    # the route turns left: 5 m straight ahead, then up +y (targets every 5 m, SDC frame, normalised by 50 m)
    config = ObservationConfig()
    route_m = np.array([[5, 0], [5, 5], [5, 10], [5, 15]] + [[0, 0]] * 6, np.float32)
    valid = np.array([True] * 4 + [False] * 6)
    targets = jnp.asarray(route_m / config.max_distance)
    points = jnp.asarray([[5.0, 12.0],  # on the route after the bend: in the way, 17 m along it
                          [15.0, 12.0],  # straight ahead of the SDC, 10 m right of the route
                          [-8.0, 0.0],  # behind the SDC, on the line of its first segment
                          [5.0, 30.0],  # beyond the route's last target, on its line
                          [5.0, 5.0]])
    along, across = route_frame(points, targets, jnp.asarray(valid), config)
    np.testing.assert_allclose(along, [17.0, 17.0, -8.0, 35.0, 10.0], atol=1e-4)
    np.testing.assert_allclose(across, [0.0, -10.0, 0.0, 0.0, 0.0], atol=1e-4)
    # no route: the SDC's heading is the route
    along, across = route_frame(points, targets, jnp.zeros(10, bool), config)
    np.testing.assert_allclose(along, points[:, 0], atol=1e-4)
    np.testing.assert_allclose(across, points[:, 1], atol=1e-4)


def test_object_route_frame_adds_two_columns_per_object_step_and_changes_nothing_else(index):
    inputs = obs_inputs(objects=[(20.0, 0.0, 0.0, 5.0), (10.0, 3.5, 0.0, 0.0)])
    plain = OBSERVE(index, inputs, ObservationConfig(num_objects=4))
    framed = OBSERVE(index, inputs, ObservationConfig(num_objects=4, object_route_frame=True))
    assert framed.objects.shape == plain.objects.shape[:-1] + (OBJECT_FEATURES + 2,)
    assert object_feature_count(ObservationConfig(object_route_frame=True)) == OBJECT_FEATURES + 2
    np.testing.assert_array_equal(framed.objects[..., :OBJECT_FEATURES], plain.objects)
    np.testing.assert_array_equal(framed.objects_valid, plain.objects_valid)
    np.testing.assert_array_equal(framed.path_targets, plain.path_targets)
    # the route runs along +x: nearest first, 10 m ahead one lane (3.5 m) to its left, 20 m ahead on it
    np.testing.assert_allclose(framed.objects[:2, -1, OBJECT_FEATURES:], [[10 / 50, 3.5 / 5], [20 / 50, 0.0]],
                               atol=1e-5)
    assert np.all(np.asarray(framed.objects[2:]) == 0)
