"""Data-parallel training over every device with `jax.sharding`: the local ones, or with several processes
(`jax.distributed`, vmax_sim.training.distributed) every process's.

The environments' batch axis and the replay buffer's block axis are split over a one-dimensional
"data" mesh; the learner's parameters, the scenario pool and the PRNG key are replicated. The jitted
chunk then runs each device's environments and buffer block locally, and XLA averages the gradients
of the (sharded) sampled batch across devices. With one device nothing is sharded.

With several processes every process computes the same whole starting carry and pool (the same seeds and, by
the stream's exchange, the same scenarios) and places only its own devices' slices of them (`from_local`).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vmax_sim.training.loop import TrainCarry


def data_mesh(num_envs: int) -> Mesh | None:
    """A mesh over the devices (every process's when there are several), or None with one device. num_envs must
    split evenly."""
    devices = jax.devices() if jax.process_count() > 1 else jax.local_devices()
    if len(devices) < 2:
        return None
    if num_envs % len(devices):
        across = f" of {jax.process_count()} processes" if jax.process_count() > 1 else ""
        raise ValueError(f"num_envs={num_envs} does not split over the {len(devices)} devices{across}; choose a "
                         f"multiple")
    return Mesh(np.asarray(devices), ("data",))


def from_local(value, sharding: NamedSharding) -> jax.Array:
    """A global array of `sharding` from this process's copy of the whole value (every process holds the same):
    each of its devices gets its slice. Unlike device_put, no cross-process comparison of the values."""
    if isinstance(value, jax.Array) and not value.is_fully_addressable:
        return jax.device_put(value, sharding)  # global already (restored from a checkpoint)
    return jax.make_array_from_callback(np.shape(value), sharding, lambda index: value[index])


def replicated_placer(mesh: Mesh) -> Callable:
    """tree -> the same tree replicated over the mesh of several processes (rows swapped into the pool)."""
    replicated = NamedSharding(mesh, PartitionSpec())
    return lambda tree: jax.tree.map(lambda a: from_local(a, replicated), tree)


def replay_shardings(buffer, mesh: Mesh):
    """The shardings of a replay (vmax_sim.training.replay.TransitionReplay): every per-block leaf split over its
    leading (block) axis, the shared write position and size replicated."""
    split = NamedSharding(mesh, PartitionSpec("data"))
    replicated = NamedSharding(mesh, PartitionSpec())
    rows = buffer.rows.replace(data=jax.tree.map(lambda _: split, buffer.rows.data), position=replicated,
                               size=replicated)
    return buffer.replace(rows=rows, kept=jax.tree.map(lambda _: split, buffer.kept))


def shard_carry(carry: TrainCarry, pool, mesh: Mesh):
    """Places the carry (envs and buffer split, the rest replicated) and the pool (replicated)."""
    split = NamedSharding(mesh, PartitionSpec("data"))
    replicated = NamedSharding(mesh, PartitionSpec())
    place = jax.device_put if jax.process_count() == 1 else from_local

    def by_leading_axis(tree):
        return jax.tree.map(lambda a: place(a, split if getattr(a, "ndim", 0) > 0 else replicated), tree)

    env = carry.env
    batched = env.replace(next_scenario=None, key=None)
    batched = by_leading_axis(batched).replace(next_scenario=place(env.next_scenario, replicated),
                                               key=place(env.key, replicated))
    buffer = carry.buffer
    if buffer is not None:
        buffer = jax.tree.map(place, buffer, replay_shardings(buffer, mesh))
    carry = carry.replace(learner=jax.tree.map(lambda a: place(a, replicated), carry.learner), env=batched,
                          buffer=buffer, key=place(carry.key, replicated),
                          env_steps=place(carry.env_steps, replicated))
    return carry, jax.tree.map(lambda a: place(a, replicated), pool)
