"""Training data from several sources with weights: `--data synthetic:0.5,shards/womd:0.5`.

A mixture spec lists sources separated by commas, each a shard directory, file or glob with an optional
`:weight` (default 1; weights are normalised). Each draw picks a source with probability proportional to
its weight from one seeded generator, then takes that source's next scenario from its own shuffled,
repeated stream: the sequence is a pure function of the seed, so a resumed run skips to where it was.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

from scenariomax.errors import InputError
from vmax_sim.data.config import DataConfig
from vmax_sim.data.loader import IndexedRecord, IndexedScenario, iter_indexed_records, read_indexed_record

SYNTHETIC = "synthetic"  # the embedded synthetic training split, as a source name


@dataclasses.dataclass(frozen=True)
class WeightedSource:
    path: str  # shard directory, file or glob, or SYNTHETIC
    weight: float  # relative share of the draws, > 0


def _split_weight(part: str) -> tuple[str, float]:
    """'path:0.3' -> ('path', 0.3); a colon not followed by a number belongs to the path."""
    path, colon, tail = part.rpartition(":")
    if colon:
        try:
            return path.strip(), float(tail)
        except ValueError:
            pass
    return part.strip(), 1.0


def parse_sources(spec: str) -> tuple[WeightedSource, ...]:
    """The sources of a data spec (one source without a weight is the plain single-source case)."""
    sources = []
    for part in (p for p in spec.split(",") if p.strip()):
        path, weight = _split_weight(part)
        if not path:
            raise InputError(f"data source {part.strip()!r} names no shards")
        if not (weight > 0 and np.isfinite(weight)):
            raise InputError(f"data source {path}: the weight must be a positive number, got {weight:g}")
        sources.append(WeightedSource(path, weight))
    if not sources:
        raise InputError(f"no data source in {spec!r}")
    return tuple(sources)


def is_mixture(spec: str) -> bool:
    return len(parse_sources(spec)) > 1


def format_sources(sources: tuple[WeightedSource, ...]) -> str:
    """The spec of `sources` (parse_sources' inverse)."""
    if len(sources) == 1:
        return sources[0].path
    return ",".join(f"{source.path}:{source.weight:g}" for source in sources)


def source_probabilities(sources: tuple[WeightedSource, ...]) -> np.ndarray:
    """(S,) float64, the normalised weights."""
    weights = np.array([source.weight for source in sources], np.float64)
    return weights / weights.sum()


def iter_mixed_indexed_scenarios(config: DataConfig, sources: tuple[WeightedSource, ...],
                                 seed: int) -> Iterator[IndexedScenario]:
    """Draws forever from `sources` (config.path is ignored): each source a repeated stream shuffled with its own
    seed, the source of each draw from a generator seeded with `seed`."""
    for item in iter_mixed_indexed_records(config, sources, seed):
        yield read_indexed_record(item)


def iter_mixed_indexed_records(config: DataConfig, sources: tuple[WeightedSource, ...],
                               seed: int) -> Iterator[IndexedRecord]:
    """`iter_mixed_indexed_scenarios` before the records are read (vmax_sim.data.loader.iter_indexed_records)."""
    streams = [iter_indexed_records(dataclasses.replace(config, path=source.path, shuffle_seed=seed + 1 + i,
                                                        repeat=True))
               for i, source in enumerate(sources)]
    probabilities = source_probabilities(sources)
    rng = np.random.default_rng([seed, len(sources)])
    while True:
        yield next(streams[int(rng.choice(len(streams), p=probabilities))])
