"""PDM-Closed's emergency brake as a guard over another driver's acceleration.

The brake: when the SDC's constant-velocity time to collision with an object ahead
(`vmax_sim.metrics.time_to_collision`) is below `ttc_s`, brake at `decel` (never so hard that the SDC would reverse
within the step), unless the driver already brakes harder. The thresholds are PDM-Closed's (`PDMConfig.emergency_ttc`,
`emergency_decel`); PDM-Closed's own brake (`vmax_sim.policies.pdm`) replaces its proposal's acceleration and checks
its 16 forecast objects, the guard keeps a harder braking of the driver's own and checks every object.

As a guard (`train.brake_guard_ttc`) it sits over a learned policy's acceleration: a student imitates its
teacher's plans but hardly its emergency brake, which fires at a few steps of a few scenes (docs/learning.md: at
nuScenes scene-0553 a student failed to brake at half of the 375 steps where its teacher did).

With `hold` the guard also looks at where the driver's acceleration leads: when the SDC would come within `ttc_s`
of an object ahead at the speed that acceleration reaches if held for `ttc_s`, the acceleration is capped at 0 (it
holds its speed; the brake still acts at the speed it has). PDM-Closed checks its proposals' forecast motion, not
only the speed it has: a student that creeps forward behind people crossing, or speeds up towards a car cutting in,
kept the time to collision of the speed it had and lost it one step later (docs/learning.md, session 79).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.dynamics.bicycle import DT
from vmax_sim.env.metrics_adapter import boxes_now, fields_now
from vmax_sim.metrics import time_to_collision
from vmax_sim.metrics.step import sdc_box_at
from vmax_sim.policies.pdm import PDMConfig
from vmax_sim.policies.route import Ego, ego_now


@dataclasses.dataclass(frozen=True)
class BrakeGuard:
    ttc_s: float = PDMConfig.emergency_ttc  # s; brake when the SDC's time to collision with an object ahead is below it
    decel: float = PDMConfig.emergency_decel  # m/s^2 of braking then
    # cap the acceleration at 0 where holding it for ttc_s would bring an object ahead within ttc_s
    hold: bool = False

    def __post_init__(self):
        if not self.ttc_s > 0 or not self.decel > 0:
            raise ValueError(f"a brake guard needs ttc_s > 0 and decel > 0, got {self.ttc_s} and {self.decel}")


def emergency_acceleration(ego: Ego, boxes: jax.Array, vel: jax.Array, valid: jax.Array, accel: jax.Array,
                           guard: BrakeGuard) -> jax.Array:
    """`accel` (m/s^2), or the guard's braking when the SDC at constant velocity would touch an object ahead within
    `guard.ttc_s` (with `guard.hold`: 0 at most where the speed `accel` reaches in `guard.ttc_s` would). boxes (K, 5)
    [x, y, length, width, yaw], vel (K, 2), valid (K,): the objects now -> ()."""
    ego_box = sdc_box_at(ego.xy, ego.yaw, jnp.stack([ego.length, ego.width]))
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    ttc = time_to_collision(ego_box, ego.speed * heading, boxes, vel, valid, guard.ttc_s)
    brake = jnp.maximum(-guard.decel, -jnp.maximum(ego.speed, 0.0) / DT)  # never reverse
    braked = jnp.where(ttc < guard.ttc_s, jnp.minimum(accel, brake), accel)
    if not guard.hold:
        return braked
    reached = jnp.maximum(ego.speed + accel * guard.ttc_s, 0.0)  # the speed the action leads to, held for ttc_s
    ttc_reached = time_to_collision(ego_box, reached * heading, boxes, vel, valid, guard.ttc_s)
    return jnp.where(ttc_reached < guard.ttc_s, jnp.minimum(braked, 0.0), braked)  # a braking `braked` stays


def guarded_acceleration(state: SimulatorState, accel: jax.Array, guard: BrakeGuard) -> jax.Array:
    """The SDC's acceleration `accel` (m/s^2) of one unbatched state after the guard, against every other object."""
    now = fields_now(state)  # (N,) fields
    vel = jnp.stack([now.vel_x, now.vel_y], -1).astype(jnp.float32)
    return emergency_acceleration(ego_now(state), boxes_now(now), vel, now.valid & ~state.object_metadata.is_sdc,
                                  accel, guard)


__all__ = ["BrakeGuard", "emergency_acceleration", "guarded_acceleration"]
