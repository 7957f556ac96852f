"""Adversarial agent (ReGentS-style, Yin et al. 2024): one logged vehicle is re-planned to cut in on the SDC.

Per scenario, after reset:
1. Candidates: vehicles present at the first policy step, not the SDC, not reversing, ranked by how close
   their logged future comes to the SDC's logged future (the object most likely to interact first);
   the `num_candidates` nearest are attacked in parallel (one vmap).
2. Each candidate's future is a sequence of bicycle actions (acceleration, curvature), initialised from
   its own log (inverse dynamics) and optimised with Adam by gradient through the bicycle rollout: a
   soft minimum over time of its distance to the SDC's logged position, counted only from
   `min_contact_step` on (the SDC gets time to react) and inflated while the adversary is behind the SDC
   (no rear-end attacks), plus a small pull towards the logged actions.
3. After every gradient step the actions are projected onto the kinematic bounds, in time order:
   |acceleration| within [-max_decel, max_accel], speed in [0, max_speed], |curvature| <= max_curvature,
   lateral acceleration v^2 |k| <= max_lateral_accel, and |k_t - k_(t-1)| <= max_curvature_rate per step
   (no swinging turns). The acceleration is also capped so that the speed never outgrows the curvature
   the rate limit can still unwind, so every bound holds together (tested on the written trajectories).
4. An attack is kept when the planned box overlaps the SDC's logged box at some step >= min_contact_step,
   the adversary is not behind the SDC there (a rear-end attack is rejected) and it touches no other
   logged object before that step. The first kept candidate in rank order replaces its log from the first
   policy step on; the others replay their logs. No kept attack leaves the scenario as it was.

The attack aims at the SDC's log (the evaluated policy is not differentiated): a policy that drives like
the log meets the cut-in; one that brakes or swerves in time avoids it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from scenariomax.schema import OBJECT_TYPE_VEHICLE
from vmax_sim.datatypes import SimulatorState
from vmax_sim.datatypes.trajectory import STEP_MICROS, Trajectory
from vmax_sim.dynamics.bicycle import DT, bicycle_forward, bicycle_inverse, heading_speed
from vmax_sim.env.metrics_adapter import sdc_index
from vmax_sim.evaluation.modes import AdversaryConfig
from vmax_sim.geometry.boxes import boxes_overlap

_FAR = 1e4  # m, the distance of a step that does not count


def project_actions(actions: jax.Array, speed0: jax.Array, curvature0: jax.Array, max_speed: jax.Array,
                    config: AdversaryConfig) -> jax.Array:
    """The actions (S, 2) [accel, curvature] moved onto the kinematic bounds in time order, from the start
    speed speed0 () >= 0 and curvature curvature0 () (see the module docstring). -> (S, 2)"""
    rate, lateral = config.max_curvature_rate, config.max_lateral_accel

    def step(carry, action):
        speed, previous = carry
        # the fastest speed at which the curvature can still be unwound to within the lateral bound
        unwind = jnp.sqrt(lateral / jnp.maximum(jnp.abs(previous) - rate, 1e-6))
        top = jnp.maximum(jnp.minimum(max_speed, unwind), speed)  # never forced to brake harder than allowed
        accel = jnp.clip(action[0], -config.max_decel, config.max_accel)
        accel = jnp.clip(accel, -speed / DT, (top - speed) / DT)
        new_speed = speed + accel * DT
        fastest = jnp.maximum(speed, new_speed)
        bound = jnp.minimum(config.max_curvature, lateral / jnp.maximum(fastest**2, 1e-6))
        low, high = jnp.maximum(previous - rate, -bound), jnp.minimum(previous + rate, bound)
        curvature = jnp.clip(action[1], low, jnp.maximum(high, low))
        return (new_speed, curvature), jnp.stack([accel, curvature])

    _, projected = jax.lax.scan(step, (speed0, curvature0), actions)
    return projected


def rollout_poses(actions: jax.Array, start: Trajectory) -> tuple[jax.Array, ...]:
    """Bicycle rollout of one object from its start state `start` (1, 1). actions (S, 2) -> x, y, yaw, speed,
    each (S,) after each step."""
    def step(current, action):
        new = bicycle_forward(action[None], current)
        return new, (new.x[0, 0], new.y[0, 0], new.yaw[0, 0], heading_speed(new)[0, 0])

    _, poses = jax.lax.scan(step, start, actions)
    return poses


def _future(values: jax.Array, steps: jax.Array) -> jax.Array:
    return jnp.take(values, steps, axis=-1)


def _candidates(state: SimulatorState, first: int, steps: jax.Array, config: AdversaryConfig):
    """Slots (K,) of the vehicles whose logged future comes nearest the SDC's, and whether each is usable."""
    log, meta = state.log_trajectory, state.object_metadata
    sdc = sdc_index(state)
    now = jax.tree.map(lambda a: a[:, first], log)
    valid = _future(log.valid, steps) & _future(log.valid[sdc], steps)[None]  # (N, S)
    gap = jnp.hypot(_future(log.x, steps) - _future(log.x[sdc], steps)[None],
                    _future(log.y, steps) - _future(log.y[sdc], steps)[None])
    closest = jnp.min(jnp.where(valid, gap, jnp.inf), axis=-1)  # (N,)
    eligible = ((meta.object_types == OBJECT_TYPE_VEHICLE) & ~meta.is_sdc & now.valid
                & (heading_speed(now) > -0.5) & (closest < config.search_radius))
    k = min(config.num_candidates, state.num_objects)
    score, slots = jax.lax.top_k(-jnp.where(eligible, closest, jnp.inf), k)
    return slots.astype(jnp.int32), jnp.isfinite(score)


def _logged_actions(state: SimulatorState, slot: jax.Array, first: int, num_steps: int) -> jax.Array:
    """The candidate's logged actions over the episode (inverse dynamics; zeros where its log ends). (S, 2)"""
    row = jax.tree.map(lambda a: a[slot][None], state.log_trajectory)  # (1, T)
    current = jnp.minimum(first + jnp.arange(num_steps), row.x.shape[-1] - 2)  # (S,) steps with a next one
    actions = jax.vmap(lambda t: bicycle_inverse(row, t)[0])(current)  # (S, 2)
    ok = row.valid[0, current] & row.valid[0, current + 1]
    return jnp.where(ok[:, None], actions, 0.0)


def _attack_one(state: SimulatorState, slot: jax.Array, usable: jax.Array, first: int, num_steps: int,
                config: AdversaryConfig):
    """Plans one candidate's cut-in. -> x, y, yaw, speed (S,) of the plan, and the checks: {"reaches": it
    overlaps the SDC's log from min_contact_step on, "rear_end": from behind, "hits_other": it touches another
    object first, "kept": reaches and neither, "contact": the first overlapping step (0-based)} (() each)."""
    log = state.log_trajectory
    sdc = sdc_index(state)
    last = log.x.shape[-1] - 1
    steps = jnp.minimum(first + 1 + jnp.arange(num_steps), last)  # (S,) the episode's future steps
    target_valid = _future(log.valid[sdc], steps) & (first + 1 + jnp.arange(num_steps) <= last)
    tx, ty, tyaw = (_future(getattr(log, k)[sdc], steps) for k in ("x", "y", "yaw"))
    sdc_length = log.length[sdc, first]
    now = jax.tree.map(lambda a: a[slot, first], log)
    speed0 = jnp.maximum(heading_speed(now), 0.0)
    start = jax.tree.map(lambda a: a[None, None], now.replace(vel_x=speed0 * jnp.cos(now.yaw),
                                                               vel_y=speed0 * jnp.sin(now.yaw)))
    logged = _logged_actions(state, slot, first, num_steps)
    curvature0 = bicycle_inverse(jax.tree.map(lambda a: a[slot][None], log), max(first - 1, 0))[0, 1]
    curvature0 = jnp.clip(curvature0, -config.max_curvature, config.max_curvature)
    curvature0 = jnp.clip(curvature0, -config.max_lateral_accel / jnp.maximum(speed0**2, 1e-6),
                          config.max_lateral_accel / jnp.maximum(speed0**2, 1e-6))
    logged_speed = jnp.where(log.valid[slot], heading_speed(log)[slot], 0.0)
    max_speed = jnp.maximum(config.speed_factor * jnp.max(logged_speed), config.min_max_speed)
    max_speed = jnp.maximum(max_speed, speed0)
    counted = target_valid & (jnp.arange(num_steps) >= config.min_contact_step - 1)
    scale = jnp.asarray([config.max_accel, config.max_curvature])

    def feasible(raw):
        return project_actions(raw * scale, speed0, curvature0, max_speed, config)

    init = feasible(logged / scale) / scale

    def loss(raw):
        actions = feasible(raw)
        x, y, _, _ = rollout_poses(actions, start)
        along = (x - tx) * jnp.cos(tyaw) + (y - ty) * jnp.sin(tyaw)  # adversary ahead (+) of the SDC
        behind = jax.nn.relu(-along - 0.5 * sdc_length)
        gap = jnp.hypot(x - tx, y - ty) + config.rear_penalty * behind
        gap = jnp.where(counted, gap, _FAR)
        soft_min = -config.softmin_temperature * jax.nn.logsumexp(-gap / config.softmin_temperature)
        keep_close = jnp.mean(jnp.square(actions / scale - logged / scale))
        return soft_min + config.log_weight * keep_close

    optimiser = optax.adam(config.learning_rate)

    def iteration(carry, _):
        raw, opt_state = carry
        grads = jax.grad(loss)(raw)
        updates, opt_state = optimiser.update(grads, opt_state)
        raw = feasible(optax.apply_updates(raw, updates)) / scale  # stay on the feasible set
        return (raw, opt_state), None

    (raw, _), _ = jax.lax.scan(iteration, (init, optimiser.init(init)), None, length=config.iterations)
    actions = feasible(raw)
    x, y, yaw, speed = rollout_poses(actions, start)

    # keep the attack only if it reaches the SDC (not from behind) without hitting anyone first
    size = jnp.stack([log.length[slot, first], log.width[slot, first]])
    boxes = jnp.stack([x, y, jnp.full_like(x, size[0]), jnp.full_like(x, size[1]), yaw], -1)  # (S, 5)
    sdc_boxes = jnp.stack([tx, ty, _future(log.length[sdc], steps), _future(log.width[sdc], steps), tyaw], -1)
    touching = boxes_overlap(boxes, sdc_boxes) & counted  # (S,)
    contact = jnp.argmax(touching)
    along = (x[contact] - tx[contact]) * jnp.cos(tyaw[contact]) + (y[contact] - ty[contact]) * jnp.sin(tyaw[contact])
    rear_end = along < -0.5 * sdc_length
    others = jnp.stack([_future(getattr(log, k), steps) for k in ("x", "y", "length", "width", "yaw")], -1)  # (N,S,5)
    other_valid = _future(log.valid, steps) & (jnp.arange(log.x.shape[0]) != slot)[:, None] & (
        jnp.arange(log.x.shape[0]) != sdc)[:, None]
    hits_other = jnp.any(boxes_overlap(boxes[None], others) & other_valid & (jnp.arange(num_steps) <= contact)[None])
    reaches = usable & jnp.any(touching)
    checks = {"reaches": reaches, "rear_end": reaches & rear_end, "hits_other": reaches & hits_other,
              "kept": reaches & ~rear_end & ~hits_other, "contact": contact.astype(jnp.int32)}
    return x, y, yaw, speed, checks


def plan_adversary(state: SimulatorState, config: AdversaryConfig, first: int,
                   num_steps: int) -> tuple[SimulatorState, dict]:
    """The reset state (timestep = first) with one vehicle's future replaced by a cut-in on the SDC, when one
    is found (see the module docstring). One unbatched state.

    -> state, {"adversary_found": 0/1, "adversary_contact_step": planned contact (policy step, 1-based; 0
    when none), "adversary_slot": the object slot (-1 when none), "adversary_candidates": vehicles attacked,
    "adversary_rear_end": 0/1, some candidate reached the SDC only from behind (rejected),
    "adversary_hits_other": 0/1, some candidate hit another object first (rejected)} (() float32 each).
    """
    last = state.num_timesteps - 1
    steps = jnp.minimum(first + 1 + jnp.arange(num_steps), last)
    slots, usable = _candidates(state, first, steps, config)
    x, y, yaw, speed, checks = jax.vmap(
        lambda slot, ok: _attack_one(state, slot, ok, first, num_steps, config))(slots, usable)
    kept, contact = checks["kept"], checks["contact"]
    found = jnp.any(kept)
    pick = jnp.argmax(kept)  # the first kept candidate in rank order
    slot = slots[pick]
    log = state.log_trajectory
    inside = (first + 1 + jnp.arange(num_steps)) <= last  # steps past the log's end are dropped
    where = jnp.where(inside, steps, state.num_timesteps)  # an out-of-range index: dropped by mode="drop"

    def written(values, new):
        row = values[slot].at[where].set(new.astype(values.dtype), mode="drop")
        return jnp.where(found, values.at[slot].set(row), values)

    start_time = log.timestamp_micros[slot, first]
    new_log = log.replace(
        x=written(log.x, x[pick]), y=written(log.y, y[pick]), yaw=written(log.yaw, yaw[pick]),
        vel_x=written(log.vel_x, speed[pick] * jnp.cos(yaw[pick])),
        vel_y=written(log.vel_y, speed[pick] * jnp.sin(yaw[pick])),
        z=written(log.z, jnp.full(num_steps, log.z[slot, first])),
        length=written(log.length, jnp.full(num_steps, log.length[slot, first])),
        width=written(log.width, jnp.full(num_steps, log.width[slot, first])),
        height=written(log.height, jnp.full(num_steps, log.height[slot, first])),
        valid=written(log.valid, jnp.ones(num_steps, bool)),
        timestamp_micros=written(log.timestamp_micros,
                                 start_time + STEP_MICROS * (1 + jnp.arange(num_steps, dtype=jnp.int32))))
    info = {"adversary_found": found.astype(jnp.float32),
            "adversary_contact_step": jnp.where(found, contact[pick] + 1, 0).astype(jnp.float32),
            "adversary_slot": jnp.where(found, slot, -1).astype(jnp.float32),
            "adversary_candidates": jnp.sum(usable).astype(jnp.float32),
            "adversary_rear_end": jnp.any(checks["rear_end"]).astype(jnp.float32),
            "adversary_hits_other": jnp.any(checks["hits_other"]).astype(jnp.float32)}
    return state.replace(log_trajectory=new_log), info
