"""Several policies evaluated on the same scenarios, and the comparison table of the V-Max benchmark.

`compare_policies` streams the scenarios once: each host batch is converted once and every named
policy runs on it (one compilation per policy), so N policies cost one pass of data loading.
Training run directories are evaluated by the `run_evaluator` the caller passes
(`vmax_sim.training.evaluate_run`, with the run's own observation and environment settings): evaluation does
not import training, which sits above it. `format_markdown` / `table_csv` lay the results out as the V-Max
paper's benchmark table (rows = metrics, columns = policies, values in %).
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from scenariomax.errors import InputError
from scenariomax.progress import Progress
from vmax_sim.data import DataConfig
from vmax_sim.evaluation.evaluate import (
    EvaluationResult,
    PreparedBatches,
    _check_mode,
    _summary,
    evaluate,
    mark_partial,
    partial_note,
    scenario_batches,
    stop_requested,
)
from vmax_sim.evaluation.policies import POLICY_NAMES

# (row label, where the value sits in an evaluation summary: a top-level key or a metric mean)
TABLE_ROWS: tuple[tuple[str, str], ...] = (
    ("Accuracy", "accuracy"),
    ("Collision (overlap)", "overlap"),
    ("Off-road", "offroad"),
    ("Red light", "red_light"),
    ("At-fault collision", "at_fault_collision"),
    ("Progress (ego_progress)", "ego_progress"),
    ("Progress ratio", "progress_ratio"),
    ("Making progress", "making_progress"),
    ("Driving direction", "driving_direction"),
    ("TTC within bound", "ttc_within_bound"),
    ("Speed-limit compliance", "speed_limit_compliance"),
    ("Multiple lanes", "multiple_lanes_score"),
    ("Comfort", "comfort"),
    ("Accuracy at-fault", "accuracy_at_fault"),
    ("nuPlan score", "nuplan_score"),
    ("V-Max score", "vmax_score"),
)

# rows shown only when a policy's summary has them (reactive mode: vmax_sim.evaluation.mode_rollout)
MODE_ROWS: tuple[tuple[str, str], ...] = (
    ("Other collisions (non-SDC)", "other_collision"),
    ("Adversary found", "adversary_found"),
)


# which way each row is better, printed under the table
DIRECTION_NOTE = ("Higher is better, except Collision, Off-road, Red light, At-fault collision and Other collisions "
                  "(lower is better) and Progress ratio (100 = the log's distance).")


@dataclasses.dataclass(frozen=True)
class PolicyRun:
    """One column of the comparison: a policy's evaluation and how long its warm batches took."""

    name: str
    result: EvaluationResult
    warm_seconds: float  # wall time of every batch but the first (which compiles); nan when unknown
    warm_episodes: int  # episodes in those batches

    @property
    def episodes_per_second(self) -> float:
        if self.warm_episodes == 0 or not math.isfinite(self.warm_seconds) or self.warm_seconds <= 0:
            return math.nan
        return self.warm_episodes / self.warm_seconds


def summary_value(summary: dict, key: str) -> float | None:
    """A score (top-level key) or the mean of an episode metric from an evaluation summary."""
    value = summary[key] if key in summary else summary["metrics"].get(key)
    return None if value is None else float(value)


def _unique_names(names: Sequence[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name}#{seen[name]}")
    return out


def split_policies(text: str) -> list[str]:
    """'expert, idm,runs/x' -> ['expert', 'idm', 'runs/x'] (one-line error when empty)."""
    entries = [part.strip() for part in text.split(",") if part.strip()]
    if not entries:
        raise ValueError("--policy needs at least one policy name or run directory")
    return entries


def is_run_directory(entry: str) -> bool:
    """A policy entry that is not a policy name but an existing directory (a training run)."""
    return entry not in POLICY_NAMES and Path(entry).is_dir()


def check_entries(entries: Sequence[str]) -> None:
    for entry in entries:
        if entry not in POLICY_NAMES and not Path(entry).is_dir():
            if "/" in entry or "\\" in entry:  # meant as a path
                raise ValueError(f"{entry}: not a training run directory (no such folder)")
            raise ValueError(f"unknown policy {entry!r}: neither one of {', '.join(POLICY_NAMES)} "
                             "nor a training run directory")


def check_run_evaluator(entries: Sequence[str], run_evaluator: Callable | None) -> None:
    """ValueError (one line) when a training run directory is to be compared but nothing can evaluate it: the
    evaluator comes from training (above evaluation), so the caller passes it."""
    runs = [entry for entry in entries if is_run_directory(entry)]
    if runs and run_evaluator is None:
        raise ValueError(f"{runs[0]}: a training run directory; compare_policies needs "
                         "run_evaluator=vmax_sim.training.evaluate_run to evaluate it")


def compare_policies(entries: Sequence[str], data: str | None, mode: str = "non_reactive", *,
                     num_scenarios: int | None = None, batch_size: int = 8, num_objects: int = 64, seed: int = 0,
                     progress: bool = True, print_fn: Callable[[str], None] = print,
                     on_batch: Callable | None = None, run_evaluator: Callable | None = None,
                     stop=None) -> list[PolicyRun]:
    """Evaluates every entry (a POLICY_NAMES name or a training run directory) on the same scenarios.

    Named policies share one pass over `data` (each batch converted once, then run by every policy);
    run directories go through `run_evaluator` (pass `vmax_sim.training.evaluate_run`; default data: the
    run's held-out split). When `progress`, stderr shows the scenarios done of the total (scenariomax.progress:
    a bar on a terminal, plain lines otherwise). Returns the columns in the order given. on_batch(column, ids,
    host batch, host Rollout with trajectories, number of real episodes) is called after every batch of
    every entry (column: its index in `entries`), see `evaluate`. stop: a flag with `requested` (`evaluate`):
    once set, the batch in flight finishes, its results are marked partial and the entries not started are left
    out of the returned list.
    """
    mode = _check_mode(mode, seed)  # an EvalMode: a name gets `seed` as its perturbation seed
    check_entries(entries)
    check_run_evaluator(entries, run_evaluator)
    named = [entry for entry in entries if not is_run_directory(entry)]
    runs: dict[int, PolicyRun] = {}
    if named:
        if not data:
            raise InputError("--data is required for the policies " + ", ".join(sorted(set(named))))
        config = DataConfig(path=data, batch_size=batch_size, num_objects=num_objects,
                            include_agent_paths=mode.is_reactive)
        for index, run in zip([i for i, e in enumerate(entries) if e in named],
                              _evaluate_named(named, config, mode, num_scenarios, seed, progress,
                                              _column_hooks(entries, named, on_batch), stop)):
            runs[index] = run
    for index, entry in enumerate(entries):
        if index in runs or stop_requested(stop):
            continue
        print_fn(f"evaluating the run {entry} ...")
        start = time.perf_counter()
        hook = None if on_batch is None else functools.partial(on_batch, index)
        stop_kw = {} if stop is None else {"stop": stop}  # an evaluator that cannot stop is still accepted
        result = run_evaluator(entry, data, mode=mode, num_scenarios=num_scenarios, batch_size=batch_size,
                               on_batch=hook, progress=progress, **stop_kw)
        runs[index] = PolicyRun(result.summary["policy"], result, time.perf_counter() - start,
                                result.summary["num_episodes"])  # includes compilation
    ordered = [runs[i] for i in range(len(entries)) if i in runs]
    names = _unique_names([run.name for run in ordered])
    return [dataclasses.replace(run, name=name) for run, name in zip(ordered, names)]


def _column_hooks(entries: Sequence[str], named: Sequence[str], on_batch: Callable | None) -> list:
    """on_batch bound to the column index of each named entry (None each without a hook)."""
    columns = [i for i, entry in enumerate(entries) if entry in named]
    return [None if on_batch is None else functools.partial(on_batch, column) for column in columns]


def _evaluate_named(names: Sequence[str], config: DataConfig, mode: str, num_scenarios: int | None, seed: int,
                    progress: bool, hooks: Sequence | None = None, stop=None) -> list[PolicyRun]:
    parts: list[list[EvaluationResult]] = [[] for _ in names]
    seconds = [0.0 for _ in names]
    warm = [0 for _ in names]
    total = expected_num_scenarios(config.path, num_scenarios) if progress else None
    with Progress("evaluating " + ",".join(names), total, "scenarios", enabled=progress) as shown:
        for number, batch in enumerate(scenario_batches(config, config, num_scenarios)):
            prepared = PreparedBatches(batches=(batch,), data_config=config)
            for i, name in enumerate(names):
                start = time.perf_counter()
                part = evaluate(name, prepared, mode, seed=seed * 1_000_003 + number,
                                on_batch=hooks[i] if hooks else None)
                if number > 0:  # the first batch compiles
                    seconds[i] += time.perf_counter() - start
                    warm[i] += batch[2]
                parts[i].append(part)
            shown.update(batch[2])  # every policy has run these scenarios
            if stop_requested(stop):
                break
    if not parts[0]:
        raise InputError(f"{config.path}: no scenarios to evaluate")
    merged = [_merge(name, mode, results) for name, results in zip(names, parts)]
    if stop_requested(stop):
        total = expected_num_scenarios(config.path, num_scenarios)
        merged = [mark_partial(result, total) for result in merged]
    return [PolicyRun(name, result, seconds[i] if warm[i] else math.nan, warm[i])
            for i, (name, result) in enumerate(zip(names, merged))]


def expected_num_scenarios(path: str | None, num_scenarios: int | None = None) -> int | None:
    """How many scenarios an evaluation of `path` will run (at most `num_scenarios`), for the progress
    display: records counted from the TFRecord length headers, data skipped. None when unknown (no path,
    or a file the reader will report as damaged)."""
    from scenariomax import list_shard_files
    from scenariomax.io import count_records

    if not path:
        return num_scenarios
    total = 0
    try:
        for file in list_shard_files(path):
            left = None if num_scenarios is None else num_scenarios - total
            if left == 0:
                break
            total += count_records(file, limit=left)
    except (ValueError, OSError):  # RecordError, a manifest mismatch: the reader reports it in a moment
        return num_scenarios
    return total


def _merge(name: str, mode: str, parts: Sequence[EvaluationResult]) -> EvaluationResult:
    episodes = {key: np.concatenate([p.episodes[key] for p in parts]) for key in parts[0].episodes}
    ids = tuple(sid for p in parts for sid in p.scenario_ids)
    return EvaluationResult(summary=_summary(episodes, name, mode), episodes=episodes, scenario_ids=ids)


def comparison_rows(runs: Sequence[PolicyRun]) -> list[tuple[str, list[float | None]]]:
    """[(row label, [value in % per policy])] in TABLE_ROWS order."""
    rows = []
    for label, key in TABLE_ROWS + MODE_ROWS:
        values = [summary_value(run.result.summary, key) for run in runs]
        if (label, key) in MODE_ROWS and all(v is None for v in values):
            continue  # a mode's own row only in that mode
        rows.append((label, [None if v is None else 100.0 * v for v in values]))
    return rows


def _cell(value: float | None) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.2f}"


def format_markdown(runs: Sequence[PolicyRun]) -> str:
    """The comparison as a Markdown table (values in %), with episodes and throughput below it."""
    header = ["Metric (%)"] + [run.name for run in runs]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, values in comparison_rows(runs):
        lines.append("| " + " | ".join([label] + [_cell(v) for v in values]) + " |")
    episodes = ", ".join(f"{run.name}: {run.result.summary['num_episodes']}" for run in runs)
    speed = ", ".join(f"{run.name}: {_speed(run)}" for run in runs)
    lines += ["", DIRECTION_NOTE, "", f"episodes: {episodes}",
              f"episodes/s (after the first batch, which compiles): {speed}"]
    note = partial_note({run.name: run.result.summary for run in runs})
    if note:
        lines.append(note)
    unjudged = max(run.result.summary.get("num_unjudged", 0) for run in runs)
    if unjudged:
        lines.append(f"left out of the means: {unjudged} episode(s) with no judged step (the SDC's log ends at "
                     "the start step)")
    return "\n".join(lines)


def _speed(run: PolicyRun) -> str:
    value = run.episodes_per_second
    return "n/a" if not math.isfinite(value) else f"{value:.2f}"


def table_csv(runs: Sequence[PolicyRun]) -> str:
    """The comparison as CSV: metric, then one column per policy (values in %)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["metric"] + [run.name for run in runs])
    for label, values in comparison_rows(runs):
        writer.writerow([label] + ["" if v is None else f"{v:.4f}" for v in values])
    writer.writerow(["episodes"] + [run.result.summary["num_episodes"] for run in runs])
    writer.writerow(["episodes_per_second"] + [f"{run.episodes_per_second:.4f}" for run in runs])
    return buffer.getvalue()


def episodes_csv(result: EvaluationResult) -> str:
    """One row per episode: scenario id and every episode metric."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    keys = sorted(result.episodes)
    writer.writerow(["scenario_id"] + keys)
    for i, scenario_id in enumerate(result.scenario_ids):
        writer.writerow([scenario_id] + [f"{float(result.episodes[k][i]):.6g}" for k in keys])
    return buffer.getvalue()


def _file_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.#@" else "_" for c in name)


def write_report(out_dir: str | Path, runs: Sequence[PolicyRun]) -> list[Path]:
    """Writes table.md, table.csv and episodes-<policy>.csv (one per policy) into out_dir. -> paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"table.md": format_markdown(runs) + "\n", "table.csv": table_csv(runs)}
    for run in runs:
        files[f"episodes-{_file_name(run.name)}.csv"] = episodes_csv(run.result)
    paths = []
    for name, text in files.items():
        path = out / name
        path.write_text(text)
        paths.append(path)
    return paths


# ----------------------------------------------------------------------------- the output directory's settings

SETTINGS_FILE = "evaluation.json"  # what `vmax-sim view EVAL_DIR` needs to re-run the evaluation's episodes


def write_evaluation_settings(out_dir: str | Path, settings: dict) -> Path:
    """Writes the evaluation's inputs (policies, data, mode and its options, seed, num_objects) beside its tables."""
    import json

    path = Path(out_dir) / SETTINGS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(settings, indent=2) + "\n")
    return path


def is_evaluation_dir(path: str | Path) -> bool:
    return Path(path).is_dir() and (Path(path) / SETTINGS_FILE).is_file()


def read_evaluation_settings(eval_dir: str | Path) -> dict:
    """The settings `write_evaluation_settings` stored (one-line InputError when unreadable)."""
    import json

    path = Path(eval_dir) / SETTINGS_FILE
    try:
        settings = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise InputError(f"{path}: not a readable evaluation settings file ({error})") from None
    if not isinstance(settings, dict) or not isinstance(settings.get("policies"), list) or not settings["policies"]:
        raise InputError(f"{path}: no 'policies' list")
    return settings


def scenario_outcomes(eval_dir: str | Path) -> dict[str, bool]:
    """scenario id -> failed (not accurate, or a V-Max score of 0) by any policy, from episodes-*.csv."""
    from vmax_sim.evaluation.gallery import is_failed

    failed: dict[str, bool] = {}
    for path in sorted(Path(eval_dir).glob("episodes-*.csv")):
        with open(path, newline="") as handle:
            for row in csv.DictReader(handle):
                episode = {key: float(row[key]) for key in ("accurate", "vmax_score") if row.get(key)}
                failed[row["scenario_id"]] = failed.get(row["scenario_id"], False) or is_failed(episode)
    return failed
