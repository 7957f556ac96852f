"""Cutting long logs into 91-step windows (10 past + current + 80 future at 10 Hz).

Rule: the first window puts its current step on the log's own current step (start =
current_time_index - num_past); later windows follow every `stride` steps (default 80, so the
80-step futures never overlap) while a full window still fits. A 91-step WOMD file gives one
window; a 199-step `training_20s` file gives windows starting at 0 and 80 (current steps 10 and
90); the last 28 steps are not enough for a third full window and are left out.
"""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.geometry import wrap_angle  # noqa: F401 (shared; re-exported)

DEFAULT_WINDOW_STRIDE = 80


def window_starts(num_steps: int, current_time_index: int, num_past: int = 10, num_timesteps: int = 91,
                  stride: int = DEFAULT_WINDOW_STRIDE) -> list[int]:
    """First step of every window that fits in a log of `num_steps` steps."""
    first = current_time_index - num_past
    if first < 0 or stride <= 0:
        return []
    return list(range(first, num_steps - num_timesteps + 1, stride))


def log_window_starts(num_steps: int, current_time_index: int, num_past: int = 10, num_timesteps: int = 91,
                      stride: int = DEFAULT_WINDOW_STRIDE) -> list[int]:
    """First log step of every window of a log whose current step (`current_time_index`) lies in it.

    Unlike `window_starts`, every log with a current step gives at least one window:
    - too little history before the current step (ScenarioNet's 20 s WOMD databases say 0): the first
      window starts at log step 0, so its current step is the first one whose history fits;
    - too few steps for a full window (UniTraj's 81-step nuScenes windows): one window, its steps after
      the log's end invalid (the episode ends where the log does);
    - a log shorter than the history itself: one window starting before the log (negative start), the
      missing history invalid, its current step on the log's.
    """
    if not 0 <= current_time_index < num_steps or stride <= 0:
        return []
    first = current_time_index - num_past
    if first < 0 and num_steps > num_past + 1:
        first = 0  # move the current step forward until the history fits; a future still follows it
    return list(range(first, num_steps - num_timesteps + 1, stride)) or [first]


def window_steps(values: np.ndarray, start: int, length: int, fill) -> np.ndarray:
    """Steps [start, start + length) of (N, T, ...) `values`, `fill` where the window leaves the log
    (before its first step when `start` < 0, after its last)."""
    out = np.full((values.shape[0], length) + values.shape[2:], fill, dtype=values.dtype)
    lo, hi = max(start, 0), min(start + length, values.shape[1])
    if hi > lo:
        out[:, lo - start:hi - start] = values[:, lo:hi]
    return out


def window_notes(start: int, num_steps: int, num_past: int, num_timesteps: int, current: int) -> dict:
    """What a window left out or moved, for the manifest: steps before the log's start or after its end
    (invalid; the episode ends where the SDC's log does), and the first window's current step where it is not
    the log's own `current` (too little history before it, or a log shorter than the history)."""
    notes = {}
    if start < 0:
        notes["history_padded"] = -start
    if start + num_timesteps > num_steps:
        notes["steps_padded"] = start + num_timesteps - num_steps
        notes["log_steps"] = num_steps
    if start <= 0 and start + num_past != current:
        notes["current_step_moved"] = {"log": current, "window": start + num_past}
    return notes
