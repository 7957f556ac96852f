"""How cleanly the logged expert drives every real recording we hold, with a picture of each failure.

Each group of real samples under ../shared/realdata is converted as `scenariomax convert` does (default
sizes: 128 object slots, enrichment on) into a temporary folder, then the `expert` policy (log replay) is
evaluated on it in non-reactive mode. An episode fails a metric when overlap, offroad, red_light,
kinematic_infeasibility or wrong_way > 0.5, comfort < 0.5, driving_direction < 1 or making_progress < 0.5,
counted over judged episodes only (one whose SDC log ends at the start step has no scored step). Every
failed episode is drawn (PNG + GIF) into <out>/<group>/, with an index.html per group.

The line under the table is the issue's bar: the share of judged real-WOMD episodes (the groups recorded in
WOMD, whatever the file format) that are clean, i.e. accurate (no overlap, off-road or red light); >= 98%.

Usage: python benchmarks/expert_replay.py [--realdata PATH] [--out DIR] [--only GROUP,GROUP] [--num-objects N]
Writes <out>/expert_replay.md and <out>/expert_replay.json (default out: runs/expert_replay).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from vmax_sim.evaluation.gallery import Failure, GalleryCollector, capture_episode, is_failed

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_REALDATA = ROOT.parent / "shared" / "realdata"
DEFAULT_OUT = ROOT / "runs" / "expert_replay"
NUM_OBJECTS = 128  # what `scenariomax convert` writes by default: the replay sees every logged object
CLEAN_BAR = 0.98  # issue 24: the logged expert is clean on >= 98% of real WOMD scenes
POLICY = "expert"


@dataclasses.dataclass(frozen=True)
class Group:
    name: str
    dataset: str  # `scenariomax convert --dataset`
    src: str  # relative to the real-data folder
    womd: bool = False  # recorded in WOMD (counted in the real-WOMD clean share)


GROUPS = (
    Group("womd-example", "womd", "womd/motion_data_one_example.tfrecord", womd=True),
    Group("womd-scenario", "womd", "womd/motion_data_one_scenario.tfrecord", womd=True),
    Group("av2", "av2", "av2"),
    Group("scenarionet-nuscenes", "scenarionet", "scenarionet/nuscenes"),
    Group("scenarionet-womd_20s", "scenarionet", "scenarionet/womd_20s", womd=True),
    Group("scenarionet-womd_91steps", "scenarionet", "scenarionet/womd_91steps", womd=True),
    Group("scenarionet-sample", "scenarionet", "scenarionet/sd_nuscenes_v1.0-mini_scene-0553.pkl"),
    Group("gpudrive", "gpudrive", "gpudrive", womd=True),
    Group("nocturne", "gpudrive", "nocturne/example_scenario.json", womd=True),
)

# (episode metric, column title, words for people, fails(value)); wrong_way only where the metrics have it
CHECKS: tuple[tuple[str, str, str, Callable[[float], bool]], ...] = (
    ("overlap", "overlap", "collision", lambda v: v > 0.5),
    ("offroad", "off-road", "off-road", lambda v: v > 0.5),
    ("red_light", "red light", "red light", lambda v: v > 0.5),
    ("comfort", "comfort", "uncomfortable", lambda v: v < 0.5),
    ("kinematic_infeasibility", "kinematics", "kinematically infeasible", lambda v: v > 0.5),
    ("driving_direction", "direction", "against the lane", lambda v: v < 1.0),
    ("wrong_way", "wrong way", "wrong way", lambda v: v > 0.5),
    # not asked for, but the only other way to a V-Max score of 0 (which the gallery calls a failure)
    ("making_progress", "no progress", "no progress", lambda v: v < 0.5),
)


class ReplayError(Exception):
    """Bad command-line input: reported as one line, exit status 2."""


# --- which episodes fail ---------------------------------------------------------------------------

def failing_metrics(episode: dict[str, float]) -> list[str]:
    """The CHECKS metrics an episode fails (none for an unjudged one: it has no scored step)."""
    if episode.get("judged_steps", 1.0) <= 0:
        return []
    return [key for key, _, _, fails in CHECKS if key in episode and fails(float(episode[key]))]


@dataclasses.dataclass(frozen=True)
class ThresholdFailure(Failure):
    """A failure the gallery does not flag by itself (e.g. comfort, or driving_direction = 0.5): says its value."""

    value: float = math.nan

    def describe(self) -> str:
        if self.step is None:
            return f"{self.label} ({self.metric} = {self.value:.2f})"
        return super().describe()


def _first_step(rollout, index: int, metric: str) -> int | None:
    if metric not in rollout.per_step:
        return None  # an episode-level metric
    valid = np.asarray(rollout.step_valid[index], bool)
    fired = np.flatnonzero(valid & (np.asarray(rollout.per_step[metric][index]) > 0.5))
    return int(fired[0]) if fired.size else None


class ReplayCollector(GalleryCollector):
    """The gallery hook, drawing every episode that fails a CHECKS metric: the plain collector draws only the
    ones not accurate or scored 0, so a comfort or driving-direction failure alone would get no picture."""

    def __init__(self, max_failed: int):
        super().__init__(max_failed=max_failed, max_passed=0)
        self.episode_numbers: list[int] = []  # evaluation-order index of each kept capture

    def __call__(self, column: int, ids: Sequence[str], batch, rollout, real: int) -> None:
        kept = self.captures.setdefault(column, [])
        for i in range(real):
            number = self.num_episodes.get(column, 0)
            self.num_episodes[column] = number + 1
            episode = {k: float(np.asarray(v[i])) for k, v in rollout.episode.items()}
            metrics = failing_metrics(episode)
            failed = is_failed(episode) or bool(metrics)
            self.num_failed[column] = self.num_failed.get(column, 0) + int(failed)
            if failed and len(kept) < self.max_failed:
                capture = capture_episode(column, ids[i], batch, rollout, i)
                _add_failures(capture, rollout, i, metrics)
                kept.append(capture)
                self.episode_numbers.append(number)


def _add_failures(capture, rollout, index: int, metrics: Sequence[str]) -> None:
    """Adds the CHECKS failures the gallery missed, so the picture and index.html name them."""
    labels = {key: label for key, _, label, _ in CHECKS}
    known = {failure.metric for failure in capture.failures}
    extra = [ThresholdFailure(m, labels[m], _first_step(rollout, index, m), capture.metrics[m])
             for m in metrics if m not in known]
    if not extra:
        return
    failures = capture.failures + extra
    failures.sort(key=lambda f: (f.step is None, f.step or 0))  # step failures first, as the gallery orders them
    capture.failures, capture.failed = failures, True
    first = failures[0].step
    capture.highlight_step = first if first is not None else max(capture.num_valid_steps - 1, 0)


# --- one group -------------------------------------------------------------------------------------

def convert_group(group: Group, realdata: Path, out: Path, num_objects: int = NUM_OBJECTS) -> tuple[int, list[dict]]:
    """Converts a group as `scenariomax convert --num-objects N` does (enrichment on). -> (scenarios, failures)."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.schema import Sizes
    from scenariomax.sources.registry import make_source

    source = make_source(group.dataset, src=str(realdata / group.src), sizes=Sizes(num_objects=num_objects),
                         orient_edges=False)  # as `scenariomax convert`: the enrichment orients road edges
    transform, transform_settings = make_transform()
    # one worker: in-process, no pool to start for a handful of files
    result = convert(source, ConvertSettings(out=out, workers=1, progress=False, transform=transform,
                                             transform_settings=transform_settings))
    return result.num_scenarios, list(result.failures)


def evaluate_group(shards: Path, gallery_dir: Path, group: Group, batch_size: int, max_pictures: int,
                   num_objects: int = NUM_OBJECTS) -> dict:
    """The expert on one group's shards: its row of the table, failures and pictures."""
    from vmax_sim.evaluation.report import compare_policies

    collector = ReplayCollector(max_pictures)
    (run,) = compare_policies([POLICY], str(shards), num_objects=num_objects, batch_size=batch_size,
                              progress=False, print_fn=lambda line: None, on_batch=collector)
    collector.write(gallery_dir, [run], progress=False, title=f"Expert replay: {group.name}",
                    note=f"{group.dataset} data from {group.src}; every episode failing a replay check is drawn")
    pictures = _pictures(collector, gallery_dir)
    result = run.result
    episodes = result.episodes
    judged = episodes["judged_steps"] > 0
    failed = []
    for i, scenario_id in enumerate(result.scenario_ids):
        metrics = failing_metrics({k: float(v[i]) for k, v in episodes.items()})
        if metrics:
            failed.append({"scenario_id": scenario_id, "episode": i, "metrics": metrics,
                           "values": {m: float(episodes[m][i]) for m in metrics}, "picture": pictures.get(i)})
    counts = {key: sum(key in f["metrics"] for f in failed) for key, *_ in CHECKS if key in episodes}
    return {"scenarios": len(result.scenario_ids), "judged": int(judged.sum()),
            "accuracy": _mean(episodes["accurate"][judged]), "vmax_score": _mean(episodes["vmax_score"][judged]),
            "failures": counts, "failed_episodes": failed, "gallery": str(gallery_dir / "index.html"),
            "unjudged_ids": [sid for sid, ok in zip(result.scenario_ids, judged) if not ok],
            "sums": {"accurate": float(episodes["accurate"][judged].sum()),
                     "vmax_score": float(episodes["vmax_score"][judged].sum())}}


def _pictures(collector: ReplayCollector, gallery_dir: Path) -> dict[int, str]:
    """episode index -> its PNG. GalleryCollector.write names the kept captures NNN-<id> in the order kept
    (all of ours are failed, so none is moved behind a passed one) under the policy's folder."""
    from vmax_sim.evaluation.gallery import _safe

    paths = {}
    for number, (capture, episode) in enumerate(zip(collector.captures.get(0, []), collector.episode_numbers)):
        path = gallery_dir / _safe(POLICY) / f"{number:03d}-{_safe(capture.scenario_id)}.png"
        if path.is_file():
            paths[episode] = str(path)
    return paths


def _mean(values: np.ndarray) -> float | None:
    return float(np.mean(values)) if values.size else None


def replay_group(group: Group, realdata: Path, out: Path, batch_size: int, max_pictures: int,
                 num_objects: int = NUM_OBJECTS) -> dict:
    """Converts then evaluates one group; a group that does not convert gets its one-line error instead."""
    from scenariomax.errors import InputError
    from scenariomax.pipeline import ConversionError

    start = time.perf_counter()
    row: dict = {"group": group.name, "dataset": group.dataset, "src": str(realdata / group.src), "womd": group.womd}
    with tempfile.TemporaryDirectory(prefix=f"expert-replay-{group.name}-") as tmp:
        try:
            num, failures = convert_group(group, realdata, Path(tmp) / "shards", num_objects)
            row["conversion_failures"] = [f"{f['unit']} [{f['scenario']}]: {f['reason']}" for f in failures]
            if num == 0:
                raise InputError("no scenario converted")
            row.update(evaluate_group(Path(tmp) / "shards", out / group.name, group, batch_size, max_pictures,
                                      num_objects))
        except (ConversionError, InputError) as error:
            row["error"] = str(error).splitlines()[0] if str(error) else type(error).__name__
    row["seconds"] = time.perf_counter() - start
    return row


# --- the report ------------------------------------------------------------------------------------

def total_row(rows: Sequence[dict]) -> dict:
    """The sum of the evaluated groups; accuracy and V-Max score averaged over every judged episode."""
    done = [row for row in rows if "error" not in row]
    judged = sum(row["judged"] for row in done)
    keys = {key for row in done for key in row["failures"]}
    return {"group": "total", "scenarios": sum(row["scenarios"] for row in done), "judged": judged,
            "accuracy": sum(row["sums"]["accurate"] for row in done) / judged if judged else None,
            "vmax_score": sum(row["sums"]["vmax_score"] for row in done) / judged if judged else None,
            "failures": {key: sum(row["failures"].get(key, 0) for row in done) for key, *_ in CHECKS if key in keys},
            "failed_episodes": [f for row in done for f in row["failed_episodes"]],
            "seconds": sum(row["seconds"] for row in rows)}


def womd_clean(rows: Sequence[dict]) -> dict | None:
    """Judged and clean (accurate) episodes over the real-WOMD groups, and the share; None without any."""
    done = [row for row in rows if row.get("womd") and "error" not in row]
    judged = sum(row["judged"] for row in done)
    if not judged:
        return None
    clean = round(sum(row["sums"]["accurate"] for row in done))
    return {"judged": judged, "clean": clean, "share": clean / judged, "meets_bar": clean / judged >= CLEAN_BAR}


def format_womd_clean(summary: dict | None) -> str:
    if summary is None:
        return "Real WOMD: no judged episode."
    verdict = "meets" if summary["meets_bar"] else "below"
    return (f"Real WOMD: {summary['clean']} of {summary['judged']} judged episodes clean (no overlap, off-road or "
            f"red light): {100 * summary['share']:.1f}% ({verdict} the {100 * CLEAN_BAR:.0f}% bar).")


def _cell(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def format_table(rows: Sequence[dict], total: dict) -> str:
    """The Markdown table (accuracy and V-Max score as fractions) and the failing episodes below it."""
    columns = [(key, title) for key, title, *_ in CHECKS if key in total["failures"]]
    header = ["group", "scenarios", "judged", "accuracy", "V-Max score"] + [title for _, title in columns]
    header.append("failed episodes")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in [*rows, total]:
        name = f"**{row['group']}**" if row is total else row["group"]
        if "error" in row:
            lines.append("| " + " | ".join([name, f"not evaluated: {row['error']}"] + [""] * (len(header) - 2)) + " |")
            continue
        cells = [name, str(row["scenarios"]), str(row["judged"]), _cell(row["accuracy"]), _cell(row["vmax_score"])]
        cells += [str(row["failures"].get(key, "n/a")) for key, _ in columns]
        cells.append(str(len(row["failed_episodes"])))
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", format_womd_clean(womd_clean(rows)), "",
              "Failure counts are judged episodes with: overlap, offroad, red_light, kinematic_infeasibility or "
              "wrong_way > 0.5; comfort < 0.5; driving_direction < 1 (0.5: 2-6 m against the lane within 1 s, "
              "0: 6 m or more); making_progress < 0.5.", ""]
    lines += format_failures(rows)
    for row in rows:
        if row.get("unjudged_ids"):
            lines.append(f"- {row['group']}: not judged (the SDC's log ends at the start step): "
                         + ", ".join(row["unjudged_ids"]))
        for failure in row.get("conversion_failures", []):
            lines.append(f"- {row['group']}: not converted: {failure}")
    return "\n".join(lines)


def format_failures(rows: Sequence[dict]) -> list[str]:
    failed = [(row["group"], f) for row in rows for f in row.get("failed_episodes", [])]
    if not failed:
        return ["No failing episode."]
    lines = ["Failing episodes (group, scenario id: metric = value, picture):", ""]
    for group, f in failed:
        values = ", ".join(f"{m} = {f['values'][m]:.3g}" for m in f["metrics"])
        lines.append(f"- {group}, {f['scenario_id']}: {values}; {f['picture'] or 'not drawn (--max-pictures)'}")
    return lines


def write_outputs(out: Path, rows: Sequence[dict], total: dict, table: str, settings: dict) -> None:
    (out / "expert_replay.md").write_text(table + "\n")
    clean = [{k: v for k, v in row.items() if k != "sums"} for row in [*rows, total]]
    data = {"settings": settings, "groups": clean[:-1], "total": clean[-1], "real_womd": womd_clean(rows)}
    (out / "expert_replay.json").write_text(json.dumps(data, indent=1) + "\n")


# --- command line ----------------------------------------------------------------------------------

def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realdata", default=None, help=f"real-data folder (default: {DEFAULT_REALDATA})")
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="folder for the table, the JSON and the galleries")
    parser.add_argument("--only", default=None, help="comma-separated groups: " + ", ".join(g.name for g in GROUPS))
    parser.add_argument("--batch-size", type=int, default=8)
    parser.add_argument("--max-pictures", type=int, default=50, help="failed episodes drawn per group")
    parser.add_argument("--num-objects", type=int, default=NUM_OBJECTS,
                        help=f"object slots, as `scenariomax convert --num-objects` (default {NUM_OBJECTS})")
    return parser.parse_args(argv)


def _groups(only: str | None) -> list[Group]:
    if only is None:
        return list(GROUPS)
    names = [name.strip() for name in only.split(",") if name.strip()]
    known = {group.name: group for group in GROUPS}
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        raise ReplayError(f"--only: unknown group(s) {', '.join(unknown) or '(none given)'}; "
                          f"choose among {', '.join(known)}")
    return [known[name] for name in names]


def _out_dir(text: str) -> Path:
    out = Path(text)
    if out.exists() and not out.is_dir():
        raise ReplayError(f"--out {out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ReplayError(f"--out {out}: cannot create it ({error.strerror or error})") from None
    if not os.access(out, os.W_OK):
        raise ReplayError(f"--out {out}: not writable")
    return out


def run(argv: Sequence[str] | None = None, print_fn: Callable[[str], None] = print) -> int:
    """The whole benchmark. -> exit status (0: done, or no real data at the default place; 2: bad input)."""
    args = _parse(argv)
    realdata = Path(args.realdata) if args.realdata else DEFAULT_REALDATA
    if not realdata.is_dir():
        if args.realdata is None:
            print_fn(f"no real data at {realdata} (the shared folder is absent): nothing to replay")
            return 0
        raise ReplayError(f"--realdata {realdata}: {'not a folder' if realdata.exists() else 'no such folder'}")
    if args.batch_size < 1 or args.max_pictures < 0 or args.num_objects < 1:
        raise ReplayError("--batch-size and --num-objects must be at least 1 and --max-pictures at least 0")
    groups = _groups(args.only)
    out = _out_dir(args.out)
    start = time.perf_counter()
    rows = []
    for number, group in enumerate(groups, 1):
        if not (realdata / group.src).exists():
            print(f"[{number}/{len(groups)}] {group.name}: skipped, {realdata / group.src} not found", file=sys.stderr)
            continue
        rows.append(replay_group(group, realdata, out, args.batch_size, args.max_pictures, args.num_objects))
        print(f"[{number}/{len(groups)}] {group.name}: {_progress_note(rows[-1])}", file=sys.stderr, flush=True)
    if not rows:
        raise ReplayError(f"--realdata {realdata}: none of the groups' inputs found")
    total = total_row(rows)
    table = format_table(rows, total)
    elapsed = time.perf_counter() - start
    settings = {"realdata": str(realdata), "policy": POLICY, "mode": "non_reactive", "num_objects": args.num_objects,
                "batch_size": args.batch_size, "elapsed_s": elapsed}
    write_outputs(out, rows, total, table, settings)
    print_fn(table)
    print_fn(f"\n{elapsed:.0f} s; wrote {out / 'expert_replay.md'}, {out / 'expert_replay.json'} and a gallery "
             f"per group under {out}")
    return 0


def _progress_note(row: dict) -> str:
    if "error" in row:
        return f"not evaluated: {row['error']} ({row['seconds']:.0f} s)"
    return (f"{row['scenarios']} scenario(s), {len(row['failed_episodes'])} failed, accuracy "
            f"{_cell(row['accuracy'])} ({row['seconds']:.0f} s)")


def main(argv: Sequence[str] | None = None) -> int:
    try:
        return run(argv)
    except ReplayError as error:
        print(f"expert_replay: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
