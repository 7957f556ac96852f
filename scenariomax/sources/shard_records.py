"""A Source over existing record files: our shards or raw WOMD motion tf.Example files.

Used by `scenariomax build-sdc-paths` to enrich existing data through the same pipeline.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

from scenariomax.codec import SchemaError, decode_scenario
from scenariomax.errors import InputError
from scenariomax.io.example import ExampleError
from scenariomax.io.record_kind import WOMD_SCENARIO_NOT_A_SHARD, looks_like_womd_scenario
from scenariomax.io.tfrecord import RecordError, iter_record_spans, iter_records
from scenariomax.shards import list_shard_files
from scenariomax.sources.base import Failure, UnitItem


@dataclasses.dataclass(frozen=True)
class ShardRecordsSource:
    src: str
    name: str = "records"

    def list_units(self) -> list[str]:
        try:
            units = [str(path) for path in list_shard_files(self.src)]
        except FileNotFoundError as error:
            raise InputError(str(error)) from None
        _refuse_raw_womd_scenarios(units[0])  # the usual mistake: a whole folder of them, said once up front
        return units

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        try:
            for index, data in enumerate(iter_records(unit)):
                try:
                    scenario = decode_scenario(data)
                except (ExampleError, SchemaError, UnicodeDecodeError) as error:
                    if index == 0 and looks_like_womd_scenario(data):  # the whole file is raw WOMD
                        raise InputError(f"{unit}: {WOMD_SCENARIO_NOT_A_SHARD}") from None
                    yield Failure(unit, f"record {index}", str(error))  # the failure names the file already
                    continue
                if not scenario.source_dataset:
                    scenario = scenario.replace(source_dataset="womd")  # raw WOMD tf.Example input
                yield scenario
        except (RecordError, OSError) as error:
            raise InputError(str(error)) from None

    def settings(self) -> dict:
        return {"src": self.src}

    def expected_num_scenarios(self) -> int:
        """Records in the input files, from their length headers (the data is skipped): the progress display
        counts scenarios of this total rather than input files, which can hold thousands of records each."""
        return sum(readable_records(unit) for unit in self.list_units())


def readable_records(path: str) -> int:
    """Records `read_unit` can reach in a file: up to its first damaged frame (0 when it cannot be opened)."""
    count = 0
    try:
        for _ in iter_record_spans(path):
            count += 1
    except (RecordError, OSError):
        pass  # read_unit reports the damage; the records before it still count
    return count


def _refuse_raw_womd_scenarios(unit: str) -> None:
    """InputError when the file's first record is a raw WOMD Scenario proto (one record read)."""
    records = iter_records(unit)
    try:
        first = next(records, None)
    except (RecordError, OSError):
        return  # read_unit reports it, for this file only
    finally:
        records.close()
    if first is not None and looks_like_womd_scenario(first):
        raise InputError(f"{unit}: {WOMD_SCENARIO_NOT_A_SHARD}")
