"""Cutting long logs into 91-step windows (10 past + current + 80 future at 10 Hz).

Rule: the first window puts its current step on the log's own current step (start =
current_time_index - num_past); later windows follow every `stride` steps (default 80, so the
80-step futures never overlap) while a full window still fits. A 91-step WOMD file gives one
window; a 199-step `training_20s` file gives windows starting at 0 and 80 (current steps 10 and
90); the last 28 steps are not enough for a third full window and are left out.
"""

from __future__ import annotations

from scenariomax.enrich.geometry import wrap_angle  # noqa: F401 (shared; re-exported)

DEFAULT_WINDOW_STRIDE = 80


def window_starts(num_steps: int, current_time_index: int, num_past: int = 10, num_timesteps: int = 91,
                  stride: int = DEFAULT_WINDOW_STRIDE) -> list[int]:
    """First step of every window that fits in a log of `num_steps` steps."""
    first = current_time_index - num_past
    if first < 0 or stride <= 0:
        return []
    return list(range(first, num_steps - num_timesteps + 1, stride))
