"""The jitted training chunks: environment steps, replay / rollouts and learner updates in one `lax.scan`.

A chunk runs `chunk_steps` batched environment steps on the device and returns the new carry plus a
handful of scalars (episode statistics, learner metrics averaged over the chunk), so the host only
touches the device between chunks (logging, the scenario pool, checkpoints).

- off-policy (sac, bc_sac): act (uniformly random before `learning_starts`), step, add to the replay
  buffer, then `updates_per_step` learner updates on batches sampled on the device;
- bc: the logged expert drives (the data are the log's observations and actions); updates as above;
- on-policy (ppo): each chunk step collects the update's rollouts (`unrolls_per_update` unrolls of
  `unroll_length` steps), then runs one PPO update (epochs x minibatches inside the learner).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.agents import Learner, Transition
from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.learning import LearningEnv, LearningState, StepOutput
from vmax_sim.env.selfplay import AgentStepOutput, SelfPlayEnv
from vmax_sim.training.replay import TransitionReplay, replay_add, replay_sample

OFF_POLICY = ("sac", "bc_sac", "bc")


@struct.dataclass
class TrainCarry:
    learner: object  # the learner's state pytree
    env: LearningState  # (num_envs, ...)
    buffer: TransitionReplay | None  # replay buffer (off-policy algorithms), None for ppo
    key: jax.Array
    env_steps: jax.Array  # () int32 (int64 would need x64), environment steps taken so far


def _active(out: StepOutput | AgentStepOutput) -> jax.Array | None:
    """Which rows are real experience: self-play's agent rows that act (None: every row, the SDC-only env)."""
    return getattr(out, "active", None)


def transition_of(out: StepOutput | AgentStepOutput, log_prob=None, value=None) -> Transition:
    """The learner's Transition of one env step (discount 0 only where the episode terminated)."""
    return Transition.make(obs=out.observation, action=out.action, reward=out.reward,
                           discount=1.0 - out.terminated.astype(jnp.float32), next_obs=out.next_observation,
                           expert_action=out.expert_action, log_prob=log_prob, value=value,
                           truncated=out.truncated, done=out.done, mask=_active(out))


def episode_stats(out: StepOutput | AgentStepOutput) -> dict[str, jax.Array]:
    """Sums over the finished episodes of one step (divided by the count on the host); under self-play an
    episode is one agent's, and `agent_steps` counts the agents that acted."""
    done = out.done.astype(jnp.float32)
    flags = {f"episode/{name}": jnp.sum(flag.astype(jnp.float32)) for name, flag in out.episode_flags.items()}
    accurate = done * (1.0 - out.episode_flags["overlap"]) * (1.0 - out.episode_flags["offroad"]) * (
        1.0 - out.episode_flags["red_light"])
    active = _active(out)
    acting = jnp.ones(out.reward.shape, jnp.float32) if active is None else active.astype(jnp.float32)
    return {"episodes": jnp.sum(done), "episode/return": jnp.sum(out.episode_return),
            "episode/length": jnp.sum(out.episode_length.astype(jnp.float32)),
            "episode/accuracy": jnp.sum(accurate), "episode/progress_ratio": jnp.sum(out.episode_progress),
            **flags, "reward_sum": jnp.sum(out.reward * acting), "agent_steps": jnp.sum(acting)}


def _sum_stats(stats: dict[str, jax.Array]) -> dict[str, jax.Array]:
    return {name: jnp.sum(values) for name, values in stats.items()}


def update_batch_size(algo_config) -> int:
    """Transitions sampled per learner update: batch_size, once for each of BC's members (`members`)."""
    return algo_config.batch_size * getattr(algo_config, "members", 1)


def _updates(learner: Learner, learner_state, buffer: TransitionReplay, key: jax.Array, num_updates: int,
             batch_size: int):
    """`num_updates` learner updates on device-sampled batches -> (state, mean metrics)."""
    def one(state, update_key):
        sample_key, learn_key = jax.random.split(update_key)
        return learner.update(state, replay_sample(buffer, sample_key, batch_size), learn_key)

    state, metrics = jax.lax.scan(one, learner_state, jax.random.split(key, num_updates))
    return state, jax.tree.map(jnp.mean, metrics)


def bc_behaviour_action(expert: jax.Array, student: jax.Array | None, key: jax.Array, noise: float,
                        student_drive: float, student_started: jax.Array, student_mix: str = "step") -> jax.Array:
    """The action BC drives with, per row: the expert's plus Gaussian noise (DART: visits states off the expert's
    path, where its closed-loop labels steer back), or on a `student_drive` share (once `student_started`) the
    student's own (DAgger: the states the student drives into, labelled by the expert). student_mix "episode":
    that share is the first rows, always (each row drives whole episodes); "step": drawn per row and step.
    expert, student (B, A) -> (B, A)"""
    action = expert + noise * jax.random.normal(key, expert.shape) if noise > 0 else expert
    if student is None or student_drive <= 0:
        return action
    rows = expert.shape[:1] + (1,)
    if student_mix == "episode":
        by_student = jnp.arange(expert.shape[0]).reshape(rows) < round(student_drive * expert.shape[0])
    else:
        by_student = jax.random.uniform(jax.random.fold_in(key, 1), rows) < student_drive
    by_student &= student_started
    return jnp.where(by_student, student, action)


def make_off_policy_chunk(env: LearningEnv, learner: Learner, algo: str, algo_config, chunk_steps: int,
                          metrics_template: dict) -> Callable:
    """(carry, pool) -> (carry, chunk scalars). `metrics_template`: the learner metrics' structure."""
    num_envs = algo_config.num_envs
    learning_starts = getattr(algo_config, "learning_starts", 0)

    def iteration(carry: TrainCarry, pool: SimulatorState):
        key, act_key, random_key, update_key = jax.random.split(carry.key, 4)
        obs = carry.env.observation
        if algo == "bc":
            # behaviour cloning drives with the expert (the log-following one, or train.teacher's planner), noisy,
            # or with the student (bc_behaviour_action)
            expert = env.expert_action(carry.env)
            student = None
            if algo_config.student_drive > 0:
                student = learner.act(learner.policy_params(carry.learner), obs, act_key, True)
            action = bc_behaviour_action(expert, student, random_key, algo_config.behaviour_noise,
                                         algo_config.student_drive, carry.env_steps >= algo_config.student_after,
                                         algo_config.student_mix)
        else:
            expert = None
            policy_action = learner.act(learner.policy_params(carry.learner), obs, act_key, False)
            random_action = jax.random.uniform(random_key, policy_action.shape, minval=-1.0, maxval=1.0)
            action = jnp.where(carry.env_steps < learning_starts, random_action, policy_action)
        env_state, out = env.step(carry.env, action, pool, expert)
        buffer = replay_add(carry.buffer, transition_of(out))
        env_steps = carry.env_steps + num_envs
        ready = (buffer.size >= algo_config.batch_size) & (env_steps >= learning_starts)

        def learn(state):
            return _updates(learner, state, buffer, update_key, algo_config.updates_per_step,
                            update_batch_size(algo_config))

        def wait(state):
            return state, jax.tree.map(jnp.zeros_like, metrics_template)

        learner_state, metrics = jax.lax.cond(ready, learn, wait, carry.learner)
        stats = episode_stats(out)
        stats.update({f"learner/{k}": v for k, v in metrics.items()})
        stats["updates"] = ready.astype(jnp.float32) * algo_config.updates_per_step
        return TrainCarry(learner=learner_state, env=env_state, buffer=buffer, key=key, env_steps=env_steps), stats

    def chunk(carry: TrainCarry, pool: SimulatorState):
        carry, stats = jax.lax.scan(lambda c, _: iteration(c, pool), carry, None, length=chunk_steps)
        summed = _sum_stats({k: v for k, v in stats.items() if not k.startswith("learner/")})
        updated = jnp.maximum(jnp.sum(stats["updates"] > 0), 1.0)
        summed.update({k: jnp.sum(v) / updated for k, v in stats.items() if k.startswith("learner/")})
        return carry, summed

    return chunk


def unrolls_per_update(algo_config, agents_per_env: int = 1) -> int:
    """PPO unrolls of num_envs environments collected per update (batch_size * num_minibatches sequences; each
    env gives `agents_per_env` sequences under self-play)."""
    return max(1, (algo_config.batch_size * algo_config.num_minibatches) // (algo_config.num_envs * agents_per_env))


def agents_per_env(env: LearningEnv | SelfPlayEnv) -> int:
    """Learner rows per environment: 1, or self-play's agent slots per scene."""
    return getattr(env, "agents_per_scene", 1)


def make_on_policy_chunk(env: LearningEnv | SelfPlayEnv, learner: Learner, algo_config, chunk_steps: int
                         ) -> Callable:
    """PPO: each chunk step collects `unrolls_per_update` unrolls of `unroll_length` steps, then updates once.
    Under self-play every (env, agent slot) pair is one sequence."""
    agents = agents_per_env(env)
    num_envs, unroll = algo_config.num_envs, algo_config.unroll_length
    num_unrolls = unrolls_per_update(algo_config, agents)
    rows = num_envs * agents

    def env_step(carry: tuple, pool: SimulatorState):
        params, env_state, key = carry
        key, act_key = jax.random.split(key)
        action, info = learner.act_with_info(params, env_state.observation, act_key, False)
        env_state, out = env.step(env_state, action, pool)
        return (params, env_state, key), (transition_of(out, info["log_prob"], info["value"]), episode_stats(out))

    def one_unroll(carry: tuple, pool: SimulatorState):
        params, env_state, key = carry
        key, unroll_key = jax.random.split(key)
        (_, env_state, _), (rollout, stats) = jax.lax.scan(
            lambda c, _: env_step(c, pool), (params, env_state, unroll_key), None, length=unroll)
        bootstrap = learner.value(params, env_state.observation)  # (E,) V after the unroll's last step
        return (params, env_state, key), (rollout, bootstrap, _sum_stats(stats))

    def iteration(carry: TrainCarry, pool: SimulatorState):
        key, rollout_key, update_key = jax.random.split(carry.key, 3)
        params = (learner.behaviour_params or learner.policy_params)(carry.learner)  # on-policy: the raw params
        (_, env_state, _), (rollouts, bootstrap, stats) = jax.lax.scan(
            lambda c, _: one_unroll(c, pool), (params, carry.env, rollout_key), None, length=num_unrolls)
        # (U, T, E, ...) -> (T, U * E, ...): every (unroll, env row) pair is one sequence
        rollout = jax.tree.map(lambda a: jnp.swapaxes(a, 0, 1).reshape((unroll, num_unrolls * rows)
                                                                        + a.shape[3:]), rollouts)
        learner_state, metrics = learner.update(carry.learner, rollout, update_key,
                                                bootstrap_value=bootstrap.reshape(-1))
        stats = _sum_stats(stats)
        stats.update({f"learner/{k}": v for k, v in metrics.items()})
        stats["updates"] = jnp.ones((), jnp.float32)
        env_steps = carry.env_steps + num_envs * unroll * num_unrolls
        return TrainCarry(learner=learner_state, env=env_state, buffer=None, key=key, env_steps=env_steps), stats

    def chunk(carry: TrainCarry, pool: SimulatorState):
        carry, stats = jax.lax.scan(lambda c, _: iteration(c, pool), carry, None, length=chunk_steps)
        summed = _sum_stats({k: v for k, v in stats.items() if not k.startswith("learner/")})
        summed.update({k: jnp.mean(v) for k, v in stats.items() if k.startswith("learner/")})
        return carry, summed

    return chunk


def env_steps_per_chunk(algo: str, algo_config, chunk_steps: int, agents: int = 1) -> int:
    """Environment (scene) steps of one chunk; `agents`: self-play's agent slots per scene."""
    if algo in OFF_POLICY:
        return algo_config.num_envs * chunk_steps
    return algo_config.num_envs * algo_config.unroll_length * unrolls_per_update(algo_config, agents) * chunk_steps
