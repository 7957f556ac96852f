"""Traffic simulation on a `RoadNetwork`: vehicles and cyclists follow lanes, pedestrians cross.

Longitudinal control is IDM towards a desired-speed profile (lane limit, slower in bends) with the
nearest mover ahead on the vehicle's own lanes as leader. Junction and merge lanes are *gated*: a
vehicle may enter only with a reservation that no conflicting lane holds, after its light shows
go (or caution when it cannot stop), after a full stop at a stop sign, and, on yielding lanes,
when no priority traffic is close. Until then the stop point is a hard limit, so logged vehicles
never collide or run a red light in normal operation. Pedestrians start crossing only when no
vehicle could reach the crosswalk before stopping; while anyone is on it, vehicles stop short.
A warm-up runs before the logged steps so the logged start is already a settled traffic state.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.schema import TL_CAUTION, TL_GO, TL_STOP
from scenariomax.sources.synthetic import agents as ag
from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.knobs import DEFAULT_KNOBS, SyntheticKnobs
from scenariomax.sources.synthetic.network import RoadNetwork
from scenariomax.sources.synthetic.routes import (
    MAX_ROUTE_POINTS,
    ROUTE_DS_M,
    Gate,
    RouteShape,
    anticipate,
    route_shape,
)
from scenariomax.sources.synthetic.signals import pedestrian_phase, signal_states

DT_S = 0.1
MAX_ROUTE_LANES = 16
SIBLING_REACH_M = 15.0  # a body just past a fork still overlaps the other branch this far
WARMUP_STEPS = 30
STANDSTILL_GAP_M = 2.0
HARD_GAP_M = 0.3
MAX_DECEL = 8.0
MAX_MOVERS = 80
YIELD_HORIZON_S = 5.0
# `stalled_vehicles`: a stalled car stands at least this far (bumper to stop line) before its lane's first gate, so it
# never holds a junction's reservation, and clear of every crosswalk zone by as much
STALL_CLEAR_M = 8.0


@dataclasses.dataclass(frozen=True)
class Traffic:
    """Logged objects (movers, then pedestrians, then parked cars; street objects, when on, after them as parked)."""

    object_type: np.ndarray  # (N,) int64
    length: np.ndarray  # (N,) float64
    width: np.ndarray  # (N,) float64
    height: np.ndarray  # (N,) float64
    x: np.ndarray  # (N, T) float64
    y: np.ndarray  # (N, T) float64
    yaw: np.ndarray  # (N, T) float64, wrapped to [-pi, pi)
    speed: np.ndarray  # (N, T) float64, m/s along yaw
    valid: np.ndarray  # (N, T) bool
    is_parked: np.ndarray  # (N,) bool
    is_stalled: np.ndarray  # (N,) bool, movers that stand in their lane throughout (knob stalled_vehicles)
    routes: tuple[tuple[int, ...], ...]  # lanes each mover follows (empty for the others)
    gates_entered: tuple[tuple[tuple[int, int], ...], ...]  # (gated lane, logged step; -1 in warm-up)


@dataclasses.dataclass
class _Plan:
    """Per-mover bookkeeping the vectorised state does not hold."""

    route: tuple[int, ...]
    gates: list[Gate]
    zones: list[tuple[int, float, float]]  # (crosswalk, first, last centre arc length in the crosswalk zone)
    next_gate: int = 0
    committed: bool = False
    has_stopped: bool = False
    held: list = dataclasses.field(default_factory=list)  # (lane id, release arc length)
    entered: list = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class _Walker:
    start: np.ndarray  # (2,)
    end: np.ndarray  # (2,)
    crosswalk: int
    speed: float
    ready_step: int
    progress: float = 0.0
    state: str = "waiting"  # waiting | crossing | done

    @property
    def position(self) -> np.ndarray:
        length = np.linalg.norm(self.end - self.start)
        return self.start + (self.end - self.start) * min(self.progress / length, 1.0)

    @property
    def yaw(self) -> float:
        d = self.end - self.start
        return float(np.arctan2(d[1], d[0]))


def crosswalk_zones(shape: RouteShape, length: float) -> list[tuple[int, float, float]]:
    """(crosswalk, first, last centre arc length along the route) where a body `length` long would be on or by each
    crosswalk near the route."""
    return [(index, float(hits[0]), float(hits[-1]))
            for index, along, across, half_len, half_wid in shape.crosswalks
            if len(hits := np.flatnonzero((along < half_len + 1.0) & (across < half_wid + length / 2 + 0.8))
                   * ROUTE_DS_M)]


class _World:
    """Mutable simulation state (internal; `simulate` is the pure entry point)."""

    def __init__(self, network: RoadNetwork, rng: np.random.Generator, num_steps: int):
        self.net, self.rng, self.num_steps = network, rng, num_steps
        total = WARMUP_STEPS + num_steps
        self.total_steps = total
        times = (np.arange(total) - WARMUP_STEPS) * DT_S
        plan = network.signal_plan
        self.signal = signal_states(plan, times) if plan else np.zeros((0, total), np.int64)
        self.ped_phase = pedestrian_phase(plan, times) if plan else np.ones(total, bool)
        cap = MAX_MOVERS
        self.s, self.v = np.zeros(cap), np.zeros(cap)
        self.length, self.width, self.height = np.ones(cap), np.ones(cap), np.ones(cap)
        self.a_max, self.b_comf, self.headway = np.ones(cap), np.ones(cap), np.ones(cap)
        self.v_desired = np.ones((cap, MAX_ROUTE_POINTS))  # desired speed along the route
        self.kind = np.zeros(cap, np.int64)
        self.active = np.zeros(cap, bool)
        self.stalled = np.zeros(cap, bool)  # stands where it was placed (knob stalled_vehicles)
        self.route_xy = np.zeros((cap, MAX_ROUTE_POINTS, 2))
        self.route_yaw = np.zeros((cap, MAX_ROUTE_POINTS))
        self.last_index = np.zeros(cap, np.int64)
        self.plans: list[_Plan | None] = [None] * cap
        self.shapes: dict[tuple[int, ...], RouteShape] = {}
        self.gate_s = np.full(cap, np.inf)  # route arc length of each mover's next gate
        self.release_at = np.full(cap, np.inf)  # arc length where its first reservation ends
        self.has_zones = np.zeros(cap, bool)
        num_lanes = len(network.lanes)
        self.lane_offset = np.full((cap, num_lanes), np.nan)  # route arc length where each lane starts
        self.is_sibling = np.zeros((cap, num_lanes), bool)  # lanes that branch off beside the route
        self.route_lane = np.zeros((cap, MAX_ROUTE_LANES), np.int64)
        self.route_start = np.full((cap, MAX_ROUTE_LANES), np.inf)
        self.count = 0
        self.holders: dict[int, set[int]] = {}
        self.log = {name: np.zeros((cap, num_steps)) for name in ("x", "y", "yaw", "speed")}
        self.log_valid = np.zeros((cap, num_steps), bool)
        self.walkers: list[_Walker] = []
        self.walker_body: list[ag.Body] = []
        self.walker_log = []
        self.blocked = np.zeros(len(network.crosswalks), bool)

    # --- spawning ----------------------------------------------------------------------------------
    def random_route(self, first_lane: int) -> tuple[int, ...]:
        route = [first_lane]
        while True:
            # Never revisit a lane: a roundabout is left within one turn.
            successors = [lane for lane in self.net.lane(route[-1]).successors if lane not in route]
            if not successors or len(route) == MAX_ROUTE_LANES:
                return tuple(route)
            route.append(int(successors[int(self.rng.integers(len(successors)))]))

    def shape(self, route: tuple[int, ...]) -> RouteShape:
        if route not in self.shapes:
            self.shapes[route] = route_shape(self.net, route)
        return self.shapes[route]

    def spawn(self, route: tuple[int, ...], s: float, speed: float, body: ag.Body, driver: ag.Driver,
              stalled: bool = False) -> bool:
        if self.count >= MAX_MOVERS:
            return False
        shape = self.shape(route)
        slot = self.count
        self.count += 1
        n = len(shape.xy)
        self.route_xy[slot, :n], self.route_xy[slot, n:] = shape.xy, shape.xy[-1]
        self.route_yaw[slot, :n], self.route_yaw[slot, n:] = shape.yaw, shape.yaw[-1]
        self.last_index[slot] = n - 1
        self.s[slot], self.v[slot] = s, 0.0 if stalled else speed
        self.length[slot], self.width[slot], self.height[slot] = body.length, body.width, body.height
        self.kind[slot] = body.object_type
        desired = anticipate(np.minimum(shape.speed_limit * driver.speed_factor, shape.bend_speed))
        self.v_desired[slot, :n], self.v_desired[slot, n:] = desired, desired[-1]
        self.a_max[slot], self.b_comf[slot], self.headway[slot] = (driver.max_accel, driver.comfort_decel,
                                                                   driver.time_headway)
        self.active[slot] = True
        zones = crosswalk_zones(shape, body.length)
        self.plans[slot] = _Plan(route, list(shape.gates), zones)
        first = self.net.lanes[0].lane_id
        for k, lane_id in enumerate(route[:MAX_ROUTE_LANES]):
            self.lane_offset[slot, lane_id - first] = shape.starts[k]
            self.route_lane[slot, k] = lane_id - first
            self.route_start[slot, k] = shape.starts[k]
        for sibling, start in shape.siblings:
            self.lane_offset[slot, sibling - first] = start
            self.is_sibling[slot, sibling - first] = True
        self.gate_s[slot] = shape.gates[0].start_s if shape.gates and not stalled else np.inf
        self.stalled[slot] = stalled
        self.release_at[slot] = np.inf
        self.has_zones[slot] = bool(zones)
        return True

    # --- per-step state ----------------------------------------------------------------------------
    def poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Active slots, their positions (k, 2) and headings (k,)."""
        slots = np.flatnonzero(self.active[: self.count])
        pos_index = self.s[slots] / ROUTE_DS_M
        i0 = np.minimum(pos_index.astype(np.int64), np.maximum(self.last_index[slots] - 1, 0))
        frac = np.clip(pos_index - i0, 0.0, 1.0)[:, None]
        xy = self.route_xy[slots, i0] * (1 - frac) + self.route_xy[slots, i0 + 1] * frac
        return slots, xy, self.route_yaw[slots, i0]

    def obstacles_ahead(self, slots):
        """For each active mover: bumper gap to the nearest mover ahead on its route (its own lanes,
        or the first metres of a branch beside it) and that mover's speed. -> gap (k,), lead_speed (k,)

        Other geometric conflicts cannot happen: crossing and merging lanes are reserved one
        vehicle stream at a time, and pedestrians are kept off by the crosswalk logic."""
        k = len(slots)
        gap, lead_speed = np.full(k, np.inf), np.zeros(k)
        if k < 2:
            return gap, lead_speed
        s = self.s[slots]
        current = (self.route_start[slots] <= s[:, None]).sum(axis=1) - 1  # (k,)
        lane = self.route_lane[slots, current]
        on_lane = s - self.route_start[slots, current]
        offset = self.lane_offset[slots[:, None], lane[None, :]]  # (k, k): where j's lane starts on i's route
        along = offset + on_lane[None, :]
        ahead = np.isfinite(along) & (along > s[:, None])
        ahead &= ~self.is_sibling[slots[:, None], lane[None, :]] | (on_lane[None, :] < SIBLING_REACH_M)
        np.fill_diagonal(ahead, False)
        pair_gap = np.where(ahead, along - s[:, None] - (self.length[slots][:, None] + self.length[slots][None, :]) / 2,
                            np.inf)
        leader = pair_gap.argmin(axis=1)
        gap = pair_gap[np.arange(k), leader]
        lead_speed = np.where(np.isfinite(gap), self.v[slots][leader], 0.0)
        return gap, lead_speed

    # --- gates ---------------------------------------------------------------------------------------
    def release(self, slot: int) -> None:
        plan = self.plans[slot]
        keep = []
        for lane_id, release_s in plan.held:
            if self.s[slot] > release_s or not self.active[slot]:
                self.holders.get(lane_id, set()).discard(slot)
            else:
                keep.append((lane_id, release_s))
        plan.held = keep
        self.release_at[slot] = min((h[1] for h in keep), default=np.inf)

    def drop_hold(self, slot: int, lane_id: int) -> None:
        plan = self.plans[slot]
        self.holders.get(lane_id, set()).discard(slot)
        plan.held = [h for h in plan.held if h[0] != lane_id]
        self.release_at[slot] = min((h[1] for h in plan.held), default=np.inf)

    def may_enter(self, slot: int, gate: Gate, distance: float, step: int) -> bool:
        speed = self.v[slot]
        if gate.signal_group >= 0:
            light = self.signal[gate.signal_group, step]
            if light == TL_STOP or (light == TL_CAUTION and distance > speed * speed / 8.0):
                return False
        plan = self.plans[slot]
        if gate.has_stop_sign and not plan.has_stopped:
            return False
        if any(self.holders.get(lane, set()) - {slot} for lane in gate.conflicts):
            return False
        for lane in gate.yields_to:
            for other in np.flatnonzero(self.active[: self.count]):
                other_plan = self.plans[other]
                if other == slot or other_plan.next_gate >= len(other_plan.gates):
                    continue
                other_gate = other_plan.gates[other_plan.next_gate]
                if other_gate.lane_id != lane:
                    continue
                other_distance = other_gate.start_s - self.s[other] - self.length[other] / 2
                if other_distance / max(self.v[other], 1.0) < YIELD_HORIZON_S:
                    return False
        return True

    def stop_limit(self, slot: int, step: int) -> float:
        """Furthest centre arc length the mover may reach this step (gates and crosswalks)."""
        plan = self.plans[slot]
        s, speed, half = self.s[slot], self.v[slot], self.length[slot] / 2
        limit = np.inf
        while plan.next_gate < len(plan.gates):
            gate = plan.gates[plan.next_gate]
            distance = gate.start_s - (s + half)
            if distance < 0:
                if plan.committed:
                    plan.entered.append((gate.lane_id, step - WARMUP_STEPS))
                    plan.next_gate += 1
                    plan.committed, plan.has_stopped = False, False
                    self.gate_s[slot] = (plan.gates[plan.next_gate].start_s if plan.next_gate < len(plan.gates)
                                         else np.inf)
                    continue
                # Only reachable if something pushed the vehicle over: take the gate as entered.
                plan.committed = True
                continue
            # Dilemma zone: on caution or stop, a vehicle that can still stop comfortably does.
            if plan.committed and gate.signal_group >= 0 and self.signal[gate.signal_group, step] != TL_GO \
                    and distance > speed * speed / 6.0 + 0.3:
                plan.committed = False
                self.drop_hold(slot, gate.lane_id)
            if not plan.committed:
                if gate.has_stop_sign and speed < 0.3 and distance < 6.0:
                    plan.has_stopped = True
                horizon = speed * speed / 3.0 + 1.5 * speed + 6.0
                if distance < horizon and self.may_enter(slot, gate, distance, step):
                    plan.committed = True
                    plan.held.append((gate.lane_id, gate.end_s + half + 0.5))
                    self.release_at[slot] = min(self.release_at[slot], gate.end_s + half + 0.5)
                    self.holders.setdefault(gate.lane_id, set()).add(slot)
                else:
                    limit = gate.start_s - half
            break
        for crosswalk, first, _last in plan.zones:
            if self.blocked[crosswalk] and s < first < s + 80.0:
                limit = min(limit, first)
        return limit

    def threatens(self, slot: int, crosswalk: int) -> bool:
        """Could this mover be on the crosswalk before a pedestrian gets across?"""
        plan = self.plans[slot]
        for index, first, last in plan.zones:
            if index != crosswalk or self.s[slot] > last:
                continue
            if self.s[slot] >= first:
                return True
            if plan.next_gate < len(plan.gates) and not plan.committed:
                gate = plan.gates[plan.next_gate]
                if gate.start_s - self.length[slot] / 2 <= first:
                    return False  # it must stop at its gate first (and stops short of a busy crosswalk later)
            speed = self.v[slot]
            return first - self.s[slot] < speed * speed / 5.0 + speed + 3.0
        return False

    # --- the step ------------------------------------------------------------------------------------
    def step(self, step: int) -> None:
        slots, xy, yaw = self.poses()
        logged = step - WARMUP_STEPS
        if logged >= 0:
            for name, values in (("x", xy[:, 0]), ("y", xy[:, 1]), ("yaw", yaw), ("speed", self.v[slots])):
                self.log[name][slots, logged] = values
            self.log_valid[slots, logged] = True
            self.walker_log.append([(w.position.copy(), w.yaw, w.speed if w.state == "crossing" else 0.0)
                                    for w in self.walkers])
        for slot in slots[self.s[slots] > self.release_at[slots]]:
            self.release(slot)
        self.update_walkers(step, slots)
        gap, lead_speed = self.obstacles_ahead(slots)
        speed = self.v[slots]
        # Only movers near their next gate (or with a busy crosswalk ahead) need the slow path.
        gate_distance = self.gate_s[slots] - self.s[slots] - self.length[slots] / 2
        need = gate_distance < speed * speed / 3.0 + 1.5 * speed + 7.0
        if self.blocked.any():
            need |= self.has_zones[slots]
        limit = np.full(len(slots), np.inf)
        for row in np.flatnonzero(need):
            limit[row] = self.stop_limit(slots[row], step)
        stop_gap = limit - self.s[slots]
        accel = np.minimum(self.idm(slots, speed, gap, lead_speed), self.idm(slots, speed, stop_gap, 0.0))
        accel = np.clip(accel, -MAX_DECEL, self.a_max[slots])
        new_speed = np.maximum(speed + accel * DT_S, 0.0)
        room = np.minimum(gap, stop_gap) - HARD_GAP_M
        new_speed = np.minimum(new_speed, np.maximum(room, 0.0) / DT_S)
        new_speed[self.stalled[slots]] = 0.0
        self.v[slots] = new_speed
        self.s[slots] += new_speed * DT_S
        gone = slots[self.s[slots] + self.length[slots] / 2 > self.last_index[slots] * ROUTE_DS_M - 0.5]
        self.active[gone] = False
        for slot in gone:
            self.release(slot)
            self.gate_s[slot] = np.inf

    def idm(self, slots, speed, gap, lead_speed):
        a, b, headway = self.a_max[slots], self.b_comf[slots], self.headway[slots]
        desired = STANDSTILL_GAP_M + np.maximum(
            0.0, speed * headway + speed * (speed - lead_speed) / (2 * np.sqrt(a * b)))
        here = np.minimum((self.s[slots] / ROUTE_DS_M).astype(np.int64), self.last_index[slots])
        free = (speed / self.v_desired[slots, here]) ** 4
        interaction = np.where(np.isfinite(gap), (desired / np.maximum(gap, 0.1)) ** 2, 0.0)
        return a * (1.0 - free - interaction)

    def update_walkers(self, step: int, slots: np.ndarray) -> None:
        for index, _walk in enumerate(self.net.crosswalks):
            self.blocked[index] = any(w.state == "crossing" and w.crosswalk == index for w in self.walkers)
        for walker in self.walkers:
            if walker.state == "waiting" and step >= walker.ready_step:
                walk = self.net.crosswalks[walker.crosswalk]
                allowed = self.ped_phase[step] if walk.is_signalised else True
                if allowed and not any(self.threatens(slot, walker.crosswalk) for slot in slots[self.has_zones[slots]]):
                    walker.state = "crossing"
                    self.blocked[walker.crosswalk] = True
            if walker.state == "crossing":
                walker.progress += walker.speed * DT_S
                if walker.progress >= np.linalg.norm(walker.end - walker.start):
                    walker.state = "done"


def simulate(network: RoadNetwork, rng: np.random.Generator, num_steps: int = 91,
             knobs: SyntheticKnobs | None = None) -> Traffic:
    """Runs warm-up + `num_steps` logged steps of traffic on the network."""
    knobs = knobs or DEFAULT_KNOBS
    # the parked cars' reach is drawn from a stream of its own, so that every other draw is the knob-off scene's
    reach_rng = np.random.Generator(rng.bit_generator.jumped()) if knobs.parked_reach[1] > 0 else None
    world = _World(network, rng, num_steps)
    urban = network.topology not in ("merge",)
    parked = _park(network, rng, knobs)
    _populate(world, rng, urban, knobs)
    _add_walkers(world, rng, knobs)
    entries = [lane for lane in network.lanes if not lane.predecessors and not lane.is_gated]
    inflow = float(rng.uniform(0.015, 0.05)) * knobs.traffic_density
    for step in range(world.total_steps):
        world.step(step)
        for lane in entries:
            if rng.random() < inflow:
                _spawn_at_entry(world, rng, lane, urban, knobs)
    if reach_rng is not None:
        parked = _reach_towards_lanes(parked, network, world, reach_rng, knobs.parked_reach)
    return _collect(world, parked)


def _park(network: RoadNetwork, rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> dict:
    spots = network.parking_spots
    if len(spots):
        take = spots[rng.random(len(spots)) < rng.uniform(*knobs.parked_fraction)]
        if knobs.max_parked == DEFAULT_KNOBS.max_parked:
            take = take[:knobs.max_parked]  # the generator's own rule: the first spots in road order
        elif len(take) > knobs.max_parked:  # spread along every strip, not bunched at the first one's start
            take = take[np.sort(rng.choice(len(take), knobs.max_parked, replace=False))]
    else:
        take = spots
    bodies = [ag.parked_body(rng) for _ in range(len(take))]
    return {"xy": take[:, :2].reshape(-1, 2), "yaw": take[:, 2].reshape(-1), "bodies": bodies}


# room a parked car leaves between itself and every vehicle the log drives past it
PARKED_CLEARANCE_M = 0.3


def _reach_towards_lanes(parked: dict, network: RoadNetwork, world: _World, rng: np.random.Generator,
                         reach_range: tuple[float, float]) -> dict:
    """`parked` with each car moved a distance drawn from `reach_range` towards the nearest lane centre, cut so that
    its box stays PARKED_CLEARANCE_M apart from every logged vehicle's box at every step (apart along the move,
    or beside it, where the move changes nothing: two separating axes)."""
    xy = parked["xy"]  # (k, 2)
    if not len(xy) or not network.lanes:
        return parked
    wanted = rng.uniform(*reach_range, size=len(xy))  # (k,)
    centres = np.concatenate([lane.xy for lane in network.lanes])  # (L, 2), ~1 m apart
    offsets = centres[None] - xy[:, None, :]  # (k, L, 2)
    nearest = offsets[np.arange(len(xy)), np.hypot(offsets[..., 0], offsets[..., 1]).argmin(axis=1)]  # (k, 2)
    beside = np.stack([np.cos(parked["yaw"]), np.sin(parked["yaw"])], axis=1)  # (k, 2) unit, along the kerb
    towards = np.stack([-beside[:, 1], beside[:, 0]], axis=1)  # (k, 2) unit, across the car: the move...
    towards *= np.where(np.sum(towards * nearest, axis=1) < 0, -1.0, 1.0)[:, None]  # ...to the lane's side
    logged = np.flatnonzero(world.log_valid.any(axis=1))
    reach = wanted
    if len(logged):
        # the parked box's half extents along the move (across the car) and beside it (along the car)
        parked_u = np.array([b.width for b in parked["bodies"]])[:, None, None] / 2.0  # (k, 1, 1)
        parked_v = np.array([b.length for b in parked["bodies"]])[:, None, None] / 2.0  # (k, 1, 1)
        mover_xy = np.stack([world.log["x"][logged], world.log["y"][logged]], axis=-1)[None]  # (1, M, T, 2)
        mover_yaw = world.log["yaw"][logged][None]  # (1, M, T)
        mover_body = np.stack([world.length[logged], world.width[logged]], axis=-1)[None, :, None]  # (1, M, 1, 2)

        def half_extent(axis, heading, size):  # a mover box's half extent along the unit axis (k, 1, 1, 2)
            cos = np.abs(axis[..., 0] * np.cos(heading) + axis[..., 1] * np.sin(heading))
            sin = np.abs(-axis[..., 0] * np.sin(heading) + axis[..., 1] * np.cos(heading))
            return 0.5 * (size[..., 0] * cos + size[..., 1] * sin)

        u, v = towards[:, None, None, :], beside[:, None, None, :]
        apart = mover_xy - xy[:, None, None, :]  # (k, M, T, 2)
        along_u = np.sum(apart * u, axis=-1)  # (k, M, T)
        gap_u = along_u - parked_u - half_extent(u, mover_yaw, mover_body)
        gap_v = np.abs(np.sum(apart * v, axis=-1)) - parked_v - half_extent(v, mover_yaw, mover_body)
        limits = np.where(world.log_valid[logged][None] & (gap_v < PARKED_CLEARANCE_M) & (along_u > 0),
                          gap_u - PARKED_CLEARANCE_M, np.inf)  # (k, M, T)
        reach = np.clip(wanted, 0.0, np.maximum(limits.min(axis=(1, 2)), 0.0))
    return {**parked, "xy": xy + reach[:, None] * towards}


def _populate(world: _World, rng: np.random.Generator, urban: bool, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> None:
    """Vehicles (and a few cyclists) spread along the ordinary lanes at the start of the warm-up (the gaps
    between them divided by the knobs' traffic density)."""
    density = knobs.traffic_density
    spacing = (10.0, 45.0) if urban else (25.0, 80.0)
    for lane in world.net.lanes:
        if lane.is_gated or lane.length < 20.0:
            continue
        s = float(rng.uniform(4.0, spacing[1])) / density
        behind_front = -np.inf  # front of the car placed before on this lane (behind this one)
        while True:
            is_bike = urban and not lane.right_neighbors and rng.random() < 0.08
            body = ag.cyclist_body(rng) if is_bike else ag.vehicle_body(rng)
            if s + body.length / 2 > lane.length - 4.0:
                break
            driver = ag.cyclist_driver(rng, lane.speed_limit) if is_bike else ag.vehicle_driver(rng, knobs)
            s_centre = max(s, body.length / 2 + 1.0)
            speed = lane.speed_limit * driver.speed_factor * float(rng.uniform(0.5, 0.9))
            route = world.random_route(lane.lane_id)
            # no draw when off: the default stream stays. Cars are placed closer than they stand in a queue (the
            # warm-up spreads them); one that never moves must leave the car behind it room to stop
            stalled = (not is_bike and knobs.stalled_vehicles > 0 and rng.random() < knobs.stalled_vehicles
                       and s_centre - body.length / 2 > behind_front + STANDSTILL_GAP_M
                       and _may_stall(world, route, s_centre, body.length))
            if not world.spawn(route, s_centre, speed, body, driver, stalled=stalled):
                return
            behind_front = s_centre + body.length / 2
            s = s_centre + body.length / 2 + float(rng.uniform(*spacing)) / density


def _may_stall(world: _World, route: tuple[int, ...], s_centre: float, length: float) -> bool:
    """Whether a car whose centre is `s_centre` along `route` may stand there all scene: STALL_CLEAR_M before the
    route's first gate and clear of its crosswalk zones."""
    shape = world.shape(route)
    front, back = s_centre + length / 2, s_centre - length / 2
    if shape.gates and front > shape.gates[0].start_s - STALL_CLEAR_M:
        return False
    return not any(back < last + STALL_CLEAR_M and front > first - STALL_CLEAR_M
                   for _index, first, last in crosswalk_zones(shape, length))


def _spawn_at_entry(world: _World, rng: np.random.Generator, lane, urban: bool,
                    knobs: SyntheticKnobs = DEFAULT_KNOBS) -> None:
    slots, xy, _ = world.poses()
    if len(slots) and np.min(np.linalg.norm(xy - lane.xy[0], axis=1)) < 25.0:
        return
    is_bike = urban and not lane.right_neighbors and rng.random() < 0.08
    body = ag.cyclist_body(rng) if is_bike else ag.vehicle_body(rng)
    driver = ag.cyclist_driver(rng, lane.speed_limit) if is_bike else ag.vehicle_driver(rng, knobs)
    world.spawn(world.random_route(lane.lane_id), body.length / 2 + 0.5,
                lane.speed_limit * driver.speed_factor * 0.8, body, driver)


def _add_walkers(world: _World, rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> None:
    low, high = (int(round(v)) for v in knobs.walkers_per_crosswalk)
    for index, walk in enumerate(world.net.crosswalks):
        for _ in range(int(rng.integers(low, high + 1))):
            forward = rng.random() < 0.5
            start, end = (walk.start, walk.end) if forward else (walk.end, walk.start)
            side = geo.left_normal((end - start) / np.linalg.norm(end - start))
            lateral = side * float(rng.uniform(-1.0, 1.0))  # side by side within the zebra
            world.walkers.append(_Walker(start + lateral, end + lateral, index, float(rng.uniform(1.1, 1.6)),
                                         int(rng.integers(0, WARMUP_STEPS + 60))))
            world.walker_body.append(ag.pedestrian_body(rng))


def _collect(world: _World, parked: dict) -> Traffic:
    n_move, steps = world.count, world.num_steps
    movers = np.flatnonzero(world.log_valid[:n_move].any(axis=1))
    n_walk, n_park = len(world.walkers), len(parked["bodies"])
    walk_log = np.array([[(p[0], p[1], yaw, speed) for p, yaw, speed in row] for row in world.walker_log])
    walk_log = walk_log.reshape(steps, n_walk, 4).transpose(1, 0, 2)
    # Walkers' speed from their displacement, so it agrees with positions at the kerbs too.
    walk_log[:, 1:, 3] = np.hypot(np.diff(walk_log[..., 0], axis=1), np.diff(walk_log[..., 1], axis=1)) / DT_S
    bodies_walk, bodies_park = world.walker_body, parked["bodies"]

    def stack(mover_values, walker_values, parked_values):
        return np.concatenate([mover_values, walker_values, parked_values])

    x = stack(world.log["x"][movers], walk_log[..., 0], np.repeat(parked["xy"][:, :1], steps, 1))
    y = stack(world.log["y"][movers], walk_log[..., 1], np.repeat(parked["xy"][:, 1:], steps, 1))
    yaw = stack(world.log["yaw"][movers], walk_log[..., 2], np.repeat(parked["yaw"][:, None], steps, 1))
    speed = stack(world.log["speed"][movers], walk_log[..., 3], np.zeros((n_park, steps)))
    valid = stack(world.log_valid[movers], np.ones((n_walk, steps), bool), np.ones((n_park, steps), bool))
    body_rows = [(world.kind[m], world.length[m], world.width[m], world.height[m]) for m in movers]
    body_rows += [(b.object_type, b.length, b.width, b.height) for b in bodies_walk + bodies_park]
    bodies = np.array(body_rows, dtype=np.float64).reshape(-1, 4)
    return Traffic(
        object_type=bodies[:, 0].astype(np.int64), length=bodies[:, 1], width=bodies[:, 2], height=bodies[:, 3],
        x=x, y=y, yaw=geo.wrap_angle(yaw), speed=speed, valid=valid,
        is_parked=np.concatenate([np.zeros(len(movers) + n_walk, bool), np.ones(n_park, bool)]),
        is_stalled=np.concatenate([world.stalled[movers], np.zeros(n_walk + n_park, bool)]),
        routes=tuple(world.plans[m].route for m in movers) + ((),) * (n_walk + n_park),
        gates_entered=tuple(tuple(world.plans[m].entered) for m in movers) + ((),) * (n_walk + n_park),
    )
