"""The shards of a long run checked before it starts, so that a damaged record stops it at once instead of
minutes and gigabytes in.

- Always (unless skipped): every record's framing and CRC32C, reading each file once without decoding
  (google-crc32c runs at GB/s: seconds for the 4.5 GB default split; a progress line per file when long).
  The loader's per-record `Scenario.validate` (NaN, negative sizes, ...) still runs as records are read.
- `deep`: every record decoded and held against `scenariomax validate --deep`'s plausibility bounds
  (positions of 1e9 m, impossible speeds or jumps): ~1-3 ms a record, opt-in.

The first bad record ends the check with one line naming the file, the record and the reason.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.io import RecordError, iter_records
from scenariomax.progress import Progress
from scenariomax.validate import BadRecord, check_record, format_bad, plausibility_problems, resolve_files
from vmax_sim.data.mixture import SYNTHETIC, parse_sources

SKIP_HINT = "--skip-checks starts anyway"


def shard_paths(specs: Iterable[str]) -> list[str]:
    """The shard paths of data specs (a path, a glob or a weighted mixture); empty specs and the embedded
    synthetic split (generated here, not read from a user's files) are left out."""
    paths: list[str] = []
    for spec in specs:
        if spec:
            paths += [source.path for source in parse_sources(spec) if source.path != SYNTHETIC]
    return list(dict.fromkeys(paths))


def _record_problem(data: bytes, deep: bool) -> tuple[str, str] | None:
    """(scenario id, reason) of a record that fails the deep check, else None."""
    check = check_record(data)
    problems = list(check.problems)
    if check.scenario is not None:
        problems += plausibility_problems(check.scenario)
    return (check.scenario_id, problems[0]) if problems else None


def _check_file(file: Path, deep: bool) -> int:
    """Records in `file`; InputError on the first damaged (or, with deep, implausible) one."""
    index = 0
    try:
        for data in iter_records(file, check_crc=True):
            found = _record_problem(data, deep) if deep else None
            if found:
                line = format_bad(BadRecord(str(file), index, found[0], found[1]))
                raise InputError(f"{line}; {SKIP_HINT}")
            index += 1
    except RecordError as error:
        raise InputError(f"{format_bad(BadRecord(str(file), index, '', str(error)))}; {SKIP_HINT}") from None
    except OSError as error:
        raise InputError(f"{file}: cannot read ({error.strerror or error})") from None
    return index


def check_shards(paths: Sequence[str], deep: bool = False, progress: bool = True,
                 share: tuple[int, int] = (0, 1)) -> int:
    """Checks every record under `paths` (see the module docstring); returns how many there are.
    share=(index, count): only files index, index + count, ... (the processes of one training run split the check)."""
    files = [file for path in paths for file in resolve_files(path)][share[0]::share[1]]
    what = "checking shards (framing, CRC" + (", plausibility)" if deep else ")")
    total = 0
    with Progress(what, len(files), "files", enabled=progress and len(files) > 1) as shown:
        for file in files:
            total += _check_file(file, deep)
            shown.update(1)
    return total


__all__ = ["check_shards", "shard_paths"]
