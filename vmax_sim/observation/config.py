"""Observation settings (frozen; named presets for the roadgraph type sets)."""

from __future__ import annotations

import dataclasses
import math

from scenariomax.schema import LANE_TYPES, ROAD_EDGE_TYPES, ROAD_LINE_TYPES

ROADGRAPH_TYPE_SETS = {
    "edges": ROAD_EDGE_TYPES,
    "edges+lanes": ROAD_EDGE_TYPES + LANE_TYPES,
    "edges+lanes+lines": ROAD_EDGE_TYPES + LANE_TYPES + ROAD_LINE_TYPES,
}


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """Perception noise, all driven by the PRNG key passed to `observe`."""

    position_std: float = 0.0  # m, Gaussian noise on object positions
    dropout_start: float = 30.0  # m, objects nearer are never dropped
    dropout_max_prob: float = 0.0  # drop probability reached at ObservationConfig.max_distance
    occlusion: bool = False  # hide objects whose line of sight crosses a nearer object's box
    # chance that each map point of the observation is hidden (its slot masked), drawn afresh every step: a student
    # that sees another sample of the same road should drive the same (which points a crowded map cell keeps moved
    # one checkpoint's real-scene score by up to 7 points; docs/learning.md, session 41)
    map_dropout: float = 0.0
    # chance that an observation hides the SDC's own past (every step but now), drawn afresh every step: a student
    # that reads its teacher's next label off its own standing history brakes where the teacher pulls away (the
    # copycat effect; hiding the past always, `sdc_history=1`, cost more than it gained: docs/learning.md, session 35).
    # Half an hour at 0.5 was behind the preset on both splits and held still more, not less (session 43)
    sdc_history_dropout: float = 0.0

    def __post_init__(self):
        for name in ("map_dropout", "sdc_history_dropout"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ValueError(f"obs.noise.{name} must be in [0, 1), got {getattr(self, name)}")

    @property
    def on_objects(self) -> bool:
        """Whether any of the object noises is on."""
        return self.position_std > 0 or self.dropout_max_prob > 0 or self.occlusion

    @property
    def active(self) -> bool:
        """Whether the observation needs a key (any noise on)."""
        return self.on_objects or self.map_dropout > 0 or self.sdc_history_dropout > 0


OBJECT_SELECTIONS = ("nearest", "route")
ROUTE_FORECAST_STEP_S = 0.5  # s between the forecast positions tested against the route


@dataclasses.dataclass(frozen=True)
class ObservationConfig:
    num_objects: int = 8  # n closest objects
    # which objects fill the n slots: "nearest" (by distance to the SDC, the paper's) or "route" (first the
    # objects within route_corridor_m of the SDC's route ahead, nearest first, then the nearest others). On real
    # streets parked cars and pedestrians beside the SDC can push the car ahead out of the nearest n
    object_selection: str = "nearest"
    route_corridor_m: float = 3.0  # an object whose centre is this near the route polyline ahead is on it
    # how far along the route ahead (m) an object can count as on it for object_selection="route"; None: as far as the
    # path targets reach (num_path_targets x path_target_spacing, 50 m). A teacher brakes for a car standing 50-100 m
    # ahead (IDM's desired gap at 14 m/s is ~75 m), where the student's slots hold the parked cars nearer it instead
    route_selection_m: float | None = None
    # extra object slots for the on-route objects out to route_selection_m that the num_objects slots leave out
    # (0: none, the slots above reach route_selection_m themselves). With them the num_objects slots stay the 50 m
    # route-first choice: on crowded real streets the 100 m choice took the slots of pedestrians and cars within 25 m
    # at 98% of one nuScenes scene's steps (docs/learning.md, session 62)
    route_far_slots: int = 0
    # seconds of constant-velocity forecast (every ROUTE_FORECAST_STEP_S) in which an object heading onto the route
    # counts as on it for object_selection="route" (0: its position now only). A car crossing the junction the SDC
    # pulls into stands beside the route until it is in the way: in the nuScenes window where the student drove into
    # one the slots left such an object out at 74% of the steps (`benchmarks/route_entry.py`; docs/learning.md,
    # session 63); its teacher forecasts 4 s ahead
    route_forecast_s: float = 0.0
    num_history: int = 5  # k steps of history per object (last = now)
    # how many of those steps the SDC sees of itself (None, or k and more: all k). A student that sees itself standing
    # learns to keep standing: its own history predicts its teacher's label better than the scene does
    sdc_history: int | None = None
    # the SDC's own length and width beside its history (two more columns of `Observation.sdc`): real SDCs range from
    # 4.1 x 1.7 m (nuScenes) to 5.3 x 2.3 m (the Waymo car); a student that cannot see its size keeps the margins of
    # the cars it trained in (docs/learning.md, session 48)
    sdc_size: bool = False
    # two more columns per object step: how far along the SDC's route ahead it is and how far across it
    # (`features.route_frame`); the per-object MLP then reads whether an object is in the SDC's way on a bend
    object_route_frame: bool = False
    max_distance: float = 50.0  # m, positions are divided by it
    max_speed: float = 30.0  # m/s, velocities and speed limits are divided by it
    max_size: float = 10.0  # m, box sizes are divided by it
    roadgraph_front: float = 50.0  # m ahead of the SDC
    roadgraph_back: float = 5.0  # m behind
    roadgraph_side: float = 20.0  # m to each side
    roadgraph_types: str = "edges+lanes+lines"  # key of ROADGRAPH_TYPE_SETS
    roadgraph_window: int = 5  # observation cells per side gathered around the box centre
    # None: every point of the window (window^2 * obs_slots_per_cell = 200 by default) with a mask,
    # no sort. A number: the in-box points are packed into that many slots (evenly thinned when
    # more); this costs ~4 us per scene-step on a CPU core, so give the map index more obs slots.
    num_roadgraph_points: int | None = None
    num_lights: int = 5
    num_path_targets: int = 10
    path_target_spacing: float = 5.0  # m along the route
    noise: NoiseConfig = NoiseConfig()

    def __post_init__(self):
        if self.object_selection not in OBJECT_SELECTIONS:
            raise ValueError(f"ObservationConfig.object_selection must be one of {OBJECT_SELECTIONS}, "
                             f"got {self.object_selection!r}")
        if self.route_selection_m is not None and not self.route_selection_m > 0:
            raise ValueError(f"ObservationConfig.route_selection_m must be None or positive, "
                             f"got {self.route_selection_m!r}")
        if self.route_far_slots < 0:
            raise ValueError(f"ObservationConfig.route_far_slots must be 0 or more, got {self.route_far_slots!r}")
        if not self.route_forecast_s >= 0:
            raise ValueError(f"ObservationConfig.route_forecast_s must be 0 or more, got {self.route_forecast_s!r}")
        if self.sdc_history is not None and self.sdc_history < 1:
            raise ValueError(f"ObservationConfig.sdc_history must be None or at least 1, got {self.sdc_history!r}")
        if self.roadgraph_types not in ROADGRAPH_TYPE_SETS:
            raise ValueError(f"ObservationConfig.roadgraph_types must be one of {sorted(ROADGRAPH_TYPE_SETS)}, "
                             f"got {self.roadgraph_types!r}")

    @property
    def num_object_slots(self) -> int:
        """How many objects an observation holds: num_objects, and route_far_slots with the route-first choice."""
        return self.num_objects + (self.route_far_slots if self.object_selection == "route" else 0)

    @property
    def route_near_targets(self) -> int:
        """How many route points the num_objects slots read: all route_selection_m's, or with route_far_slots the
        path targets' (the far slots read the rest)."""
        return self.num_path_targets if self.route_far_slots else self.route_selection_targets

    @property
    def route_selection_targets(self) -> int:
        """How many route points, path_target_spacing apart, the route-first slots read (route_selection_m's)."""
        if self.route_selection_m is None:
            return self.num_path_targets
        return max(math.ceil(self.route_selection_m / self.path_target_spacing), 1)

    @property
    def route_forecast_times(self) -> tuple[float, ...]:
        """The forecast times (s) at which an object may enter the route: ROUTE_FORECAST_STEP_S apart up to
        route_forecast_s (none when 0)."""
        count = math.floor(self.route_forecast_s / ROUTE_FORECAST_STEP_S + 1e-6)
        return tuple(ROUTE_FORECAST_STEP_S * (i + 1) for i in range(count))

    @property
    def roadgraph_type_ids(self) -> tuple[int, ...]:
        return ROADGRAPH_TYPE_SETS[self.roadgraph_types]


DEFAULT_OBSERVATION_CONFIG = ObservationConfig()
