"""`vmax-sim view`: the scenariomax web viewer for closed-loop rollouts.

Policies run on the first few scenarios through the evaluation code (`compare_policies`, the same
path as `vmax-sim evaluate`; a training run directory is evaluated with its own settings on its
held-out split). An `on_batch` hook keeps, per policy, only the simulated SDC and its per-step
metrics of those scenarios (a few kilobytes each), so memory does not grow with the data. The page
shows the logged scene with every policy's simulated SDC overlaid in its own colour, and a strip
chart of a chosen per-step metric under the map with the failures marked.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from scenariomax.sources.base import InputError
from scenariomax.view.index import ShardIndex, compact_summary
from scenariomax.view.page import ViewResult, write_page
from scenariomax.view.scene import SimTrack, error_scene, pack_scene, scene_from_scenario

DEFAULT_POLICIES = ("constant", "idm")
DEFAULT_NUM_SCENARIOS = 4
_SKIPPED_METRICS = ("sdc_x", "sdc_y", "sdc_yaw")  # drawn on the map already


class RolloutCollector:
    """An evaluation `on_batch` hook keeping the simulated SDC of the first `max_scenarios` scenarios of
    every policy column (see `vmax_sim.evaluation.report.compare_policies`)."""

    def __init__(self, max_scenarios: int):
        self.max_scenarios = max_scenarios
        self.order: list[str] = []  # scenario ids in data order (the first column's)
        self.tracks: dict[str, dict[int, SimTrack]] = {}

    def __call__(self, column: int, ids: Sequence[str], batch, rollout, real: int) -> None:
        from vmax_sim.evaluation.gallery import episode_failures

        for i in range(real):
            scenario_id = ids[i]
            if scenario_id not in self.tracks:
                if len(self.order) >= self.max_scenarios:
                    continue
                self.order.append(scenario_id)
                self.tracks[scenario_id] = {}
            per_step = {k: np.asarray(v[i], np.float32) for k, v in rollout.per_step.items()}
            episode = {k: float(np.asarray(v[i])) for k, v in rollout.episode.items()}
            step_valid = np.asarray(rollout.step_valid[i], bool)
            traj = rollout.trajectory
            sdc = int(np.argmax(np.asarray(batch.object_metadata.is_sdc[i])))
            first = int(np.asarray(traj["first_timestep"][i]))
            x, y, yaw = (np.asarray(traj[k][i][sdc], np.float64) for k in ("x", "y", "yaw"))
            steps = np.arange(x.shape[0])
            # the policy's part of the episode only: from reset to the last valid step
            last = first + int(step_valid.sum())
            valid = np.asarray(traj["valid"][i][sdc], bool) & (steps >= first) & (steps <= last)
            failures = tuple({"metric": f.metric, "label": f.label, "step": f.step}
                             for f in episode_failures(per_step, step_valid, episode))
            self.tracks[scenario_id][column] = SimTrack(
                name=str(column), x=x, y=y, yaw=yaw, valid=valid,
                length=float(np.asarray(traj["length"][i][sdc, first])),
                width=float(np.asarray(traj["width"][i][sdc, first])), first_timestep=first,
                metrics={k: v for k, v in per_step.items() if k not in _SKIPPED_METRICS}, step_valid=step_valid,
                failures=failures, episode=episode)


def is_training_run(path: str) -> bool:
    from vmax_sim.training.run import CONFIG_FILE

    return Path(path).is_dir() and (Path(path) / CONFIG_FILE).is_file()


def _plan(target: str, policies: Sequence[str] | None, data: str | None,
          print_fn: Callable[[str], None]) -> tuple[list[str], str]:
    """(policy entries for compare_policies, shard path the episodes run on)."""
    if is_training_run(target):
        from vmax_sim.training.run import load_run_config, resolve_data

        entries = [target] + [p for p in (policies or ()) if p != target]
        return entries, data or resolve_data(load_run_config(target), print_fn)[1]
    if not Path(target).exists() and not any(ch in target for ch in "*?["):
        raise InputError(f"{target}: no such training run directory, shard file, directory or glob")
    if data:
        raise InputError("--data goes with a training run directory; for shards, pass them as the argument")
    return list(policies or DEFAULT_POLICIES), target


def write_rollout_view(target: str, policies: Sequence[str] | None = None, *, out: str | Path = "rollouts.html",
                       num_scenarios: int = DEFAULT_NUM_SCENARIOS, data: str | None = None, num_objects: int = 64,
                       seed: int = 0, progress: bool = True,
                       print_fn: Callable[[str], None] = print) -> ViewResult:
    """Runs `policies` (names or run directories) on the first `num_scenarios` scenarios of `target` (shards,
    or a training run directory: its policy on its held-out split) and writes the viewer page to `out`."""
    from vmax_sim.evaluation.report import compare_policies

    if num_scenarios < 1:
        raise InputError("--num-scenarios must be at least 1")
    entries, path = _plan(target, policies, data, print_fn)
    index = ShardIndex.build(path)  # one-line errors for a missing path or no shards, before any compiling
    collector = RolloutCollector(num_scenarios)
    runs = compare_policies(entries, path, "non_reactive", num_scenarios=num_scenarios,
                            batch_size=min(num_scenarios, 8), num_objects=num_objects, seed=seed, progress=progress,
                            print_fn=print_fn, on_batch=collector)
    names = [run.name for run in runs]
    wanted = set(collector.order)
    scenes: dict[str, tuple[bytes, dict]] = {}
    for position in range(len(index)):
        if len(scenes) == len(wanted):
            break
        if index.entries[position].scenario_id not in wanted or index.entries[position].scenario_id in scenes:
            continue
        check = index.check(position)
        entry = index.describe(position)
        entry["summary"] = compact_summary(check)
        if check.scenario is None:
            scenes[check.scenario_id] = (error_scene("; ".join(check.problems), entry["id"]), entry)
            continue
        tracks = collector.tracks[check.scenario_id]
        sims = [dataclasses.replace(tracks[c], name=names[c]) for c in sorted(tracks)]
        meta, arrays = scene_from_scenario(check.scenario, summary=entry["summary"], problems=check.problems,
                                           sims=sims)
        scenes[check.scenario_id] = (pack_scene(meta, arrays), entry)
    ordered = [scenes[i] for i in collector.order if i in scenes]
    if not ordered:
        raise InputError(f"{path}: no scenarios to view")
    note = (f"{', '.join(names)} on the first {len(ordered)} scenario(s) of {path} (non_reactive); "
            f"the logged SDC in magenta, each policy's simulated SDC in its colour")
    config = {"mode": "embedded", "title": f"V-Max rollouts - {', '.join(names)}", "note": note,
              "entries": [entry for _, entry in ordered], "file_errors": list(index.file_errors), "initial": 0}
    written = write_page(out, config, [blob for blob, _ in ordered])
    return ViewResult(written, len(ordered), len(index), written.stat().st_size)


__all__ = ["DEFAULT_POLICIES", "RolloutCollector", "is_training_run", "write_rollout_view"]
