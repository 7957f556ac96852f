"""Bird's-eye picture of closed-loop rollouts over the scenario they ran on.

The scenario is drawn as `scenariomax inspect --render` draws it (map, paths, logged trajectories,
objects at the first policy step); each policy's simulated SDC path is drawn on top, with a box at
its last pose, coloured red where the episode had failed (collision, off-road or red light).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from scenariomax import Scenario, draw_scenario

COLOURS = ("#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def rollout_paths(rollout, index: int = 0) -> dict[str, np.ndarray]:
    """The simulated SDC positions of episode `index` of a batched Rollout, valid steps only.

    -> {"xy": (S, 2), "failed_at": step of the first collision / off-road / red light or -1}
    """
    per_step = {k: np.asarray(v)[index] for k, v in rollout.per_step.items()}
    valid = np.asarray(rollout.step_valid)[index]
    xy = np.stack([per_step["sdc_x"], per_step["sdc_y"]], -1)[valid]
    failed = (per_step["overlap"] > 0.5) | (per_step["offroad"] > 0.5) | (per_step["red_light"] > 0.5)
    failed_steps = np.flatnonzero(failed & valid)
    return {"xy": xy, "failed_at": int(failed_steps[0]) if failed_steps.size else -1}


def render_rollouts(scenario: Scenario, rollouts: Mapping[str, dict], out_path: str | Path,
                    title: str | None = None) -> Path:
    """Saves a PNG of `scenario` with each policy's simulated SDC path (`rollout_paths` outputs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9.5, 7.5))
    try:
        draw_scenario(ax, scenario, title=title, legend=False)
        for (name, path), colour in zip(rollouts.items(), COLOURS):
            xy = path["xy"]
            if len(xy) == 0:
                continue
            failed = path["failed_at"] >= 0
            label = f"{name} ({'fails at step ' + str(path['failed_at']) if failed else 'no failure'})"
            ax.plot(xy[:, 0], xy[:, 1], "-", color=colour, lw=2.2, label=label, zorder=6)
            ax.plot(xy[-1, 0], xy[-1, 1], "X" if failed else "o", color=colour, ms=9, zorder=7)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        fig.tight_layout()
        fig.savefig(out_path, dpi=110)
    finally:
        plt.close(fig)
    return out_path
