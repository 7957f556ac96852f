"""Learning-curve picture of a run: held-out accuracy and V-Max score against env steps and wall time,
with the training episodes' return underneath."""

from __future__ import annotations

import math
from pathlib import Path


def plot_learning_curve(path: Path, eval_rows: list[dict], train_rows: list[dict], title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    steps = [row["env_steps"] for row in eval_rows]
    walls = [row["wall_s"] / 60.0 for row in eval_rows]
    for axis, xs, label in ((axes[0], steps, "env steps"), (axes[1], walls, "wall time (min)")):
        axis.plot(xs, [row["accuracy"] for row in eval_rows], "o-", label="accuracy")
        axis.plot(xs, [row["vmax_score"] for row in eval_rows], "s-", label="V-Max score")
        axis.set_xlabel(label)
        axis.set_ylim(0.0, 1.02)
        axis.grid(alpha=0.3)
        axis.legend(loc="lower right")
        axis.set_title("held-out evaluation")
    returns = [(row["env_steps"], row["episode/return"]) for row in train_rows
               if not math.isnan(row.get("episode/return", math.nan))]
    if returns:
        axes[2].plot([r[0] for r in returns], [r[1] for r in returns], lw=1, color="tab:green")
    axes[2].set_xlabel("env steps")
    axes[2].set_title("training episode return")
    axes[2].grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
