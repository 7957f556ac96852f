"""`SelfPlayEnv`: one shared policy drives the SDC and up to K - 1 controllable agents of every scene.

One environment with an agents axis (docs/selfplay.md). Each scene picks its agents at reset: the SDC, then
the controllable objects present at the first policy step with a path, nearest the SDC first
(`choose_agents`). Every agent sees the scene through `agent_view` -- it is "the SDC" and its own path is the
route -- so the observation, the metrics, the reward and the terminations are the SDC's own functions, vmapped
over agents. The learner sees a flat batch of B * K rows (scene-major) with `active` marking the rows that
are real agents still acting; everything else (empty slots, agents already finished) is masked.

An agent's episode ends when it collides, leaves the road or runs a red light (as `EnvConfig.terminate_on`),
when it reaches its goal (within `goal_radius_m` of its last logged position: GPUDrive's goal-reaching; with
`at_goal="drive_on"` it drives on instead), or when the scene reaches its time limit. A goal reacher leaves the
scene; a crashed agent leaves it too (`crashed="remove"`: others stop seeing it) or stays where it stopped as a
still obstacle (`"obstacle"`).
Objects that are not agents replay the log. A scene restarts on the next pool scenario when no agent is
left acting or at its time limit; its slots then hold new agents.

Everything is pure and jittable; `reset` and `step` take the scenario pool as an argument like `LearningEnv`'s.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.datatypes import Action, RoadgraphPoints, SimulatorState, update_timestep
from vmax_sim.env.agent_view import agent_view, choose_agents, stop_sign_points, with_sdc_route
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.environment import Environment
from vmax_sim.env.learning import EPISODE_FLAGS, TERMINATION_METRICS, check_learning_settings
from vmax_sim.env.metrics_adapter import reference_arcs, sdc_index, sdc_observation, step_inputs
from vmax_sim.metrics import MetricsConfig, shared_queries, step_metrics
from vmax_sim.observation import Observation, ObservationConfig
from vmax_sim.rewards import RewardConfig, compute_reward

CRASHED_CHOICES = ("remove", "obstacle")
AT_GOAL_CHOICES = ("leave", "drive_on")
AGENT_FLAGS = (*EPISODE_FLAGS, "goal_reached")  # per-agent episode indicators


@dataclasses.dataclass(frozen=True)
class SelfPlayConfig:
    max_agents: int = 8  # K: agents driven per scene, the SDC included (1: the SDC alone)
    goal_radius_m: float = 2.0  # an agent reaches its goal within this distance of its last logged position
    goal_reward: float = 1.0  # added to the reward of the step an agent reaches its goal
    # added per metre the agent got closer to its goal in a step (dense: the goal is its position 8 s on in the
    # log, so an agent slower than its log never reaches it, and the binary progress term does not tell)
    approach_reward: float = 0.05
    crashed: str = "remove"  # "remove": a crashed agent leaves the scene; "obstacle": it stays, standing still
    # "leave": a goal reacher's episode ends and it leaves the scene (GPUDrive's); "drive_on": it keeps driving to
    # the scene's time limit after its goal reward (no approach term then), as learned traffic must in evaluation
    at_goal: str = "leave"
    # shares of SDCs and of the other agents driven by the rule driver (`SelfPlayEnv.rule_driver`: IDM at the speed
    # limit) instead of the policy, drawn per agent at the scene's start; their rows teach nothing, but the agents
    # around them meet a driver that stops where its log went on (a red light it reaches late), which students
    # keeping their logged pace never show each other
    rule_sdc: float = 0.0
    rule_agents: float = 0.0

    def __post_init__(self) -> None:
        if self.max_agents < 1:
            raise ValueError(f"selfplay.max_agents must be at least 1, got {self.max_agents}")
        if not self.goal_radius_m > 0:
            raise ValueError(f"selfplay.goal_radius_m must be positive, got {self.goal_radius_m}")
        if self.crashed not in CRASHED_CHOICES:
            raise ValueError(f"selfplay.crashed must be one of {CRASHED_CHOICES}, got {self.crashed!r}")
        if self.at_goal not in AT_GOAL_CHOICES:
            raise ValueError(f"selfplay.at_goal must be one of {AT_GOAL_CHOICES}, got {self.at_goal!r}")
        for name in ("rule_sdc", "rule_agents"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"selfplay.{name} must be a share in [0, 1], got {getattr(self, name)}")

    @property
    def has_rule_drivers(self) -> bool:
        return self.rule_sdc > 0 or self.rule_agents > 0


@struct.dataclass
class SelfPlayState:
    sim: SimulatorState  # (B, ...) the running scenes (agent_paths with the SDC's route in its row)
    slots: jax.Array  # (B, K) int32, object slot of each agent
    present: jax.Array  # (B, K) bool, the slot holds an agent this episode
    active: jax.Array  # (B, K) bool, the agent still acts
    ruled: jax.Array  # (B, K) bool, the agent is driven by the rule driver this episode: its row teaches nothing
    gone: jax.Array  # (B, N) bool, objects taken out of the scene (finished agents)
    still: jax.Array  # (B, N) bool, crashed agents kept as standing obstacles
    goal_xy: jax.Array  # (B, K, 2) float32, each agent's last logged position in the episode
    arcs: jax.Array  # (B, K, 1, 2) float32, logged start / end arcs along each agent's own path
    metrics: dict  # name -> (B, K) float32, each agent's step metrics now
    signs: RoadgraphPoints  # (B, S) the stop-sign points handed to the teacher's views (found once per scene)
    observation: Observation  # (B * K, ...) the policy's input now (flat, scene-major)
    expert_action: jax.Array  # (B * K, A) float32, the teacher's label of each agent now (zeros without a teacher)
    episode_return: jax.Array  # (B, K) float32
    episode_length: jax.Array  # (B, K) int32
    episode_flags: dict  # name -> (B, K) bool, AGENT_FLAGS seen so far
    next_scenario: jax.Array  # () int32
    key: jax.Array


@struct.dataclass
class AgentStepOutput:
    """One step of every agent slot, flat (B * K) like the learner's batch; the fields `StepOutput` has mean
    the same, per agent. Rows where `active` is False carry no experience (zeros, never done)."""

    observation: Observation  # (BK, ...) before the step
    action: jax.Array  # (BK, A) float32 in [-1, 1]
    expert_action: jax.Array  # (BK, A) the teacher's label at the observation's state (zeros without a teacher)
    reward: jax.Array  # (BK,) float32
    terminated: jax.Array  # (BK,) bool, crash, off-road, red light or goal reached
    truncated: jax.Array  # (BK,) bool, the scene's time limit (and not terminated)
    next_observation: Observation  # (BK, ...) after the step, before any restart
    episode_return: jax.Array  # (BK,) float32 where the agent's episode ended, else 0
    episode_length: jax.Array  # (BK,) int32, likewise
    episode_flags: dict  # name -> (BK,) bool, AGENT_FLAGS, likewise
    episode_progress: jax.Array  # (BK,) float32, progress ratio along its path where done
    active: jax.Array  # (BK,) bool, the row is an agent acting at this step
    scene_done: jax.Array  # (B,) bool, the scene restarts after this step

    @property
    def done(self) -> jax.Array:
        return self.terminated | self.truncated


@dataclasses.dataclass(frozen=True)
class SelfPlayEnv:
    """Batched self-play environment (see the module docstring). Same batched API as `LearningEnv`, with
    B * K learner rows for B scenes."""

    env_config: EnvConfig = EnvConfig(controlled="controllable")
    obs_config: ObservationConfig = ObservationConfig()
    reward_config: RewardConfig = RewardConfig()
    metrics_config: MetricsConfig = MetricsConfig()
    selfplay: SelfPlayConfig = SelfPlayConfig()
    action_repeat: int = 1
    expert_labels: bool = False  # no log-following labels: kept for LearningEnv's interface
    # a factory (core Environment) -> a rule driver, one state -> the SDC's action (A,) in [-1, 1]
    # (`vmax_sim.policies.teacher`): run on every agent's view, it labels each agent's step (`expert_action`)
    teacher: Callable[[Environment], Callable[[SimulatorState], jax.Array]] | None = None
    # the same kind of factory: the driver of the agents `selfplay.rule_sdc` / `rule_agents` hand to rules
    rule_driver: Callable[[Environment], Callable[[SimulatorState], jax.Array]] | None = None

    def __post_init__(self) -> None:
        check_learning_settings(self.env_config, self.reward_config, self.action_repeat)
        if self.selfplay.has_rule_drivers and self.rule_driver is None:
            raise ValueError("selfplay.rule_sdc or rule_agents > 0 needs SelfPlayEnv(rule_driver=...) to drive them")
        config = dataclasses.replace(self.env_config, normalize_actions=True, controlled="controllable")
        object.__setattr__(self, "env_config", config)
        object.__setattr__(self, "core", Environment(config))
        object.__setattr__(self, "_teacher_fn", None if self.teacher is None else self.teacher(self.core))
        ruling = self.selfplay.has_rule_drivers  # a driver is there (checked above)
        object.__setattr__(self, "_rule_fn", self.rule_driver(self.core) if ruling else None)

    @property
    def action_dim(self) -> int:
        return self.core.action_dim

    @property
    def agents_per_scene(self) -> int:
        return self.selfplay.max_agents

    # ------------------------------------------------------------------ one agent of one scene

    def _queries(self, sim: SimulatorState, slot: jax.Array, arcs: jax.Array):
        """The agent's shared queries and step metrics now (its observation reuses the queries)."""
        inputs = step_inputs(agent_view(sim, slot), arcs)
        shared = shared_queries(inputs, self.metrics_config)
        return shared, step_metrics(sim.map_index, inputs, self.metrics_config, shared)

    def _observe(self, sim: SimulatorState, slot: jax.Array, shared, key: jax.Array | None) -> Observation:
        noise_key = key if key is not None and self.obs_config.noise.active else None
        return sdc_observation(agent_view(sim, slot), shared, self.obs_config, noise_key)

    def _labels(self, sim: SimulatorState, slots: jax.Array, acting: jax.Array, signs: RoadgraphPoints) -> jax.Array:
        """Each acting agent's teacher action on its own view (the scene's stop signs handed over, not the whole
        roadgraph K times). (K, A) float32; zeros in the other rows and without a teacher."""
        if self._teacher_fn is None:
            return jnp.zeros((slots.shape[0], self.action_dim), jnp.float32)
        labels = jax.vmap(lambda slot: self._teacher_fn(agent_view(sim, slot, signs)))(slots)
        return jnp.where(acting[:, None], labels, 0.0)

    def _goal(self, sim: SimulatorState, slot: jax.Array) -> jax.Array:
        """The agent's last logged position within the episode window. (2,)"""
        log = sim.log_trajectory
        steps = jnp.arange(log.valid.shape[-1])
        last = jnp.max(jnp.where(log.valid[slot] & (steps <= self.env_config.last_timestep), steps, 0))
        return jnp.stack([log.x[slot, last], log.y[slot, last]])

    # ------------------------------------------------------------------ one scene (vmapped below)

    def _start(self, sim: SimulatorState, key: jax.Array):
        """Reset one scene: its agents, their goals, arcs, metrics and observations; which agents rules drive
        (drawn with `key`; the rest of the start is deterministic)."""
        k = self.selfplay.max_agents
        share = jnp.full(k, self.selfplay.rule_agents).at[0].set(self.selfplay.rule_sdc)
        ruled = jax.random.uniform(key, (k,)) < share
        sim = with_sdc_route(self.core.reset(sim))
        first = self.env_config.first_policy_timestep
        others, others_valid = choose_agents(sim, max(k - 1, 1), first)
        sdc = sdc_index(sim)
        slots = jnp.concatenate([sdc[None], others[:k - 1]]).astype(jnp.int32)
        has_route = jnp.any(sim.agent_paths.valid[sdc])
        present = jnp.concatenate([has_route[None], others_valid[:k - 1]])
        arcs = jax.vmap(lambda slot: reference_arcs(agent_view(sim, slot), self.env_config))(slots)
        goals = jax.vmap(lambda slot: self._goal(sim, slot))(slots)
        shared, metrics = jax.vmap(lambda slot, a: self._queries(sim, slot, a))(slots, arcs)
        # an agent that starts overlapping another object or off the road (a car logged on a driveway, a box
        # touching its neighbour's) would end its episode at its first step, one that starts at its goal (logged
        # standing still) has nowhere to go: they replay their logs instead
        start = sim.current_sim_trajectory
        to_goal = jnp.hypot(start.x[slots, 0] - goals[:, 0], start.y[slots, 0] - goals[:, 1])
        present = (present & (metrics["overlap"] < 0.5) & (metrics["offroad"] < 0.5)
                   & (to_goal >= self.selfplay.goal_radius_m))
        is_agent = jnp.zeros(sim.num_objects, bool).at[jnp.where(present, slots, sim.num_objects)].set(
            True, mode="drop")
        sim = sim.replace(object_metadata=sim.object_metadata.replace(is_controlled=is_agent, max_controlled=k))
        observation = jax.vmap(lambda slot, q: self._observe(sim, slot, q, None))(slots, shared)
        none = jnp.zeros(sim.num_objects, bool)
        signs = stop_sign_points(sim)  # as LearningEnv's traffic: once per scene, not at every step
        labels = self._labels(sim, slots, present, signs)
        return sim, slots, present, present, ruled, none, none, goals, arcs, metrics, signs, (observation, labels)

    def _move(self, sim: SimulatorState, slots: jax.Array, acting: jax.Array, action: jax.Array,
              gone: jax.Array, still: jax.Array) -> SimulatorState:
        """One simulator step: acting agents by their actions (K, A), gone objects stay out, still ones stay put."""
        num = sim.num_objects
        target = jnp.where(acting, slots, num)
        data = jnp.zeros((num, self.action_dim), jnp.float32).at[target].set(action, mode="drop")
        valid = jnp.zeros((num, 1), bool).at[target, 0].set(True, mode="drop")
        before = sim.current_sim_trajectory
        sim = self.core.step(sim, Action(data=data, valid=valid))
        now = sim.current_sim_trajectory
        standing = before.replace(vel_x=jnp.zeros_like(before.vel_x), vel_y=jnp.zeros_like(before.vel_y))
        now = jax.tree.map(lambda held, moved: jnp.where(still[:, None], held.astype(moved.dtype), moved),
                           standing, now)
        now = now.replace(valid=now.valid & ~gone[:, None])
        return sim.replace(sim_trajectory=update_timestep(sim.sim_trajectory, sim.timestep, now), current_sim=now)

    def _substep(self, parts, slots, arcs, goals, reached_before, action):
        """One simulator step of the held actions: agents still acting move, score and may finish.
        reached_before (K,): the agent reached its goal at an earlier policy step (`at_goal="drive_on"`)."""
        sim, acting, gone, still, metrics, reward, terminated, goal, flags = parts
        heading = ~(reached_before | goal)  # still on the way to its goal
        distance_before = self._goal_distance(sim, slots, goals)
        sim = self._move(sim, slots, acting, action, gone, still)
        shared, new_metrics = jax.vmap(lambda slot, a: self._queries(sim, slot, a))(slots, arcs)
        crashed = jnp.zeros_like(acting)
        for name in self.env_config.terminate_on:
            crashed = crashed | (new_metrics[TERMINATION_METRICS[name]] > 0.5)
        crashed = acting & crashed
        distance = self._goal_distance(sim, slots, goals)
        reached = acting & ~crashed & heading & (distance < self.selfplay.goal_radius_m)
        step_reward = compute_reward(new_metrics, metrics, self.reward_config, self.metrics_config)
        step_reward = (step_reward + self.selfplay.goal_reward * reached
                       + self.selfplay.approach_reward * heading * (distance_before - distance))
        reward = reward + jnp.where(acting, step_reward, 0.0)
        flags = {name: flags[name] | (acting & (new_metrics[name] > 0.5)) for name in EPISODE_FLAGS}
        metrics = jax.tree.map(lambda n, o: jnp.where(acting, n, o), new_metrics, metrics)
        finished = jnp.where(acting, slots, sim.num_objects)
        leaving = crashed if self.selfplay.crashed == "remove" else jnp.zeros_like(crashed)
        ends = reached if self.selfplay.at_goal == "leave" else jnp.zeros_like(reached)
        gone = gone.at[jnp.where(ends | leaving, finished, sim.num_objects)].set(True, mode="drop")
        still = still.at[jnp.where(crashed & ~leaving, finished, sim.num_objects)].set(True, mode="drop")
        acting = acting & ~crashed & ~ends
        parts = (sim, acting, gone, still, metrics, reward, terminated | crashed | ends, goal | reached, flags)
        return parts, shared

    @staticmethod
    def _goal_distance(sim: SimulatorState, slots: jax.Array, goals: jax.Array) -> jax.Array:
        """Each agent's distance to its goal now. (K,) m"""
        now = sim.current_sim_trajectory
        return jnp.hypot(now.x[slots, 0] - goals[:, 0], now.y[slots, 0] - goals[:, 1])

    def _advance(self, sim, slots, active, ruled, gone, still, goals, arcs, metrics, signs, reached_before, action,
                 key):
        """One policy step of one scene: actions (K, A) held for `action_repeat` simulator steps, or until the
        scene's time limit (a ruled agent's action is the rule driver's). The observation reuses the last step's
        queries."""
        if self._rule_fn is not None:
            rule_action = jax.vmap(lambda slot: self._rule_fn(agent_view(sim, slot, signs)))(slots)
            action = jnp.where(ruled[:, None], rule_action, action)
        zeros = jnp.zeros_like(active)
        flags = {name: zeros for name in EPISODE_FLAGS}
        parts = (sim, active, gone, still, metrics, jnp.zeros(active.shape, jnp.float32), zeros, zeros, flags)
        parts, shared = self._substep(parts, slots, arcs, goals, reached_before, action)
        truncated_scene = self._time_is_up(parts[0])
        for _ in range(self.action_repeat - 1):  # unrolled: repeats are few
            keep = _selector(~truncated_scene)
            stepped, new_shared = self._substep(parts, slots, arcs, goals, reached_before, action)
            old_sim, new_sim = parts[0], stepped[0]
            # only the simulated trajectory and the timestep change: never select (copy) the map index
            sim = old_sim.replace(sim_trajectory=keep(new_sim.sim_trajectory, old_sim.sim_trajectory),
                                  timestep=keep(new_sim.timestep, old_sim.timestep),
                                  current_sim=keep(new_sim.current_sim, old_sim.current_sim))
            parts, shared = (sim, *keep(stepped[1:], parts[1:])), keep(new_shared, shared)
            truncated_scene = truncated_scene | self._time_is_up(sim)
        sim, acting, gone, still, metrics, reward, terminated, goal, flags = parts
        flags = {**flags, "goal_reached": goal}
        truncated = active & ~terminated & truncated_scene
        keys = jax.random.split(key, slots.shape[0])
        observation = jax.vmap(lambda slot, q, k: self._observe(sim, slot, q, k))(slots, shared, keys)
        scene_done = truncated_scene | ~jnp.any(acting & ~ruled)  # no learner left
        return (sim, acting, gone, still, metrics, reward, terminated, truncated, flags,
                (observation, self._labels(sim, slots, acting, signs)), scene_done)

    def _time_is_up(self, sim: SimulatorState) -> jax.Array:
        """The scene reached its time limit or the end of its log. () bool"""
        return (sim.timestep >= self.env_config.last_timestep) | sim.is_done

    # ------------------------------------------------------------------ batched API

    def reset(self, pool: SimulatorState, batch_size: int, key: jax.Array) -> SelfPlayState:
        """Starts `batch_size` scenes on pool scenarios 0..B-1 (cycled when the pool is smaller)."""
        pool_size = pool.timestep.shape[0]
        scenes = jax.tree.map(lambda a: a[jnp.arange(batch_size) % pool_size], pool)
        parts = jax.vmap(self._start)(scenes, jax.random.split(key, batch_size))
        sim, slots, present, active, ruled, gone, still, goals, arcs, metrics, signs, (observation, labels) = parts
        shape = slots.shape
        return SelfPlayState(
            sim=sim, slots=slots, present=present, active=active, ruled=ruled, gone=gone, still=still, goal_xy=goals,
            arcs=arcs, metrics=metrics, signs=signs, observation=_flat(observation), expert_action=_flat(labels),
            episode_return=jnp.zeros(shape),
            episode_length=jnp.zeros(shape, jnp.int32), episode_flags={n: jnp.zeros(shape, bool) for n in AGENT_FLAGS},
            next_scenario=jnp.asarray(batch_size % pool_size, jnp.int32), key=key)

    @staticmethod
    def expert_action(state: SelfPlayState) -> jax.Array:
        """The teacher's label of every agent row now (zeros without a teacher). (B * K, A) in [-1, 1]"""
        return state.expert_action

    def step(self, state: SelfPlayState, action: jax.Array, pool: SimulatorState, expert: jax.Array | None = None
             ) -> tuple[SelfPlayState, AgentStepOutput]:
        """Applies actions (B * K, A) in [-1, 1]; finished scenes restart on the next pool scenarios. `expert`:
        LearningEnv's argument; the labels here are the state's own (computed with the observation)."""
        batch, k = state.slots.shape
        action = jnp.clip(action, -1.0, 1.0).reshape(batch, k, -1)
        key, step_key = jax.random.split(state.key)
        outs = jax.vmap(self._advance)(state.sim, state.slots, state.active, state.ruled, state.gone, state.still,
                                       state.goal_xy, state.arcs, state.metrics, state.signs,
                                       state.episode_flags["goal_reached"], action, jax.random.split(step_key, batch))
        sim, acting, gone, still, metrics, reward, terminated, truncated, seen, (next_obs, labels), scene_done = outs
        active = state.active
        done = terminated | truncated
        learner = active & ~state.ruled  # the rows that carry experience and episode statistics
        ended = done & learner
        episode_return = state.episode_return + reward
        episode_length = state.episode_length + active.astype(jnp.int32)
        flags = {name: state.episode_flags[name] | seen[name] for name in AGENT_FLAGS}
        output = AgentStepOutput(
            observation=state.observation, action=action.reshape(batch * k, -1),
            expert_action=state.expert_action, reward=_flat(reward),
            terminated=_flat(terminated & learner), truncated=_flat(truncated & learner),
            next_observation=_flat(next_obs),
            episode_return=_flat(jnp.where(ended, episode_return, 0.0)),
            episode_length=_flat(jnp.where(ended, episode_length, 0)),
            episode_flags={name: _flat(flag & ended) for name, flag in flags.items()},
            episode_progress=_flat(jnp.where(ended, metrics["progress_ratio"], 0.0)),
            active=_flat(learner), scene_done=scene_done)
        running = state.replace(
            sim=sim, active=acting, gone=gone, still=still, metrics=metrics, observation=_flat(next_obs),
            expert_action=_flat(labels),
            episode_return=jnp.where(done, 0.0, episode_return), episode_length=jnp.where(done, 0, episode_length),
            episode_flags={name: flag & ~done for name, flag in flags.items()}, key=key)
        return self._restart_finished(running, scene_done, pool), output

    def _restart_finished(self, state: SelfPlayState, done: jax.Array, pool: SimulatorState) -> SelfPlayState:
        """Finished scenes restart on the next pool scenarios, one at a time, written in place (as LearningEnv's)."""
        pool_size = pool.timestep.shape[0]
        batch, k = state.slots.shape
        rows = jnp.nonzero(done, size=done.shape[0], fill_value=0)[0]
        num_done = jnp.sum(done).astype(jnp.int32)

        def restart_one(i, parts):
            scenario = (state.next_scenario + i) % pool_size
            fresh = self._start(jax.tree.map(lambda a: a[scenario], pool), jax.random.fold_in(state.key, rows[i]))
            scene_parts, observation = parts
            *fresh_scene, fresh_obs = fresh
            scene_parts = jax.tree.map(
                lambda c, f: jax.lax.dynamic_update_index_in_dim(c, f.astype(c.dtype), rows[i], 0),
                scene_parts, tuple(fresh_scene))
            observation = jax.tree.map(
                lambda c, f: jax.lax.dynamic_update_slice_in_dim(c, f.astype(c.dtype), rows[i] * k, 0),
                observation, fresh_obs)
            return scene_parts, observation

        kept = ((state.sim, state.slots, state.present, state.active, state.ruled, state.gone, state.still,
                 state.goal_xy, state.arcs, state.metrics, state.signs), (state.observation, state.expert_action))
        scene_parts, observation = jax.lax.cond(
            num_done > 0, lambda parts: jax.lax.fori_loop(0, num_done, restart_one, parts), lambda parts: parts, kept)
        sim, slots, present, active, ruled, gone, still, goals, arcs, metrics, signs = scene_parts
        observation, labels = observation
        return state.replace(sim=sim, slots=slots, present=present, active=active, ruled=ruled, gone=gone, still=still,
                             goal_xy=goals, arcs=arcs, metrics=metrics, signs=signs, observation=observation,
                             expert_action=labels,
                             next_scenario=((state.next_scenario + num_done) % pool_size).astype(jnp.int32))


def _selector(condition: jax.Array):
    """(new, old) -> new where `condition` (a scalar), else old, leaf by leaf."""
    return lambda new, old: jax.tree.map(lambda n, o: jnp.where(condition, n, o), new, old)


def _flat(tree):
    """(B, K, ...) -> (B * K, ...) leaf by leaf."""
    return jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), tree)
