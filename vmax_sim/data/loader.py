"""`make_data_iterator`: shards -> shuffled, repeated, batched SimulatorStates, prefetched on a thread.

Host work (decoding, cropping, map-index building) runs in a background thread that keeps
`prefetch` device batches ready, so the jitted simulator does not wait for the data. Map indices come from
the disk cache of `vmax_sim.data.map_index_cache` when it holds the shard (built and written there otherwise).
"""

from __future__ import annotations

import collections
import dataclasses
import multiprocessing
import queue
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import jax
import numpy as np

from scenariomax import Scenario, ShardRecord, iter_shard_records, list_shard_files
from scenariomax.errors import InputError
from vmax_sim.data.config import DataConfig
from vmax_sim.data.convert import scenario_to_numpy_state, stack_states
from vmax_sim.data.map_index_cache import IndexSource, MapIndexCache, open_map_index_cache
from vmax_sim.datatypes import SimulatorState

_END = object()
IndexedScenario = tuple[Scenario, IndexSource | None]  # a scenario and where its map index comes from (None: built)
IndexedRecord = tuple[ShardRecord, IndexSource | None]  # the same before the record is read


def _shard_files(path: str) -> list[Path]:
    try:
        return list_shard_files(path)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None


def _records_once(files: list[Path], rng: np.random.Generator | None,
                  cache: MapIndexCache | None) -> Iterator[IndexedRecord]:
    order = rng.permutation(len(files)) if rng is not None else range(len(files))
    for index in order:
        rows = cache.shard_rows(files[index]) if cache is not None else None
        for record in iter_shard_records(files[index]):
            yield record, rows.source(record.index) if rows is not None else None


def _read(item: IndexedRecord) -> IndexedScenario:
    """The record's scenario, checked as `scenariomax validate` checks it (~1 ms): a bad value stops the run in one
    line naming the file and record, before it reaches the simulator."""
    record, source = item
    scenario = record.read()
    problems = scenario.validate()
    if problems:
        raise InputError(f"{record.file} record {record.index} ({scenario.scenario_id}): {problems[0]}"
                         f"{f' (and {len(problems) - 1} more)' if len(problems) > 1 else ''}; `scenariomax validate` "
                         f"lists every problem")
    return scenario, source


def _shuffled(scenarios: Iterable, rng: np.random.Generator, buffer_size: int) -> Iterator:
    """Reservoir-style shuffle buffer of record locations (a few hundred bytes each, where a decoded scenario
    is ~2 MB): memory does not grow with `buffer_size` or the data size."""
    buffer: list = []
    for scenario in scenarios:
        if len(buffer) < buffer_size:
            buffer.append(scenario)
            continue
        slot = int(rng.integers(buffer_size))
        yield buffer[slot]
        buffer[slot] = scenario
    for slot in rng.permutation(len(buffer)):
        yield buffer[slot]


def _indexed_records(config: DataConfig, cache: MapIndexCache | None) -> Iterator[IndexedRecord]:
    files = _shard_files(config.path)
    rng = np.random.default_rng(config.shuffle_seed) if config.shuffle_seed is not None else None
    while True:
        count = 0
        stream = _records_once(files, rng, cache)
        if rng is not None and config.shuffle_buffer > 1:
            stream = _shuffled(stream, rng, config.shuffle_buffer)
        for item in stream:
            count += 1
            yield item
        if count == 0:
            raise InputError(f"{config.path}: the shard files hold no scenarios")
        if not config.repeat:
            return


def _indexed_scenarios(config: DataConfig, cache: MapIndexCache | None) -> Iterator[IndexedScenario]:
    for item in _indexed_records(config, cache):
        yield _read(item)


def iter_scenarios(config: DataConfig) -> Iterator[Scenario]:
    """Scenarios in the order batches use them: seeded shuffle per pass, repeated when asked."""
    for scenario, _ in _indexed_scenarios(config, None):
        yield scenario


def iter_indexed_scenarios(config: DataConfig) -> Iterator[IndexedScenario]:
    """`iter_scenarios`, each with where its map index comes from (the cache, when on); convert the pairs with
    `indexed_to_numpy_state`. Skipping pairs costs the decode only."""
    yield from _indexed_scenarios(config, open_map_index_cache(config))


def iter_indexed_records(config: DataConfig) -> Iterator[IndexedRecord]:
    """`iter_indexed_scenarios` before the records are read: where each record lies and where its map index comes
    from. Skipping one reads nothing (several training processes each read only their own share);
    `read_indexed_record` reads one."""
    yield from _indexed_records(config, open_map_index_cache(config))


def read_indexed_record(item: IndexedRecord) -> IndexedScenario:
    """The scenario of a pair from `iter_indexed_records` (checked as `iter_indexed_scenarios` checks it)."""
    return _read(item)


def _conversion_config(source: IndexSource | None, config: DataConfig) -> DataConfig:
    if source is None or source.builds_index:
        return config
    return dataclasses.replace(config, include_map_index=False)  # the index comes from the cache


def _finish(state: SimulatorState, item: IndexedScenario, config: DataConfig) -> SimulatorState:
    """Puts a cached index into `state`, or writes the index just built into the cache."""
    scenario, source = item
    if source is None:
        return state
    return source.finish(state, scenario.scenario_id, lambda: scenario_to_numpy_state(scenario, config).map_index)


def indexed_to_numpy_state(item: IndexedScenario, config: DataConfig) -> SimulatorState:
    """`scenario_to_numpy_state` of a pair from `iter_indexed_scenarios`: the same arrays, bit for bit."""
    scenario, source = item
    return _finish(scenario_to_numpy_state(scenario, _conversion_config(source, config)), item, config)


def iter_numpy_states(config: DataConfig) -> Iterator[SimulatorState]:
    """Unbatched host states in scenario order, converted by `num_workers` processes when > 0."""
    if config.num_workers == 0:
        for item in iter_indexed_scenarios(config):
            yield indexed_to_numpy_state(item, config)
        return
    # spawn, not fork: the parent has JAX (and its threads) running.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(config.num_workers, mp_context=context) as pool:
        in_flight: collections.deque = collections.deque()
        for item in iter_indexed_scenarios(config):
            scenario, source = item
            in_flight.append((item, pool.submit(scenario_to_numpy_state, scenario, _conversion_config(source, config))))
            if len(in_flight) >= 2 * config.num_workers + config.batch_size:
                done, future = in_flight.popleft()
                yield _finish(future.result(), done, config)
        while in_flight:
            done, future = in_flight.popleft()
            yield _finish(future.result(), done, config)


def iter_numpy_batches(config: DataConfig) -> Iterator[SimulatorState]:
    """Batches of host (numpy) states with leading axis `batch_size`."""
    pending: list[SimulatorState] = []
    for state in iter_numpy_states(config):
        pending.append(state)
        if len(pending) == config.batch_size:
            yield stack_states(pending)
            pending = []
    if pending and not config.drop_remainder:
        yield stack_states(pending)


class PrefetchIterator:
    """Runs a batch generator on a daemon thread, `capacity` device batches ahead. Errors re-raise here."""

    def __init__(self, batches: Iterator[SimulatorState], capacity: int):
        self._queue: queue.Queue = queue.Queue(maxsize=max(capacity, 1))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._fill, args=(batches,), daemon=True)
        self._thread.start()

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _fill(self, batches: Iterator[SimulatorState]) -> None:
        try:
            for batch in batches:
                if not self._put(jax.device_put(batch)):
                    return
            self._put(_END)
        except Exception as error:  # noqa: BLE001 -- handed to the consumer, which re-raises it
            self._put(error)

    def _get(self):
        while True:
            try:
                return self._queue.get(timeout=1.0)
            except queue.Empty:
                if not self._thread.is_alive() and self._queue.empty():  # died without a word
                    self._stop.set()
                    raise RuntimeError("the data loader thread stopped unexpectedly") from None

    def __iter__(self) -> PrefetchIterator:
        return self

    def __next__(self) -> SimulatorState:
        if self._stop.is_set():
            raise StopIteration
        item = self._get()
        if item is _END:
            self._stop.set()
            raise StopIteration
        if isinstance(item, Exception):
            self._stop.set()
            raise item
        return item

    def close(self) -> None:
        """Stops the background thread and waits for it: it finishes the batch it is building (its map
        indices included) and exits at its next queue operation, so no work outlives the close."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join()

    def __del__(self) -> None:
        self._stop.set()


def make_data_iterator(config: DataConfig) -> Iterator[SimulatorState]:
    """Device batches of SimulatorState, shape (batch_size, ...), prefetched in the background."""
    _shard_files(config.path)  # fail fast, in the caller's thread, on a wrong path
    batches = iter_numpy_batches(config)
    if config.prefetch == 0:
        return (jax.device_put(batch) for batch in batches)
    return PrefetchIterator(batches, config.prefetch)


def load_batch(config: DataConfig, num_scenarios: int | None = None) -> SimulatorState:
    """The first `num_scenarios` scenarios of `config.path` (all when None) as one device batch."""
    states = []
    files = _shard_files(config.path)
    for item in _records_once(files, None, open_map_index_cache(config)):
        if num_scenarios is not None and len(states) >= num_scenarios:
            break
        states.append(indexed_to_numpy_state(_read(item), config))
    if not states:
        raise InputError(f"{config.path}: the shard files hold no scenarios")
    return jax.device_put(stack_states(states))
