"""What every source dataset module provides to the conversion pipeline.

A source lists *units* of work (usually one raw file each, or a chunk of seeds for the synthetic
generator) and turns one unit into Scenarios. Units must be picklable strings so worker processes
(or Ray tasks) can receive them, and `read_unit` must be deterministic so a resumed run reproduces
the same records.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import glob
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol, Union

try:  # a declared dependency; an environment not reinstalled since it came still converts, slower
    import orjson
except ImportError:  # pragma: no cover
    orjson = None

from scenariomax.errors import InputError  # its former home: importers of it from here keep working


@dataclasses.dataclass(frozen=True)
class Failure:
    """One scenario that could not be converted; recorded in the manifest, the run continues."""

    unit: str  # the input file or unit id
    scenario: str  # scenario id or position within the unit
    reason: str  # one line


# A source may put a JSON-serialisable dict under `Scenario.metadata[MANIFEST_NOTES]`: what it decided or
# repaired for that scenario (e.g. which object it chose as the SDC). The pipeline copies it, with the unit and
# scenario id, into the manifest's "notes" list when the scenario is written.
MANIFEST_NOTES = "manifest_notes"

UnitItem = Union["Scenario", Failure]  # noqa: F821 (Scenario imported lazily by sources)


class Source(Protocol):
    """A dataset reader the pipeline can run. Instances must be picklable."""

    name: str  # "synthetic", "womd", ...

    def list_units(self) -> list[str]:
        """Stable, sorted ids of the units of work."""

    def read_unit(self, unit: str) -> Iterator[UnitItem]:
        """Yields Scenarios (or Failures for scenarios that could not be built) for one unit.
        Raises InputError when the whole unit is unreadable."""

    def settings(self) -> dict:
        """Source settings recorded in the manifest (and compared on --resume)."""


def expand_inputs(src: str, pattern: str, description: str) -> list[str]:
    """Sorted input files named by `src`: a file, a directory searched recursively for `pattern`, or a
    glob (its matching files whose names fit `pattern`). Raises InputError naming `src` when none."""
    path = Path(src)
    if path.is_file():
        return [str(path)]
    if path.is_dir():
        files = sorted(str(p) for p in path.rglob(pattern) if p.is_file())
        if not files:
            raise InputError(f"{src}: no {description} ({pattern}) found in this directory")
        return files
    files = sorted(p for p in glob.glob(src, recursive=True)
                   if Path(p).is_file() and fnmatch.fnmatch(Path(p).name, pattern))
    if not files:
        raise InputError(f"{src}: no {description} ({pattern}) found (no such file, directory or glob match)")
    return files


def parse_json(data: bytes) -> object:
    """UTF-8 JSON bytes -> the parsed document. ValueError with a one-line reason (no file name: the caller
    adds it) when the bytes are not UTF-8 or not JSON."""
    # orjson: half the standard parser's time on GPUDrive's 2 MB maps (~15 ms a scenario), the same document but for
    # integer literals beyond 64 bits, which it reads as floats (an id or light state that large is then refused as
    # "a number" where an integer belongs; no real file has one)
    if orjson is not None:
        try:
            return orjson.loads(data)
        except orjson.JSONDecodeError:
            pass  # NaN / Infinity literals (Python's json.dump writes them), lone surrogates, or an error: the
            # standard parser reads what it accepts and words the error
    try:
        return json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as error:
        raise ValueError(f"not UTF-8 text ({error.reason} at byte {error.start})") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"invalid JSON: {error.msg} at line {error.lineno} column {error.colno}") from None
    except RecursionError:
        raise ValueError("invalid JSON: nesting too deep") from None
    except ValueError as error:  # e.g. an integer literal longer than Python's digit limit
        raise ValueError(f"invalid JSON: {' '.join(str(error).split())}") from None
