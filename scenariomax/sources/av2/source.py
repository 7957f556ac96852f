"""`Av2Source`: the conversion pipeline's view of an Argoverse 2 motion forecasting folder.

Layout: one directory per scenario holding `scenario_<id>.parquet` and `log_map_archive_<id>.json`.
Units are those directories (or parquet paths when `--src` names parquet files directly).
"""

from __future__ import annotations

import dataclasses
import glob
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

from scenariomax.errors import InputError
from scenariomax.schema import Sizes, default_sizes
from scenariomax.sources.av2.convert import build_scenario
from scenariomax.sources.av2.errors import Av2FormatError, Av2ScenarioError
from scenariomax.sources.av2.map import Av2Map, load_map_json, parse_map
from scenariomax.sources.av2.tracks import (
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    build_tracks,
    read_columns,
    split_scenarios,
)
from scenariomax.sources.base import Failure, UnitItem

SCENARIO_PATTERN = "scenario_*.parquet"
MAP_PATTERN = "log_map_archive_*.json"
MAX_FILE_BYTES = 512 * 2**20  # AV2 files are ~100 kB; refuse absurdly large inputs up front


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _read_bytes(path: Path) -> bytes:
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise InputError(f"{path}: {size} bytes, larger than any AV2 file ({MAX_FILE_BYTES})")
        return path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read ({_one_line(err.strerror or err)})") from None


def scenario_id_of(parquet: Path) -> str:
    return parquet.name[len("scenario_"):-len(".parquet")] if parquet.name.startswith("scenario_") else parquet.stem


def map_path_for(parquet: Path) -> Path:
    """`log_map_archive_<id>.json` beside the parquet, else the folder's only map archive."""
    exact = parquet.with_name(f"log_map_archive_{scenario_id_of(parquet)}.json")
    if exact.is_file():
        return exact
    candidates = sorted(parquet.parent.glob(MAP_PATTERN))
    if len(candidates) == 1:
        return candidates[0]
    reason = "no map file" if not candidates else f"{len(candidates)} map files and none named for it"
    raise InputError(f"{parquet}: {reason} (expected {exact.name} beside it)")


def load_tracks_table(parquet: Path):
    """Reads the columns we need. Raises InputError naming the file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = _read_bytes(parquet)
    try:
        parquet_file = pq.ParquetFile(pa.BufferReader(data))
        names = set(parquet_file.schema_arrow.names)
        missing = [name for name in REQUIRED_COLUMNS if name not in names]
        if missing:
            raise InputError(f"{parquet}: not an AV2 scenario table (missing columns {missing})")
        wanted = [name for name in REQUIRED_COLUMNS + OPTIONAL_COLUMNS if name in names]
        table = parquet_file.read(columns=wanted)
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 -- pyarrow raises ArrowInvalid/OSError/... on corrupt bytes
        raise InputError(f"{parquet}: unreadable parquet ({_one_line(err)[:200]})") from None
    try:
        return read_columns(table)
    except Av2FormatError as err:
        raise InputError(f"{parquet}: {err}") from None


def load_map(path: Path, lane_speed_limit: float) -> Av2Map:
    try:
        return parse_map(load_map_json(_read_bytes(path)), lane_speed_limit)
    except Av2FormatError as err:
        raise InputError(f"{path}: {_one_line(err)}") from None


def _expand(path: Path) -> list[str]:
    if path.is_file():
        return [str(path)]
    return sorted({str(parquet.parent) for parquet in path.rglob(SCENARIO_PATTERN) if parquet.is_file()})


def list_av2_units(src: str) -> list[str]:
    """Scenario directories (or parquet files) named by `src`: a file, a folder or a glob."""
    root = Path(src)
    if root.exists():
        units = _expand(root)
    else:
        units = sorted({unit for match in glob.glob(src, recursive=True) for unit in _expand(Path(match))})
    if not units:
        raise InputError(f"{src}: no AV2 scenarios ({SCENARIO_PATTERN}) found")
    return units


@dataclasses.dataclass(frozen=True)
class Av2Source:
    """Argoverse 2 motion forecasting scenarios -> Scenarios (see docs/datasets/av2.md)."""

    src: str
    sizes: Sizes | None = None
    lane_speed_limit: float = -1.0  # m/s given to every lane; AV2 has none, -1 = unknown
    name: ClassVar[str] = "av2"

    @property
    def budget(self) -> Sizes:
        return self.sizes or default_sizes()

    def list_units(self) -> list[str]:
        return list_av2_units(self.src)

    def settings(self) -> dict:
        return {"src": self.src, "sizes": self.budget.as_dict(), "lane_speed_limit": self.lane_speed_limit,
                    "window": "SDC valid throughout, current step nearest AV2 step 49"}

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        path = Path(unit)
        if path.is_dir():
            parquets = sorted(p for p in path.glob(SCENARIO_PATTERN) if p.is_file())
            if not parquets:
                raise InputError(f"{path}: no {SCENARIO_PATTERN} in this folder")
        elif path.is_file():
            parquets = [path]
        else:
            raise InputError(f"{path}: no such file or folder")
        for parquet in parquets:
            yield from self.read_scenario_file(parquet)

    def read_scenario_file(self, parquet: Path) -> Iterator[UnitItem]:
        map_path = map_path_for(parquet)
        columns = load_tracks_table(parquet)
        av2_map = load_map(map_path, self.lane_speed_limit)
        for scenario_id, rows in split_scenarios(columns, scenario_id_of(parquet)):
            try:
                tracks = build_tracks(columns, rows, scenario_id)
                yield build_scenario(tracks, av2_map, self.budget)
            except Av2ScenarioError as err:
                yield Failure(str(parquet), scenario_id, _one_line(err))
            except Exception as err:  # noqa: BLE001 -- fault isolation: one bad scenario never stops a run
                yield Failure(str(parquet), scenario_id, _one_line(f"{type(err).__name__}: {err}")[:300])
