"""`NuplanSource`: nuPlan log databases (+ GeoPackage city maps) -> Scenarios."""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Iterator
from typing import ClassVar

import shapely

from scenariomax.errors import InputError
from scenariomax.schema import Sizes, default_sizes
from scenariomax.sources.base import Failure, expand_inputs
from scenariomax.sources.nuplan.convert import build_scenario, scenario_id, window_time_span
from scenariomax.sources.nuplan.log_db import LogSlice, read_log_index, read_log_slice
from scenariomax.sources.nuplan.map_reader import find_map_file, load_city_map
from scenariomax.sources.nuplan.sqlite_access import one_line, open_readonly
from scenariomax.sources.nuplan.windows import anchor_groups, scenario_anchors

DB_SUFFIX = ".db"
# Errors that bad bytes can raise while reading; anything else is a bug and propagates.
_DATA_ERRORS = (sqlite3.Error, ValueError, TypeError, KeyError, IndexError, OverflowError, ZeroDivisionError,
                shapely.errors.ShapelyError)


def expand_db_paths(src: str) -> list[str]:
    """A .db file, a directory (searched recursively) or a glob -> sorted .db paths."""
    return expand_inputs(src, f"*{DB_SUFFIX}", "nuPlan log databases")


@dataclasses.dataclass(frozen=True)
class NuplanSource:
    """nuPlan logs: one unit per .db file; scenarios anchored on scenario tags (and/or a stride)."""

    src: str
    maps_root: str
    sizes: Sizes | None = None
    stride_steps: int | None = None  # extra scenarios every this many 10 Hz steps; None: tags only
    map_margin_m: float = 100.0  # map kept around the ego trajectory's bounding box
    name: ClassVar[str] = "nuplan"

    def list_units(self) -> list[str]:
        return expand_db_paths(self.src)

    def settings(self) -> dict:
        return {"maps_root": str(self.maps_root), "stride_steps": self.stride_steps,
                "map_margin_m": self.map_margin_m, "sizes": self._sizes().as_dict()}

    def _sizes(self) -> Sizes:
        return self.sizes or default_sizes()

    def _scenario_or_failure(self, unit: str, log, data, anchor: int, city, sizes: Sizes):
        try:
            if isinstance(data, Exception):
                raise data
            return build_scenario(log, data, anchor, city, sizes, self.map_margin_m)
        except _DATA_ERRORS as exc:  # InputError is a ValueError too: one bad window fails alone
            reason = one_line(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {one_line(exc)}"
            return Failure(unit, scenario_id(log, anchor), reason)

    def read_unit(self, unit: str) -> Iterator:
        sizes = self._sizes()
        conn = open_readonly(unit)
        try:
            try:
                log = read_log_index(conn, unit)
                anchors = scenario_anchors(len(log.lidar_time), sorted(log.tags), self.stride_steps)
                map_path = find_map_file(self.maps_root, log.map_version)
                minx, miny, maxx, maxy = log.ego_extent
                pad = self.map_margin_m + 10.0  # the box centre sits ahead of the rear axle
                city = load_city_map(str(map_path), log.map_version, (minx - pad, miny - pad, maxx + pad, maxy + pad))
            except InputError:
                raise
            except _DATA_ERRORS as exc:
                raise InputError(f"{unit}: {type(exc).__name__}: {one_line(exc)}") from None
            for group in anchor_groups(anchors):
                try:
                    data: LogSlice | Exception = read_log_slice(conn, unit, *window_time_span(log, group, sizes))
                except _DATA_ERRORS as exc:  # an unreadable stretch fails its scenarios, the rest go on
                    data = exc
                for anchor in group:
                    yield self._scenario_or_failure(unit, log, data, anchor, city, sizes)
        finally:
            conn.close()
