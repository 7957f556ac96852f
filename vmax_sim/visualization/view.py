"""`vmax-sim view`: the scenariomax web viewer for closed-loop rollouts.

Policies run on the first few scenarios through the evaluation code (`compare_policies`, the same
path as `vmax-sim evaluate`; a training run directory is evaluated with its own settings on its
held-out split, by `vmax_sim.training.evaluate_run`). The `on_batch` hook that keeps each policy's
simulated SDC and the page it writes are evaluation's (`vmax_sim.evaluation.rollout_view`, re-exported
here): this module runs training runs too, so it sits above training, and evaluation never imports it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.view import ShardIndex, ViewResult
from vmax_sim.evaluation.rollout_view import (
    ReplannedObject,
    RolloutCollector,
    first_positions,
    with_replanned,
    write_collected_view,
)

DEFAULT_POLICIES = ("constant", "idm")
DEFAULT_NUM_SCENARIOS = 4


def is_training_run(path: str) -> bool:
    from vmax_sim.training.run import CONFIG_FILE

    return Path(path).is_dir() and (Path(path) / CONFIG_FILE).is_file()


def run_data(entries: Sequence[str], data: str | None, print_fn: Callable[[str], None]) -> str | None:
    """`data`, else the held-out split of the first training run among `entries` (None when there is none)."""
    if data:
        return data
    from vmax_sim.training.run import load_run_config, resolve_eval_data

    runs = [entry for entry in entries if is_training_run(entry)]
    return resolve_eval_data(load_run_config(runs[0]), print_fn) if runs else None


def _plan(target: str, policies: Sequence[str] | None, data: str | None,
          print_fn: Callable[[str], None]) -> tuple[list[str], str]:
    """(policy entries for compare_policies, shard path the episodes run on)."""
    if is_training_run(target):
        entries = [target] + [p for p in (policies or ()) if p != target]
        return entries, run_data(entries, data, print_fn)
    if not Path(target).exists() and not any(ch in target for ch in "*?["):
        raise InputError(f"{target}: no such training run directory, evaluation directory, shard file, directory "
                         "or glob")
    if data:
        raise InputError("--data goes with a training run directory; for shards, pass them as the argument")
    return list(policies or DEFAULT_POLICIES), target


def write_rollout_view(target: str, policies: Sequence[str] | None = None, *, out: str | Path = "rollouts.html",
                       num_scenarios: int = DEFAULT_NUM_SCENARIOS, data: str | None = None, num_objects: int = 64,
                       seed: int = 0, progress: bool = True,
                       print_fn: Callable[[str], None] = print) -> ViewResult:
    """Runs `policies` (names or run directories) on the first `num_scenarios` scenarios of `target` (shards,
    or a training run directory: its policy on its held-out split; or a `vmax-sim evaluate --out` directory:
    its policies, data and mode on its failed scenarios first) and writes the viewer page to `out`."""
    from vmax_sim.evaluation.report import compare_policies, is_evaluation_dir
    from vmax_sim.training.run_policy import evaluate_run

    if num_scenarios < 1:
        raise InputError("--num-scenarios must be at least 1")
    if is_evaluation_dir(target):
        return _view_evaluation_dir(target, policies, out=out, num_scenarios=num_scenarios, data=data,
                                    num_objects=num_objects, progress=progress, print_fn=print_fn)
    entries, path = _plan(target, policies, data, print_fn)
    ShardIndex.build(path)  # one-line errors for a missing path or no shards, before any compiling
    collector = RolloutCollector(num_scenarios)
    runs = compare_policies(entries, path, "non_reactive", num_scenarios=num_scenarios,
                            batch_size=min(num_scenarios, 8), num_objects=num_objects, seed=seed, progress=progress,
                            print_fn=print_fn, on_batch=collector, run_evaluator=evaluate_run)
    return write_collected_view(collector, [run.name for run in runs], path, out)


def _view_evaluation_dir(eval_dir: str, policies: Sequence[str] | None, *, out: str | Path, num_scenarios: int,
                         data: str | None, num_objects: int, progress: bool,
                         print_fn: Callable[[str], None]) -> ViewResult:
    """Re-runs an evaluation's policies, in its mode, on its failed scenarios first (from its per-episode CSVs):
    the chosen records are copied into a temporary shard so only those episodes are simulated."""
    import tempfile

    from scenariomax.io import TFRecordWriter
    from vmax_sim.evaluation.modes import parse_mode
    from vmax_sim.evaluation.report import compare_policies, read_evaluation_settings, scenario_outcomes
    from vmax_sim.training.run_policy import evaluate_run

    settings = read_evaluation_settings(eval_dir)
    entries = list(settings["policies"]) + [p for p in (policies or ()) if p not in settings["policies"]]
    path = run_data(entries, data or settings.get("data"), print_fn)
    if not path:
        raise InputError(f"{eval_dir}: the evaluation names no data; pass --data")
    index = ShardIndex.build(path)
    failed = scenario_outcomes(eval_dir)  # scenario id -> failed by any policy
    order = [entry.scenario_id for entry in index.entries]
    chosen = ([i for i in order if failed.get(i)] + [i for i in order if not failed.get(i)])[:num_scenarios]
    positions = first_positions(index)
    mode = parse_mode(settings.get("mode", "non_reactive"), agents=settings.get("agents"),
                      perturb_sigma=settings.get("perturb_sigma"), max_agents=settings.get("max_agents"),
                      seed=int(settings.get("seed", 0)))
    with tempfile.TemporaryDirectory(prefix="vmax_view_") as tmp:
        selected = Path(tmp) / "selected.tfrecord"
        with TFRecordWriter(selected) as writer:
            for scenario_id in chosen:
                writer.write(index.read(positions[scenario_id]))
        collector = RolloutCollector(len(chosen))
        runs = compare_policies(entries, str(selected), mode, num_scenarios=len(chosen),
                                batch_size=min(len(chosen), 8), num_objects=settings.get("num_objects", num_objects),
                                seed=int(settings.get("seed", 0)), progress=progress, print_fn=print_fn,
                                on_batch=collector, run_evaluator=evaluate_run)
        collector.order = [i for i in chosen if i in collector.tracks]  # failed first, as chosen
        return write_collected_view(collector, [run.name for run in runs], str(selected), out, mode.name,
                                    label=f"{path} (from the evaluation {eval_dir})")


__all__ = ["DEFAULT_POLICIES", "ReplannedObject", "RolloutCollector", "first_positions", "is_training_run", "run_data",
           "with_replanned", "write_collected_view", "write_rollout_view"]
