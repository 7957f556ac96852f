"""A held-out synthetic split of people crossing in front of an SDC that waits for them, and a training set like it.

nuScenes scene-0553 (four judged windows of the 29 real scenes) is where most students of the default preset fail at
fault: at the head of a queue at an unlit junction the logged SDC waits while people cross in front of it, and the
student pulls away into them. The held-out synthetic split cannot tell the students that do so from the ones that do
not (docs/learning.md, session 53). This script builds the scenes that isolate the situation, from the generator:

- `probe OUT`: the probe split. Synthetic junction scenes with more people crossing (the knobs of PROBE_BATCHES)
  where the logged SDC stands at the current step while a pedestrian walks through the corridor in front of it within
  the next 4 s, and later drives on; traffic-light states removed (an unlit junction). Evaluate a run on it with
  `vmax-sim evaluate --policy RUN --data "OUT/*.tfrecord"` and read it with `score EVAL_DIR`: the at-fault collisions
  are the number to look at (session 56: checkpoints that pass scene-0553 had 1-3, those that fail it 4-16).
- `train OUT`: scenes of the same kind from other seeds, looser (the SDC stands for >= 5 of its first 30 steps while a
  pedestrian is in front of it), lights kept, to mix into training (`vmax-sim train --data synthetic:0.85,OUT:0.15`).

Usage: python benchmarks/crossing_probe.py probe OUT | train OUT | score EVAL_DIR [--workers N]
"""

from __future__ import annotations

import argparse
import csv
import glob
import tempfile
from pathlib import Path

import numpy as np

STANDING_MPS = 0.5  # the SDC stands below this speed
DRIVES_ON_M = 5.0  # ... and later drives at least this far from where it stood
PEDESTRIAN = 2  # object type enum
# (seed, candidate scenes, knobs) of the probe: the split as measured in session 56 (the second batch adds the SDC
# chosen among the slow starters too, for more standing starts)
_JUNCTIONS = {"walkers_per_crosswalk": (2.0, 5.0), "sdc_waits": 1.0,
              "topology_weights": "intersection4:1,intersection3:1"}
PROBE_BATCHES = ((4242, 600, _JUNCTIONS), (4243, 3000, {**_JUNCTIONS, "sdc_slow_start": 1.0}))
TRAIN_BATCHES = ((5151, 4000, {**_JUNCTIONS, "sdc_slow_start": 1.0}),)


def _in_front(x, y, valid, pose, front_m: float, ahead_m: float, aside_m: float) -> np.ndarray:
    """Whether each pedestrian is in the corridor in front of the SDC at each step: 0..`ahead_m` beyond its front
    (`front_m` ahead of its centre) and within `aside_m` of its centre line. x, y, valid (P, k) of the people;
    pose: the SDC's x, y, yaw, each (k,) (its pose at each step) or a scalar (one pose for all). -> (P, k)"""
    sx, sy, syaw = pose
    dx, dy = x - sx, y - sy
    along = dx * np.cos(syaw) + dy * np.sin(syaw) - front_m
    aside = np.abs(dy * np.cos(syaw) - dx * np.sin(syaw))
    return valid & (along > 0.0) & (along < ahead_m) & (aside < aside_m)


def _drives_on(x, y, valid, sdc: int, start: int) -> bool:
    later = valid[sdc, start:]
    travel = np.hypot(x[sdc, start:][later] - x[sdc, start], y[sdc, start:][later] - y[sdc, start])
    return bool(travel.max(initial=0.0) >= DRIVES_ON_M)


def probe_scene(x, y, yaw, speed, valid, object_type, length, sdc: int, start: int) -> bool:
    """The probe's rule: the SDC stands at step `start`, a pedestrian is within 12 m in front of it (1.8 m aside, in
    its pose there) at some step of the next 40, and it later drives on. Arrays (N, T); object_type (N,)."""
    if not valid[sdc, start] or speed[sdc, start] > STANDING_MPS or not _drives_on(x, y, valid, sdc, start):
        return False
    people = np.flatnonzero(object_type == PEDESTRIAN)
    window = slice(start, start + 40)
    pose = (x[sdc, start], y[sdc, start], yaw[sdc, start])
    return bool(_in_front(x[people, window], y[people, window], valid[people, window], pose, length[sdc, start] / 2,
                          12.0, 1.8).any())


def training_scene(x, y, yaw, speed, valid, object_type, length, sdc: int, start: int) -> bool:
    """The training set's rule: the SDC stands at >= 5 of the 30 steps from `start`, at one of them with a pedestrian
    within 15 m in front of it (2 m aside, in its pose at that step), and later drives on."""
    window = slice(start, start + 30)
    standing = valid[sdc, window] & (speed[sdc, window] < STANDING_MPS)
    if standing.sum() < 5 or not _drives_on(x, y, valid, sdc, start):
        return False
    people = np.flatnonzero(object_type == PEDESTRIAN)
    pose = (x[sdc, window], y[sdc, window], yaw[sdc, window])
    inside = _in_front(x[people, window], y[people, window], valid[people, window], pose, length[sdc, start] / 2,
                       15.0, 2.0)
    return bool((inside & standing).any())


def _matches(scenario, rule) -> bool:
    speed = np.hypot(scenario.velocity_x, scenario.velocity_y)
    return rule(scenario.x, scenario.y, scenario.bbox_yaw, speed, scenario.valid, scenario.object_type,
                scenario.length, scenario.sdc_index, scenario.current_time_index)


def _unlit(scenario):
    """The scenario as an unlit recording: no traffic-light state anywhere."""
    if scenario.tl_valid is None or not scenario.tl_valid.size:
        return scenario
    return scenario.replace(tl_valid=np.zeros_like(scenario.tl_valid), tl_state=np.zeros_like(scenario.tl_state),
                            tl_inferred=np.zeros_like(scenario.tl_inferred))


def build(out: str, batches, rule, unlit: bool, workers: int = 2) -> tuple[int, int]:
    """Generates each batch's candidates (64 objects, as training), keeps those the rule picks, writes them to
    `out`. -> (kept, candidates)"""
    from scenariomax import Sizes, read_shards, write_shards
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.sources.synthetic.knobs import SyntheticKnobs
    from scenariomax.sources.synthetic.source import SyntheticSource

    sizes = Sizes(num_objects=64)
    transform, transform_settings = make_transform()  # enriched, as `scenariomax convert` does by default
    kept, total = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for index, (seed, count, knobs) in enumerate(batches):
            folder = Path(tmp) / f"batch{index}"
            source = SyntheticSource(num_scenarios=count, seed=seed, sizes=sizes, knobs=SyntheticKnobs(**knobs))
            convert(source, ConvertSettings(out=folder, sizes=sizes, workers=workers, transform=transform,
                                            transform_settings=transform_settings))
            for scenario in read_shards(folder):
                total += 1
                if _matches(scenario, rule):
                    kept.append(_unlit(scenario) if unlit else scenario)
        write_shards(kept, out, overwrite=True)
    return len(kept), total


def score(eval_dir: str) -> dict:
    """Accuracy, V-Max score and at-fault collisions of the judged episodes of a `vmax-sim evaluate` folder."""
    rows = [row for path in glob.glob(f"{eval_dir}/episodes-*.csv") for row in csv.DictReader(open(path))]
    judged = [row for row in rows if float(row["judged_steps"]) > 0]
    if not judged:
        raise SystemExit(f"{eval_dir}: no judged episodes (not a vmax-sim evaluate folder?)")
    return {"episodes": len(judged), "accuracy": sum(float(r["accurate"]) for r in judged) / len(judged),
            "vmax_score": sum(float(r["vmax_score"]) for r in judged) / len(judged),
            "at_fault_collisions": sum(float(r["at_fault_collision"]) > 0 for r in judged)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=("probe", "train", "score"))
    parser.add_argument("path", help="output folder (probe, train) or a vmax-sim evaluate folder (score)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.command == "score":
        print(score(args.path))
        return
    probe = args.command == "probe"
    kept, total = build(args.path, PROBE_BATCHES if probe else TRAIN_BATCHES, probe_scene if probe else
                        training_scene, unlit=probe, workers=args.workers)
    print(f"{args.path}: {kept} of {total} candidate scenes")


if __name__ == "__main__":
    main()
