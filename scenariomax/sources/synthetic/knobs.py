"""`SyntheticKnobs`: randomisation knobs of the synthetic generator (traffic density, tracking noise, lane
widths, speed limits, driver styles, parked cars, where they park and how far they reach towards the lanes, how
the SDC starts, how junction lights are phased, slow and stalled drivers, the SDC's size, cones and barriers,
topology mix).

The defaults reproduce the generator exactly (same arrays, same random stream), so a source or a cache made
with default knobs is the one made before the knobs existed. Every knob widens or shifts a draw the
generator makes anyway; only the tracking noise, the slow and stalled drivers, the U-turns and the street objects draw
extra numbers, and only when on.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping

# The topologies the generator builds, in the order of its default weights (topologies.TOPOLOGIES).
TOPOLOGY_NAMES: tuple[str, ...] = ("straight", "curve", "intersection4", "intersection3", "merge", "lane_drop",
                                   "roundabout")
# `stalled_vehicles` above this leaves maps where no car moves, and so none to be the SDC
MAX_STALLED = 0.5
# The lane-width range every builder's draw is measured against (`rng.uniform(3.3, 3.8)`).
BASE_LANE_WIDTH_M: tuple[float, float] = (3.3, 3.8)


@dataclasses.dataclass(frozen=True)
class SyntheticKnobs:
    """How the synthetic scenes are randomised (the defaults are the generator as it always was)."""

    traffic_density: float = 1.0  # x vehicles: initial gaps / density, entry inflow x density (capped by MAX_MOVERS)
    position_noise_m: float = 0.0  # std of Gaussian tracking noise on logged x, y (all valid objects but the SDC)
    heading_noise_rad: float = 0.0  # std of Gaussian tracking noise on logged bbox_yaw (same objects)
    lane_width_m: tuple[float, float] = BASE_LANE_WIDTH_M  # range of lane widths (metres)
    speed_limit_scale: float = 1.0  # x every lane's speed limit
    driver_style_spread: float = 1.0  # x spread of driver traits around their centres (>1 more varied)
    parked_fraction: tuple[float, float] = (0.15, 0.5)  # range of the share of parking spots taken
    # the most parked cars in a scene: 14 (the default) keeps the first taken spots in road order, as the generator
    # always did; any other value keeps that many taken spots drawn at random along every strip
    max_parked: int = 14
    # chance that each side of each junction arm has a kerbside parking strip (real streets are lined with
    # parked cars up to the junction; the generator's junctions had none)
    junction_parking: float = 0.0
    # chance that a signalised four-way junction releases opposite approaches together (two phases, turns across the
    # oncoming lanes permitted, the junction's reservations ordering the crossings) instead of one approach at a time:
    # real traffic crosses close in front of a car that drives on green (a left turner, a late crosser), which the
    # split phases never show (the blind teacher driving has a vehicle crossing the corridor ahead at 0.2% of its
    # moving steps, 5.9% on real scenes; with every four-way junction paired 0.37%: docs/learning.md, session 46)
    paired_signals: float = 0.0
    # chance that each arm of a junction with 3 or more lanes each way has a U-turn lane, from its innermost incoming
    # lane round into its outermost outgoing one (a half circle of 1.5 lane widths' radius): real routes U-turn at
    # junctions (GPUDrive 2d84b1ab, one of the 29 judged real scenes, fails off-road in 28% of checkpoints) and the
    # generator drew none, so no student had seen one. Drawn only when on
    junction_uturns: float = 0.0
    # chance that the SDC is chosen among the cars that enter a U-turn lane during the episode; such a scene tries up
    # to MAX_ATTEMPTS fresh networks for one (a car U-turns in the episode in only ~1 junction map of 30). Drawn only
    # when on, after the other SDC rules
    sdc_uturn: float = 0.0
    # range of the metres each parked car stands nearer the lanes than its spot's centre (drawn per car, and cut
    # so that every vehicle the log drives past it keeps traffic.PARKED_CLEARANCE_M): real kerbside cars
    # reach towards the lane (a real route passes parked cars' centres at 1.5-2.5 m; the spots' centres are ~3 m
    # from the nearest lane centre). Drawn from a stream of its own: every other draw of the scene is unchanged
    parked_reach: tuple[float, float] = (0.0, 0.0)
    # range of the pedestrians who cross at each crosswalk during a scene (a whole number drawn uniformly in it;
    # real urban scenes have several people on foot near the SDC, the generator's about one)
    walkers_per_crosswalk: tuple[float, float] = (0.0, 2.0)
    # chance that the SDC is chosen among the candidates nearly at rest (< 2 m/s) at the current step, when there
    # are any (a queue or a light about to turn; a quarter to a half of real WOMD / nuScenes scenes start so)
    sdc_slow_start: float = 0.0
    # chance that the SDC is chosen among the candidates that stand for 3 s or more from the current step on (at a red,
    # a stop sign, in a queue) when there are any: real logged SDCs stand for a third of their steps, the generator's
    # for a tenth, and a driver that cannot see the light learns what to do there only where it stands
    sdc_waits: float = 0.0
    # chance that the SDC is chosen among the cars that stand (< 0.5 m/s) at every step from the current one on, when
    # there are any (at the head of, or in, a queue at a long red): nuScenes scene-0553's logged SDC waits its whole
    # 16 s while people and cars cross in front of it, and every other rule here picks a car that moves during the
    # episode, so a student never saw an SDC whose log stands throughout. Drawn only when on
    sdc_stands_through: float = 0.0
    # chance that a vehicle's driver crawls, wanting only SLOW_SPEED_FACTOR of the limit (a driver looking for a spot
    # or an address, a delivery van): the generator's drivers want 85-110% of the limit, so its slow leaders are
    # queues. Measured, the synthetic scenes do not lack slow leaders (benchmarks/crossing_traffic.py: real 3.7% of
    # the moving SDC steps within 30 m, the bc-dagger knobs 3.0%); off in the preset. Drawn after the driver's other
    # traits, only when on
    slow_vehicles: float = 0.0
    # chance (at most MAX_STALLED: beyond it whole maps stand still) that each vehicle on the road at the start stands
    # in its lane for the whole scene (broken down, or double-parked for a delivery: a car at rest on a real route's
    # centreline with no light or queue ahead of it, as in ScenarioNet WOMD 2a1e44d4, where the students run into its
    # back); the traffic behind it queues. Never on a crosswalk nor within traffic.STALL_CLEAR_M of a junction's gate.
    # Drawn after the driver's other traits, only when on
    stalled_vehicles: float = 0.0
    # chance that the SDC is chosen among the cars that come to rest behind a stalled vehicle in its lane during the
    # episode, when there are any (most scenes' SDC drives through a junction, away from the stalled cars)
    sdc_behind_stalled: float = 0.0
    # ranges of the SDC's box, length and width in metres (0:0 the body it drove with; one number a fixed size): every
    # WOMD-derived real record logs the Waymo car as 5.29 m x 2.33 m, nuScenes' as 4.08 x 1.73, AV2's as 4.5 x 2.0, and
    # the generator's cars are 4.0-5.2 x 1.8-2.1. One share of each range is drawn per scene for both (a long car is a
    # wide one), from a stream of its own. Set only where the logged SDC keeps clear of every other box with it (else
    # the scene keeps its own); a student learns a car's margins only where its observation shows the size
    # (`obs.sdc_size`)
    sdc_length_m: tuple[float, float] = (0.0, 0.0)
    sdc_width_m: tuple[float, float] = (0.0, 0.0)
    # range of the static objects of type other (traffic cones, barriers) standing along the road edges of a scene, a
    # whole number drawn uniformly in it: real nuScenes and AV2 scenes have several (a row of 17 barriers in
    # scene-0553, a cone 2 m beside the SDC's path in scene-0757), the generator had none, so a student never saw the
    # type. Placed clear of every logged box, from a stream of their own: every other draw of the scene is unchanged
    street_objects: tuple[float, float] = (0.0, 0.0)
    topology_weights: str = ""  # "intersection4:2,merge:1": relative weights (others 0); "" the default mix

    def __post_init__(self) -> None:
        # Normalise lists (JSON, config files) and single numbers of range knobs to tuples and integers to floats, so
        # equal knobs compare and describe (as_dict, cache names) alike.
        for field in dataclasses.fields(self):
            value, default = getattr(self, field.name), field.default
            if isinstance(default, tuple) and isinstance(value, (list, tuple, str, int, float)):
                object.__setattr__(self, field.name, _coerce(field.name, value, default))
            elif isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
                object.__setattr__(self, field.name, float(value))
            elif isinstance(default, int) and isinstance(value, float) and value.is_integer():
                object.__setattr__(self, field.name, int(value))
        _check_number("traffic_density", self.traffic_density, 0.0, 10.0, low_open=True)
        _check_number("position_noise_m", self.position_noise_m, 0.0, 5.0)
        _check_number("heading_noise_rad", self.heading_noise_rad, 0.0, 1.0)
        _check_range("lane_width_m", self.lane_width_m, 2.7, 5.0)
        _check_number("speed_limit_scale", self.speed_limit_scale, 0.5, 2.0)
        _check_number("driver_style_spread", self.driver_style_spread, 0.0, 3.0)
        _check_range("parked_fraction", self.parked_fraction, 0.0, 1.0)
        if isinstance(self.max_parked, bool) or not isinstance(self.max_parked, int) or not 0 <= self.max_parked <= 48:
            raise ValueError(f"synthetic knob max_parked: expected a whole number from 0 to 48, "
                             f"got {self.max_parked!r}")
        _check_number("junction_parking", self.junction_parking, 0.0, 1.0)
        _check_number("paired_signals", self.paired_signals, 0.0, 1.0)
        _check_number("junction_uturns", self.junction_uturns, 0.0, 1.0)
        _check_number("sdc_uturn", self.sdc_uturn, 0.0, 1.0)
        _check_number("stalled_vehicles", self.stalled_vehicles, 0.0, MAX_STALLED)
        _check_number("sdc_behind_stalled", self.sdc_behind_stalled, 0.0, 1.0)
        _check_range("parked_reach", self.parked_reach, 0.0, 2.0)
        _check_range("walkers_per_crosswalk", self.walkers_per_crosswalk, 0.0, 12.0)
        _check_number("sdc_slow_start", self.sdc_slow_start, 0.0, 1.0)
        _check_number("sdc_waits", self.sdc_waits, 0.0, 1.0)
        _check_number("sdc_stands_through", self.sdc_stands_through, 0.0, 1.0)
        _check_number("slow_vehicles", self.slow_vehicles, 0.0, 1.0)
        _check_range("sdc_length_m", self.sdc_length_m, 0.0, 8.0)
        _check_range("sdc_width_m", self.sdc_width_m, 0.0, 3.0)
        _check_range("street_objects", self.street_objects, 0.0, 64.0)
        if not isinstance(self.topology_weights, str):
            raise ValueError(f"synthetic knob topology_weights: expected text like 'intersection4:2,merge:1', "
                             f"got {self.topology_weights!r}")
        self.topology_probabilities()  # validates

    # --- construction and description ------------------------------------------------------------------
    @classmethod
    def from_dict(cls, values: Mapping) -> SyntheticKnobs:
        """Knobs from {name: value} (tuples may be lists or "lo:hi" / "lo,hi" text; numbers may be text)."""
        names = {f.name: f for f in dataclasses.fields(cls)}
        kwargs = {}
        for name, value in values.items():
            if name not in names:
                raise ValueError(f"unknown synthetic knob {name!r} (choose from {', '.join(names)})")
            kwargs[name] = _coerce(name, value, names[name].default)
        return cls(**kwargs)

    @classmethod
    def from_items(cls, items: Iterable[str], base: SyntheticKnobs | None = None) -> SyntheticKnobs:
        """Knobs from "name=value" strings (tuples as "lo:hi"), applied over `base` (default knobs)."""
        values = (base or cls()).as_dict()
        for item in items:
            name, sep, text = str(item).partition("=")
            if not sep or not name.strip():
                raise ValueError(f"synthetic knob {item!r} is not of the form NAME=VALUE")
            values[name.strip()] = text.strip()
        return cls.from_dict(values)

    def as_dict(self) -> dict:
        """JSON-ready {name: value} (tuples as lists)."""
        return {name: list(value) if isinstance(value, tuple) else value
                for name, value in dataclasses.asdict(self).items()}

    def is_default(self) -> bool:
        return self == SyntheticKnobs()

    # --- what the generator asks ---------------------------------------------------------------------
    def topology_probabilities(self) -> tuple[float, ...] | None:
        """Probabilities over TOPOLOGY_NAMES, or None for the generator's default mix."""
        text = self.topology_weights.strip()
        if not text:
            return None
        weights = dict.fromkeys(TOPOLOGY_NAMES, 0.0)
        for part in text.split(","):
            if not part.strip():
                continue
            name, sep, weight = part.partition(":")
            name = name.strip()
            if name not in weights:
                raise ValueError(f"synthetic knob topology_weights: unknown topology {name!r} "
                                 f"(choose from {', '.join(TOPOLOGY_NAMES)})")
            try:
                value = float(weight) if sep else 1.0
            except ValueError:
                raise ValueError(f"synthetic knob topology_weights: bad weight {weight.strip()!r} for {name}") \
                    from None
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"synthetic knob topology_weights: weight of {name} must be >= 0, got {value}")
            weights[name] = value
        total = sum(weights.values())
        if total <= 0:
            raise ValueError("synthetic knob topology_weights: at least one weight must be > 0")
        return tuple(w / total for w in weights.values())

    def lane_width(self, draw: float) -> float:
        """A builder's lane-width draw (made on the 3.3-3.8 m scale) mapped linearly onto `lane_width_m`.
        Builders with their own range on that scale (merge 3.4-3.8, roundabout 3.5-4.0) keep their place
        relative to it."""
        if self.lane_width_m == BASE_LANE_WIDTH_M:
            return draw
        (lo, hi), (base_lo, base_hi) = self.lane_width_m, BASE_LANE_WIDTH_M
        return lo + (draw - base_lo) * (hi - lo) / (base_hi - base_lo)

    def sdc_box(self, share: float) -> tuple[float, float]:
        """The SDC's length and width at `share` (0-1) of their ranges; 0 for a dimension whose knob is 0:0."""
        return tuple(lo + share * (hi - lo) for lo, hi in (self.sdc_length_m, self.sdc_width_m))

    def spread(self, draw: float, centre: float, limits: tuple[float, float]) -> float:
        """A driver trait drawn as usual, its distance from `centre` scaled by `driver_style_spread` and
        clipped to `limits` (agents.VEHICLE_TRAITS)."""
        if self.driver_style_spread == 1.0:
            return draw
        return float(min(max(centre + (draw - centre) * self.driver_style_spread, limits[0]), limits[1]))


def _check_number(name: str, value, low: float, high: float, low_open: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < low or value > high or (low_open and value == low):
        bound = f"> {low:g}" if low_open else f">= {low:g}"
        raise ValueError(f"synthetic knob {name}: expected a number {bound} and <= {high:g}, got {value!r}")


def _check_range(name: str, value, low: float, high: float) -> None:
    if not (isinstance(value, tuple) and len(value) == 2 and all(math.isfinite(v) for v in value)
            and low <= value[0] <= value[1] <= high):
        shown = ":".join(f"{v:g}" for v in value) if isinstance(value, tuple) else repr(value)
        raise ValueError(f"synthetic knob {name}: expected lo:hi with {low:g} <= lo <= hi <= {high:g}, got {shown}")


def _coerce(name: str, value, default):
    """`value` as the type of the knob's default (text from a command line or an override is parsed)."""
    try:
        if isinstance(default, tuple):
            if isinstance(value, str):
                parts = value.replace(",", ":").split(":")
                if len(parts) == 1:  # a single number: a fixed value
                    parts = parts * 2
                value = parts
            elif isinstance(value, (int, float)) and not isinstance(value, bool):  # a fixed value (older configs)
                value = (value, value)
            return tuple(float(v) for v in value)
        if isinstance(value, bool):
            raise ValueError
        if isinstance(default, float):
            return float(value)
        if isinstance(default, int):
            number = float(value)
            if not number.is_integer():
                raise ValueError
            return int(number)
        return str(value)
    except (TypeError, ValueError):
        kind = "lo:hi (two numbers)" if isinstance(default, tuple) else "a number" if isinstance(default, float) \
            else "a whole number" if isinstance(default, int) else "text"
        raise ValueError(f"synthetic knob {name}: expected {kind}, got {value!r}") from None


DEFAULT_KNOBS = SyntheticKnobs()
