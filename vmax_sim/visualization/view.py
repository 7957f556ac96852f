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

from scenariomax.errors import InputError
from scenariomax.view import (
    ShardIndex,
    SimTrack,
    ViewResult,
    compact_summary,
    error_scene,
    pack_scene,
    scene_from_scenario,
    write_page,
)
from vmax_sim.dynamics.bicycle import DT

DEFAULT_POLICIES = ("constant", "idm")
DEFAULT_NUM_SCENARIOS = 4
_SKIPPED_METRICS = ("sdc_x", "sdc_y", "sdc_yaw")  # drawn on the map already


@dataclasses.dataclass(frozen=True)
class ReplannedObject:
    """An object whose simulated trajectory replaces its log on the page (the adversarial mode's attacker)."""

    slot: int  # object slot in the simulated state
    num_objects: int  # slots the state had (maps the slot back to the scenario's object)
    x: np.ndarray  # (T,) metres
    y: np.ndarray  # (T,)
    yaw: np.ndarray  # (T,) radians
    valid: np.ndarray  # (T,) bool


def with_replanned(scenario, replanned: ReplannedObject):
    """The scenario with one object's logged boxes (and speeds, by finite differences) replaced."""
    from vmax_sim.data.convert import object_slots

    index = int(object_slots(scenario, replanned.num_objects)[replanned.slot])
    steps = min(scenario.x.shape[1], len(replanned.x))
    valid = replanned.valid[:steps].astype(bool)
    fields = {}
    for name, values in (("x", replanned.x), ("y", replanned.y), ("bbox_yaw", replanned.yaw)):
        array = np.array(getattr(scenario, name), copy=True)
        array[index, :steps] = np.where(valid, values[:steps], array[index, :steps])
        fields[name] = array
    for name, source in (("velocity_x", fields["x"]), ("velocity_y", fields["y"])):
        array = np.array(getattr(scenario, name), copy=True)
        array[index, :steps] = np.where(valid, np.gradient(source[index, :steps]) / DT, array[index, :steps])
        fields[name] = array
    present = np.array(scenario.valid, copy=True)
    present[index, :steps] = valid
    return scenario.replace(**fields, valid=present)


class RolloutCollector:
    """An evaluation `on_batch` hook keeping the simulated SDC of the first `max_scenarios` scenarios of
    every policy column (see `vmax_sim.evaluation.report.compare_policies`)."""

    def __init__(self, max_scenarios: int, prefer_failures: bool = False, keep_limit: int = 2000):
        self.max_scenarios = max_scenarios
        # prefer_failures: keep up to keep_limit scenarios (a few kB each) and show the failed ones first
        self.prefer_failures = prefer_failures
        self.keep = keep_limit if prefer_failures else max_scenarios
        self.order: list[str] = []  # scenario ids in data order (the first column's)
        self.tracks: dict[str, dict[int, SimTrack]] = {}
        # adversarial mode: scenario id -> the re-planned vehicle (the same plan for every policy column)
        self.adversaries: dict[str, ReplannedObject] = {}

    def selected(self) -> list[str]:
        """The scenarios to show: the first max_scenarios, failed ones (by any policy) first when asked."""
        if not self.prefer_failures:
            return self.order[:self.max_scenarios]
        failed = [i for i in self.order if any(track.failures for track in self.tracks[i].values())]
        passed = [i for i in self.order if i not in set(failed)]
        return (failed + passed)[:self.max_scenarios]

    def __call__(self, column: int, ids: Sequence[str], batch, rollout, real: int) -> None:
        from vmax_sim.evaluation.gallery import episode_failures

        for i in range(real):
            scenario_id = ids[i]
            if scenario_id not in self.tracks:
                if len(self.order) >= self.keep:
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
            slot = int(episode.get("adversary_slot", -1.0)) if episode.get("adversary_found", 0.0) > 0.5 else -1
            if slot >= 0 and scenario_id not in self.adversaries:
                self.adversaries[scenario_id] = ReplannedObject(
                    slot=slot, num_objects=int(np.asarray(traj["x"]).shape[-2]),
                    **{k: np.asarray(traj[k][i][slot]) for k in ("x", "y", "yaw", "valid")})
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


def first_positions(index: ShardIndex) -> dict[str, int]:
    """scenario id -> position of its first record (`ShardIndex.find` for many ids at once)."""
    positions: dict[str, int] = {}
    for position, entry in enumerate(index.entries):
        positions.setdefault(entry.scenario_id, position)
    return positions


def run_data(entries: Sequence[str], data: str | None, print_fn: Callable[[str], None]) -> str | None:
    """`data`, else the held-out split of the first training run among `entries` (None when there is none)."""
    if data:
        return data
    from vmax_sim.training.run import load_run_config, resolve_data

    runs = [entry for entry in entries if is_training_run(entry)]
    return resolve_data(load_run_config(runs[0]), print_fn)[1] if runs else None


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


def write_collected_view(collector: RolloutCollector, names: Sequence[str], path: str, out: str | Path,
                         mode_name: str = "non_reactive", label: str | None = None) -> ViewResult:
    """The viewer page of the rollouts a `RolloutCollector` kept (policy columns named `names`), the logged
    scenes read from the shards at `path`."""
    index = ShardIndex.build(path)
    wanted = collector.selected()
    positions = first_positions(index)
    scenes: dict[str, tuple[bytes, dict]] = {}
    for scenario_id in wanted:
        if scenario_id not in positions:
            continue
        position = positions[scenario_id]
        check = index.check(position)
        entry = index.describe(position)
        entry["summary"] = compact_summary(check)
        if check.scenario is None:
            scenes[scenario_id] = (error_scene("; ".join(check.problems), entry["id"]), entry)
            continue
        tracks = collector.tracks[scenario_id]
        sims = [dataclasses.replace(tracks[c], name=names[c]) for c in sorted(tracks)]
        scenario = check.scenario
        if scenario_id in collector.adversaries:  # draw the attacker where it drove, not where it was logged
            scenario = with_replanned(scenario, collector.adversaries[scenario_id])
        meta, arrays = scene_from_scenario(scenario, summary=entry["summary"], problems=check.problems,
                                           sims=sims)
        scenes[scenario_id] = (pack_scene(meta, arrays), entry)
    ordered = [scenes[i] for i in wanted if i in scenes]
    if not ordered:
        raise InputError(f"{path}: no scenarios to view")
    which = "failed first" if collector.prefer_failures else "the first"
    note = (f"{', '.join(names)} on {len(ordered)} scenario(s) of {label or path} ({mode_name}, {which}); the logged "
            f"SDC in magenta, each policy's simulated SDC in its colour")
    if mode_name == "adversarial":
        note += "; the re-planned adversary is drawn where it drove, the other objects from the log"
    elif mode_name != "non_reactive":
        note += "; the other objects are drawn from the log"
    config = {"mode": "embedded", "title": f"V-Max rollouts - {', '.join(names)}", "note": note,
              "entries": [entry for _, entry in ordered], "file_errors": list(index.file_errors), "initial": 0}
    written = write_page(out, config, [blob for blob, _ in ordered])
    return ViewResult(written, len(ordered), len(index), written.stat().st_size)


def write_rollout_view(target: str, policies: Sequence[str] | None = None, *, out: str | Path = "rollouts.html",
                       num_scenarios: int = DEFAULT_NUM_SCENARIOS, data: str | None = None, num_objects: int = 64,
                       seed: int = 0, progress: bool = True,
                       print_fn: Callable[[str], None] = print) -> ViewResult:
    """Runs `policies` (names or run directories) on the first `num_scenarios` scenarios of `target` (shards,
    or a training run directory: its policy on its held-out split; or a `vmax-sim evaluate --out` directory:
    its policies, data and mode on its failed scenarios first) and writes the viewer page to `out`."""
    from vmax_sim.evaluation.report import compare_policies, is_evaluation_dir

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
                            print_fn=print_fn, on_batch=collector)
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
                                on_batch=collector)
        collector.order = [i for i in chosen if i in collector.tracks]  # failed first, as chosen
        return write_collected_view(collector, [run.name for run in runs], str(selected), out, mode.name,
                                    label=f"{path} (from the evaluation {eval_dir})")


__all__ = ["DEFAULT_POLICIES", "RolloutCollector", "is_training_run", "run_data", "write_collected_view",
           "write_rollout_view"]
