"""Perturbed start (ChauffeurNet, Bansal et al. 2018): the SDC begins its episode off the log.

A lateral offset d ~ N(0, sigma) and a heading error psi ~ N(0, heading_sigma) (both clipped to
`max_sigmas`) are drawn per scenario. The SDC's simulated history over the last `num_steps` steps
before the first policy step is bent sideways along the logged path by a cubic Hermite blend in arc
length u = s / L (L = distance driven over the blend):

    o(u) = d (3u^2 - 2u^3) + m (u^3 - u^2),   m = L tan(psi)

so the offset starts at 0 with zero slope where the blend begins (the history before it is the
log's), reaches d at the first policy step with slope tan(psi), and heading and velocity turn by
atan(do/ds) at every step: the history is a smooth, drivable path, not a jump. An SDC that drove
less than `min_travel` over the blend (stopped) is shifted by d and turned by psi as a whole.

The first of `scales` (default 1, 0.5, 0.25, 0) whose start is on the road and clear of every other
object is used: a start that already collides or is off-road would score the same for every policy.
Only the simulated trajectory changes; the log (progress, log divergence) stays the recorded one.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.metrics_adapter import collision_now, offroad_now, sdc_index
from vmax_sim.evaluation.modes import PerturbConfig
from vmax_sim.metrics import MetricsConfig


def draw_perturbation(key: jax.Array, config: PerturbConfig) -> tuple[jax.Array, jax.Array]:
    """Lateral offset (m, + left) and heading error (rad) of one scenario. -> (), ()"""
    normal = jnp.clip(jax.random.normal(key, (2,)), -config.max_sigmas, config.max_sigmas)
    return config.sigma * normal[0], config.heading_sigma_rad * normal[1]


def blend_profile(arc: jax.Array, travel: jax.Array, offset: jax.Array,
                  heading: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Offset o and its slope do/ds of the Hermite blend at arc lengths `arc` (...) along a blend of
    length `travel` () ending at (offset, tan(heading)). -> (...), (...)."""
    length = jnp.maximum(travel, 1e-3)
    u = jnp.clip(arc / length, 0.0, 1.0)
    m = length * jnp.tan(heading)
    o = offset * (3 * u**2 - 2 * u**3) + m * (u**3 - u**2)
    do_du = offset * (6 * u - 6 * u**2) + m * (3 * u**2 - 2 * u)
    return o, do_du / length


def perturb_sdc(state: SimulatorState, offset: jax.Array, heading: jax.Array, config: PerturbConfig,
                first: int) -> SimulatorState:
    """The state with the SDC's simulated history up to step `first` bent to end `offset` m to the left of
    the log with a heading error `heading` (rad). One unbatched state; () offset, () heading."""
    sim, i = state.sim_trajectory, sdc_index(state)
    x, y, yaw, vx, vy, valid = sim.x[i], sim.y[i], sim.yaw[i], sim.vel_x[i], sim.vel_y[i], sim.valid[i]  # (T,)
    steps = jnp.arange(x.shape[0])
    start = max(first - config.num_steps, 0)
    seg = jnp.hypot(jnp.diff(x), jnp.diff(y))  # (T - 1,), step k -> k + 1
    counted = (steps[1:] > start) & (steps[1:] <= first) & valid[1:] & valid[:-1]
    arc = jnp.concatenate([jnp.zeros(1), jnp.cumsum(jnp.where(counted, seg, 0.0))])  # (T,) 0 until `start`
    travel = arc[first]
    moving = travel > config.min_travel
    o, slope = blend_profile(arc, travel, offset, heading)
    o = jnp.where(moving, o, offset)
    turn = jnp.where(moving, jnp.arctan(slope), heading)
    history = (steps <= first) & valid
    o, turn = jnp.where(history, o, 0.0), jnp.where(history, turn, 0.0)
    cos, sin = jnp.cos(turn), jnp.sin(turn)
    new = sim.replace(
        x=sim.x.at[i].set(x - o * jnp.sin(yaw)), y=sim.y.at[i].set(y + o * jnp.cos(yaw)),
        yaw=sim.yaw.at[i].set(yaw + turn),
        vel_x=sim.vel_x.at[i].set(cos * vx - sin * vy), vel_y=sim.vel_y.at[i].set(sin * vx + cos * vy))
    return state.replace(sim_trajectory=new)


def perturb_start(state: SimulatorState, key: jax.Array, config: PerturbConfig, first: int,
                  metrics_config: MetricsConfig) -> tuple[SimulatorState, dict]:
    """The reset state (timestep = first) with the SDC's start perturbed, at the largest of config.scales
    whose start neither overlaps another object nor is off-road (the smallest scale when none is).

    -> state, {"perturb_offset": |applied offset| m, "perturb_heading": |applied heading error| rad,
    "perturb_scale": the scale used} (() float32 each).
    """
    offset, heading = draw_perturbation(key, config)
    scales = jnp.asarray(config.scales, jnp.float32)

    def blocked(scale):
        moved = perturb_sdc(state, scale * offset, scale * heading, config, first)
        return collision_now(moved, metrics_config) | offroad_now(moved, metrics_config)

    ok = ~jax.vmap(blocked)(scales)
    ok = ok.at[-1].set(True)
    scale = scales[jnp.argmax(ok)]
    info = {"perturb_offset": jnp.abs(scale * offset), "perturb_heading": jnp.abs(scale * heading),
            "perturb_scale": scale}
    return perturb_sdc(state, scale * offset, scale * heading, config, first), info
