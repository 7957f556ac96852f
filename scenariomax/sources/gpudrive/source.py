"""`GpuDriveSource`: the pipeline's view of GPUDrive / Nocturne JSON scenarios (one file, one scenario)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure, UnitItem, expand_inputs
from scenariomax.sources.gpudrive.convert import SOURCE_NAME, scenario_windows
from scenariomax.sources.gpudrive.layout import INDEX_FILES, parse_document, read_json
from scenariomax.sources.womd.source import one_line
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE

FILE_PATTERN = "*.json"


@dataclasses.dataclass(frozen=True)
class GpuDriveSource:
    """GPUDrive / Nocturne JSON scenarios. `src`: a `.json` file, a folder (searched recursively) or a glob.
    Nocturne's `valid_files.json` / `invalid_files.json` index files are not scenarios and are skipped."""

    src: str
    sizes: Sizes | None = None
    window_stride: int = DEFAULT_WINDOW_STRIDE
    name: str = SOURCE_NAME

    def __post_init__(self) -> None:
        if self.window_stride <= 0:
            raise ValueError(f"window_stride must be positive, got {self.window_stride}")

    @property
    def budget(self) -> Sizes:
        return self.sizes or Sizes()

    def list_units(self) -> list[str]:
        files = [f for f in expand_inputs(self.src, FILE_PATTERN, "GPUDrive / Nocturne JSON scenarios")
                 if Path(f).name not in INDEX_FILES]
        if not files:
            raise InputError(f"{self.src}: no GPUDrive / Nocturne JSON scenarios (only {', '.join(INDEX_FILES)})")
        return files

    def settings(self) -> dict:
        return {"window_stride": self.window_stride, "sizes": self.budget.as_dict()}

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        raw = parse_document(read_json(unit), unit)  # InputError (one line) for an unreadable or malformed file
        try:
            for item in scenario_windows(raw, self.budget, self.window_stride):
                yield Failure(unit, raw.scenario_id, one_line(item)) if isinstance(item, Exception) else item
        except Exception as error:  # noqa: BLE001 - fault isolation: a bad scenario never stops the run
            yield Failure(unit, raw.scenario_id, one_line(error))
