"""The viewer page of evaluated rollouts: an `on_batch` hook that keeps each policy's simulated SDC, and the page.

`RolloutCollector` is an evaluation `on_batch` hook (see `compare_policies` / `evaluate`): it keeps, per policy,
only the simulated SDC and its per-step metrics of the first scenarios (a few kilobytes each), so memory does
not grow with the data. `write_collected_view` writes the scenariomax web viewer page of what it kept: the
logged scene with every policy's simulated SDC overlaid in its own colour, and a strip chart of a chosen per-step
metric under the map with the failures marked. `vmax-sim evaluate --view` and `vmax-sim view`
(vmax_sim.visualization.view) both use them; they live in evaluation so that evaluation never imports upward.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
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


def first_positions(index: ShardIndex) -> dict[str, int]:
    """scenario id -> position of its first record (`ShardIndex.find` for many ids at once)."""
    positions: dict[str, int] = {}
    for position, entry in enumerate(index.entries):
        positions.setdefault(entry.scenario_id, position)
    return positions


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


__all__ = ["ReplannedObject", "RolloutCollector", "first_positions", "with_replanned", "write_collected_view"]
