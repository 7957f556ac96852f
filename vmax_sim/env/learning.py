"""`LearningEnv`: the one place a training loop gets reset / step / observe / reward, over a batch.

The SDC is driven by the policy (actions in [-1, 1], mapped onto the dynamics' bounds). Every other
object replays the log, or (`traffic`, e.g. `vmax_sim.policies.traffic.idm_traffic`) up to `traffic_agents`
controllable agents nearest the SDC follow their own paths with that driver, so traffic reacts to a learner
that drives differently from the logged SDC (a log-replayed follower drives into a learner that brakes).
Each step computes the metrics once and derives from them the reward, the termination (collision /
off-road / red light, as `EnvConfig.terminate_on`), the truncation (episode length or end of the log)
and the next observation, which reuses the metrics' candidate objects and
path projection. Finished episodes restart on the next scenario of a device-side pool (auto-reset);
the transition of the finishing step keeps the true last observation, so a time-limit truncation
can be bootstrapped while a crash is not.

Everything is pure and jittable; `reset` and `step` take the pool as an argument so the host can
swap fresh scenarios into it between jitted chunks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.datatypes import RoadgraphPoints, SimulatorState, sdc_action
from vmax_sim.env.agent_view import (
    AgentFn,
    agents_action,
    check_agent_paths,
    choose_agents,
    control_agents,
    stop_sign_points,
)
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.environment import Environment
from vmax_sim.env.metrics_adapter import reference_arcs, sdc_index, sdc_observation, step_inputs
from vmax_sim.env.multi_agent import sdc_and_agents_action
from vmax_sim.metrics import MetricsConfig, SharedQueries, shared_queries, step_metrics
from vmax_sim.observation import Observation, ObservationConfig
from vmax_sim.rewards import RewardConfig, check_reward_config, compute_reward

# Termination names of EnvConfig.terminate_on -> the step metric that decides them (same rules as
# vmax_sim.env.metrics_adapter.termination_fns, read from the metrics the step computed anyway).
TERMINATION_METRICS = {"collision": "overlap", "offroad": "offroad", "red_light": "red_light"}
# Per-episode indicators reported when an episode ends (any step of the episode).
EPISODE_FLAGS = ("overlap", "offroad", "red_light", "off_route", "wrong_way", "at_fault_collision")


@struct.dataclass
class TrafficAgents:
    """The agents the traffic driver drives in one episode, chosen when it starts."""

    slots: jax.Array  # (K,) int32, object slots, nearest the SDC first
    valid: jax.Array  # (K,) bool, a slot holds a driven agent
    signs: RoadgraphPoints  # (S,) the roadgraph's stop-sign points the agents see (`stop_sign_points`)


@struct.dataclass
class LearningState:
    sim: SimulatorState  # (B, ...) the running episodes
    arcs: jax.Array  # (B, P, 2) float32, logged start / end arcs along the SDC paths (`reference_arcs`)
    shared: SharedQueries  # (B, ...) this step's candidate objects and path projection
    metrics: dict  # name -> (B,) float32, `step_metrics` of the current step (the progress term compares)
    observation: Observation  # (B, ...) the policy's input now
    episode_return: jax.Array  # (B,) float32, reward summed since the episode started
    episode_length: jax.Array  # (B,) int32, policy steps since the episode started
    episode_flags: dict  # name -> (B,) bool, EPISODE_FLAGS seen so far in the episode
    next_scenario: jax.Array  # () int32, pool index of the next episode to start
    key: jax.Array  # PRNG key for observation noise
    traffic: TrafficAgents | None = None  # (B, ...) the driven agents (LearningEnv.traffic given), else None


@struct.dataclass
class StepOutput:
    """One batched step of experience (the learner's Transition is built from it)."""

    observation: Observation  # (B, ...) before the step
    action: jax.Array  # (B, A) float32 in [-1, 1], what was applied
    expert_action: jax.Array  # (B, A) float32 in [-1, 1], the label at the same state (teacher's or log-following)
    reward: jax.Array  # (B,) float32
    terminated: jax.Array  # (B,) bool, collision / off-road / red light ended the episode
    truncated: jax.Array  # (B,) bool, time limit or end of log (and not terminated)
    next_observation: Observation  # (B, ...) after the step, before any reset (the true last one)
    episode_return: jax.Array  # (B,) float32, the finished episode's return where done, else 0
    episode_length: jax.Array  # (B,) int32, likewise
    episode_flags: dict  # name -> (B,) bool, likewise (EPISODE_FLAGS)
    episode_progress: jax.Array  # (B,) float32, progress ratio at the end of finished episodes

    @property
    def done(self) -> jax.Array:
        return self.terminated | self.truncated


@dataclasses.dataclass(frozen=True)
class LearningEnv:
    """Batched learning environment over SDC-controlled episodes (see the module docstring)."""

    env_config: EnvConfig = EnvConfig()
    obs_config: ObservationConfig = ObservationConfig()
    reward_config: RewardConfig = RewardConfig()
    metrics_config: MetricsConfig = MetricsConfig()
    # compute the log-following action at every step (BC labels; BC+SAC's imitation term); learners that
    # never read StepOutput.expert_action skip that work and get zeros
    expert_labels: bool = True
    # simulator steps each policy action is held for (one transition; rewards summed, an episode that ends
    # within them stops there): at 10 Hz one action barely changes the future, so a critic learns little
    # about it (docs/learning.md)
    action_repeat: int = 1
    # who drives the other objects: None (they replay the log) or a factory (core Environment) -> AgentFn of the
    # agents' driver (`vmax_sim.policies.traffic.idm_traffic`); the env floor cannot import the planners
    traffic: Callable[[Environment], AgentFn] | None = None
    traffic_agents: int = 8  # with traffic: at most this many agents are driven, the rest replay the log
    # with traffic: the agents see the SDC only while heading within this cosine of it (they follow a learner that
    # brakes, and cross or meet it as their log does, as evaluation's replayed traffic does); None: always
    traffic_sees_sdc_cos: float | None = None
    # who labels the SDC's steps (StepOutput.expert_action, what BC imitates): None (the log-following action) or
    # a factory (core Environment) -> the teacher, one state -> (A,) in [-1, 1] (`vmax_sim.policies.teacher`)
    teacher: Callable[[Environment], Callable[[SimulatorState], jax.Array]] | None = None

    def __post_init__(self) -> None:
        if self.env_config.controlled != "sdc":
            raise ValueError("LearningEnv drives the SDC only: EnvConfig.controlled must be 'sdc'")
        check_learning_settings(self.env_config, self.reward_config, self.action_repeat)
        if self.traffic_agents < 1:
            raise ValueError(f"traffic_agents must be at least 1, got {self.traffic_agents}")
        config = dataclasses.replace(self.env_config, normalize_actions=True)  # policies act in [-1, 1]
        object.__setattr__(self, "env_config", config)
        object.__setattr__(self, "core", Environment(config))
        if self.traffic is not None:
            object.__setattr__(self, "_agent_fn", self.traffic(self.core))
        if self.teacher is not None:
            object.__setattr__(self, "_teacher_fn", self.teacher(self.core))

    @property
    def action_dim(self) -> int:
        return self.core.action_dim

    # ------------------------------------------------------------------ one scene (vmapped below)

    def _measure(self, sim: SimulatorState, arcs: jax.Array):
        """This step's shared queries and metrics of one scene."""
        inputs = step_inputs(sim, arcs)
        shared = shared_queries(inputs, self.metrics_config)
        return shared, step_metrics(sim.map_index, inputs, self.metrics_config, shared)

    def _start(self, sim: SimulatorState):
        """Reset one scene: state, arcs, shared queries, metrics, observation, traffic agents (or None)."""
        sim = self.core.reset(sim)
        sim, traffic = self._choose_traffic(sim)
        arcs = reference_arcs(sim, self.env_config)
        shared, metrics = self._measure(sim, arcs)
        return sim, arcs, shared, metrics, sdc_observation(sim, shared, self.obs_config), traffic

    def _choose_traffic(self, sim: SimulatorState) -> tuple[SimulatorState, TrafficAgents | None]:
        """With traffic: the agents to drive this episode, marked controlled (the dynamics move them)."""
        if self.traffic is None:
            return sim, None
        slots, valid = choose_agents(sim, self.traffic_agents, self.env_config.first_policy_timestep)
        sim = control_agents(sim, slots, valid, bound=1 + slots.shape[0])
        return sim, TrafficAgents(slots=slots, valid=valid, signs=stop_sign_points(sim))

    def _full_action(self, sim: SimulatorState, action: jax.Array, traffic: TrafficAgents | None, key: jax.Array):
        """The SDC's action (A,) in its slot, with the traffic agents' actions in theirs. -> Action (N, A)"""
        full = sdc_action(sim, action)
        if traffic is None:
            return full
        others = agents_action(sim, traffic.slots, traffic.valid, self._agent_fn, None, key, self.action_dim,
                               traffic.signs, self.traffic_sees_sdc_cos)
        return sdc_and_agents_action(sim, full, others)

    def _expert(self, sim: SimulatorState) -> jax.Array:
        """The SDC's label in [-1, 1]: the teacher's action, or the log-following one (inverse dynamics of the SDC's
        row only). (A,)"""
        if self.teacher is not None:
            return self._teacher_fn(sim)
        sdc = sdc_index(sim)
        row = lambda trajectory: jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, sdc, 1, 0),  # noqa: E731
                                              trajectory)
        dynamics = self.core.dynamics
        action = dynamics.expert_step(row(sim.current_sim_trajectory), row(sim.next_log_trajectory))[0]
        return jnp.clip(dynamics.normalize(action), -1.0, 1.0)

    def _move(self, sim: SimulatorState, arcs: jax.Array, action: jax.Array, traffic: TrafficAgents | None,
              key: jax.Array):
        """One simulator step of one scene with the SDC's action (A,) (and the traffic agents'): state, queries,
        metrics, termination, truncation."""
        sim = self.core.step(sim, self._full_action(sim, action, traffic, key))
        shared, metrics = self._measure(sim, arcs)
        terminated = jnp.zeros((), bool)
        for name in self.env_config.terminate_on:
            terminated = terminated | (metrics[TERMINATION_METRICS[name]] > 0.5)
        truncated = self.core.is_truncated(sim) & ~terminated
        return sim, shared, metrics, terminated, truncated

    def _observe(self, sim: SimulatorState, shared: SharedQueries, key: jax.Array) -> Observation:
        noise_key = key if self.obs_config.noise.active else None
        return sdc_observation(sim, shared, self.obs_config, noise_key)

    def _advance(self, sim: SimulatorState, arcs: jax.Array, metrics: dict, action: jax.Array,
                 traffic: TrafficAgents | None, key: jax.Array):
        """One policy step of one scene: the action held for `action_repeat` simulator steps, or until the
        episode ends -> (state, queries, metrics, reward summed, terminated, truncated, flags seen, observation).
        `metrics` are the current step's (the progress term compares with them)."""
        sim, shared, new_metrics, terminated, truncated = self._move(sim, arcs, action, traffic, key)
        reward = compute_reward(new_metrics, metrics, self.reward_config, self.metrics_config)
        flags = {name: new_metrics[name] > 0.5 for name in EPISODE_FLAGS}
        parts = (sim, shared, new_metrics, reward, terminated, truncated, flags)
        for _ in range(self.action_repeat - 1):  # unrolled: repeats are few
            parts = self._repeat_once(parts, arcs, action, traffic, key)
        sim, shared, metrics, reward, terminated, truncated, flags = parts
        return sim, shared, metrics, reward, terminated, truncated, flags, self._observe(sim, shared, key)

    def _repeat_once(self, parts, arcs: jax.Array, action: jax.Array, traffic: TrafficAgents | None,
                     key: jax.Array):
        """One simulator step of a held action; a scene whose episode already ended keeps its state."""
        sim, shared, metrics, reward, terminated, truncated, flags = parts
        running = ~(terminated | truncated)
        moved = self._move(sim, arcs, action, traffic, key)
        new_sim, new_shared, new_metrics, new_terminated, new_truncated = moved
        keep = lambda new, old: jax.tree.map(lambda n, o: jnp.where(running, n, o), new, old)  # noqa: E731
        reward = reward + jnp.where(running, compute_reward(new_metrics, metrics, self.reward_config,
                                                            self.metrics_config), 0.0)
        flags = {name: flag | (running & (new_metrics[name] > 0.5)) for name, flag in flags.items()}
        # a step changes only the simulated trajectory and the timestep: the log and the map index stay as they are
        sim = sim.replace(sim_trajectory=keep(new_sim.sim_trajectory, sim.sim_trajectory),
                          timestep=keep(new_sim.timestep, sim.timestep),
                          current_sim=keep(new_sim.current_sim, sim.current_sim))
        return (sim, keep(new_shared, shared), keep(new_metrics, metrics), reward,
                terminated | (running & new_terminated), truncated | (running & new_truncated), flags)

    # ------------------------------------------------------------------ batched API

    def reset(self, pool: SimulatorState, batch_size: int, key: jax.Array) -> LearningState:
        """Starts `batch_size` episodes on pool scenarios 0..B-1 (cycled when the pool is smaller)."""
        if self.traffic is not None:
            check_agent_paths(pool, "traffic while training (train.traffic)")
        pool_size = pool.timestep.shape[0]
        indices = jnp.arange(batch_size) % pool_size
        sim, arcs, shared, metrics, observation, traffic = jax.vmap(self._start)(_take(pool, indices))
        zeros = jnp.zeros(batch_size)
        return LearningState(
            sim=sim, arcs=arcs, shared=shared, metrics=metrics, observation=observation,
            episode_return=zeros, episode_length=jnp.zeros(batch_size, jnp.int32),
            episode_flags={name: jnp.zeros(batch_size, bool) for name in EPISODE_FLAGS},
            next_scenario=jnp.asarray(batch_size % pool_size, jnp.int32), key=key, traffic=traffic)

    def expert_action(self, state: LearningState) -> jax.Array:
        """The label of every running episode's SDC (the teacher's action, or the log-following one). (B, A) in
        [-1, 1]"""
        return jax.vmap(self._expert)(state.sim)

    def step(self, state: LearningState, action: jax.Array, pool: SimulatorState,
             expert: jax.Array | None = None) -> tuple[LearningState, StepOutput]:
        """Applies action (B, A) in [-1, 1]; finished episodes restart on the next pool scenarios. `expert`: this
        state's labels when the caller computed them already (a planner teacher is costly), else computed here."""
        batch_size = action.shape[0]
        action = jnp.clip(action, -1.0, 1.0)
        if expert is None:
            expert = self.expert_action(state) if self.expert_labels else jnp.zeros_like(action)
        key, step_key = jax.random.split(state.key)
        sim, shared, metrics, reward, terminated, truncated, seen, next_obs = jax.vmap(self._advance)(
            state.sim, state.arcs, state.metrics, action, state.traffic, jax.random.split(step_key, batch_size))
        done = terminated | truncated
        episode_return = state.episode_return + reward
        episode_length = state.episode_length + 1
        flags = {name: state.episode_flags[name] | seen[name] for name in EPISODE_FLAGS}
        output = StepOutput(
            observation=state.observation, action=action, expert_action=expert, reward=reward,
            terminated=terminated, truncated=truncated, next_observation=next_obs,
            episode_return=jnp.where(done, episode_return, 0.0),
            episode_length=jnp.where(done, episode_length, 0),
            episode_flags={name: flag & done for name, flag in flags.items()},
            episode_progress=jnp.where(done, metrics["progress_ratio"], 0.0))

        running = LearningState(
            sim=sim, arcs=state.arcs, shared=shared, metrics=metrics, observation=next_obs,
            episode_return=jnp.where(done, 0.0, episode_return),
            episode_length=jnp.where(done, 0, episode_length),
            episode_flags={name: flag & ~done for name, flag in flags.items()},
            next_scenario=state.next_scenario, key=key, traffic=state.traffic)
        new_state = self._restart_finished(running, done, pool)
        return new_state, output

    def _restart_finished(self, state: LearningState, done: jax.Array, pool: SimulatorState) -> LearningState:
        """Finished rows restart on the next pool scenarios: the k-th finished row (in row order) takes the
        k-th next scenario. One row at a time, written in place: restarting the whole batch and selecting
        rows would copy every scene's map index (~3.5 MB each) whenever any episode ends."""
        pool_size = pool.timestep.shape[0]
        rows = jnp.nonzero(done, size=done.shape[0], fill_value=0)[0]  # (B,) finished rows first
        num_done = jnp.sum(done).astype(jnp.int32)

        def restart_one(k, parts):
            scenario = (state.next_scenario + k) % pool_size
            fresh = self._start(jax.tree.map(lambda a: a[scenario], pool))
            return jax.tree.map(lambda c, f: jax.lax.dynamic_update_index_in_dim(c, f.astype(c.dtype), rows[k], 0),
                                parts, fresh)

        kept = (state.sim, state.arcs, state.shared, state.metrics, state.observation, state.traffic)
        sim, arcs, shared, metrics, observation, traffic = jax.lax.cond(
            num_done > 0, lambda parts: jax.lax.fori_loop(0, num_done, restart_one, parts), lambda parts: parts, kept)
        return state.replace(sim=sim, arcs=arcs, shared=shared, metrics=metrics, observation=observation,
                             traffic=traffic,
                             next_scenario=((state.next_scenario + num_done) % pool_size).astype(jnp.int32))


def check_learning_settings(env_config: EnvConfig, reward_config: RewardConfig, action_repeat: int) -> None:
    """One-line ValueError for terminations, reward terms or an action repeat a learning env cannot use."""
    unknown = set(env_config.terminate_on) - set(TERMINATION_METRICS)
    if unknown:
        raise ValueError(f"EnvConfig.terminate_on: unknown {sorted(unknown)}; choose among "
                         f"{sorted(TERMINATION_METRICS)}")
    check_reward_config(reward_config)
    if action_repeat < 1:
        raise ValueError(f"action_repeat must be at least 1, got {action_repeat}")


def _take(pool: SimulatorState, indices: jax.Array) -> SimulatorState:
    return jax.tree.map(lambda a: a[indices], pool)


