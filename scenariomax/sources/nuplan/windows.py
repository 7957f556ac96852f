"""Cutting a 20 Hz nuPlan log into 91-step scenarios at 10 Hz.

Every other lidar_pc (ordered by timestamp) is one 10 Hz step. A scenario is anchored on a
lidar_pc that becomes its current step; its steps are the lidar_pcs 2*(k - current_index)
positions away, so the anchor keeps its exact timestamp.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

LIDAR_PCS_PER_STEP = 2  # 20 Hz lidar_pc -> 10 Hz steps
NO_TAG_STRIDE_STEPS = 80
GROUP_SPAN_LIDAR_PCS = 600  # 30 s of anchors read in one pass; bounds memory per pass


def window_indices(anchor: int, num_lidar_pcs: int, num_steps: int = 91, current_index: int = 10) -> np.ndarray:
    """lidar_pc indices of each step, -1 where the step falls outside the log. -> (num_steps,) int64"""
    offsets = (np.arange(num_steps, dtype=np.int64) - current_index) * LIDAR_PCS_PER_STEP
    indices = anchor + offsets
    return np.where((indices >= 0) & (indices < num_lidar_pcs), indices, -1)


def stride_anchors(num_lidar_pcs: int, stride_steps: int, num_steps: int = 91, current_index: int = 10) -> list[int]:
    """Anchors every `stride_steps` 10 Hz steps whose whole window lies inside the log.

    A log too short for one full window still yields one anchor (its future is partly invalid).
    """
    first = current_index * LIDAR_PCS_PER_STEP
    last = num_lidar_pcs - 1 - (num_steps - 1 - current_index) * LIDAR_PCS_PER_STEP
    if num_lidar_pcs <= first:
        return []
    if last < first:
        return [first]
    return list(range(first, last + 1, max(int(stride_steps), 1) * LIDAR_PCS_PER_STEP))


def scenario_anchors(num_lidar_pcs: int, tag_indices: Sequence[int], stride_steps: int | None) -> list[int]:
    """Sorted unique anchors: one per tagged lidar_pc, plus stride anchors when `stride_steps` is set
    (or every NO_TAG_STRIDE_STEPS when the log has no tags)."""
    anchors = {int(i) for i in tag_indices if 0 <= int(i) < num_lidar_pcs}
    if stride_steps is not None:
        anchors |= set(stride_anchors(num_lidar_pcs, stride_steps))
    elif not anchors:
        anchors = set(stride_anchors(num_lidar_pcs, NO_TAG_STRIDE_STEPS))
    return sorted(anchors)


def anchor_groups(anchors: Sequence[int], max_span: int = GROUP_SPAN_LIDAR_PCS) -> list[list[int]]:
    """Sorted anchors cut into runs spanning at most `max_span` lidar_pcs (read together, so a
    table without an index is scanned once per run instead of once per scenario)."""
    groups: list[list[int]] = []
    for anchor in sorted(anchors):
        if groups and anchor - groups[-1][0] <= max_span:
            groups[-1].append(anchor)
        else:
            groups.append([anchor])
    return groups
