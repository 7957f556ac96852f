"""Road network builders, one per topology, drawn from an rng.

Every builder returns a `RoadNetwork` in world coordinates (random rotation and shift).
Lane width ~3.5 m, 1-3 lanes per direction, speed limits in m/s; `SyntheticKnobs` widen or narrow the
lanes, scale the speed limits and reweight the topologies.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from shapely.geometry import Polygon

from scenariomax.schema import (
    RG_BROKEN_SINGLE_WHITE,
    RG_BROKEN_SINGLE_YELLOW,
    RG_LANE_FREEWAY,
    RG_LANE_SURFACE_STREET,
    RG_SOLID_DOUBLE_YELLOW,
    RG_SOLID_SINGLE_WHITE,
)
from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.knobs import DEFAULT_KNOBS, TOPOLOGY_NAMES, SyntheticKnobs
from scenariomax.sources.synthetic.network import NetworkBuilder, RoadNetwork
from scenariomax.sources.synthetic.signals import random_plan

PARKING_WIDTH_M = 2.6
PARKING_PITCH_M = 6.5
CROSSWALK_WIDTH_M = 3.0


def _road(b: NetworkBuilder, ref: np.ndarray, num_fwd: int, num_bwd: int, width: float, speed: float,
          lane_type: int, rng: np.random.Generator | None = None, parking: tuple[bool, bool] = (False, False),
          keep_clear: tuple[np.ndarray, ...] = ()) -> tuple[list[int], list[int]]:
    """A two-way road along `ref`: forward lanes on its right, backward lanes on its left, both
    listed from the centre line outwards. Adds lane lines and optional kerbside parking strips."""
    fwd = [b.add_lane(geo.offset(ref, -(j + 0.5) * width), width, speed, lane_type) for j in range(num_fwd)]
    bwd = [b.add_lane(geo.offset(ref, (j + 0.5) * width)[::-1], width, speed, lane_type) for j in range(num_bwd)]
    b.neighbours(fwd)
    b.neighbours(bwd)
    for k in range(1, num_fwd):
        b.add_line(geo.offset(ref, -k * width), RG_BROKEN_SINGLE_WHITE)
    for k in range(1, num_bwd):
        b.add_line(geo.offset(ref, k * width)[::-1], RG_BROKEN_SINGLE_WHITE)
    if num_fwd and num_bwd:
        b.add_line(ref, RG_SOLID_DOUBLE_YELLOW if num_fwd + num_bwd > 2 else RG_BROKEN_SINGLE_YELLOW)
    for side, (wanted, num) in enumerate(zip(parking, (num_fwd, num_bwd))):
        if wanted and rng is not None:
            sign = -1.0 if side == 0 else 1.0
            _parking_strip(b, ref, sign, num * width, rng, keep_clear, reverse=side == 1)
    return fwd, bwd


def _parking_strip(b: NetworkBuilder, ref: np.ndarray, sign: float, lanes_width: float,
                   rng: np.random.Generator, keep_clear: tuple[np.ndarray, ...], reverse: bool) -> None:
    """A kerbside strip outside the travel lanes; a white line separates it from traffic."""
    b.add_line(geo.offset(ref, sign * lanes_width), RG_SOLID_SINGLE_WHITE)
    centre = geo.offset(ref, sign * (lanes_width + PARKING_WIDTH_M / 2))
    outer = geo.offset(ref, sign * (lanes_width + PARKING_WIDTH_M))
    inner = geo.offset(ref, sign * (lanes_width - 0.2))
    b.add_area(Polygon(np.concatenate([inner, outer[::-1]])).buffer(0))
    spots = geo.resample(centre, PARKING_PITCH_M)[2:-2]
    heading = geo.tangents(geo.resample(centre, PARKING_PITCH_M))[2:-2]
    for xy, h in zip(spots, heading):
        # Keep 6 m either side of a crosswalk clear (the centre is on the road's axis).
        if any(np.linalg.norm(xy - c) < lanes_width + PARKING_WIDTH_M + 6.0 for c in keep_clear):
            continue
        yaw = np.arctan2(h[1], h[0]) + (np.pi if reverse else 0.0)
        b.add_parking(xy, yaw)


def _world(b: NetworkBuilder, rng: np.random.Generator, knobs: SyntheticKnobs) -> RoadNetwork:
    if knobs.speed_limit_scale != 1.0:  # every lane's limit, wherever the builder chose it
        for draft in b.lanes:
            draft.speed_limit *= knobs.speed_limit_scale
    return b.build(angle=float(rng.uniform(-np.pi, np.pi)), shift=rng.uniform(-300.0, 300.0, size=2))


def _lane_width(rng: np.random.Generator, knobs: SyntheticKnobs, low: float = 3.3, high: float = 3.8) -> float:
    """A lane width drawn on the usual scale, mapped onto the knobs' range."""
    return knobs.lane_width(float(rng.uniform(low, high)))


def _urban_speed(rng) -> float:
    return float(rng.choice([8.9, 11.2, 13.4, 15.6]))  # 20-35 mph


def build_straight(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    """A long two-way street with kerbside parking and (often) a mid-block zebra crossing."""
    b = NetworkBuilder("straight")
    width, num = _lane_width(rng, knobs), int(rng.integers(1, 4))
    length = float(rng.uniform(300.0, 380.0))
    ref = geo.segment(np.array([-length / 2, 0.0]), np.array([length / 2, 0.0]))
    walk = rng.random() < 0.7
    centre = np.array([float(rng.uniform(-40, 40)), 0.0])
    parking = (bool(rng.random() < 0.7), bool(rng.random() < 0.5))
    _road(b, ref, num, num, width, _urban_speed(rng), RG_LANE_SURFACE_STREET, rng,
          parking=parking, keep_clear=(centre,) if walk else ())
    if walk:  # kerb to kerb, across the parking strips too
        right = num * width + PARKING_WIDTH_M * parking[0]
        left = num * width + PARKING_WIDTH_M * parking[1]
        b.add_crosswalk(centre + np.array([0.0, (left - right) / 2]), np.array([0.0, 1.0]), left + right,
                        CROSSWALK_WIDTH_M, is_signalised=False)
    return _world(b, rng, knobs)


def build_curve(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    """Straight, circular bend (30-100 degrees, radius 35-150 m), straight."""
    b = NetworkBuilder("curve")
    width, num = _lane_width(rng, knobs), int(rng.integers(1, 4))
    radius = float(rng.uniform(35.0 + 4 * num * width, 150.0))
    sweep = float(np.radians(rng.uniform(30.0, 100.0))) * rng.choice([-1.0, 1.0])
    lead, tail = float(rng.uniform(110, 140)), float(rng.uniform(110, 140))
    first = geo.segment(np.array([-lead, 0.0]), np.zeros(2))
    side = np.sign(sweep)
    bend = geo.arc(np.array([0.0, side * radius]), radius, -side * np.pi / 2, sweep)
    end_heading = sweep
    last = geo.segment(bend[-1], bend[-1] + tail * geo.unit(end_heading))
    ref = geo.join(first, bend, last)
    _road(b, ref, num, num, width, _urban_speed(rng), RG_LANE_SURFACE_STREET, rng,
          parking=(rng.random() < 0.3, rng.random() < 0.3))
    return _world(b, rng, knobs)


def _junction(rng: np.random.Generator, topology: str, arm_angles: list[float], control: str,
              knobs: SyntheticKnobs) -> RoadNetwork:
    """Arms radiate from the origin; incoming lanes end at stop points, connectors cross the box."""
    b = NetworkBuilder(topology)
    width = _lane_width(rng, knobs)
    lanes_main, lanes_cross = int(rng.integers(1, 4)), int(rng.integers(1, 4))
    speed = _urban_speed(rng)
    # Arms 0 and 2 form the main road; the others the cross road.
    num_lanes = [lanes_main if k % 2 == 0 else lanes_cross for k in range(len(arm_angles))]
    corner = max(num_lanes) * width + 2.5
    stop_at = corner + 1.0 + CROSSWALK_WIDTH_M + 1.0
    arms = []
    for _k, (angle, num) in enumerate(zip(arm_angles, num_lanes)):
        u, normal = geo.unit(angle), geo.left_normal(geo.unit(angle))
        length = float(rng.uniform(110.0, 150.0))
        ref = geo.segment(u * stop_at, u * (stop_at + length))
        # kerbside parking on the arm (its first spots are 13 m past the stop line): drawn only when the knob is
        # on, so the default generator's random stream is unchanged
        parking = (bool(rng.random() < knobs.junction_parking), bool(rng.random() < knobs.junction_parking)) \
            if knobs.junction_parking > 0 else (False, False)
        outgoing, incoming = _road(b, ref, num, num, width, speed, RG_LANE_SURFACE_STREET, rng, parking=parking)
        half = num * width
        b.add_area(Polygon([normal * half, normal * half + u * (stop_at + 0.5),
                            -normal * half + u * (stop_at + 0.5), -normal * half]))
        if rng.random() < 0.75:
            centre = u * (corner + 1.0 + CROSSWALK_WIDTH_M / 2)
            along = normal if rng.random() < 0.5 else -normal
            b.add_crosswalk(centre, along, 2 * half, CROSSWALK_WIDTH_M, is_signalised=control == "signal")
        arms.append((angle, outgoing, incoming))
    # one light group per approach (split phasing), or opposite approaches together (paired): drawn only when the
    # knob is on, so the default generator's random stream is unchanged
    paired = control == "signal" and len(arms) == 4 and knobs.paired_signals > 0 \
        and bool(rng.random() < knobs.paired_signals)
    num_groups = 2 if paired else len(arms)
    for a, (angle_a, _, incoming) in enumerate(arms):
        heading_in = angle_a + np.pi
        moves = []  # (entry lane index, exit arm, exit lane index)
        for target, (angle_b, outgoing, _) in enumerate(arms):
            if target == a:
                continue
            turn = float(geo.wrap_angle(angle_b - heading_in))
            if abs(turn) < np.radians(30):
                moves += [(j, target, min(j, len(outgoing) - 1)) for j in range(len(incoming))]
            elif turn > 0:
                moves.append((0, target, 0))
            else:
                moves.append((len(incoming) - 1, target, len(outgoing) - 1))
        served = {m[0] for m in moves}
        for j in range(len(incoming)):
            if j not in served:  # a middle lane with no straight-on: follow the nearest turn
                nearest = min(moves, key=lambda m: abs(m[0] - j))
                moves.append((j, nearest[1], min(j, len(arms[nearest[1]][1]) - 1)))
        for j, target, exit_lane in moves:
            b.connect(incoming[j], arms[target][1][exit_lane])
        for lane in incoming:
            draft = b.draft(lane)
            if control == "signal":
                draft.signal_group = a % num_groups
            else:
                draft.has_stop_sign = True
    if knobs.junction_uturns > 0:  # drawn only when the knob is on: the default random stream stays
        _add_uturns(b, [(incoming, outgoing) for _, outgoing, incoming in arms], rng, knobs.junction_uturns)
    if control == "signal":
        b.signal_plan = random_plan(rng, num_groups, has_crosswalks=bool(b.crosswalks))
    return _world(b, rng, knobs)


# lanes each way an arm needs for a U-turn: the half circle's radius is 1.5 lane widths (>= 4.05 m for the narrowest
# lanes the knobs allow, 2.7 m; 4.95-5.7 m for the default 3.3-3.8 m)
UTURN_MIN_LANES = 3


def _add_uturns(b: NetworkBuilder, arms: list[tuple[list[int], list[int]]], rng: np.random.Generator,
                chance: float) -> None:
    """U-turn lanes (added after every other lane, so the other lanes keep their ids): with `chance`, an arm of
    UTURN_MIN_LANES or more lanes each way turns from its innermost incoming lane round into its outermost outgoing
    one, a half circle from the stop line into the junction, gated with the incoming lane's approach."""
    for incoming, outgoing in arms:
        if min(len(incoming), len(outgoing)) < UTURN_MIN_LANES or rng.random() >= chance:
            continue
        entry, exit_ = b.draft(incoming[0]), b.draft(outgoing[-1])
        b.connect(incoming[0], outgoing[-1], xy=geo.half_turn(entry.xy[-1], geo.tangents(entry.xy)[-1], exit_.xy[0]),
                  is_uturn=True)


def build_intersection4(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    """Four-way junction, signalised (split or, with the `paired_signals` knob, paired phasing + pedestrian phase) or
    all-way stop."""
    base = 0.0
    control = "signal" if rng.random() < 0.8 else "stop"
    return _junction(rng, "intersection4", [base, base + np.pi / 2, base + np.pi, base + 1.5 * np.pi], control,
                     knobs)


def build_intersection3(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    """T junction, usually all-way stop, sometimes signalised."""
    control = "stop" if rng.random() < 0.7 else "signal"
    return _junction(rng, "intersection3", [0.0, 1.5 * np.pi, np.pi], control, knobs)


def _merge(rng: np.random.Generator, topology: str, knobs: SyntheticKnobs) -> RoadNetwork:
    """One-way carriageway; traffic from an on-ramp (or a dropped lane) yields and merges into
    the rightmost through lane along a merge zone."""
    b = NetworkBuilder(topology)
    width = _lane_width(rng, knobs, 3.4, 3.8)
    is_ramp = topology == "merge"
    num = int(rng.integers(1, 4)) if is_ramp else int(rng.integers(2, 4))
    speed = float(rng.uniform(22.0, 29.0)) if is_ramp else float(rng.uniform(13.0, 20.0))
    lane_type = RG_LANE_FREEWAY if is_ramp else RG_LANE_SURFACE_STREET
    start, end, zone = -260.0, 260.0, float(rng.uniform(50.0, 70.0))
    num_through = num if is_ramp else num - 1
    target = num_through - 1  # the lane that traffic merges into

    def centre_y(j):
        return -(j + 0.5) * width

    lanes_left_to_right = []
    for j in range(num_through):
        if j == target:
            parts = [b.add_lane(geo.segment(np.array([x0, centre_y(j)]), np.array([x1, centre_y(j)])),
                                width, speed, lane_type) for x0, x1 in ((start, 0.0), (0.0, zone), (zone, end))]
            b.link(parts[0], parts[1])
            b.link(parts[1], parts[2])
            b.draft(parts[1]).is_gated = True
            lanes_left_to_right.append(parts[0])
        else:
            lanes_left_to_right.append(b.add_lane(
                geo.segment(np.array([start, centre_y(j)]), np.array([end, centre_y(j)])), width, speed, lane_type))
    merge_from_y = centre_y(num_through)
    if is_ramp:
        ramp_speed = float(min(speed, rng.uniform(15.0, 20.0)))
        bend = geo.bezier(np.array([-240.0, merge_from_y - 45.0]), geo.unit(np.radians(12)),
                          np.array([-70.0, merge_from_y]), geo.unit(0.0))
        feeder = b.add_lane(geo.join(bend, geo.segment(np.array([-70.0, merge_from_y]), np.array([0.0, merge_from_y]))),
                            width, ramp_speed, lane_type)
        # Pave the gore between ramp and carriageway: a sharp V of kerb right beside a lane would
        # make nearest-edge tests misjudge which side of the road a vehicle is on.
        edge_y = -num_through * width
        near = bend[edge_y - bend[:, 1] < 20.0]
        # It meets the kerb at a shallow angle (a square corner would be just as misleading).
        back = near[0, 0] - 3.0 * (edge_y - near[0, 1])
        b.add_area(Polygon(np.concatenate([near, [[0.0, edge_y], [back, edge_y]]])).buffer(0))
    else:
        feeder = b.add_lane(geo.segment(np.array([start, merge_from_y]), np.array([0.0, merge_from_y])),
                            width, speed, lane_type)
        lanes_left_to_right.append(feeder)
    b.neighbours(lanes_left_to_right)
    through = b.draft(lanes_left_to_right[target]).successors[0]
    after = b.draft(through).successors[0]
    b.connect(feeder, after, yields=True)
    for k in range(1, num_through):
        b.add_line(geo.segment(np.array([start, -k * width]), np.array([end, -k * width])), RG_BROKEN_SINGLE_WHITE)
    if not is_ramp:
        b.add_line(geo.segment(np.array([start, -num_through * width]), np.array([0.0, -num_through * width])),
                   RG_BROKEN_SINGLE_WHITE)
    return _world(b, rng, knobs)


def build_merge(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    return _merge(rng, "merge", knobs)


def build_lane_drop(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    return _merge(rng, "lane_drop", knobs)


def build_roundabout(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> RoadNetwork:
    """Single-lane roundabout with 3 or 4 arms; entering traffic gives way to circulating traffic.

    The ring is cut at every arm into a short *passing* stretch (from the exit point to the entry
    point, which circulating traffic reserves) and a *running* stretch up to the next arm."""
    b = NetworkBuilder("roundabout")
    width = _lane_width(rng, knobs, 3.5, 4.0)
    radius = float(rng.uniform(14.0, 22.0))
    num_arms = int(rng.choice([3, 4]))
    angles = np.arange(num_arms) * 2 * np.pi / num_arms + rng.uniform(-0.12, 0.12, num_arms)
    arm_speed, ring_speed = float(min(_urban_speed(rng), 13.4)), 8.0
    spread = (width / 2 + 4.0) / radius  # exit and entry points sit this angle either side of an arm
    start_at = radius + width / 2 + 10.0
    arms = []
    for angle in angles:
        u, normal = geo.unit(angle), geo.left_normal(geo.unit(angle))
        length = float(rng.uniform(110.0, 150.0))
        ref = geo.segment(u * start_at, u * (start_at + length))
        (outgoing,), (incoming,) = _road(b, ref, 1, 1, width, arm_speed, RG_LANE_SURFACE_STREET)
        if rng.random() < 0.5:
            b.add_crosswalk(u * (start_at + 5.0), normal if rng.random() < 0.5 else -normal, 2 * width,
                            CROSSWALK_WIDTH_M, is_signalised=False)
        arms.append((outgoing, incoming))
    passing, running = [], []
    for k, angle in enumerate(angles):
        next_exit = angles[(k + 1) % num_arms] - spread
        sweep = (next_exit - (angle + spread)) % (2 * np.pi)
        passing.append(b.add_lane(geo.arc(np.zeros(2), radius, angle - spread, 2 * spread, 0.5), width,
                                  ring_speed, RG_LANE_SURFACE_STREET, is_gated=True))
        running.append(b.add_lane(geo.arc(np.zeros(2), radius, angle + spread, sweep, 0.5), width,
                                  ring_speed, RG_LANE_SURFACE_STREET))
    for k in range(num_arms):
        b.link(passing[k], running[k])
        b.link(running[k], passing[(k + 1) % num_arms])
        outgoing, incoming = arms[k]
        b.connect(incoming, running[k], yields=True)
        # Leaving is reserved too: a long vehicle's corners sweep across the entry beside it.
        b.connect(running[k - 1], outgoing)
    return _world(b, rng, knobs)


TOPOLOGY_BUILDERS: dict[str, Callable[[np.random.Generator, SyntheticKnobs], RoadNetwork]] = {
    "straight": build_straight,
    "curve": build_curve,
    "intersection4": build_intersection4,
    "intersection3": build_intersection3,
    "merge": build_merge,
    "lane_drop": build_lane_drop,
    "roundabout": build_roundabout,
}
TOPOLOGIES: tuple[str, ...] = tuple(TOPOLOGY_BUILDERS)
TOPOLOGY_WEIGHTS = np.array([0.12, 0.11, 0.25, 0.18, 0.12, 0.1, 0.12])
if TOPOLOGIES != TOPOLOGY_NAMES:  # the knobs name the topologies without importing the builders
    raise ImportError(f"knobs.TOPOLOGY_NAMES {TOPOLOGY_NAMES} differ from the builders {TOPOLOGIES}")


def build_network(rng: np.random.Generator, topology: str | None = None,
                  knobs: SyntheticKnobs | None = None) -> RoadNetwork:
    """A random network of the given topology (drawn from the rng when None, with the knobs' weights)."""
    knobs = knobs or DEFAULT_KNOBS
    if topology is None:
        chosen = knobs.topology_probabilities()
        weights = TOPOLOGY_WEIGHTS if chosen is None else np.array(chosen)
        topology = TOPOLOGIES[int(rng.choice(len(TOPOLOGIES), p=weights))]
    if topology not in TOPOLOGY_BUILDERS:
        raise ValueError(f"unknown synthetic topology {topology!r} (choose from {', '.join(TOPOLOGIES)})")
    return TOPOLOGY_BUILDERS[topology](rng, knobs)
