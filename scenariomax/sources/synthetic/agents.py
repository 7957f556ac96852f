"""Who is on the road: body sizes and driver traits drawn from an rng."""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.schema import OBJECT_TYPE_CYCLIST, OBJECT_TYPE_OTHER, OBJECT_TYPE_PEDESTRIAN, OBJECT_TYPE_VEHICLE
from scenariomax.sources.synthetic.knobs import DEFAULT_KNOBS, SyntheticKnobs


@dataclasses.dataclass(frozen=True)
class Body:
    object_type: int  # enum object_type
    length: float  # metres
    width: float
    height: float


@dataclasses.dataclass(frozen=True)
class Driver:
    speed_factor: float  # desired speed / speed limit
    max_accel: float  # m/s^2 (IDM a)
    comfort_decel: float  # m/s^2 (IDM b)
    time_headway: float  # s (IDM T)


def vehicle_body(rng: np.random.Generator, allow_trucks: bool = True) -> Body:
    if allow_trucks and rng.random() < 0.08:
        return Body(OBJECT_TYPE_VEHICLE, float(rng.uniform(6.0, 8.0)), float(rng.uniform(2.3, 2.5)),
                    float(rng.uniform(2.8, 3.5)))
    return Body(OBJECT_TYPE_VEHICLE, float(np.clip(rng.normal(4.6, 0.3), 3.9, 5.2)),
                float(rng.uniform(1.8, 2.1)), float(rng.uniform(1.45, 1.8)))


def parked_body(rng: np.random.Generator) -> Body:
    return Body(OBJECT_TYPE_VEHICLE, float(np.clip(rng.normal(4.5, 0.3), 3.8, 5.0)),
                float(rng.uniform(1.75, 2.0)), float(rng.uniform(1.45, 1.8)))


def cyclist_body(rng: np.random.Generator) -> Body:
    return Body(OBJECT_TYPE_CYCLIST, float(rng.uniform(1.7, 1.9)), float(rng.uniform(0.6, 0.8)),
                float(rng.uniform(1.6, 1.9)))


def pedestrian_body(rng: np.random.Generator) -> Body:
    return Body(OBJECT_TYPE_PEDESTRIAN, float(rng.uniform(0.5, 0.7)), float(rng.uniform(0.5, 0.7)),
                float(rng.uniform(1.5, 1.9)))


def cone_body(rng: np.random.Generator) -> Body:
    """A traffic cone or bollard (real nuScenes cones are logged 0.3-0.65 m a side)."""
    side = float(rng.uniform(0.3, 0.7))
    return Body(OBJECT_TYPE_OTHER, side, side * float(rng.uniform(0.9, 1.1)), float(rng.uniform(0.5, 1.1)))


def barrier_body(rng: np.random.Generator) -> Body:
    """A road barrier, logged as real nuScenes ones are: 0.4-0.55 m long along its heading, 2.9-3.6 m wide."""
    return Body(OBJECT_TYPE_OTHER, float(rng.uniform(0.35, 0.55)), float(rng.uniform(2.8, 3.6)),
                float(rng.uniform(0.8, 1.1)))


# A vehicle driver's traits, in Driver's order: the range each is drawn from, and the floor and ceiling
# that keep it physically sensible when knobs.driver_style_spread widens the spread around the range's centre.
VEHICLE_TRAITS: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = (
    ((0.85, 1.1), (0.3, 1.6)),  # speed_factor
    ((1.5, 2.5), (0.5, 4.0)),  # max_accel
    ((1.8, 2.6), (0.8, 5.0)),  # comfort_decel
    ((1.0, 1.8), (0.3, 3.5)),  # time_headway
)


# `slow_vehicles`: the desired speed of a crawling driver, as a share of the limit (2-4 m/s: routes.MIN_DESIRED_SPEED)
SLOW_SPEED_FACTOR: tuple[float, float] = (0.1, 0.3)


def vehicle_driver(rng: np.random.Generator, knobs: SyntheticKnobs = DEFAULT_KNOBS) -> Driver:
    draws = [float(rng.uniform(*drawn)) for drawn, _ in VEHICLE_TRAITS]
    driver = Driver(*(knobs.spread(draw, sum(drawn) / 2, limits)
                      for draw, (drawn, limits) in zip(draws, VEHICLE_TRAITS)))
    if knobs.slow_vehicles > 0 and rng.random() < knobs.slow_vehicles:  # no draw when off: the default stream stays
        driver = dataclasses.replace(driver, speed_factor=float(rng.uniform(*SLOW_SPEED_FACTOR)))
    return driver


def cyclist_driver(rng: np.random.Generator, speed_limit: float) -> Driver:
    # Cyclists ride at 4-6.5 m/s whatever the limit: express that as a factor of the limit.
    return Driver(float(rng.uniform(4.0, 6.5)) / max(speed_limit, 1.0), 1.0, 1.5, 1.0)
