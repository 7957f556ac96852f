"""The host side of auto-reset: a deterministic stream of converted scenarios feeding the device pool.

Scenario n of the (seeded, shuffled, repeated) stream always lands in pool slot n % pool_size, so
the pool after any number of chunks is a pure function of how many scenarios were consumed: a
resumed run rebuilds it exactly by skipping (reading nothing) to that point. A background thread
converts scenarios (map index included) ahead of the learner; `take` blocks only if it is behind,
and the time it waited is reported so a slow loader is visible in the logs.

With several training processes (`jax.distributed`) each converts only its share of the stream, the indices
n with n % num_processes == process_index, reading nothing of the other records; `take` then exchanges the
shares, so every process holds the same pool as a single process reading the whole stream would.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import queue
import threading
import time
from collections.abc import Callable, Iterator

import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.errors import InputError
from scenariomax.schema import RG_STOP_SIGN
from vmax_sim.data import DataConfig
from vmax_sim.data.convert import stack_states
from vmax_sim.data.loader import (
    indexed_to_numpy_state,
    iter_indexed_records,
    iter_indexed_scenarios,
    read_indexed_record,
)
from vmax_sim.data.mixture import is_mixture, iter_mixed_indexed_records, iter_mixed_indexed_scenarios, parse_sources
from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.agent_view import MAX_STOP_SIGN_POINTS

_END = object()


def slim_state(state: SimulatorState, max_signs: int = MAX_STOP_SIGN_POINTS) -> SimulatorState:
    """Keeps only the stop-sign points of the raw roadgraph (the rest is a quarter of a state's bytes): the
    learning environment's metrics and observation read the map index built from the points, never the points;
    the planners that drive traffic or teach (IDM, PDM-Closed) read the stop signs. The first `max_signs` sign
    points in roadgraph order, padded with invalid points, so every slim state has the same shapes."""
    rg = state.roadgraph_points
    signs = np.flatnonzero(np.asarray(rg.valid) & (np.asarray(rg.types) == RG_STOP_SIGN))[:max_signs]
    index = np.zeros(max_signs, np.int64)
    index[:signs.size] = signs
    kept = jax.tree.map(lambda a: np.asarray(a)[index], rg)
    return state.replace(roadgraph_points=kept.replace(valid=np.arange(max_signs) < signs.size))


def stream_items(config: DataConfig) -> Iterator:
    """The (scenario, map index source) pairs of a training stream: `config.path` is one source, or a weighted
    mixture spec (vmax_sim.data.mixture) drawn with `config.shuffle_seed`."""
    if is_mixture(config.path):
        return iter_mixed_indexed_scenarios(config, parse_sources(config.path), config.shuffle_seed or 0)
    return iter_indexed_scenarios(config)


def stream_records(config: DataConfig) -> Iterator:
    """`stream_items` before the records are read (skipping one reads nothing)."""
    if is_mixture(config.path):
        return iter_mixed_indexed_records(config, parse_sources(config.path), config.shuffle_seed or 0)
    return iter_indexed_records(config)


@dataclasses.dataclass(frozen=True)
class StreamShare:
    """The stream indices one process converts, n % num_processes == process_index, and how the processes'
    shares meet: exchange(tree of (k, ...) numpy leaves) -> every process's, (num_processes, k, ...), the same
    in every process (None with one process)."""

    process_index: int = 0
    num_processes: int = 1
    exchange: Callable | None = None


WHOLE_STREAM = StreamShare()


def own_count(first: int, count: int, share: StreamShare) -> int:
    """How many of the stream indices first .. first + count - 1 are `share`'s."""
    return len(range((share.process_index - first) % share.num_processes, count, share.num_processes))


def share_order(first: int, count: int, num_processes: int) -> tuple[np.ndarray, np.ndarray]:
    """Where stream index first + i comes from: (process (count,), position among that process's own indices
    in the range (count,)), both int."""
    index = np.arange(first, first + count)
    process = index % num_processes
    position = (index - first - (process - first) % num_processes) // num_processes
    return process, position


def interleave(gathered, first: int, count: int, num_processes: int):
    """The exchanged shares (leaves (num_processes, k, ...)) in stream order: leaves (count, ...)."""
    process, position = share_order(first, count, num_processes)
    return jax.tree.map(lambda a: np.asarray(a)[process, position], gathered)


def _pad(states: list, size: int, template) -> list:
    """`states` filled up to `size` with zeros shaped like `template` (the exchange needs equal shapes)."""
    filler = jax.tree.map(np.zeros_like, template)
    return states + [filler] * (size - len(states))


class ScenarioStream:
    """Converted numpy states of `config`'s scenarios in stream order, from index `start` on (this process converts
    its `share`; `take` returns every process's)."""

    def __init__(self, config: DataConfig, start: int = 0, capacity: int = 32, share: StreamShare = WHOLE_STREAM):
        self.consumed = start  # stream index of the next state `take` returns
        self.waited_s = 0.0  # total time `take` blocked (the exchange with other processes included)
        self.share = share
        self._template = None  # one converted state: the shape of the padding of an uneven share
        self._queue: queue.Queue = queue.Queue(maxsize=max(capacity, 1))
        self._stop = threading.Event()
        records = itertools.islice(stream_records(config), start, None)  # map indices from the cache
        own = (record for index, record in enumerate(records, start)
               if index % share.num_processes == share.process_index)
        self._thread = threading.Thread(target=self._fill, args=(own, config), daemon=True)
        self._thread.start()

    def _fill(self, records: Iterator, config: DataConfig) -> None:
        try:
            for record in records:
                state = slim_state(indexed_to_numpy_state(read_indexed_record(record), config))
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
        own = own_count(self.consumed, count, self.share)
        while len(states) < own:
            item = self._queue.get()
            if item is _END:
                raise RuntimeError("the scenario stream ended (it should repeat forever)")
            if isinstance(item, Exception):
                raise item
            states.append(item)
        if self.share.num_processes > 1:
            stacked = self._exchanged(states, count)
        else:
            stacked = stack_states(states)
        self.waited_s += time.perf_counter() - start
        self.consumed += count
        return stacked

    def _exchanged(self, states: list, count: int) -> SimulatorState:
        """Every process's share of the next `count` states, in stream order."""
        num = self.share.num_processes
        if states and self._template is None:
            self._template = states[0]
        if self._template is None:  # only a take shorter than the process count leaves a process nothing
            raise ValueError(f"process {self.share.process_index} has no scenario of the first {count} to share; "
                             f"train.pool_size must be at least the process count ({num})")
        gathered = self.share.exchange(stack_states(_pad(states, -(-count // num), self._template)))
        return interleave(gathered, self.consumed, count, num)

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


def refresh_pool(pool: SimulatorState, stream: ScenarioStream, count: int,
                 place: Callable | None = None) -> SimulatorState:
    """Swaps the next `count` scenarios of the stream into their pool slots (`pool` is donated: use the result).
    place(host tree) puts the new rows where `pool` lives (None: the default device; several processes: every
    process's devices, vmax_sim.training.parallel.replicated_placer)."""
    if count == 0:
        return pool
    pool_size = pool.timestep.shape[0]
    slots = pool_slots(stream.consumed, count, pool_size)
    if place is None:
        return _write_rows(pool, jnp.asarray(slots), jax.device_put(stream.take(count)))
    return _write_rows(pool, place(slots), place(stream.take(count)))


def rebuild_pool(config: DataConfig, consumed: int, pool_size: int,
                 share: StreamShare = WHOLE_STREAM) -> tuple[SimulatorState, ScenarioStream]:
    """The pool as it was after `consumed` stream scenarios, and the stream positioned after them.

    Slot j holds the latest stream index n < consumed with n % pool_size == j.
    """
    first = max(consumed - pool_size, 0)
    stream = ScenarioStream(config, start=first, share=share)
    states = stream.take(consumed - first)
    slots = pool_slots(first, consumed - first, pool_size)
    order = np.argsort(slots)
    pool = jax.tree.map(lambda a: a[order], states)
    return jax.device_put(pool), stream
