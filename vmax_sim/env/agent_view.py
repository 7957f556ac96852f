"""An agent's view of a scene: the state with the SDC flag moved to the agent's slot and the agent's own path
(`SimulatorState.agent_paths`) as its only route, so every SDC-centred function (observation, metrics, reward,
the planners) serves any agent unchanged; the choice of which agents to drive; and their actions from a driver
(`AgentFn`, e.g. IDM in `vmax_sim.policies.traffic`) vmapped over the chosen slots (static count, no Python loop)
and scattered into one `Action`.

Used by reactive evaluation (rule or learned agents around the evaluated SDC), by self-play training
(`vmax_sim.env.selfplay`) and by IDM traffic while training (`LearningEnv(traffic=...)`). Everything works on
one unbatched state and is jittable.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, RoadgraphPoints, SimulatorState
from vmax_sim.env.metrics_adapter import sdc_index

MAX_STOP_SIGN_POINTS = 64  # stop-sign points handed to the agents' views (the nearest the SDC)

# (params, agent view, key) -> the agent's action (action_dim,) in the env's convention, and its validity ()
AgentFn = Callable[[object, SimulatorState, jax.Array], tuple[jax.Array, jax.Array]]


def check_agent_paths(state: SimulatorState, needed_by: str = "reactive evaluation") -> None:
    if state.agent_paths is None:
        raise ValueError(f"{needed_by} needs the agents' paths: load the data with "
                         "DataConfig(include_agent_paths=True)")


def choose_agents(state: SimulatorState, max_agents: int, timestep: int) -> tuple[jax.Array, jax.Array]:
    """The slots of the agents to drive: controllable, not the SDC, present at `timestep`, with a path;
    at most max_agents of them, nearest the SDC first. -> slots (K,) int32, valid (K,) bool, K = min(max_agents, N).
    """
    meta, log = state.object_metadata, state.log_trajectory
    present = log.valid[:, timestep]
    has_path = jnp.any(state.agent_paths.valid, axis=-1)
    eligible = meta.is_controllable & ~meta.is_sdc & present & has_path  # (N,)
    sdc = sdc_index(state)
    distance = jnp.hypot(log.x[:, timestep] - log.x[sdc, timestep], log.y[:, timestep] - log.y[sdc, timestep])
    k = min(max_agents, state.num_objects)
    _, slots = jax.lax.top_k(-jnp.where(eligible, distance, jnp.inf), k)
    return slots.astype(jnp.int32), eligible[slots]


def control_agents(state: SimulatorState, slots: jax.Array, valid: jax.Array,
                   bound: int | None = None) -> SimulatorState:
    """The state with the SDC and the agents in `slots` (K,) (where `valid`) marked controlled, so the dynamics
    move them from actions; bound: `max_controlled` (the dynamics then run on that many rows only), None for none."""
    num = state.num_objects
    driven = jnp.zeros(num, bool).at[jnp.where(valid, slots, num)].set(True, mode="drop")
    meta = state.object_metadata
    return state.replace(object_metadata=meta.replace(is_controlled=meta.is_sdc | driven, max_controlled=bound))


def agent_view(state: SimulatorState, slot: jax.Array, roadgraph: RoadgraphPoints | None = None) -> SimulatorState:
    """The state as the agent in `slot` sees it: it is "the SDC" and its own path is the only route
    (on_route). The real SDC becomes an ordinary object. roadgraph: replaces `roadgraph_points` (e.g.
    `stop_sign_points`). () slot -> SimulatorState (sdc_paths (1, Q))."""
    meta = state.object_metadata
    is_sdc = jnp.arange(state.num_objects) == slot
    own = jax.tree.map(lambda a: a[slot][None], state.agent_paths)  # (1, Q) fields, on_route (1,)
    own = own.replace(on_route=jnp.ones_like(own.on_route))
    view = state.replace(object_metadata=meta.replace(is_sdc=is_sdc), sdc_paths=own, agent_paths=None)
    return view if roadgraph is None else view.replace(roadgraph_points=roadgraph)


def with_sdc_route(state: SimulatorState) -> SimulatorState:
    """The state whose `agent_paths` row of the SDC holds the SDC's on-route path (cut or padded to the agent
    paths' length), so the SDC is one more agent with a route of its own (self-play). Without an on-route path
    the row stays as it was (invalid)."""
    paths, agents = state.sdc_paths, state.agent_paths
    length = agents.x.shape[-1]
    route = jnp.argmax(paths.on_route)  # the first on-route path
    has_route = jnp.any(paths.on_route)
    sdc = sdc_index(state)

    def row(full, own):  # (P, M), (N, Q) -> (N, Q) with the SDC's row replaced
        line = full[route]
        line = line[:length] if line.shape[-1] >= length else jnp.pad(line, (0, length - line.shape[-1]))
        return own.at[sdc].set(jnp.where(has_route, line.astype(own.dtype), own[sdc]))

    names = ("x", "y", "z", "ids", "valid", "arc_length")
    updated = {name: row(getattr(paths, name), getattr(agents, name)) for name in names}
    on_route = agents.on_route.at[sdc].set(has_route | agents.on_route[sdc])
    return state.replace(agent_paths=agents.replace(**updated, on_route=on_route))


def stop_sign_points(state: SimulatorState, max_points: int = MAX_STOP_SIGN_POINTS) -> RoadgraphPoints:
    """The roadgraph's stop-sign points (nearest the SDC first, at most max_points), as a small
    RoadgraphPoints: the only part of `roadgraph_points` the planners read (map queries go through the
    map index). Handing it to the agents' views keeps K agents from each scanning the whole roadgraph
    every step. -> RoadgraphPoints (max_points,)."""
    from scenariomax.schema import RG_STOP_SIGN

    rg = state.roadgraph_points
    sdc = sdc_index(state)
    t = state.timestep
    centre = jnp.stack([state.log_trajectory.x[sdc, t], state.log_trajectory.y[sdc, t]])
    is_sign = rg.valid & (rg.types == RG_STOP_SIGN)
    distance = jnp.hypot(rg.x - centre[0], rg.y - centre[1])
    k = min(max_points, rg.x.shape[-1])
    _, index = jax.lax.top_k(-jnp.where(is_sign, distance, jnp.inf), k)
    kept = jax.tree.map(lambda a: a[index], rg)
    return kept.replace(valid=is_sign[index])


def sdc_seen_only_the_same_way(state: SimulatorState, slot: jax.Array, min_cos: float) -> SimulatorState:
    """The state in which the SDC is invisible (invalid) to the agent in `slot` unless their headings differ by less
    than arccos(min_cos): an agent then brakes for an SDC ahead of it on its way, but crosses or meets one as its
    log does."""
    sim, sdc, t = state.sim_trajectory, sdc_index(state), state.timestep
    same_way = jnp.cos(sim.yaw[slot, t] - sim.yaw[sdc, t]) >= min_cos
    return state.replace(sim_trajectory=sim.replace(valid=sim.valid.at[sdc].set(sim.valid[sdc] & same_way)))


def agents_action(state: SimulatorState, slots: jax.Array, slot_valid: jax.Array, agent_fn: AgentFn, params,
                  key: jax.Array, action_dim: int, roadgraph: RoadgraphPoints | None = None,
                  sdc_seen_cos: float | None = None) -> Action:
    """Actions of the agents in `slots` (K,) (where slot_valid) from `agent_fn` on their views (`agent_view`,
    with `roadgraph` in them when given); every other row is zero and invalid. sdc_seen_cos: each agent sees the
    SDC only while heading within that cosine of it (`sdc_seen_only_the_same_way`); None: always.
    -> Action (N, action_dim)."""
    num = state.num_objects
    keys = jax.random.split(key, slots.shape[0])

    def view(slot):
        seen = state if sdc_seen_cos is None else sdc_seen_only_the_same_way(state, slot, sdc_seen_cos)
        return agent_view(seen, slot, roadgraph)

    data, valid = jax.vmap(lambda slot, k: agent_fn(params, view(slot), k))(slots, keys)
    target = jnp.where(slot_valid, slots, num)  # out of range: dropped by the scatter
    full = jnp.zeros((num, action_dim), jnp.float32).at[target].set(data.astype(jnp.float32), mode="drop")
    full_valid = jnp.zeros((num, 1), bool).at[target, 0].set(valid & slot_valid, mode="drop")
    return Action(data=full, valid=full_valid)
