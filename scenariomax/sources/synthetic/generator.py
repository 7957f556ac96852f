"""`generate_scenario(seed, index, sizes, knobs=...)`: one deterministic synthetic Scenario.

Everything random is drawn from `np.random.default_rng([seed, index])`, so a (seed, index) pair
(with the same knobs) always gives the same arrays, on any machine and in any process.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.roadgraph import LaneLinks, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import OBJECT_TYPE_VEHICLE, Sizes
from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.checks import overlaps_others
from scenariomax.sources.synthetic.knobs import DEFAULT_KNOBS, SyntheticKnobs
from scenariomax.sources.synthetic.network import RoadNetwork
from scenariomax.sources.synthetic.signals import signal_states
from scenariomax.sources.synthetic.street_objects import with_street_objects
from scenariomax.sources.synthetic.topologies import build_network
from scenariomax.sources.synthetic.traffic import DT_S, Traffic, simulate

SOURCE_DATASET = "synthetic"
MAX_ATTEMPTS = 4  # fresh networks tried when a simulation offers no usable SDC
SDC_BOX_STREAM = 5  # the SDC box's draw has a stream of its own: every other draw stays as without the knobs
STREET_OBJECT_STREAM = 6  # so have the street objects' (knob street_objects)
FIRST_OBJECT_ID = 1000


class GenerationError(RuntimeError):
    """No acceptable scenario could be generated for a (seed, index)."""


def scenario_id(seed: int, index: int) -> str:
    return f"synthetic-{seed}-{index:06d}"


def generate_scenario(seed: int, index: int, sizes: Sizes | None = None, topology: str | None = None,
                      knobs: SyntheticKnobs | None = None) -> Scenario:
    """The synthetic scenario number `index` of the set drawn with `seed` (deterministic), randomised as the
    knobs say (default knobs: the generator's own mix)."""
    sizes = sizes or Sizes()
    knobs = knobs or DEFAULT_KNOBS
    rng = np.random.default_rng([int(seed), int(index)])
    street_rng = np.random.default_rng([int(seed), int(index), STREET_OBJECT_STREAM])
    # `sdc_uturn`: few maps have a car that U-turns in the episode, so such a scene tries fresh networks for one
    # (keeping the first SDC found when none does); drawn only when the knob is on
    wants_uturn = knobs.sdc_uturn > 0 and bool(rng.random() < knobs.sdc_uturn)
    chosen = None
    for _ in range(MAX_ATTEMPTS):
        network = build_network(rng, topology, knobs)
        traffic = simulate(network, rng, sizes.num_timesteps, knobs)
        traffic = with_street_objects(traffic, network, street_rng, knobs.street_objects)
        sdc = _choose_sdc(network, traffic, rng, sizes, knobs, wants_uturn)
        if sdc is None:
            continue
        turns_back = wants_uturn and _enters_uturn(_uturn_lanes(network), traffic, sdc)
        chosen = (network, traffic, sdc) if chosen is None or turns_back else chosen
        if not wants_uturn or turns_back:
            break
    if chosen is None:
        raise GenerationError(f"{scenario_id(seed, index)}: no vehicle fit to be the SDC in {MAX_ATTEMPTS} attempts")
    network, traffic, sdc = chosen
    box_share = np.random.default_rng([int(seed), int(index), SDC_BOX_STREAM]).uniform()
    scenario = _sdc_box(_assemble(scenario_id(seed, index), network, traffic, sdc, sizes), *knobs.sdc_box(box_share))
    return fit_to_budget(_tracking_noise(scenario, rng, knobs), sizes)


def _uturn_lanes(network: RoadNetwork) -> set[int]:
    return {lane.lane_id for lane in network.lanes if lane.is_uturn}


def _enters_uturn(uturns: set[int], traffic: Traffic, obj: int) -> bool:
    """Whether mover `obj` enters one of the `uturns` lanes during the logged episode (not in the warm-up)."""
    return any(lane in uturns and step >= 1 for lane, step in traffic.gates_entered[obj])


SLOW_START_MPS = 2.0  # `sdc_slow_start`: a candidate this slow at the current step starts nearly at rest
# `sdc_waits`: a candidate that stands (below STANDING_MPS) for WAIT_STEPS of the steps from the current one on waits
STANDING_MPS, WAIT_STEPS = 0.5, 30


def _choose_sdc(network: RoadNetwork, traffic: Traffic, rng: np.random.Generator, sizes: Sizes,
                knobs: SyntheticKnobs = DEFAULT_KNOBS, wants_uturn: bool = False) -> int | None:
    """A car valid at every step that moves, never passes a red stop point and, where the map
    has junction or merge lanes, drives through one during the episode; with the `sdc_slow_start` knob's
    chance, one of those nearly at rest at the current step (when there is one), and with the `sdc_waits` knob's, one
    that stands for 3 s or more of the episode (at a light, a stop, in a queue); with the `sdc_stands_through` knob's,
    one that stands at every step from the current one on (it never moves in the episode), before all of these; with
    `wants_uturn` (the `sdc_uturn` knob), one that enters a U-turn lane during the episode (when there is one), after
    all of them; with the `sdc_behind_stalled` knob's chance, one that ends the episode at rest right behind a stalled
    car, last."""
    is_car = (traffic.object_type == OBJECT_TYPE_VEHICLE) & ~traffic.is_parked & (traffic.length < 5.5)
    always_valid = is_car & traffic.valid.all(axis=1)
    if knobs.sdc_stands_through > 0 and rng.random() < knobs.sdc_stands_through:
        standing = (traffic.speed[:, sizes.current_time_index:] < STANDING_MPS).all(axis=1)
        waiting = np.flatnonzero(always_valid & standing & ~traffic.is_stalled)  # a stalled car has no reason to wait
        if len(waiting):
            return int(waiting[int(rng.integers(len(waiting)))])
    candidates = np.flatnonzero(always_valid & (traffic.speed.max(axis=1) > 3.0))
    if len(candidates) == 0:
        return None
    light_times = np.arange(sizes.num_timesteps) * DT_S
    states = signal_states(network.signal_plan, light_times) if network.signal_plan else None
    clean = [c for c in candidates if not _runs_red(network, traffic, states, c)]
    if not clean:
        return None
    through = [c for c in clean if any(step >= 1 for _, step in traffic.gates_entered[c])]
    pool = through or clean
    if knobs.sdc_slow_start > 0 and rng.random() < knobs.sdc_slow_start:
        slow = [c for c in clean if traffic.speed[c, sizes.current_time_index] < SLOW_START_MPS]
        pool = [c for c in slow if c in through] or slow or pool
    if knobs.sdc_waits > 0 and rng.random() < knobs.sdc_waits:
        standing = (traffic.speed[:, sizes.current_time_index:] < STANDING_MPS).sum(axis=1)
        waiting = [c for c in clean if standing[c] >= WAIT_STEPS]
        pool = [c for c in waiting if c in through] or waiting or pool
    if wants_uturn:
        uturns = _uturn_lanes(network)
        pool = [c for c in clean if _enters_uturn(uturns, traffic, c)] or pool
    if knobs.sdc_behind_stalled > 0 and rng.random() < knobs.sdc_behind_stalled:
        pool = [c for c in clean if _rests_behind_stalled(traffic, c)] or pool
    return int(pool[int(rng.integers(len(pool)))])


# `sdc_behind_stalled`: at the last step the SDC stands (STANDING_MPS) with a stalled car's back this near its front,
# on its line (a queue's first car; IDM leaves STANDSTILL_GAP_M)
STALLED_GAP_M, STALLED_LATERAL_M = 6.0, 1.5


def _rests_behind_stalled(traffic: Traffic, obj: int) -> bool:
    """Whether mover `obj` ends the episode at rest right behind a stalled car in its lane."""
    if traffic.speed[obj, -1] >= STANDING_MPS:
        return False
    stalled = np.flatnonzero(traffic.is_stalled)
    heading = np.array([np.cos(traffic.yaw[obj, -1]), np.sin(traffic.yaw[obj, -1])])
    rel = np.stack([traffic.x[stalled, -1] - traffic.x[obj, -1], traffic.y[stalled, -1] - traffic.y[obj, -1]], -1)
    along, across = rel @ heading, rel @ np.array([-heading[1], heading[0]])  # (k,)
    gap = along - (traffic.length[stalled] + traffic.length[obj]) / 2
    return bool(np.any((along > 0) & (gap < STALLED_GAP_M) & (np.abs(across) < STALLED_LATERAL_M)))


def _runs_red(network: RoadNetwork, traffic: Traffic, states, obj: int) -> bool:
    if states is None:
        return False
    for lane in network.lights:
        heading = lane.xy[-1] - lane.xy[-2]
        heading /= np.linalg.norm(heading)
        rel = np.stack([traffic.x[obj], traffic.y[obj]], -1) - lane.xy[-1]
        along = rel @ heading
        lateral = np.abs(rel @ np.array([-heading[1], heading[0]]))
        crossed = np.flatnonzero((along[:-1] < 0) & (along[1:] >= 0) & (lateral[1:] < lane.width)) + 1
        red = states[lane.signal_group]
        if any(red[t] == 4 or red[t - 1] == 4 for t in crossed):
            return True
    return False


def _assemble(sid: str, network: RoadNetwork, traffic: Traffic, sdc: int, sizes: Sizes) -> Scenario:
    order = np.concatenate([[sdc], np.delete(np.arange(len(traffic.object_type)), sdc)])
    num, steps = len(order), sizes.num_timesteps
    valid = traffic.valid[order]
    yaw = traffic.yaw[order]
    speed = traffic.speed[order]

    def per_step(values):  # (N,) -> (N, T)
        return np.repeat(np.asarray(values)[order][:, None], steps, axis=1)

    height = per_step(traffic.height)
    lanes = network.lanes
    links = [LaneLinks(lane.lane_id, lane.successors, lane.predecessors, lane.left_neighbors, lane.right_neighbors)
             for lane in lanes]
    lights = network.lights
    if lights:
        light_states = signal_states(network.signal_plan, np.arange(steps) * DT_S)
        tl_state = np.stack([light_states[light.signal_group] for light in lights])
        stop_points = np.array([light.xy[-1] for light in lights])
        light_fields = {
            "tl_state": tl_state, "tl_valid": np.ones_like(tl_state, bool),
            "tl_lane_id": np.repeat(np.array([light.lane_id for light in lights])[:, None], steps, 1),
            "tl_x": np.repeat(stop_points[:, :1], steps, 1), "tl_y": np.repeat(stop_points[:, 1:], steps, 1),
            "tl_z": np.zeros_like(tl_state, np.float32)}
    else:
        light_fields = {}
    current = sizes.current_time_index
    tracks, interest = _labels(traffic, order, current)
    return Scenario(
        scenario_id=sid,
        object_id=FIRST_OBJECT_ID + order,
        object_type=traffic.object_type[order],
        is_sdc=np.arange(num) == 0,
        x=np.where(valid, traffic.x[order], -1.0),
        y=np.where(valid, traffic.y[order], -1.0),
        z=np.where(valid, height / 2, -1.0),
        bbox_yaw=np.where(valid, yaw, -1.0),
        length=np.where(valid, per_step(traffic.length), -1.0),
        width=np.where(valid, per_step(traffic.width), -1.0),
        height=np.where(valid, height, -1.0),
        velocity_x=np.where(valid, speed * np.cos(yaw), -1.0),
        velocity_y=np.where(valid, speed * np.sin(yaw), -1.0),
        valid=valid,
        speed=np.where(valid, speed, -1.0),
        vel_yaw=np.where(valid, yaw, -1.0),
        tracks_to_predict=tracks,
        objects_of_interest=interest,
        source_dataset=SOURCE_DATASET,
        current_time_index=current,
        metadata={"topology": network.topology},
        **polylines_to_roadgraph(network.map_polylines()),
        **lane_graph_arrays(links, sizes.num_lane_links),
        **light_fields,
    )


def _sdc_box(scenario: Scenario, box_length: float, box_width: float) -> Scenario:
    """The SDC's (object 0's) box at `box_length` x `box_width` m (0 keeps that dimension as it is), unless the box
    would overlap another object's anywhere in the log: then the scenario as it is."""
    if not (box_length or box_width):
        return scenario
    valid = scenario.valid[0]  # (T,)
    length = np.where(valid, box_length or scenario.length[0], scenario.length[0])  # (T,)
    width = np.where(valid, box_width or scenario.width[0], scenario.width[0])
    if overlaps_others(scenario, 0, length, width):
        return scenario
    new_length, new_width = scenario.length.copy(), scenario.width.copy()
    new_length[0], new_width[0] = length, width
    return dataclasses.replace(scenario, length=new_length, width=new_width)


def _tracking_noise(scenario: Scenario, rng: np.random.Generator, knobs: SyntheticKnobs) -> Scenario:
    """Gaussian noise on the logged x, y and bbox_yaw of every valid object but the SDC (a real log's tracker
    jitters the others; the SDC's own pose is precise). Draws nothing when the noise knobs are 0."""
    noisy = scenario.valid & ~scenario.is_sdc[:, None]
    changes = {}
    if knobs.position_noise_m > 0:
        noise = rng.normal(0.0, knobs.position_noise_m, size=(2, *noisy.shape))
        changes["x"] = np.where(noisy, scenario.x + noise[0], scenario.x)
        changes["y"] = np.where(noisy, scenario.y + noise[1], scenario.y)
    if knobs.heading_noise_rad > 0:
        noise = rng.normal(0.0, knobs.heading_noise_rad, size=noisy.shape)
        changes["bbox_yaw"] = np.where(noisy, geo.wrap_angle(scenario.bbox_yaw + noise), scenario.bbox_yaw)
    return scenario.replace(**changes) if changes else scenario


def _labels(traffic: Traffic, order: np.ndarray, current: int, num_tracks: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """tracks_to_predict: the SDC's nearest moving neighbours valid throughout; objects_of_interest:
    the movers that come within 10 m of the SDC."""
    x, y, valid = traffic.x[order], traffic.y[order], traffic.valid[order]
    moving = (traffic.speed[order].max(axis=1) > 1.0) & ~traffic.is_parked[order]
    dist = np.hypot(x - x[0], y - y[0])
    now = np.where(valid[:, current] & valid.all(axis=1) & moving, dist[:, current], np.inf)
    now[0] = np.inf
    tracks = np.zeros(len(order), bool)
    nearest = np.argsort(now, kind="stable")[:num_tracks]
    tracks[nearest[np.isfinite(now[nearest])]] = True
    closest = np.where(valid & valid[:1], dist, np.inf).min(axis=1)
    interest = moving & (closest < 10.0)
    interest[0] = False
    if interest.any():
        interest[0] = True
    return tracks, interest
