"""`ScenarioNetSource`: the pipeline's view of a ScenarioNet database (or single `sd_*.pkl` files)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator, Mapping
from pathlib import Path

from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure, InputError, UnitItem, expand_inputs
from scenariomax.sources.scenarionet.convert import SOURCE_NAME, description_windows
from scenariomax.sources.scenarionet.unpickle import load_pickle
from scenariomax.sources.womd.source import one_line
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE

FILE_PATTERN = "sd_*.pkl"
SUMMARY_FILE, MAPPING_FILE = "dataset_summary.pkl", "dataset_mapping.pkl"


def mapped_files(directory: Path) -> list[str]:
    """Scenario files a database's `dataset_mapping.pkl` names ({file name: relative dir})."""
    mapping = load_pickle(directory / MAPPING_FILE)
    if not isinstance(mapping, Mapping):
        raise InputError(f"{directory / MAPPING_FILE}: expected a dict of file name -> relative directory")
    return [str((directory / str(rel) / str(name)).resolve()) for name, rel in mapping.items()]


@dataclasses.dataclass(frozen=True)
class ScenarioNetSource:
    """ScenarioNet scenario descriptions. `src`: a `.pkl` file, a database directory (files named by
    its dataset_mapping.pkl, else every sd_*.pkl found recursively) or a glob."""

    src: str
    sizes: Sizes | None = None
    window_stride: int = DEFAULT_WINDOW_STRIDE
    name: str = SOURCE_NAME

    @property
    def budget(self) -> Sizes:
        return self.sizes or Sizes()

    def list_units(self) -> list[str]:
        path = Path(self.src)
        if path.is_dir():
            listed = expand_inputs(self.src, FILE_PATTERN, "ScenarioNet scenario files")
            found = {str(Path(f).resolve()) for f in listed}
            for mapping in [path / MAPPING_FILE, *path.rglob(f"*/{MAPPING_FILE}")]:
                if mapping.is_file():
                    found.update(f for f in mapped_files(mapping.parent) if os.path.isfile(f))
            return sorted(found)
        pickles = expand_inputs(self.src, "*.pkl", "ScenarioNet pickles")
        return [u for u in pickles if Path(u).name not in (SUMMARY_FILE, MAPPING_FILE)]

    def settings(self) -> dict:
        return {"window_stride": self.window_stride, "sizes": self.budget.as_dict()}

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        desc = load_pickle(unit)  # InputError for an unreadable or refused file
        if not isinstance(desc, Mapping) or "tracks" not in desc or "metadata" not in desc:
            raise InputError(f"{unit}: not a ScenarioNet scenario description (a dict with 'tracks' and 'metadata')")
        ref = str((desc.get("metadata") or {}).get("scenario_id", desc.get("id", Path(unit).stem)))
        try:
            for item in description_windows(desc, self.budget, self.window_stride):
                yield Failure(unit, ref, one_line(item)) if isinstance(item, Exception) else item
        except Exception as error:  # noqa: BLE001 - fault isolation: a bad scenario never stops the run
            yield Failure(unit, ref, one_line(error))
