"""`SyntheticKnobs`: each knob changes what it names, measured on generated scenarios; the default knobs leave
the generator bit-identical (hashes recorded from the generator before the knobs existed)."""

import dataclasses
import hashlib
import json
import pickle

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

import scenariomax
from scenariomax.scenario import array_fields
from scenariomax.schema import (
    LANE_TYPES,
    OBJECT_TYPE_CYCLIST,
    OBJECT_TYPE_OTHER,
    OBJECT_TYPE_PEDESTRIAN,
    OBJECT_TYPE_VEHICLE,
    Sizes,
)
from scenariomax.sources.synthetic import (
    TOPOLOGIES,
    SyntheticKnobs,
    SyntheticSource,
    agents,
    build_network,
    generate_scenario,
    overlapping_vehicle_pairs,
    red_light_crossings,
)
from scenariomax.sources.synthetic.checks import road_edge_signed_distance
from scenariomax.sources.synthetic.generator import STANDING_MPS, WAIT_STEPS
from scenariomax.sources.synthetic.knobs import TOPOLOGY_NAMES

SIZES = Sizes(num_objects=64)

# sha256 (first 16 hex digits) of every array field (floats rounded to 1 mm / 1 mrad, so a last-bit difference
# in a maths library cannot flip it), the id and the topology, computed with the generator *before* the knobs
# were added: (seed, index, topology override) -> digest.
DEFAULT_DIGESTS = {
    (11, 0, None): "cad1d39e8c425e3c",
    (11, 1, None): "ef2dbd2b4a37e53a",
    (11, 2, None): "3946a45275c05e17",
    (11, 3, None): "208abda0bbc2718a",
    (5, 3, "straight"): "2d628c8cd6d3a54d",
    (5, 3, "curve"): "bcc97cdc4ca392c5",
    (5, 3, "intersection4"): "ba9ff7ca8093eeb2",
    (5, 3, "intersection3"): "43e47eda08edc02e",
    (5, 3, "merge"): "abcde72623b77e93",
    (5, 3, "lane_drop"): "10eb1e6670ea338d",
    (5, 3, "roundabout"): "54c2e0aad243de3c",
}


def digest(scenario) -> str:
    h = hashlib.sha256(scenario.scenario_id.encode())
    h.update(repr(sorted(scenario.metadata.items())).encode())
    for name in array_fields():
        value = getattr(scenario, name)
        if value is None:
            h.update(b"none")
            continue
        value = np.asarray(value)
        if value.dtype.kind == "f":
            value = np.round(value.astype(np.float64), 3)
        h.update(name.encode())
        h.update(str(value.shape).encode())
        h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()[:16]


@pytest.mark.parametrize("knobs", [None, SyntheticKnobs(), SyntheticKnobs.from_items([])])
def test_default_knobs_leave_the_generator_bit_identical(knobs):
    for (seed, index, topology), expected in DEFAULT_DIGESTS.items():
        scenario = generate_scenario(seed, index, SIZES, topology=topology, knobs=knobs)
        assert digest(scenario) == expected, (seed, index, topology)


def test_more_traffic_density_gives_more_vehicles():
    def mean_vehicles(density):
        counts = []
        for index in range(6):
            s = generate_scenario(21, index, SIZES, knobs=SyntheticKnobs(traffic_density=density))
            counts.append(int(((s.object_type == OBJECT_TYPE_VEHICLE) & s.valid.any(axis=1)).sum()))
        return np.mean(counts)

    sparse, dense = mean_vehicles(0.5), mean_vehicles(2.0)
    assert dense > 1.5 * sparse, (sparse, dense)


def _second_difference(scenario, rows) -> float:
    """Mean |x[t+1] - 2 x[t] + x[t-1]| over the rows' valid steps (jerky tracks have large ones)."""
    x, valid = scenario.x[rows], scenario.valid[rows]
    ok = valid[:, 2:] & valid[:, 1:-1] & valid[:, :-2]
    return float(np.abs(x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2])[ok].mean())


def test_tracking_noise_jitters_every_object_but_the_sdc():
    clean = generate_scenario(21, 0, SIZES)
    noisy = generate_scenario(21, 0, SIZES, knobs=SyntheticKnobs(position_noise_m=0.3, heading_noise_rad=0.05))
    # The noise is drawn after everything else: same objects, same SDC, same validity.
    assert np.array_equal(clean.object_id, noisy.object_id) and np.array_equal(clean.valid, noisy.valid)
    sdc = clean.sdc_index
    assert noisy.sdc_index == sdc
    for name in ("x", "y", "bbox_yaw", "speed"):
        assert np.array_equal(getattr(clean, name)[sdc], getattr(noisy, name)[sdc]), name
    others = np.delete(np.arange(clean.num_objects), sdc)
    valid = clean.valid[others]
    moved = np.hypot(noisy.x[others] - clean.x[others], noisy.y[others] - clean.y[others])[valid]
    assert 0.25 < float(np.mean(moved)) < 0.5  # Rayleigh mean of sigma 0.3: 0.376
    turned = np.abs(np.angle(np.exp(1j * (noisy.bbox_yaw[others] - clean.bbox_yaw[others]))))[valid]
    assert 0.02 < float(np.mean(turned)) < 0.06  # half-normal mean of 0.05: 0.04
    assert np.all(np.abs(noisy.bbox_yaw) <= np.pi + 1e-6)
    assert _second_difference(noisy, others) > 10 * _second_difference(clean, others)
    assert np.array_equal(noisy.x[~noisy.valid], clean.x[~clean.valid])  # padding stays padding


def _centre_line_spacings(network) -> list[float]:
    """Distance from each lane's middle point to the centre line of its left neighbour."""
    spacings = []
    for lane in network.lanes:
        middle = lane.xy[len(lane.xy) // 2]
        for other in lane.left_neighbors:
            xy = network.lane(other).xy
            a, b = xy[:-1], xy[1:]
            t = np.clip(np.einsum("ij,ij->i", middle - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
            spacings.append(float(np.min(np.linalg.norm(a + t[:, None] * (b - a) - middle, axis=1))))
    return spacings


@pytest.mark.parametrize("topology", ["straight", "intersection4", "lane_drop"])
def test_lane_width_knob_sets_the_spacing_of_adjacent_lanes(topology):
    def spacings(width_range):
        knobs = SyntheticKnobs.from_items([f"lane_width_m={width_range}"])
        found = []
        for i in range(6):
            found += _centre_line_spacings(build_network(np.random.default_rng([4, i]), topology, knobs))
        return np.array(found)

    narrow, wide = spacings("2.9:3.0"), spacings("4.0:4.2")
    assert len(narrow) and len(wide)
    assert np.all((narrow > 2.85) & (narrow < 3.05)), narrow
    assert np.all((wide > 3.95) & (wide < 4.25)), wide


def test_speed_limit_scale_scales_every_lane_limit():
    for topology in TOPOLOGIES:
        base = build_network(np.random.default_rng([8, 1]), topology)
        fast = build_network(np.random.default_rng([8, 1]), topology, SyntheticKnobs(speed_limit_scale=1.5))
        assert np.allclose([lane.speed_limit for lane in fast.lanes],
                           [1.5 * lane.speed_limit for lane in base.lanes]), topology
    # ... and the scenario's roadgraph records them.
    base = generate_scenario(8, 1, SIZES, topology="roundabout")
    slow = generate_scenario(8, 1, SIZES, topology="roundabout", knobs=SyntheticKnobs(speed_limit_scale=0.5))

    def limits(s):
        return np.unique(s.roadgraph_speed_limit[s.roadgraph_valid & (s.roadgraph_speed_limit > 0)])

    assert np.allclose(limits(slow), 0.5 * limits(base))


def test_topology_weights_choose_the_topologies():
    knobs = SyntheticKnobs(topology_weights="roundabout:1")
    assert {generate_scenario(3, i, SIZES, knobs=knobs).metadata["topology"] for i in range(5)} == {"roundabout"}
    mix = SyntheticKnobs(topology_weights="merge:1, curve:3")
    drawn = {build_network(np.random.default_rng([0, i]), knobs=mix).topology for i in range(40)}
    assert drawn == {"merge", "curve"}
    assert TOPOLOGY_NAMES == TOPOLOGIES  # the knobs name the builders' topologies


def test_parked_fraction_and_driver_spread_change_the_scene():
    def parked(fraction):
        return sum(int((s.valid.all(axis=1) & (s.speed.max(axis=1) <= 0)).sum())
                   for s in (generate_scenario(2, i, SIZES, topology="straight",
                                               knobs=SyntheticKnobs(parked_fraction=fraction)) for i in range(4)))

    assert parked((0.0, 0.0)) < parked((0.9, 1.0))
    base, spread = generate_scenario(6, 0, SIZES), generate_scenario(6, 0, SIZES,
                                                                     knobs=SyntheticKnobs(driver_style_spread=2.5))
    assert not np.array_equal(base.speed, spread.speed)


def _static_within(scenario, radius_m: float = 30.0) -> int:
    """Objects that never move and stand within `radius_m` of the SDC at the current step."""
    t, sdc = scenario.current_time_index, int(np.argmax(scenario.is_sdc))
    near = np.hypot(scenario.x[:, t] - scenario.x[sdc, t], scenario.y[:, t] - scenario.y[sdc, t]) < radius_m
    return int((near & scenario.valid[:, t] & (scenario.speed.max(axis=1) <= 0)).sum())


def test_junction_parking_and_max_parked_put_parked_cars_near_the_sdc():
    def static_near(**knobs):
        return sum(_static_within(generate_scenario(8, i, SIZES, topology="intersection4",
                                                    knobs=SyntheticKnobs(**knobs))) for i in range(5))

    # the generator's junctions have no kerbside parking (what stands still there is queued at a light)
    assert static_near(junction_parking=1.0, max_parked=40, parked_fraction=(0.6, 0.9)) >= static_near() + 5
    # max_parked bounds the parked cars; the default 14 keeps the first spots as before
    straight = [generate_scenario(4, i, SIZES, topology="straight",
                                  knobs=SyntheticKnobs(max_parked=4, parked_fraction=(0.9, 1.0))) for i in range(3)]
    assert all(int((s.valid.all(axis=1) & (s.speed.max(axis=1) <= 0)).sum()) <= 4 + 4 for s in straight)


def _parked_rows(scenario) -> np.ndarray:
    return np.flatnonzero(scenario.valid.all(axis=1) & (scenario.speed.max(axis=1) <= 0)
                          & (scenario.object_type == OBJECT_TYPE_VEHICLE))


def test_parked_reach_brings_parked_cars_nearer_the_lanes_and_keeps_the_rest_of_the_scene():
    base_knobs = dict(max_parked=40, parked_fraction=(0.8, 1.0))
    before, after = [], []
    for i in range(4):
        base = generate_scenario(9, i, SIZES, topology="straight", knobs=SyntheticKnobs(**base_knobs))
        reach = generate_scenario(9, i, SIZES, topology="straight",
                                  knobs=SyntheticKnobs(parked_reach=(1.0, 1.5), **base_knobs))
        # the same objects (matched by id; the budget keeps those nearest the SDC, so rows may move)
        shared, rows_base, rows_reach = np.intersect1d(base.object_id, reach.object_id, return_indices=True)
        parked = np.isin(rows_base, _parked_rows(base))
        assert np.array_equal(parked, np.isin(rows_reach, _parked_rows(reach)))
        # everything but the parked cars' positions is the knob-off scene (the reach has a random stream of its own)
        for name in ("x", "y", "bbox_yaw", "speed", "valid"):
            assert np.array_equal(getattr(base, name)[rows_base[~parked]], getattr(reach, name)[rows_reach[~parked]])
        assert np.array_equal(base.bbox_yaw[rows_base[parked]], reach.bbox_yaw[rows_reach[parked]])
        lane_xy = base.roadgraph_xyz[base.roadgraph_valid & np.isin(base.roadgraph_type, LANE_TYPES), :2]
        for scenario, rows, out in ((base, rows_base[parked], before), (reach, rows_reach[parked], after)):
            out.append(np.hypot(scenario.x[rows, :1] - lane_xy[None, :, 0],  # distance to the nearest lane point
                                scenario.y[rows, :1] - lane_xy[None, :, 1]).min(axis=1))
        # the log stays safe: every vehicle it drives passes the nearer parked cars without touching them
        assert overlapping_vehicle_pairs(reach) == [] and reach.validate() == []
    nearer = np.concatenate(before) - np.concatenate(after)
    assert (nearer > 0.5).sum() >= 10 and np.median(nearer) >= 0.3 and nearer.min() >= -1e-3, np.round(nearer, 2)


def _pairs_touching_street_objects(scenario) -> list:
    """Overlapping boxes (any types) where one of the two is a street object (type other)."""
    pairs = overlapping_vehicle_pairs(scenario, types=(OBJECT_TYPE_VEHICLE, OBJECT_TYPE_PEDESTRIAN,
                                                           OBJECT_TYPE_CYCLIST, OBJECT_TYPE_OTHER))
    return [p for p in pairs if OBJECT_TYPE_OTHER in scenario.object_type[list(p[:2])]]


def test_street_objects_stand_along_the_road_edges_clear_of_the_log_and_keep_the_rest_of_the_scene():
    counts = []
    for i, topology in enumerate(TOPOLOGIES):
        base = generate_scenario(21, i, SIZES, topology=topology)
        street = generate_scenario(21, i, SIZES, topology=topology, knobs=SyntheticKnobs(street_objects=(6, 10)))
        assert not (base.object_type == OBJECT_TYPE_OTHER).any()
        rows = np.flatnonzero(street.object_type == OBJECT_TYPE_OTHER)
        counts.append(len(rows))
        # standing still for the whole log, cone- or barrier-sized
        assert street.valid[rows].all() and (street.speed[rows] == 0).all()
        assert (np.ptp(street.x[rows], axis=1) == 0).all() and (np.ptp(street.y[rows], axis=1) == 0).all()
        assert (street.length[rows] <= 0.7).all() and (street.width[rows] <= 3.6).all()
        # along the road edges: on the road or just off it
        edge = road_edge_signed_distance(street, np.stack([street.x[rows, 0], street.y[rows, 0]], axis=1))
        assert (np.abs(edge) <= 1.6).all(), np.round(edge, 2)
        # nothing logged touches them, and every other object is the knob-off scene's (their draws are their own)
        assert _pairs_touching_street_objects(street) == [] and street.validate() == []
        shared, rows_base, rows_street = np.intersect1d(base.object_id, street.object_id, return_indices=True)
        assert len(shared) >= base.num_objects - len(rows)  # the budget may drop the farthest for them
        for name in ("x", "y", "bbox_yaw", "speed", "valid", "object_type"):
            assert np.array_equal(getattr(base, name)[rows_base], getattr(street, name)[rows_street]), name
    assert sum(counts) >= 4 * len(TOPOLOGIES) and max(counts) <= 10, counts


def test_walkers_per_crosswalk_sets_how_many_cross():
    def pedestrians(walkers):
        knobs = SyntheticKnobs(walkers_per_crosswalk=walkers)
        return [int(((s.object_type == OBJECT_TYPE_PEDESTRIAN) & s.valid.any(axis=1)).sum())
                for s in (generate_scenario(3, i, SIZES, topology="intersection4", knobs=knobs) for i in range(4))]

    assert pedestrians((0.0, 0.0)) == [0, 0, 0, 0]
    crowded = pedestrians((6.0, 6.0))  # every crosswalk of the junction (up to 4) gets six
    assert all(n >= 6 for n in crowded) and sum(crowded) > 2 * sum(pedestrians((0.0, 2.0)))


def test_paired_signals_release_opposite_approaches_together():
    def light_sequences(knobs):  # distinct state sequences of the lights of each signalised four-way junction
        scenes = (generate_scenario(4, i, SIZES, topology="intersection4", knobs=knobs) for i in range(8))
        return [len({tuple(row) for row in s.tl_state[s.tl_valid.any(axis=1)]}) for s in scenes if s.tl_valid.any()]

    split, paired = light_sequences(SyntheticKnobs()), light_sequences(SyntheticKnobs(paired_signals=1.0))
    assert len(paired) == len(split) >= 3
    assert max(split) >= 3  # one group per approach: more than two sequences show within the 9.1 s
    assert max(paired) == 2  # two groups: the opposite approaches share their lights


def test_junction_uturns_turn_from_the_innermost_lane_round_into_the_outermost():
    uturns = 0
    for i in range(12):
        plain = build_network(np.random.default_rng([3, i]), "intersection4", SyntheticKnobs())
        network = build_network(np.random.default_rng([3, i]), "intersection4", SyntheticKnobs(junction_uturns=1.0))
        assert not any(lane.is_uturn for lane in plain.lanes)
        for lane in (lane for lane in network.lanes if lane.is_uturn):
            uturns += 1
            before, after = network.lane(lane.predecessors[0]), network.lane(lane.successors[0])
            heading_in, heading_out = before.xy[-1] - before.xy[-2], after.xy[1] - after.xy[0]
            cos = heading_in @ heading_out / np.linalg.norm(heading_in) / np.linalg.norm(heading_out)
            assert cos < -0.99  # back the way it came
            assert before.left_neighbors == () and after.right_neighbors == ()  # innermost in, outermost out
            assert np.linalg.norm(lane.xy[0] - lane.xy[-1]) / 2 >= 4.9  # a car's turning circle, not a hairpin
            assert lane.is_gated and lane.conflicts  # it waits its turn with the junction's other lanes
            assert network.drivable_area.buffer(0.01).contains(shapely.geometry.LineString(lane.xy))
    assert uturns >= 4


def test_sdc_uturn_chooses_sdcs_that_turn_back_at_a_junction():
    def turned_back(chance):  # scenes whose SDC's heading swings by more than 160 degrees in the log
        knobs = SyntheticKnobs(junction_uturns=1.0, sdc_uturn=chance)
        scenes = [generate_scenario(7, i, SIZES, knobs=knobs) for i in range(16)]
        return sum(np.ptp(np.unwrap(s.bbox_yaw[s.sdc_index][s.valid[s.sdc_index]])) > np.radians(160) for s in scenes)

    assert turned_back(0.0) == 0
    assert turned_back(1.0) >= 3


def test_sdc_slow_start_chooses_sdcs_nearly_at_rest():
    def slow_share(chance):
        scenarios = [generate_scenario(9, i, SIZES, knobs=SyntheticKnobs(sdc_slow_start=chance)) for i in range(30)]
        return np.mean([s.speed[0, s.current_time_index] < 2.0 for s in scenarios])

    assert slow_share(1.0) >= slow_share(0.0) + 0.1


def test_sdc_waits_chooses_sdcs_that_stand_for_seconds():
    def standing_steps(chance):  # per scene: the SDC's steps below walking pace from the current step on
        scenarios = [generate_scenario(9, i, SIZES, knobs=SyntheticKnobs(sdc_waits=chance)) for i in range(30)]
        return np.array([(s.speed[s.sdc_index, s.current_time_index:] < STANDING_MPS).sum() for s in scenarios])

    usual, waiting = standing_steps(0.0), standing_steps(1.0)
    assert waiting.mean() >= 2 * usual.mean() + 5  # the generator's SDCs stand ~7 of 81 steps, the real ones ~26
    assert (waiting >= WAIT_STEPS).mean() >= 0.5  # most scenes have one that waits 3 s (not every map has such a car)


def test_sdc_stands_through_chooses_sdcs_that_never_move_in_the_episode():
    def stand_through(chance):  # per scene: whether the SDC stays below walking pace at every step from the current one
        knobs = SyntheticKnobs(sdc_stands_through=chance, topology_weights="intersection4:1,intersection3:1")
        scenarios = [generate_scenario(9, i, SIZES, knobs=knobs) for i in range(20)]
        return np.array([(s.speed[s.sdc_index, s.current_time_index:] < STANDING_MPS).all() for s in scenarios])

    assert not stand_through(0.0).any()  # every other rule picks a car that moves
    assert stand_through(1.0).mean() >= 0.3  # at junctions, a car waits through the episode in most maps


def test_slow_vehicles_puts_crawling_leaders_on_the_road():
    def crawlers(chance):  # per scene: moving vehicles (not the SDC) whose fastest logged speed stays under 4.5 m/s
        counts = []
        for i in range(20):
            s = generate_scenario(9, i, SIZES, knobs=SyntheticKnobs(slow_vehicles=chance, traffic_density=1.5))
            top = np.where(s.valid, s.speed, 0.0).max(axis=1)
            moving = (s.object_type == OBJECT_TYPE_VEHICLE) & ~s.is_sdc & (top > 1.0)
            counts.append(int((moving & (top < 4.5)).sum()))
        return np.array(counts)

    usual, slow = crawlers(0.0), crawlers(0.3)
    assert slow.sum() >= usual.sum() + 20 and (slow > 0).mean() >= 0.5
    rng, knobs = np.random.default_rng(0), SyntheticKnobs(slow_vehicles=1.0)
    factors = [agents.vehicle_driver(rng, knobs).speed_factor for _ in range(100)]
    assert agents.SLOW_SPEED_FACTOR[0] <= min(factors) and max(factors) <= agents.SLOW_SPEED_FACTOR[1]


# the bc-dagger preset's traffic knobs, with which the stalled-car knobs are meant to train
PRESET_TRAFFIC = dict(traffic_density=1.5, parked_fraction=(0.4, 0.9), max_parked=40, junction_parking=0.6,
                      sdc_slow_start=1.0)


def _standing_in_lane(s) -> np.ndarray:
    """(N,) vehicles valid and at rest at every step whose box reaches within 1.5 m of some lane centre (a parked car
    stands ~3 m off)."""
    still = (s.object_type == OBJECT_TYPE_VEHICLE) & s.valid.all(axis=1) & (np.abs(s.speed) < 0.01).all(axis=1)
    lanes = s.roadgraph_xyz[s.roadgraph_valid & np.isin(s.roadgraph_type, list(LANE_TYPES))][:, :2]
    centre = np.stack([s.x[:, 0], s.y[:, 0]], -1)
    near = np.min(np.linalg.norm(centre[:, None] - lanes[None], axis=-1), axis=1) < 1.5
    return still & near


def _rests_behind_one(s, standing: np.ndarray, obj: int) -> bool:
    """Whether object `obj` ends at rest with one of the `standing` cars' back within 6 m of its front, on its line."""
    h = np.array([np.cos(s.bbox_yaw[obj, -1]), np.sin(s.bbox_yaw[obj, -1])])
    rel = np.stack([s.x[:, -1] - s.x[obj, -1], s.y[:, -1] - s.y[obj, -1]], -1)
    along, across = rel @ h, rel @ np.array([-h[1], h[0]])
    gap = along - (s.length[:, -1] + s.length[obj, -1]) / 2
    return bool(s.speed[obj, -1] < STANDING_MPS and np.any(standing & (along > 0) & (gap < 6) & (np.abs(across) < 1.5)))


def test_stalled_vehicles_stand_in_their_lanes_off_the_crosswalks_and_the_traffic_queues_behind():
    def scenes(chance):
        return [generate_scenario(21, i, SIZES, knobs=SyntheticKnobs(stalled_vehicles=chance, **PRESET_TRAFFIC))
                for i in range(12)]

    usual, stalled = scenes(0.0), scenes(0.3)
    assert sum(_standing_in_lane(s).sum() for s in stalled) >= sum(_standing_in_lane(s).sum() for s in usual) + 10
    for s in stalled:  # nobody walks through a stalled car: they stand clear of the crosswalks
        pairs = overlapping_vehicle_pairs(s, types=(OBJECT_TYPE_VEHICLE, OBJECT_TYPE_PEDESTRIAN))
        assert not [p for p in pairs if _standing_in_lane(s)[list(p[:2])].any()], s.scenario_id
    queued = 0  # movers that end at rest right behind a stalled car
    for s in stalled:
        standing = _standing_in_lane(s)
        movers = np.flatnonzero((s.object_type == OBJECT_TYPE_VEHICLE) & s.valid[:, -1] & ~standing)
        queued += sum(_rests_behind_one(s, standing, obj) for obj in movers)
    assert queued >= 5


def test_sdc_behind_stalled_chooses_sdcs_that_come_to_rest_behind_a_stalled_car():
    def behind(chance):
        knobs = SyntheticKnobs(stalled_vehicles=0.1, sdc_behind_stalled=chance, **PRESET_TRAFFIC)
        scenes = [generate_scenario(21, i, SIZES, knobs=knobs) for i in range(20)]
        return sum(_rests_behind_one(s, _standing_in_lane(s), s.sdc_index) for s in scenes)

    # most SDCs drive through a junction, away from the stalled cars (3 of 20 measured without the knob, 9 with it;
    # not every map has a car queued right behind one)
    assert behind(1.0) >= behind(0.0) + 4


def test_sdc_size_gives_the_sdc_the_box_of_a_real_sdc_and_nothing_else_changes():
    real_waymo = SyntheticKnobs(sdc_length_m=5.29, sdc_width_m=2.33)
    for i in range(10):
        usual, sized = generate_scenario(9, i, SIZES), generate_scenario(9, i, SIZES, knobs=real_waymo)
        valid = sized.valid[0]
        assert np.allclose(sized.length[0, valid], 5.29) and np.allclose(sized.width[0, valid], 2.33)
        for name in ("x", "y", "bbox_yaw", "valid"):  # the same log, drawn from the same stream
            assert np.array_equal(getattr(usual, name), getattr(sized, name)), name
        assert np.array_equal(usual.length[1:], sized.length[1:]) and np.array_equal(usual.width[1:], sized.width[1:])
        assert not [pair for pair in overlapping_vehicle_pairs(sized, types=(1, 2, 3)) if 0 in pair[:2]]
    only_wider = generate_scenario(9, 0, SIZES, knobs=SyntheticKnobs(sdc_width_m=2.33))
    assert np.array_equal(only_wider.length, generate_scenario(9, 0, SIZES).length)  # a knob at 0 keeps its own


def test_sdc_size_ranges_draw_one_share_per_scene_for_length_and_width():
    ranged = SyntheticKnobs.from_items(["sdc_length_m=4.0:5.4", "sdc_width_m=1.7:2.4"])
    boxes = []
    for i in range(12):
        usual, sized = generate_scenario(9, i, SIZES), generate_scenario(9, i, SIZES, knobs=ranged)
        valid = sized.valid[0]
        length, width = float(sized.length[0, valid][0]), float(sized.width[0, valid][0])
        if (length, width) == (float(usual.length[0, valid][0]), float(usual.width[0, valid][0])):
            continue  # the drawn box would overlap the log: the scene keeps its own
        assert 4.0 <= length <= 5.4 and 1.7 <= width <= 2.4
        assert (length - 4.0) / 1.4 == pytest.approx((width - 1.7) / 0.7, abs=1e-5)  # one share for both
        assert np.array_equal(usual.x, sized.x) and np.array_equal(usual.length[1:], sized.length[1:])
        boxes.append(length)
    assert len(boxes) >= 8 and max(boxes) - min(boxes) > 0.5  # sizes vary over the range, scene by scene
    assert SyntheticKnobs(sdc_length_m=5.29).sdc_length_m == (5.29, 5.29)  # a number (older configs): fixed


def test_an_sdc_box_that_would_overlap_the_log_is_not_applied():
    from scenariomax.sources.synthetic.generator import _sdc_box

    scenario = generate_scenario(13, 0, SIZES, knobs=SyntheticKnobs(traffic_density=3.0))
    assert _sdc_box(scenario, 6.0, 2.6) is not scenario
    assert _sdc_box(scenario, 20.0, 10.0) is scenario  # past the knobs' bounds: over its neighbours


def test_driver_style_spread_widens_the_traits_around_their_centres():
    def traits(spread):
        rng, knobs = np.random.default_rng(0), SyntheticKnobs(driver_style_spread=spread)
        return np.array([dataclasses.astuple(agents.vehicle_driver(rng, knobs)) for _ in range(400)])

    narrow, usual, wide = traits(0.5), traits(1.0), traits(2.0)
    assert np.allclose(narrow.std(axis=0), 0.5 * usual.std(axis=0))  # same draws, half the distance
    assert np.all(wide.std(axis=0) > 1.6 * usual.std(axis=0))  # (clipping trims the widest a little)
    assert np.allclose(narrow.mean(axis=0), usual.mean(axis=0), atol=0.02)
    floors = np.array([limits[0] for _, limits in agents.VEHICLE_TRAITS])
    assert np.all(traits(3.0) >= floors) and np.all(traits(0.0) == traits(0.0)[0])


@pytest.mark.parametrize("kwargs, name", [
    ({"traffic_density": 0.0}, "traffic_density"), ({"position_noise_m": -0.1}, "position_noise_m"),
    ({"heading_noise_rad": float("nan")}, "heading_noise_rad"), ({"lane_width_m": (4.0, 3.0)}, "lane_width_m"),
    ({"lane_width_m": (1.0, 3.0)}, "lane_width_m"), ({"speed_limit_scale": 9.0}, "speed_limit_scale"),
    ({"speed_limit_scale": 0.3}, "speed_limit_scale"),
    ({"driver_style_spread": -1.0}, "driver_style_spread"), ({"parked_fraction": (0.2, 1.5)}, "parked_fraction"),
    ({"topology_weights": "spaghetti:1"}, "topology_weights"), ({"topology_weights": "merge:0"}, "topology_weights"),
    ({"topology_weights": "merge:x"}, "topology_weights"),
    ({"max_parked": 2.5}, "max_parked"), ({"max_parked": 99}, "max_parked"), ({"max_parked": True}, "max_parked"),
    ({"junction_parking": 1.5}, "junction_parking"), ({"paired_signals": -0.1}, "paired_signals"),
    ({"junction_uturns": 2.0}, "junction_uturns"), ({"sdc_uturn": -1.0}, "sdc_uturn"),
    ({"parked_reach": (0.0, 2.5)}, "parked_reach"),
    ({"walkers_per_crosswalk": (3.0, 1.0)}, "walkers_per_crosswalk"),
    ({"sdc_slow_start": -0.1}, "sdc_slow_start"), ({"sdc_waits": 1.5}, "sdc_waits"),
    ({"sdc_stands_through": 2.0}, "sdc_stands_through"),
    ({"slow_vehicles": 2.0}, "slow_vehicles"), ({"stalled_vehicles": 0.6}, "stalled_vehicles"),
    ({"sdc_behind_stalled": -0.5}, "sdc_behind_stalled"), ({"sdc_width_m": 3.5}, "sdc_width_m"),
    ({"sdc_length_m": -1.0}, "sdc_length_m"), ({"street_objects": (5.0, 2.0)}, "street_objects"),
])
def test_bad_knobs_raise_one_line_naming_the_knob(kwargs, name):
    with pytest.raises(ValueError, match=name) as caught:
        SyntheticKnobs(**kwargs)
    assert "\n" not in str(caught.value)


def test_unknown_topology_lists_the_valid_names_and_unknown_knob_is_named():
    with pytest.raises(ValueError, match="spaghetti.*roundabout"):
        SyntheticKnobs(topology_weights="spaghetti:1")
    with pytest.raises(ValueError, match="'bogus'.*traffic_density"):
        SyntheticKnobs.from_items(["bogus=1"])
    with pytest.raises(ValueError, match="lane_width_m"):
        SyntheticKnobs.from_items(["lane_width_m=wide"])
    with pytest.raises(ValueError, match="NAME=VALUE"):
        SyntheticKnobs.from_items(["traffic_density"])


def test_knobs_parse_describe_and_round_trip():
    knobs = SyntheticKnobs.from_items(["traffic_density=2", "lane_width_m=2.8:4.2", "parked_fraction=0.1,0.2",
                                       "topology_weights=intersection4:2,merge:1"])
    assert knobs == SyntheticKnobs(traffic_density=2.0, lane_width_m=(2.8, 4.2), parked_fraction=(0.1, 0.2),
                                   topology_weights="intersection4:2,merge:1")
    assert SyntheticKnobs.from_dict(json.loads(json.dumps(knobs.as_dict()))) == knobs
    assert pickle.loads(pickle.dumps(knobs)) == knobs
    assert SyntheticKnobs(traffic_density=1).is_default() and not knobs.is_default()
    assert scenariomax.SyntheticKnobs is SyntheticKnobs and "SyntheticKnobs" in scenariomax.__all__


def test_source_passes_the_knobs_and_records_only_non_default_ones():
    assert "knobs" not in SyntheticSource(num_scenarios=2).settings()
    assert "knobs" not in SyntheticSource(num_scenarios=2, knobs=SyntheticKnobs()).settings()
    knobs = SyntheticKnobs(topology_weights="merge:1")
    source = SyntheticSource(num_scenarios=2, seed=1, sizes=Sizes(num_objects=16), knobs=knobs)
    assert source.settings()["knobs"] == knobs.as_dict()
    scenarios = list(source.read_unit("synthetic:00000-00001"))
    assert [s.metadata["topology"] for s in scenarios] == ["merge", "merge"]


def test_convert_command_takes_synthetic_knobs(tmp_path):
    from vmax_cli.scenariomax_cli import main

    out = tmp_path / "shards"
    result = CliRunner().invoke(main, ["convert", "--num-scenarios", "2", "--num-objects", "16", "--roadgraph-points",
                                       "3000", "--workers", "1", "--no-enrich", "--out", str(out),
                                       "--synthetic-knob", "topology_weights=roundabout:1",
                                       "--synthetic-knob", "lane_width_m=3.0:3.2"])
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["settings"]["source"]["knobs"]["topology_weights"] == "roundabout:1"
    assert manifest["settings"]["source"]["knobs"]["lane_width_m"] == [3.0, 3.2]


@pytest.mark.parametrize("args, words", [
    (["--synthetic-knob", "bogus=1"], "bogus"),
    (["--synthetic-knob", "lane_width_m=5:3"], "lane_width_m"),
    (["--synthetic-knob", "topology_weights=spaghetti:2"], "spaghetti"),
    (["--dataset", "womd", "--src", "x", "--synthetic-knob", "traffic_density=2"], "--dataset synthetic"),
])
def test_convert_command_rejects_bad_knobs_in_one_line(tmp_path, args, words):
    from vmax_cli.scenariomax_cli import main

    result = CliRunner().invoke(main, ["convert", "--out", str(tmp_path / "out"), *args])
    assert result.exit_code == 2
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and words in errors[0], result.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("knobs", [
    SyntheticKnobs(lane_width_m=(2.7, 2.8), traffic_density=3.0),
    SyntheticKnobs(speed_limit_scale=2.0, driver_style_spread=3.0),
    SyntheticKnobs(speed_limit_scale=0.5, lane_width_m=(4.5, 5.0), parked_fraction=(1.0, 1.0)),
    SyntheticKnobs(junction_parking=1.0, max_parked=48, parked_fraction=(1.0, 1.0), sdc_slow_start=1.0,
                   walkers_per_crosswalk=(8.0, 12.0)),
    SyntheticKnobs(junction_parking=1.0, max_parked=48, parked_fraction=(1.0, 1.0), parked_reach=(2.0, 2.0),
                   traffic_density=3.0),
    SyntheticKnobs(paired_signals=1.0, traffic_density=3.0, walkers_per_crosswalk=(3.0, 6.0)),
    SyntheticKnobs(junction_uturns=1.0, sdc_uturn=1.0, traffic_density=3.0, walkers_per_crosswalk=(3.0, 6.0)),
    SyntheticKnobs(sdc_waits=1.0, sdc_slow_start=1.0, traffic_density=3.0),
    SyntheticKnobs(slow_vehicles=1.0, traffic_density=3.0, sdc_slow_start=1.0),
    SyntheticKnobs(stalled_vehicles=0.5, sdc_behind_stalled=1.0, traffic_density=3.0, walkers_per_crosswalk=(3.0, 6.0)),
    SyntheticKnobs(sdc_length_m=8.0, sdc_width_m=3.0, traffic_density=3.0, parked_reach=(1.5, 1.5)),
    SyntheticKnobs(street_objects=(64.0, 64.0), traffic_density=3.0, parked_fraction=(1.0, 1.0), max_parked=48,
                   walkers_per_crosswalk=(4.0, 8.0)),
])
def test_extreme_knobs_keep_the_logs_safe(knobs):
    """At the knobs' limits vehicles still never overlap nor run a red light, and the scenarios validate."""
    for i, topology in enumerate(TOPOLOGIES):
        s = generate_scenario(13, i, SIZES, topology=topology, knobs=knobs)
        assert s.validate() == [] and overlapping_vehicle_pairs(s) == [], topology
        assert _pairs_touching_street_objects(s) == [], topology
        vehicles = np.flatnonzero(s.object_type == OBJECT_TYPE_VEHICLE)
        assert not any(red_light_crossings(s, obj) for obj in vehicles), topology
