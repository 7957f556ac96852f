"""The demo's two pictures read on their own: the rollout picture (`render_rollouts`) keeps its whole legend, both
axis labels and a legend of the map symbols inside the image, draws the expert's path apart from the policy's with
end markers unlike the map's; the learning curve (`plot_learning_curve`) has three labelled panels (scores, failure
rates, training return) and draws baselines as labelled dashed lines."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.legend import Legend  # noqa: E402

from tests.inspect.scenes import make_scenario  # noqa: E402
from vmax_sim.training.plots import learning_curve_figure, plot_learning_curve  # noqa: E402
from vmax_sim.visualization import render_rollouts, rollout_paths  # noqa: E402
from vmax_sim.visualization.rollouts import rollout_figure  # noqa: E402

LONG_NAME = "trained bc-mlp-navigation with a deliberately long legend name"


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def _legends(fig) -> list[Legend]:
    found = [*fig.legends]
    for ax in fig.axes:
        found += [artist for artist in ax.get_children() if isinstance(artist, Legend)]
    return list({id(legend): legend for legend in found}.values())


def _inside(fig, artist) -> bool:
    box, frame = artist.get_window_extent(fig.canvas.get_renderer()), fig.bbox
    return (box.x0 >= frame.x0 - 1 and box.y0 >= frame.y0 - 1 and box.x1 <= frame.x1 + 1
            and box.y1 <= frame.y1 + 1)


def _legend_texts(fig) -> list[str]:
    return [text.get_text() for legend in _legends(fig) for text in legend.get_texts()]


@pytest.fixture
def rollouts():
    x = np.linspace(15.0, 60.0, 46)
    expert = {"xy": np.stack([x, np.zeros_like(x)], -1), "failed_at": -1, "failure": ""}
    policy = {"xy": np.stack([x[:20], 0.15 * np.arange(20)], -1), "failed_at": 12, "failure": "off-road"}
    return {"expert (log replay)": expert, LONG_NAME: policy}


@pytest.fixture
def rollout_fig(rollouts):
    fig = rollout_figure(make_scenario(with_lights=True, with_paths=True, with_controllable=True), rollouts,
                         title="scene: closed loop")
    fig.canvas.draw()
    yield fig
    plt.close(fig)


def test_rollout_legends_and_axis_labels_lie_inside_the_picture(rollout_fig):
    legends = _legends(rollout_fig)
    assert len(legends) == 2  # the simulated paths, the map symbols
    for legend in legends:
        assert _inside(rollout_fig, legend), legend.get_title().get_text()
        for text in legend.get_texts():
            assert _inside(rollout_fig, text), text.get_text()
    (ax,) = [ax for ax in rollout_fig.axes if ax.axison]
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    assert _inside(rollout_fig, ax.xaxis.label) and _inside(rollout_fig, ax.yaxis.label)


def test_rollout_legend_wraps_long_names_and_says_how_each_path_ended(rollout_fig):
    texts = _legend_texts(rollout_fig)
    policy = next(text for text in texts if text.startswith("trained"))
    assert "\n" in policy  # wrapped, not cut
    assert " ".join(policy.split()) == f"{LONG_NAME}: off-road at step 12 (1.2 s)"
    assert any(" ".join(text.split()) == "expert (log replay): no failure in 46 steps" for text in texts)


def test_rollout_map_symbols_have_their_own_legend(rollout_fig):
    texts = {" ".join(text.split()) for text in _legend_texts(rollout_fig)}
    assert {"road edge", "lane centre", "white line", "crosswalk", "stop sign", "vehicle", "pedestrian",
            "SDC (at the first policy step)"} <= texts
    assert any(text.startswith("light ") for text in texts)


def test_expert_path_is_a_wide_band_under_the_policy_and_ends_unlike_the_map_markers(rollout_fig, rollouts):
    (ax,) = [ax for ax in rollout_fig.axes if ax.axison]
    lines = {len(line.get_xdata()): line for line in ax.get_lines() if len(line.get_xdata()) > 1}
    expert, policy = lines[46], lines[20]
    assert expert.get_linewidth() >= 2 * policy.get_linewidth() and expert.get_zorder() < policy.get_zorder()
    assert expert.get_color() != policy.get_color()
    markers = [line for line in ax.get_lines() if len(line.get_xdata()) == 1]
    # light markers and stop signs are circles / octagons: the paths end in a square, an X where one failed
    assert sorted(line.get_marker() for line in markers) == ["X", "s", "s"]
    (cross,) = [line for line in markers if line.get_marker() == "X"]
    np.testing.assert_allclose([cross.get_xdata()[0], cross.get_ydata()[0]], rollouts[LONG_NAME]["xy"][12])


def test_render_rollouts_keeps_the_old_call_and_accepts_paths_without_a_failure_reason(tmp_path, rollouts):
    old_style = {name: {"xy": path["xy"], "failed_at": path["failed_at"]} for name, path in rollouts.items()}
    out = render_rollouts(make_scenario(), old_style, tmp_path / "pictures" / "rollout.png", title="t")
    width, height = _png_size(out)
    assert width > height > 600


def test_rollout_paths_names_the_first_failure():
    steps = 6
    per_step = {"sdc_x": np.arange(steps, dtype=float)[None], "sdc_y": np.zeros((1, steps)),
                "overlap": np.zeros((1, steps)), "offroad": np.array([[0, 0, 0, 1, 1, 0.0]]),
                "red_light": np.array([[0, 0, 0, 1, 0, 0.0]])}
    rollout = SimpleNamespace(per_step=per_step, step_valid=np.array([[True] * 5 + [False]]))
    path = rollout_paths(rollout)
    assert path["failed_at"] == 3 and path["failure"] == "off-road + red light" and len(path["xy"]) == 5
    per_step["offroad"][:] = per_step["red_light"][:] = 0
    assert rollout_paths(rollout)["failed_at"] == -1 and rollout_paths(rollout)["failure"] == ""


# --- learning curve -----------------------------------------------------------------------------------------

def _eval_rows(columns=("overlap", "offroad", "red_light")) -> list[dict]:
    rows = []
    for i, steps in enumerate((8000.0, 16000.0, 24000.0)):
        row = {"env_steps": steps, "wall_s": 28.0 * (i + 1), "accuracy": 0.69 - 0.08 * i,
               "vmax_score": 0.64 - 0.04 * i, "nuplan_score": 0.66, "accuracy_at_fault": 0.69}
        row.update({"overlap": 0.06 + 0.02 * i, "offroad": 0.22 + 0.06 * i, "red_light": 0.03, "off_route": 0.0})
        rows.append({k: v for k, v in row.items() if k not in {"overlap", "offroad", "red_light"} or k in columns})
    return rows


def _train_rows() -> list[dict]:
    return [{"env_steps": 400.0 * (i + 1), "episode/return": math.nan if i % 3 == 0 else 15.0 + 0.1 * i}
            for i in range(30)]


@pytest.fixture
def curve():
    figures = []

    def make(*args, **kwargs):
        fig = learning_curve_figure(*args, **kwargs)
        fig.canvas.draw()
        figures.append(fig)
        return fig

    yield make
    for fig in figures:
        plt.close(fig)


def test_learning_curve_has_three_labelled_panels_and_the_title_as_given(curve):
    title = "BC (MLP encoder), 160 synthetic training scenarios -> 32 held-out"
    fig = curve(_eval_rows(), _train_rows(), title)
    scores, failures, returns = fig.axes
    assert [ax.get_ylabel() for ax in fig.axes] == ["score (0-1)", "rate (0-1)", "episode return"]
    assert all(ax.get_xlabel() == "env steps" for ax in fig.axes)  # no duplicate panel against wall time
    assert fig.get_suptitle() == title
    assert "1.4 min" in scores.get_title()  # wall time of the last evaluation: 84 s
    assert [line.get_label() for line in scores.get_lines()] == ["accuracy", "V-Max score"]
    assert all(line.get_marker() not in (None, "None", "") for line in scores.get_lines())
    raw = returns.get_lines()[0]
    assert len(raw.get_xdata()) == 20 and np.isfinite(raw.get_ydata()).all()  # the 10 NaN rows are skipped
    for legend in _legends(fig):
        assert _inside(fig, legend)


def test_failure_panel_plots_the_columns_present(curve):
    fig = curve(_eval_rows(), _train_rows())
    assert [line.get_label() for line in fig.axes[1].get_lines()] == ["collision", "off-road", "red light"]
    np.testing.assert_allclose(fig.axes[1].get_lines()[1].get_ydata(), [0.22, 0.28, 0.34])
    fig = curve(_eval_rows(columns=("offroad",)), _train_rows())
    assert [line.get_label() for line in fig.axes[1].get_lines()] == ["off-road"]
    fig = curve(_eval_rows(columns=()), [])  # an old run: no failure columns, no finished training episode
    assert fig.axes[1].get_lines() == [] and fig.axes[2].get_lines() == []
    assert "no failure rates" in " ".join(text.get_text() for text in fig.axes[1].texts)


def test_baselines_are_labelled_dashed_lines_in_their_metric_s_panel(curve):
    baselines = {"constant velocity": {"accuracy": 0.62, "vmax_score": 0.61, "offroad": 0.16}}
    fig = curve(_eval_rows(), _train_rows(), baselines=baselines)
    dashed = {line.get_label(): line for ax in fig.axes[:2] for line in ax.get_lines() if line.get_linestyle() == "--"}
    assert set(dashed) == {"constant velocity: accuracy 0.62", "constant velocity: V-Max score 0.61",
                           "constant velocity: off-road 0.16"}
    assert dashed["constant velocity: off-road 0.16"] in fig.axes[1].get_lines()
    np.testing.assert_allclose(dashed["constant velocity: accuracy 0.62"].get_ydata(), [0.62, 0.62])
    assert set(dashed) <= {text.get_text() for legend in _legends(fig) for text in legend.get_texts()}


def test_plot_learning_curve_keeps_the_old_call(tmp_path):
    out = plot_learning_curve(tmp_path / "learning_curve.png", _eval_rows(), _train_rows(), title="bc / mlp")
    width, height = _png_size(out)
    assert width > 2 * height and out.stat().st_size > 10_000
