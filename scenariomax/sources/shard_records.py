"""A Source over existing record files: our shards or raw WOMD motion tf.Example files.

Used by `scenariomax build-sdc-paths` to enrich existing data through the same pipeline.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

from scenariomax.codec import SchemaError, decode_scenario
from scenariomax.io.example import ExampleError
from scenariomax.io.tfrecord import RecordError, iter_records
from scenariomax.shards import list_shard_files
from scenariomax.sources.base import Failure, InputError, UnitItem


@dataclasses.dataclass(frozen=True)
class ShardRecordsSource:
    src: str
    name: str = "records"

    def list_units(self) -> list[str]:
        try:
            return [str(path) for path in list_shard_files(self.src)]
        except FileNotFoundError as error:
            raise InputError(str(error)) from None

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        try:
            for index, data in enumerate(iter_records(unit)):
                try:
                    scenario = decode_scenario(data)
                except (ExampleError, SchemaError, UnicodeDecodeError) as error:
                    yield Failure(unit, f"record {index}", f"{unit}: record {index}: {error}")
                    continue
                if not scenario.source_dataset:
                    scenario = scenario.replace(source_dataset="womd")  # raw WOMD tf.Example input
                yield scenario
        except (RecordError, OSError) as error:
            raise InputError(str(error)) from None

    def settings(self) -> dict:
        return {"src": self.src}
