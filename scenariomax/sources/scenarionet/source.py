"""`ScenarioNetSource`: the pipeline's view of ScenarioNet databases (or single scenario `.pkl` files).

A database is a folder with `dataset_mapping.pkl` ({file name: folder relative to the database})
and/or `dataset_summary.pkl` ({file name: metadata}); the index, not a file-name pattern, says which
files are scenarios (ScenarioNet's own files are `sd_*.pkl`, MetaDrive's assets `0.pkl`...).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator, Mapping
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure, UnitItem, expand_inputs
from scenariomax.sources.scenarionet.convert import SOURCE_NAME, description_windows, scenario_name
from scenariomax.sources.scenarionet.unpickle import INDEX_LIMITS, load_pickle
from scenariomax.sources.womd.source import one_line
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE

SUMMARY_FILE, MAPPING_FILE = "dataset_summary.pkl", "dataset_mapping.pkl"
INDEX_FILES = (SUMMARY_FILE, MAPPING_FILE)


def is_database(directory: Path) -> bool:
    return any((directory / name).is_file() for name in INDEX_FILES)


def _index(path: Path, what: str) -> Mapping:
    index = load_pickle(path, INDEX_LIMITS)
    if not isinstance(index, Mapping) or not all(isinstance(name, str) and name for name in index):
        raise InputError(f"{path}: expected a dict of scenario file name -> {what}")
    return index


def database_files(directory: Path) -> list[Path]:
    """Scenario files one database names. The mapping gives each file's folder; without a mapping,
    the summary's keys are files beside it (the summary is not read when a mapping exists: it can
    be large, and ScenarioNet writes both with the same keys)."""
    if (directory / MAPPING_FILE).is_file():
        mapping = _index(directory / MAPPING_FILE, "relative folder")
        if not all(isinstance(folder, str) for folder in mapping.values()):
            raise InputError(f"{directory / MAPPING_FILE}: expected a dict of scenario file name -> relative folder")
        return [directory / folder / name for name, folder in mapping.items()]
    return [directory / name for name in _index(directory / SUMMARY_FILE, "metadata")]


def _loose_pickles(directory: Path, names: list[str]) -> list[Path]:
    return [directory / name for name in names if name.endswith(".pkl") and name not in INDEX_FILES]


def find_scenario_files(root: Path) -> list[str]:
    """Scenario files under `root`: what each database (a folder with an index, at any depth) names,
    plus every other `.pkl` in folders that belong to no database. Files in a database folder that
    its index leaves out are not scenarios (ScenarioNet's filters keep files and rewrite the index).
    Files an index names but that are missing stay in the list: reading them reports the problem."""
    found: set[str] = set()
    databases: list[Path] = []
    for folder, subfolders, names in os.walk(root):
        subfolders.sort()
        here = Path(folder)
        if is_database(here):
            databases.append(here)
            found.update(os.path.abspath(path) for path in database_files(here))
        elif not any(here.is_relative_to(db) for db in databases):
            found.update(os.path.abspath(path) for path in _loose_pickles(here, names))
    return sorted(found)


@dataclasses.dataclass(frozen=True)
class ScenarioNetSource:
    """ScenarioNet scenario descriptions. `src`: a scenario `.pkl`, an index file, a folder (databases
    found at any depth, see `find_scenario_files`) or a glob of `.pkl` files."""

    src: str
    sizes: Sizes | None = None
    window_stride: int = DEFAULT_WINDOW_STRIDE
    orient_edges: bool = True  # as `WomdSource.orient_edges`
    name: str = SOURCE_NAME

    @property
    def budget(self) -> Sizes:
        return self.sizes or Sizes()

    def list_units(self) -> list[str]:
        path = Path(self.src)
        if path.is_file() and path.name in INDEX_FILES:
            path = path.parent  # an index file stands for its database
        if path.is_dir():
            files = find_scenario_files(path)
            if not files:
                raise InputError(f"{self.src}: no ScenarioNet scenario files (*.pkl, or a {SUMMARY_FILE} / "
                                 f"{MAPPING_FILE} naming them) found in this directory")
            return files
        pickles = expand_inputs(self.src, "*.pkl", "ScenarioNet pickles")
        return [u for u in pickles if Path(u).name not in INDEX_FILES]

    def settings(self) -> dict:
        return {"window_stride": self.window_stride, "orient_edges": self.orient_edges,
                "sizes": self.budget.as_dict()}

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        desc = load_pickle(unit)  # InputError for an unreadable, refused or oversized file
        if not isinstance(desc, Mapping) or not isinstance(desc.get("tracks"), Mapping):
            raise InputError(f"{unit}: not a ScenarioNet scenario description (a dict with a 'tracks' dict)")
        ref = scenario_name(desc, Path(unit).stem)
        try:
            for item in description_windows(desc, self.budget, self.window_stride, default_id=ref,
                                            orient_edges=self.orient_edges):
                yield Failure(unit, ref, one_line(item)) if isinstance(item, Exception) else item
        except Exception as error:  # noqa: BLE001 - fault isolation: a bad scenario never stops the run
            yield Failure(unit, ref, one_line(error))
