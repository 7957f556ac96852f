"""Learning-curve picture of a run, three panels against env steps: held-out accuracy and V-Max score
(wall time in the panel's subtitle), held-out failure rates (collision, off-road, red light), and the
training episodes' return. Baselines passed in are dashed horizontal lines in the panel of their metric."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

DEFAULT_TITLE = "learning curve: held-out evaluation and training episode return"
SCORES = (("accuracy", "accuracy", "o", "tab:blue"), ("vmax_score", "V-Max score", "s", "tab:orange"))
FAILURE_RATES = (("overlap", "collision", "o", "tab:red"), ("offroad", "off-road", "s", "tab:brown"),
                 ("red_light", "red light", "^", "tab:purple"))
BASELINE_STYLES = ("--", ":", "-.", (0, (6, 2, 1, 2, 1, 2)))
SMOOTHING = 10  # training returns: a moving mean over this many logged rows, over the raw points


def _finite(value) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def _series(rows: list[dict], key: str) -> tuple[list[float], list[float]]:
    points = [(float(row["env_steps"]), float(row[key])) for row in rows
              if _finite(row.get(key)) and _finite(row.get("env_steps"))]
    return [p[0] for p in points], [p[1] for p in points]


def _metric_panel(ax, rows: list[dict], metrics, baselines: Mapping[str, Mapping[str, float]]) -> list[str]:
    """Plots the `metrics` present in `rows` with markers, the last value written beside its point, and each
    baseline's value of those metrics as a dashed line of the metric's colour. -> the metrics plotted."""
    plotted = []
    for key, label, marker, colour in metrics:
        xs, ys = _series(rows, key)
        if not xs:
            continue
        plotted.append(key)
        ax.plot(xs, ys, "-", marker=marker, color=colour, label=label, ms=6, lw=1.8, zorder=3)
        ax.annotate(f"{ys[-1]:.2f}", (xs[-1], ys[-1]), textcoords="offset points", xytext=(6, 0), va="center",
                    fontsize=8, color=colour)
    for style, (name, values) in zip(BASELINE_STYLES * 4, (baselines or {}).items()):
        for key, label, _, colour in metrics:
            if _finite(values.get(key)):
                ax.axhline(float(values[key]), color=colour, ls=style, lw=1.3, alpha=0.85, zorder=2,
                           label=f"{name}: {label} {float(values[key]):.2f}")
    return plotted


def _wall_time_note(rows: list[dict]) -> str:
    timed = [row for row in rows if _finite(row.get("wall_s")) and _finite(row.get("env_steps"))]
    if not timed:
        return ""
    last = timed[-1]
    return f"last at {float(last['env_steps']):,.0f} env steps, {float(last['wall_s']) / 60.0:.1f} min wall time"


def _moving_mean(values: list[float], window: int) -> list[float]:
    out, total = [], 0.0
    for i, value in enumerate(values):
        total += value - (values[i - window] if i >= window else 0.0)
        out.append(total / min(i + 1, window))
    return out


def learning_curve_figure(eval_rows: list[dict], train_rows: list[dict], title: str = DEFAULT_TITLE,
                          baselines: Mapping[str, Mapping[str, float]] | None = None):
    """The matplotlib Figure `plot_learning_curve` saves (close it with `plt.close(fig)`)."""
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    baselines = baselines or {}
    fig, (scores, failures, returns) = plt.subplots(1, 3, figsize=(16.5, 6.0), layout="constrained")
    steps = [float(row["env_steps"]) for row in [*eval_rows, *train_rows] if _finite(row.get("env_steps"))]
    for ax in (scores, failures, returns):
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
        if steps:
            ax.set_xlim(0, max(steps) * 1.08)
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda value, _: f"{value:,.0f}"))

    _metric_panel(scores, eval_rows, SCORES, baselines)
    scores.set_ylim(0.0, 1.02)
    scores.set_ylabel("score (0-1)")
    note = _wall_time_note(eval_rows)
    scores.set_title("held-out accuracy and V-Max score" + (f"\n({note})" if note else ""), fontsize=10)

    plotted = _metric_panel(failures, eval_rows, FAILURE_RATES, baselines)
    failures.set_ylabel("rate (0-1)")
    failures.set_title("held-out failure rates (episodes with at least one)", fontsize=10)
    failures.set_ylim(bottom=0.0)
    top = failures.get_ylim()[1]
    failures.set_ylim(0.0, min(1.02, max(0.1, top * 1.1)))
    if not plotted:
        failures.text(0.5, 0.5, "no failure rates logged\n(an older run)", ha="center", va="center",
                      transform=failures.transAxes, color="0.4")

    xs, ys = _series(train_rows, "episode/return")
    if xs:
        returns.plot(xs, ys, "o", color="tab:green", ms=3, alpha=0.45, label="logged (mean of finished episodes)")
        if len(xs) >= 3:
            window = min(SMOOTHING, max(2, len(xs) // 3))
            returns.plot(xs, _moving_mean(ys, window), "-", color="tab:green", lw=2.0,
                         label=f"moving mean ({window} points)")
    else:
        returns.text(0.5, 0.5, "no finished training episodes logged", ha="center", va="center",
                     transform=returns.transAxes, color="0.4")
    returns.set_ylabel("episode return")
    returns.set_title("training episode return", fontsize=10)

    for ax in (scores, failures, returns):
        entries = len(ax.get_legend_handles_labels()[0])
        if entries:  # under the panel: never over the curves
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncols=3 if entries <= 3 else 2, fontsize=8,
                      frameon=False, borderaxespad=0.0)
    if title:
        fig.suptitle(title, fontsize=12)
    return fig


def plot_learning_curve(path: Path, eval_rows: list[dict], train_rows: list[dict], title: str = DEFAULT_TITLE,
                        baselines: Mapping[str, Mapping[str, float]] | None = None) -> Path:
    """Saves the learning curve PNG (see `learning_curve_figure`). `eval_rows`: eval.csv rows (env_steps, wall_s,
    accuracy, vmax_score, overlap, offroad, red_light, ...; absent columns are skipped); `train_rows`: metrics.csv
    rows (env_steps, episode/return; NaN rows are skipped); `baselines`: {name: {metric: value}}, e.g.
    {"constant velocity": {"accuracy": 0.62, "vmax_score": 0.61}}, drawn as labelled dashed lines."""
    import matplotlib.pyplot as plt

    fig = learning_curve_figure(eval_rows, train_rows, title, baselines)
    path = Path(path)
    try:
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)
    return path
