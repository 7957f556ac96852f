"""The host side of auto-reset: a deterministic stream of converted scenarios feeding the device pool.

Scenario n of the (seeded, shuffled, repeated) stream always lands in pool slot n % pool_size, so
the pool after any number of chunks is a pure function of how many scenarios were consumed: a
resumed run rebuilds it exactly by skipping (decoding only) to that point. A background thread
converts scenarios (map index included) ahead of the learner; `take` blocks only if it is behind,
and the time it waited is reported so a slow loader is visible in the logs.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import queue
import threading
import time
from collections.abc import Iterator

import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.errors import InputError
from vmax_sim.data import DataConfig
from vmax_sim.data.convert import stack_states
from vmax_sim.data.loader import indexed_to_numpy_state, iter_indexed_scenarios
from vmax_sim.data.mixture import is_mixture, iter_mixed_indexed_scenarios, parse_sources
from vmax_sim.datatypes import SimulatorState

_END = object()


def slim_state(state: SimulatorState) -> SimulatorState:
    """Drops the raw roadgraph points (a quarter of a state's bytes): the learning environment's metrics and
    observation read the map index built from them, never the points. One point is kept for the shapes."""
    return state.replace(roadgraph_points=jax.tree.map(lambda a: a[:1], state.roadgraph_points))


def stream_items(config: DataConfig) -> Iterator:
    """The (scenario, map index source) pairs of a training stream: `config.path` is one source, or a weighted
    mixture spec (vmax_sim.data.mixture) drawn with `config.shuffle_seed`."""
    if is_mixture(config.path):
        return iter_mixed_indexed_scenarios(config, parse_sources(config.path), config.shuffle_seed or 0)
    return iter_indexed_scenarios(config)


class ScenarioStream:
    """Converted numpy states of `config`'s scenarios in stream order, from index `start` on."""

    def __init__(self, config: DataConfig, start: int = 0, capacity: int = 32):
        self.consumed = start  # stream index of the next state `take` returns
        self.waited_s = 0.0  # total time `take` blocked
        self._queue: queue.Queue = queue.Queue(maxsize=max(capacity, 1))
        self._stop = threading.Event()
        scenarios = itertools.islice(stream_items(config), start, None)  # map indices from the cache
        self._thread = threading.Thread(target=self._fill, args=(scenarios, config), daemon=True)
        self._thread.start()

    def _fill(self, scenarios: Iterator, config: DataConfig) -> None:
        try:
            for scenario in scenarios:
                state = slim_state(indexed_to_numpy_state(scenario, config))
                while not self._stop.is_set():
                    try:
                        self._queue.put(state, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if self._stop.is_set():
                    return
            self._queue.put(_END)
        except Exception as error:  # noqa: BLE001 -- re-raised in the consumer's thread
            self._queue.put(error)

    def take(self, count: int) -> SimulatorState:
        """The next `count` states stacked (numpy, leading axis count)."""
        states = []
        start = time.perf_counter()
        while len(states) < count:
            item = self._queue.get()
            if item is _END:
                raise RuntimeError("the scenario stream ended (it should repeat forever)")
            if isinstance(item, Exception):
                raise item
            states.append(item)
        self.waited_s += time.perf_counter() - start
        self.consumed += count
        return stack_states(states)

    def close(self) -> None:
        """Stops the converter thread and waits for it (a daemon thread killed at interpreter exit while
        inside numpy / JAX code aborts the process)."""
        self._stop.set()
        while True:  # unblock a put() waiting on a full queue
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        self._thread.join(timeout=30)


def pool_shapes(config: DataConfig, pool_size: int) -> SimulatorState:
    """Shapes and dtypes (jax.ShapeDtypeStruct leaves) of a pool of `config`'s scenarios, from the first one in
    file order: jitted functions compile from them before a stream fills its shuffle buffer."""
    first_source = parse_sources(config.path)[0].path  # every source of a mixture is read with the same sizes
    in_order = dataclasses.replace(config, path=first_source, shuffle_seed=None, repeat=False)
    for item in iter_indexed_scenarios(in_order):
        state = slim_state(indexed_to_numpy_state(item, in_order))
        return jax.tree.map(lambda a: jax.ShapeDtypeStruct((pool_size,) + np.shape(a),
                                                           jax.dtypes.canonicalize_dtype(np.asarray(a).dtype)), state)
    raise InputError(f"{config.path}: the shard files hold no scenarios")


def initial_pool(stream: ScenarioStream, pool_size: int) -> SimulatorState:
    """The first `pool_size` states of a fresh stream, on the device."""
    return jax.device_put(stream.take(pool_size))


def pool_slots(first_index: int, count: int, pool_size: int) -> np.ndarray:
    """Pool slots of stream indices first_index .. first_index + count - 1. (count,) int32"""
    return (np.arange(first_index, first_index + count) % pool_size).astype(np.int32)


@functools.partial(jax.jit, donate_argnums=0)  # in place: no second pool while the new one is written
def _write_rows(pool: SimulatorState, slots: jax.Array, fresh: SimulatorState) -> SimulatorState:
    return jax.tree.map(lambda p, f: p.at[slots].set(f), pool, fresh)


def refresh_pool(pool: SimulatorState, stream: ScenarioStream, count: int) -> SimulatorState:
    """Swaps the next `count` scenarios of the stream into their pool slots (`pool` is donated: use the result)."""
    if count == 0:
        return pool
    pool_size = pool.timestep.shape[0]
    slots = pool_slots(stream.consumed, count, pool_size)
    return _write_rows(pool, jnp.asarray(slots), jax.device_put(stream.take(count)))


def rebuild_pool(config: DataConfig, consumed: int, pool_size: int) -> tuple[SimulatorState, ScenarioStream]:
    """The pool as it was after `consumed` stream scenarios, and the stream positioned after them.

    Slot j holds the latest stream index n < consumed with n % pool_size == j.
    """
    first = max(consumed - pool_size, 0)
    stream = ScenarioStream(config, start=first)
    states = stream.take(consumed - first)
    slots = pool_slots(first, consumed - first, pool_size)
    order = np.argsort(slots)
    pool = jax.tree.map(lambda a: a[order], states)
    return jax.device_put(pool), stream
