"""The off-policy replay of environment transitions, storing every observation once.

Each add writes one step of the same `num_envs` environments in the same order, so in every buffer block
(`vmax_sim.training.buffer`) the next observation of the transition in row r is the observation stored one
add later for the same environment: row (r + envs per block) of the ring. A transition keeps its own
next observation only where that row does not hold it:

- the newest add (its successors are not written yet): its next observations are kept apart;
- truncated transitions (time limit, end of the log): the learner bootstraps from the true last
  observation while the successor row holds the next episode's first one. A small ring keeps those last
  observations, sized for truncated episodes of MIN_TRUNCATED_LENGTH steps or more on average (time-limit
  truncations take the whole episode length, 80 steps by default); an older one overwritten while its
  transition is still in the buffer is counted in `lost_last_observations`;
- terminated transitions (discount 0): nothing. No learner reads their next observation (every target
  multiplies its bootstrap by the discount), so a sample returns the successor row's observation there.

Sampling draws the same rows from the same key as a buffer of whole transitions and returns the same values
(terminated transitions' next observations aside) in a little over half the memory: observations are nearly
all of a transition (5.1 instead of 9.2 kB with the default observation in float16).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from vmax_sim.agents import Transition
from vmax_sim.training.buffer import ReplayBuffer, buffer_add, gather_rows, sample_rows, storage_dtype

MIN_TRUNCATED_LENGTH = 10  # steps: the average truncated-episode length the ring of last observations covers


@struct.dataclass
class TransitionReplay:
    rows: ReplayBuffer  # {"transition": Transition without next_obs, "last_slot": int32}, leaves (blocks, R, ...)
    # per block, leading axis num_blocks: "next_obs" (E, ...) of the newest add (E envs per block);
    # "last_obs" (L, ...) ring of truncated transitions' last observations, "last_row" (L,) int32 the row
    # each belongs to (-1: none), "last_position" () int32 its next slot, "lost" () int32 overwritten too early
    kept: dict

    @property
    def size(self) -> jax.Array:
        return self.rows.size

    @property
    def envs_per_block(self) -> int:
        return jax.tree.leaves(self.kept["next_obs"])[0].shape[1]


def last_observation_slots(rows_per_block: int, envs_per_block: int, min_truncated_length: int) -> int:
    """Slots of the per-block ring of truncated transitions' last observations: enough for every truncated
    transition in the buffer while truncated episodes average `min_truncated_length` steps or more (plus one
    per environment for the episodes cut by the buffer's oldest row)."""
    steps = -(-rows_per_block // envs_per_block)  # adds the buffer holds
    return envs_per_block * (-(-steps // min_truncated_length) + 1)


def _zeros(example, count: int, num_blocks: int, float_dtype):
    return jax.tree.map(lambda leaf: jnp.zeros((num_blocks, count) + jnp.shape(leaf),
                                               storage_dtype(jnp.result_type(leaf), float_dtype)), example)


def _layout(capacity: int, num_envs: int, num_blocks: int, min_truncated_length: int) -> tuple[int, int, int]:
    """(rows per block, envs per block, last-observation slots per block); capacity rounds up to the blocks."""
    if capacity < 1 or num_blocks < 1:
        raise ValueError(f"replay buffer capacity and blocks must be at least 1, got {capacity}, {num_blocks}")
    if num_envs % num_blocks:
        raise ValueError(f"{num_envs} environments do not split into {num_blocks} buffer blocks")
    rows, envs = -(-capacity // num_blocks), num_envs // num_blocks
    if envs > rows:
        raise ValueError(f"a replay buffer of {capacity} transitions cannot hold one step of {num_envs} environments")
    return rows, envs, last_observation_slots(rows, envs, max(min_truncated_length, 1))


def replay_init(example: Transition, capacity: int, num_envs: int, float_dtype=jnp.float32, num_blocks: int = 1,
                min_truncated_length: int = MIN_TRUNCATED_LENGTH) -> TransitionReplay:
    """An empty replay for adds of `num_envs` transitions shaped like `example` (one unbatched Transition).
    min_truncated_length sizes the ring of last observations (1: one slot per row, never overwritten early)."""
    rows, envs, slots = _layout(capacity, num_envs, num_blocks, min_truncated_length)
    stored = {"transition": example.replace(next_obs=None), "last_slot": jnp.zeros((), jnp.int32)}
    data = _zeros(stored, rows, num_blocks, float_dtype)
    data["last_slot"] = jnp.full((num_blocks, rows), -1, jnp.int32)
    kept = {"next_obs": _zeros(example.next_obs, envs, num_blocks, float_dtype),
            "last_obs": _zeros(example.next_obs, slots, num_blocks, float_dtype),
            "last_row": jnp.full((num_blocks, slots), -1, jnp.int32),
            "last_position": jnp.zeros((num_blocks,), jnp.int32), "lost": jnp.zeros((num_blocks,), jnp.int32)}
    buffer = ReplayBuffer(data=data, position=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))
    return TransitionReplay(rows=buffer, kept=kept)


def replay_bytes(example: Transition, capacity: int, num_envs: int, float_dtype=jnp.float32,
                 num_blocks: int = 1) -> int:
    """Bytes the replay of `replay_init` with these arguments takes (the budget printed before training)."""
    shapes = jax.eval_shape(lambda: replay_init(example, capacity, num_envs, float_dtype, num_blocks))
    return int(sum(np.prod(leaf.shape, dtype=np.int64) * np.dtype(leaf.dtype).itemsize
                   for leaf in jax.tree.leaves(shapes)))


def replay_add(replay: TransitionReplay, batch: Transition) -> TransitionReplay:
    """Writes one step of every environment (leading axis num_envs, in the order of every add)."""
    buffer, kept = replay.rows, replay.kept
    blocks, rows_per_block, envs = buffer.num_blocks, buffer.rows_per_block, replay.envs_per_block
    if batch.reward.shape[0] != blocks * envs:
        raise ValueError(f"the replay takes steps of {blocks * envs} environments, got {batch.reward.shape[0]}")
    slots = kept["last_row"].shape[1]
    truncated = batch.truncated.reshape(blocks, envs)
    order = jnp.cumsum(truncated, axis=1) - 1
    last_slot = jnp.where(truncated, (kept["last_position"][:, None] + order) % slots, -1).astype(jnp.int32)
    written = (buffer.position + jnp.arange(envs)) % rows_per_block  # rows this add writes, in every block
    buffer = buffer_add(buffer, {"transition": batch.replace(next_obs=None), "last_slot": last_slot.reshape(-1)})

    def keep_block(block: dict, next_obs, slot: jax.Array, row_slots: jax.Array) -> dict:
        target = jnp.where(slot >= 0, slot, slots)  # out of range: dropped
        owner = block["last_row"][jnp.maximum(slot, 0)]
        rewritten = (owner - written[0]) % rows_per_block < envs  # the owner's row was just replaced
        lost = (slot >= 0) & (owner >= 0) & ~rewritten & (row_slots[jnp.maximum(owner, 0)] == slot)
        store = lambda ring, new: ring.at[target].set(new.astype(ring.dtype), mode="drop")  # noqa: E731
        return {"next_obs": jax.tree.map(lambda old, new: new.astype(old.dtype), block["next_obs"], next_obs),
                "last_obs": jax.tree.map(store, block["last_obs"], next_obs),
                "last_row": block["last_row"].at[target].set(written, mode="drop"),
                "last_position": ((block["last_position"] + jnp.sum(slot >= 0)) % slots).astype(jnp.int32),
                "lost": block["lost"] + jnp.sum(lost).astype(jnp.int32)}

    next_obs = jax.tree.map(lambda a: a.reshape((blocks, envs) + a.shape[1:]), batch.next_obs)
    kept = jax.vmap(keep_block)(kept, next_obs, last_slot, buffer.data["last_slot"])
    return TransitionReplay(rows=buffer, kept=kept)


def replay_sample(replay: TransitionReplay, key: jax.Array, batch_size: int) -> Transition:
    """`batch_size` transitions drawn uniformly (with replacement), an equal share from every block (the
    rows and values a buffer of whole transitions gives for the same key); floats as float32."""
    buffer, envs = replay.rows, replay.envs_per_block
    rows_per_block = buffer.rows_per_block
    rows = sample_rows(buffer, key, batch_size)
    picked = gather_rows(buffer.data, rows)

    def next_rows(block: dict, obs, row_slots: jax.Array, index: jax.Array):
        newest = (index - buffer.position + envs) % rows_per_block  # < envs: written by the newest add
        slot = jnp.maximum(row_slots[index], 0)
        has_last = (row_slots[index] >= 0) & (block["last_row"][slot] == index)

        def pick(successor, last, latest):
            shape = (-1,) + (1,) * (successor.ndim - 1)
            chosen = jnp.where(has_last.reshape(shape), last[slot], successor[(index + envs) % rows_per_block])
            return jnp.where((newest < envs).reshape(shape), latest[jnp.minimum(newest, envs - 1)], chosen)

        return jax.tree.map(pick, obs, block["last_obs"], block["next_obs"])

    next_obs = jax.vmap(next_rows)(replay.kept, buffer.data["transition"].obs, buffer.data["last_slot"], rows)
    next_obs = jax.tree.map(lambda a: a.reshape((batch_size,) + a.shape[2:]), next_obs)
    next_obs = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                            next_obs)
    return picked["transition"].replace(next_obs=next_obs)


def lost_last_observations(replay: TransitionReplay) -> int:
    """Truncated transitions whose last observation was overwritten while they were still in the buffer
    (their samples bootstrap from the next episode's first observation instead)."""
    return int(jnp.sum(replay.kept["lost"]))
