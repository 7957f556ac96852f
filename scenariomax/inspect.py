"""Statistics over shard files: what `scenariomax inspect PATH` prints.

`inspect_shards` streams records once, validates each (reusing `scenariomax.validate`), summarises
every decodable scenario with the pure `summarize_scenario`, and folds the summaries into
JSON-serialisable totals. `format_report` turns those into an aligned text table. Where a folder holds a
`manifest.json`, the report says whether the folder is the complete output it lists (the cheap checks plus
record counts; `scenariomax validate` adds sha256), and `inspection_ok` is False for any problem found.
"""

from __future__ import annotations

import dataclasses
import os
import struct
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from scenariomax.errors import InputError
from scenariomax.io.skim import skim_scenario_id, skim_scenario_id_in
from scenariomax.io.tfrecord import RecordError, file_compression, iter_records_with_spans
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes, load_schema
from scenariomax.validate import (
    duplicate_problem,
    find_files_to_check,
    format_bad,
    join_reasons,
    manifest_findings,
    scan_records,
)

MAX_LISTED_PROBLEMS = 5
_DIGITS = 4


# --- one scenario ----------------------------------------------------------------------------------

def _names(enum: str, values: np.ndarray) -> dict[str, int]:
    """Counts of enum values, keyed by their schema names (unknown values as `unknown(<v>)`)."""
    names = load_schema().enums[enum]
    uniques, counts = np.unique(np.asarray(values, dtype=np.int64), return_counts=True)
    return {names.get(int(v), f"unknown({int(v)})"): int(c) for v, c in zip(uniques, counts)}


def _sdc_index(scenario: Scenario) -> int | None:
    indices = np.flatnonzero(scenario.is_sdc)
    return int(indices[0]) if indices.size else None  # tolerate broken records: first SDC wins


def _travelled_distance(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> float:
    """Sum of straight segments between consecutive valid steps. (T,), (T,), (T,) -> metres."""
    xy = np.stack([x[valid], y[valid]], axis=-1).astype(np.float64)
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=-1).sum()) if len(xy) > 1 else 0.0


def summarize_scenario(scenario: Scenario) -> dict:
    """Per-scenario numbers (JSON-serialisable) that `inspect_shards` aggregates."""
    s = scenario
    is_present = s.valid.any(axis=1)  # (N,) objects observed at least once
    t = s.num_timesteps
    sdc = _sdc_index(s)
    sdc_block = None
    if sdc is not None:
        sdc_valid = s.valid[sdc]
        now = s.current_time_index
        sdc_block = {
            "index": sdc,
            "num_valid_steps": int(sdc_valid.sum()),
            "speeds": [float(v) for v in s.speed[sdc][sdc_valid]],
            "current_speed": float(s.speed[sdc, now]) if 0 <= now < t and sdc_valid[now] else None,
            "distance_m": _travelled_distance(s.x[sdc], s.y[sdc], sdc_valid),
        }
    rg_valid = s.roadgraph_valid
    tl_valid = s.tl_valid  # (L, T)
    now = s.current_time_index
    path_is_valid = s.path_valid.any(axis=1) if s.path_valid.size else np.zeros((0,), bool)  # (P,)
    return {
        "scenario_id": s.scenario_id,
        "source_dataset": s.source_dataset,
        "num_objects": int(is_present.sum()),
        "objects_by_type": _names("object_type", s.object_type[is_present]),
        "num_valid_object_steps": int(s.valid[is_present].sum()),
        "num_object_steps": int(is_present.sum()) * t,
        "sdc": sdc_block,
        "roadgraph_valid_points": int(rg_valid.sum()),
        "roadgraph_by_type": _names("roadgraph_type", s.roadgraph_type[rg_valid]),
        "num_lights": int(tl_valid.any(axis=1).sum()),
        "light_states": _names("traffic_light_state", s.tl_state[tl_valid]),
        "light_states_now": (_names("traffic_light_state", s.tl_state[:, now][tl_valid[:, now]])
                             if 0 <= now < t else {}),
        "num_paths": int(path_is_valid.sum()),
        "num_on_route_paths": int((path_is_valid & s.path_on_route).sum()),
        "num_controllable": int((s.is_controllable & is_present).sum()),
    }


# --- totals ------------------------------------------------------------------------------------------

@dataclasses.dataclass
class _Totals:
    """Running sums over scenario summaries (kept private: only `inspect_shards` mutates it)."""

    num_scenarios: int = 0
    sources: Counter = dataclasses.field(default_factory=Counter)
    objects_by_type: Counter = dataclasses.field(default_factory=Counter)
    num_objects_sum: int = 0
    num_objects_max: int = 0
    valid_object_steps: int = 0
    object_steps: int = 0
    num_with_sdc: int = 0
    sdc_speed_sum: float = 0.0
    sdc_speed_count: int = 0
    sdc_speed_max: float = float("-inf")
    sdc_current_speed_sum: float = 0.0
    sdc_current_speed_count: int = 0
    sdc_distance_sum: float = 0.0
    sdc_distance_max: float = 0.0
    roadgraph_points_sum: int = 0
    roadgraph_points_max: int = 0
    roadgraph_by_type: Counter = dataclasses.field(default_factory=Counter)
    scenarios_with_lights: int = 0
    lights_sum: int = 0
    light_states: Counter = dataclasses.field(default_factory=Counter)
    scenarios_with_paths: int = 0
    scenarios_with_on_route_path: int = 0
    paths_sum: int = 0
    scenarios_with_controllable: int = 0
    controllable_sum: int = 0

    def add(self, summary: dict) -> None:
        self.num_scenarios += 1
        self.sources[summary["source_dataset"] or "(unset)"] += 1
        self.objects_by_type.update(summary["objects_by_type"])
        self.num_objects_sum += summary["num_objects"]
        self.num_objects_max = max(self.num_objects_max, summary["num_objects"])
        self.valid_object_steps += summary["num_valid_object_steps"]
        self.object_steps += summary["num_object_steps"]
        sdc = summary["sdc"]
        if sdc is not None:
            self.num_with_sdc += 1
            self.sdc_speed_sum += sum(sdc["speeds"])
            self.sdc_speed_count += len(sdc["speeds"])
            self.sdc_speed_max = max([self.sdc_speed_max] + sdc["speeds"])
            if sdc["current_speed"] is not None:
                self.sdc_current_speed_sum += sdc["current_speed"]
                self.sdc_current_speed_count += 1
            self.sdc_distance_sum += sdc["distance_m"]
            self.sdc_distance_max = max(self.sdc_distance_max, sdc["distance_m"])
        self.roadgraph_points_sum += summary["roadgraph_valid_points"]
        self.roadgraph_points_max = max(self.roadgraph_points_max, summary["roadgraph_valid_points"])
        self.roadgraph_by_type.update(summary["roadgraph_by_type"])
        self.scenarios_with_lights += summary["num_lights"] > 0
        self.lights_sum += summary["num_lights"]
        self.light_states.update(summary["light_states"])
        self.scenarios_with_paths += summary["num_paths"] > 0
        self.scenarios_with_on_route_path += summary["num_on_route_paths"] > 0
        self.paths_sum += summary["num_paths"]
        self.scenarios_with_controllable += summary["num_controllable"] > 0
        self.controllable_sum += summary["num_controllable"]


def _ratio(numerator: float, denominator: float) -> float | None:
    return round(float(numerator) / denominator, _DIGITS) if denominator else None


def _sorted_counts(counter: Counter) -> dict[str, int]:
    return {key: int(value) for key, value in sorted(counter.items(), key=lambda kv: (-kv[1], kv[0]))}


def _totals_to_dict(totals: _Totals) -> dict:
    n = totals.num_scenarios
    return {
        "source_datasets": _sorted_counts(totals.sources),
        "objects": {
            "by_type": _sorted_counts(totals.objects_by_type),
            "mean_per_scenario": _ratio(totals.num_objects_sum, n),
            "max_per_scenario": totals.num_objects_max,
            "valid_step_fraction": _ratio(totals.valid_object_steps, totals.object_steps),
        },
        "sdc": {
            "num_scenarios": totals.num_with_sdc,
            "speed_mean": _ratio(totals.sdc_speed_sum, totals.sdc_speed_count),
            "speed_max": round(totals.sdc_speed_max, _DIGITS) if totals.sdc_speed_count else None,
            "current_speed_mean": _ratio(totals.sdc_current_speed_sum, totals.sdc_current_speed_count),
            "distance_mean_m": _ratio(totals.sdc_distance_sum, totals.num_with_sdc),
            "distance_max_m": round(totals.sdc_distance_max, _DIGITS) if totals.num_with_sdc else None,
        },
        "roadgraph": {
            "mean_valid_points": _ratio(totals.roadgraph_points_sum, n),
            "max_valid_points": totals.roadgraph_points_max,
            "points_by_type": _sorted_counts(totals.roadgraph_by_type),
        },
        "traffic_lights": {
            "scenarios_with_lights": totals.scenarios_with_lights,
            "mean_lights_per_scenario": _ratio(totals.lights_sum, n),
            "state_counts": _sorted_counts(totals.light_states),
        },
        "paths": {
            "scenarios_with_paths": totals.scenarios_with_paths,
            "scenarios_with_on_route_path": totals.scenarios_with_on_route_path,
            "mean_valid_paths": _ratio(totals.paths_sum, n),
        },
        "controllable": {
            "scenarios_with_controllable": totals.scenarios_with_controllable,
            "mean_per_scenario": _ratio(totals.controllable_sum, n),
        },
    }


def _scenario_block(summary: dict, file: Path, record_index: int, sizes: Sizes | None,
                    problems: tuple[str, ...]) -> dict:
    block = dict(summary)
    sdc = block.pop("sdc")
    if sdc is not None:
        speeds = sdc.pop("speeds")
        sdc["speed_mean"] = round(float(np.mean(speeds)), _DIGITS) if speeds else None
        sdc["speed_max"] = round(float(np.max(speeds)), _DIGITS) if speeds else None
        sdc["distance_m"] = round(sdc["distance_m"], _DIGITS)
    block["sdc"] = sdc
    block.update(file=str(file), record_index=record_index, found=True,
                 sizes=sizes.as_dict() if sizes else None, problems=list(problems))
    return block


def inspect_shards(path: str | os.PathLike, scenario_id: str | None = None,
                   max_records: int | None = None) -> dict:
    """Streams the records under `path` once and returns JSON-serialisable statistics.

    Records that fail validation (or repeat a scenario id) are counted under "validation"; those that
    still decode are included in the statistics. "manifest" lists what the folders' manifest.json files
    say is wrong. With `scenario_id`, a "scenario" block describes that scenario; InputError, before any
    record is validated, when no record holds that id.
    """
    files = find_files_to_check(path)
    if scenario_id is not None:
        require_scenario(path, files, scenario_id)
    totals = _Totals()
    sizes_seen: Counter = Counter()
    num_records, num_bad, first_problems = 0, 0, []
    block = None
    digests: dict | None = {} if max_records is None else None  # record counts only mean something in full
    first_seen: dict[str, tuple[str, int]] = {}
    for item in scan_records(files, max_records, digests=digests):
        check = item.check
        problems = (item.framing_error,) if check is None else check.problems
        duplicate = duplicate_problem(first_seen, item)
        problems = (*problems, duplicate) if duplicate else problems
        if problems:
            num_bad += 1
            if len(first_problems) < MAX_LISTED_PROBLEMS:
                who = f" ({check.scenario_id})" if check is not None and check.scenario_id else ""
                first_problems.append(f"{item.file.name}: record {item.record_index}{who}: {join_reasons(problems)}")
        if check is None:
            continue
        num_records += 1
        if check.sizes is not None:
            sizes_seen[tuple(sorted(check.sizes.as_dict().items()))] += 1
        if check.scenario is None:
            continue
        summary = summarize_scenario(check.scenario)
        totals.add(summary)
        if scenario_id is not None and block is None and check.scenario_id == scenario_id:
            block = _scenario_block(summary, item.file, item.record_index, check.sizes, check.problems)
    stats = {
        "path": str(path),
        "files": [str(f) for f in files],
        "num_files": len(files),
        "num_records": num_records,
        "num_scenarios": totals.num_scenarios,
        "sizes": [{"sizes": dict(key), "num_records": count} for key, count in sizes_seen.most_common()],
        **_totals_to_dict(totals),
        "validation": {"num_bad_records": num_bad, "first_problems": first_problems},
        "manifest": _manifest_block(manifest_findings(path, files, digests)),
    }
    if max_records is not None:
        stats["max_records"] = max_records
    if scenario_id is not None:
        stats["scenario"] = block or {"scenario_id": scenario_id, "found": False}
    return stats


def _manifest_block(findings) -> dict:
    return {"num_checked": findings.num_checked, "problems": [format_bad(problem) for problem in findings.problems],
            "warnings": list(findings.warnings)}


def inspection_ok(stats: dict) -> bool:
    """False when `inspect_shards` found a bad record, a repeated scenario id or a manifest problem."""
    return stats["validation"]["num_bad_records"] == 0 and not stats["manifest"]["problems"]


def scenario_ids(files: list[Path]) -> Iterator[str]:
    """The scenario id of every record in `files` ("" where none), skimmed without decoding or CRC checks:
    a lookup, fast even for large shards. A file stops at its first damaged frame."""
    for file in files:
        try:
            if file_compression(file) == "gzip":  # no bytes to skim in place: decompress each record once
                yield from _gzip_scenario_ids(file)
                continue
            with open(file, "rb") as stream:
                fd, offset = stream.fileno(), 0
                size = os.fstat(fd).st_size
                while offset + 16 <= size:
                    (length,) = struct.unpack("<Q", os.pread(fd, 8, offset))
                    if offset + 16 + length > size:
                        break
                    yield skim_scenario_id(fd, offset + 12, length)
                    offset += 16 + length
        except OSError:
            continue


def _gzip_scenario_ids(file: Path) -> Iterator[str]:
    try:
        for _, _, data in iter_records_with_spans(file):
            yield skim_scenario_id_in(data)
    except RecordError:
        return  # the file stops at its first damaged record, as a plain one does


def require_scenario(path: str | os.PathLike, files: list[Path], scenario_id: str) -> None:
    """InputError (one line, with a few ids that do exist) unless a record under `path` holds `scenario_id`."""
    examples: list[str] = []
    for found in scenario_ids(files):
        if found == scenario_id:
            return
        if found and found not in examples and len(examples) < 3:
            examples.append(found)
    hint = f"ids look like: {', '.join(examples)}" if examples else "no record there holds a readable id"
    raise InputError(f"no scenario {scenario_id!r} in {path}; {hint}")


def load_scenario(path: str | os.PathLike, scenario_id: str | None = None) -> Scenario:
    """The scenario with `scenario_id` (the first decodable one when None) from the records under
    `path`; InputError when it is not there. Streams, stopping at the match. Like inspect, it reads
    outputs whose manifest reports problems (inspect reports them)."""
    for item in scan_records(find_files_to_check(path)):
        check = item.check
        if check is None or check.scenario is None:
            continue
        if scenario_id is None or check.scenario_id == scenario_id:
            return check.scenario
    wanted = f"scenario {scenario_id!r}" if scenario_id is not None else "a decodable scenario"
    raise InputError(f"{path}: no {wanted} found")


# --- text report -----------------------------------------------------------------------------------

def _fmt(value, unit: str = "") -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        text = f"{value:,.2f}"
    else:
        text = f"{value:,}"
    return text + unit


def _percent(value) -> str:
    return "-" if value is None else f"{100.0 * value:.1f}%"


def _rows(rows: list[tuple[str, str]], indent: int = 2) -> list[str]:
    width = max((len(label) for label, _ in rows), default=0)
    return [" " * indent + f"{label:<{width}}  {value}" for label, value in rows]


def _count_rows(counts: dict[str, int], total_label: str | None = None) -> list[tuple[str, str]]:
    total = sum(counts.values())
    rows = [(name, f"{count:>10,}  {100.0 * count / total:5.1f}%") for name, count in counts.items()]
    if total_label is not None and counts:
        rows.append((total_label, f"{total:>10,}"))
    return rows or [("(none)", "")]


def _sizes_line(sizes: dict) -> str:
    return (f"objects={sizes['num_objects']} steps={sizes['num_past']}+{sizes['num_current']}+{sizes['num_future']} "
            f"roadgraph={sizes['num_roadgraph']} lights={sizes['num_lights']} "
            f"paths={sizes['num_paths']}x{sizes['num_points_per_path']} "
            f"lanes={sizes['num_lanes']}x{sizes['num_lane_links']} agent_paths={sizes['num_agent_paths']}")


def _scenario_lines(block: dict) -> list[str]:
    if not block.get("found"):
        return [f"Scenario {block['scenario_id']}: not found"]
    sdc = block["sdc"] or {}
    rows = [
        ("file", f"{block['file']} (record {block['record_index']})"),
        ("source", block["source_dataset"] or "(unset)"),
        ("objects", f"{block['num_objects']}  " + ", ".join(f"{k} {v}" for k, v in block["objects_by_type"].items())),
        ("SDC slot", _fmt(sdc.get("index"))),
        ("SDC speed now", _fmt(sdc.get("current_speed"), " m/s")),
        ("SDC speed mean/max", f"{_fmt(sdc.get('speed_mean'))} / {_fmt(sdc.get('speed_max'))} m/s"),
        ("SDC distance", _fmt(sdc.get("distance_m"), " m")),
        ("roadgraph points", _fmt(block["roadgraph_valid_points"])),
        ("traffic lights", f"{block['num_lights']}  now: "
                           + (", ".join(f"{k} {v}" for k, v in block["light_states_now"].items()) or "-")),
        ("paths (on route)", f"{block['num_paths']} ({block['num_on_route_paths']})"),
        ("controllable", _fmt(block["num_controllable"])),
        ("problems", "; ".join(block["problems"]) or "none"),
    ]
    return [f"Scenario {block['scenario_id']}"] + _rows(rows)


def _manifest_verdict(stats: dict) -> str:
    manifest = stats["manifest"]
    if manifest["problems"]:
        return f"{len(manifest['problems'])} problem(s)"
    if manifest["num_checked"]:
        counts = "" if "max_records" in stats else ", record counts match"
        return f"OK (complete: every listed shard present, none unlisted{counts})"
    if manifest["warnings"]:
        return "none: completeness cannot be checked"
    return "none"


def format_report(stats: dict) -> str:
    """An aligned, plain-text report of `inspect_shards` statistics."""
    objects, sdc, rg = stats["objects"], stats["sdc"], stats["roadgraph"]
    lights, paths, ctrl = stats["traffic_lights"], stats["paths"], stats["controllable"]
    validation = stats["validation"]
    n = stats["num_scenarios"]
    lines = [f"Shards: {stats['path']}"]
    summary_rows = [
        ("files", _fmt(stats["num_files"])),
        ("records",
         _fmt(stats["num_records"]) + (f" (first {stats['max_records']})" if "max_records" in stats else "")),
        ("scenarios decoded", _fmt(n)),
        ("sources", ", ".join(f"{k} {v}" for k, v in stats["source_datasets"].items()) or "-"),
    ]
    summary_rows += [("sizes" if i == 0 else "", f"{_sizes_line(entry['sizes'])}  ({entry['num_records']} records)")
                     for i, entry in enumerate(stats["sizes"])]
    bad = validation["num_bad_records"]
    summary_rows.append(("schema validation", "OK" if bad == 0 else f"{bad} bad record(s)"))
    summary_rows.append(("manifest", _manifest_verdict(stats)))
    rendered = _rows(summary_rows)
    lines += rendered[:-1]
    lines += _rows([("", problem) for problem in validation["first_problems"]], indent=4)
    lines.append(rendered[-1])
    manifest = stats["manifest"]
    lines += _rows([("", line) for line in manifest["problems"][:MAX_LISTED_PROBLEMS]], indent=4)
    if len(manifest["problems"]) > MAX_LISTED_PROBLEMS:
        lines += _rows([("", f"... and {len(manifest['problems']) - MAX_LISTED_PROBLEMS} more")], indent=4)

    lines.append("Objects (observed at least once)")
    lines += _rows(_count_rows(objects["by_type"], "total") + [
        ("per scenario mean/max", f"{_fmt(objects['mean_per_scenario'])} / {_fmt(objects['max_per_scenario'])}"),
        ("valid object-steps", _percent(objects["valid_step_fraction"])),
    ])
    lines.append("SDC")
    lines += _rows([
        ("speed mean/max", f"{_fmt(sdc['speed_mean'])} / {_fmt(sdc['speed_max'])} m/s"),
        ("speed at current step", _fmt(sdc["current_speed_mean"], " m/s") + " (mean)"),
        ("distance mean/max", f"{_fmt(sdc['distance_mean_m'])} / {_fmt(sdc['distance_max_m'])} m"),
    ])
    lines.append("Roadgraph points (valid)")
    lines += _rows(_count_rows(rg["points_by_type"], "total") + [
        ("per scenario mean/max", f"{_fmt(rg['mean_valid_points'])} / {_fmt(rg['max_valid_points'])}"),
    ])
    lines.append("Traffic lights")
    lines += _rows([
        ("scenarios with lights", f"{lights['scenarios_with_lights']} of {n}"),
        ("lights per scenario", _fmt(lights["mean_lights_per_scenario"]) + " (mean)"),
    ])
    lines += _rows(_count_rows(lights["state_counts"]), indent=4)
    lines.append("SDC paths")
    lines += _rows([
        ("scenarios with paths", f"{paths['scenarios_with_paths']} of {n}"),
        ("with an on-route path", f"{paths['scenarios_with_on_route_path']} of {n}"),
        ("valid paths per scenario", _fmt(paths["mean_valid_paths"]) + " (mean)"),
    ])
    lines.append("Controllable agents")
    lines += _rows([
        ("scenarios with any", f"{ctrl['scenarios_with_controllable']} of {n}"),
        ("per scenario", _fmt(ctrl["mean_per_scenario"]) + " (mean)"),
    ])
    if "scenario" in stats:
        lines += _scenario_lines(stats["scenario"])
    return "\n".join(lines)


__all__ = ["format_report", "inspect_shards", "inspection_ok", "load_scenario", "require_scenario", "scenario_ids",
           "summarize_scenario"]
