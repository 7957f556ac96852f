"""Data-parallel training over every local device with `jax.sharding`.

The environments' batch axis and the replay buffer's block axis are split over a one-dimensional
"data" mesh; the learner's parameters, the scenario pool and the PRNG key are replicated. The jitted
chunk then runs each device's environments and buffer block locally, and XLA averages the gradients
of the (sharded) sampled batch across devices. With one device nothing is sharded.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vmax_sim.training.loop import TrainCarry


def data_mesh(num_envs: int) -> Mesh | None:
    """A mesh over the local devices, or None with one device. num_envs must split evenly."""
    devices = jax.local_devices()
    if len(devices) < 2:
        return None
    if num_envs % len(devices):
        raise ValueError(f"num_envs={num_envs} does not split over {len(devices)} devices; choose a multiple")
    return Mesh(np.asarray(devices), ("data",))


def shard_carry(carry: TrainCarry, pool, mesh: Mesh):
    """Places the carry (envs and buffer split, the rest replicated) and the pool (replicated)."""
    split = NamedSharding(mesh, PartitionSpec("data"))
    replicated = NamedSharding(mesh, PartitionSpec())

    def by_leading_axis(tree):
        return jax.tree.map(lambda a: jax.device_put(a, split if getattr(a, "ndim", 0) > 0 else replicated), tree)

    env = carry.env
    batched = env.replace(next_scenario=None, key=None)
    batched = by_leading_axis(batched).replace(next_scenario=jax.device_put(env.next_scenario, replicated),
                                               key=jax.device_put(env.key, replicated))
    buffer = carry.buffer
    if buffer is not None:  # every per-block leaf splits over its leading (block) axis
        rows = buffer.rows.replace(data=jax.tree.map(lambda a: jax.device_put(a, split), buffer.rows.data),
                                   position=jax.device_put(buffer.rows.position, replicated),
                                   size=jax.device_put(buffer.rows.size, replicated))
        buffer = buffer.replace(rows=rows, kept=jax.tree.map(lambda a: jax.device_put(a, split), buffer.kept))
    carry = carry.replace(learner=jax.device_put(carry.learner, replicated), env=batched, buffer=buffer,
                          key=jax.device_put(carry.key, replicated),
                          env_steps=jax.device_put(carry.env_steps, replicated))
    return carry, jax.device_put(pool, replicated)
