"""The rollout's loop writes each simulated step in place: no full copy of a trajectory buffer per step.

XLA copies a buffer it writes in place when the write's fusion also reads other buffers written in the same step;
the step reads its current state outside those fusions (`select_timestep`) so that never happens. The copies were
the whole cost of the physics step (docs/benchmarks.md), so this checks the compiled program, not a timing.
"""

from __future__ import annotations

import re

import pytest

from vmax_sim import bench
from vmax_sim.datatypes.trajectory import read_outside_fusion

BATCH, OBJECTS, STEPS = 2, 64, 20


def _compiled_rollout(with_metrics_and_observation: bool) -> str:
    scenes = bench._scenes(BATCH, OBJECTS, 5000)
    init_fn, step_fn = bench.make_episode_fns(with_metrics_and_observation, with_metrics_and_observation, OBJECTS)
    return bench.make_rollout(init_fn, step_fn, STEPS).lower(scenes).compile().as_text()


@pytest.mark.skipif(not read_outside_fusion(), reason="the conditional read is used on the CPU backend only")
@pytest.mark.parametrize("full_step", [False, True], ids=["physics", "full-step"])
def test_no_trajectory_buffer_is_copied_per_step(full_step):
    num_timesteps = int(bench._scenes(1, OBJECTS, 5000).log_trajectory.x.shape[-1])
    shape = re.compile(rf"\[{BATCH},{OBJECTS},{num_timesteps}\]")
    copies = [line for line in _compiled_rollout(full_step).splitlines()
              if " copy(" in line and shape.search(line.split(" copy(")[0])]
    assert copies == [], f"{len(copies)} full trajectory copies in the compiled rollout: {copies[:2]}"


@pytest.mark.parametrize("full_step", [False, True], ids=["physics", "full-step"])
def test_the_timed_rollout_writes_every_step_into_the_trajectory(full_step):
    """The bench keeps the written trajectory alive, so its figures include the in-place writes (a simulator that
    caches the current step would otherwise have them removed as dead code and time less work than Waymax)."""
    num_timesteps = int(bench._scenes(1, OBJECTS, 5000).log_trajectory.x.shape[-1])
    written = re.compile(rf"= f32\[{BATCH},{OBJECTS},{num_timesteps}\]\S* \S*dynamic-update-slice")
    writes = [line for line in _compiled_rollout(full_step).splitlines() if written.search(line)]
    assert len(writes) >= len(bench.WRITTEN_FIELDS) - 1  # every float field written (valid is a pred buffer)
