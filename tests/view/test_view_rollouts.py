"""`vmax-sim view`: rollouts on the viewer page. The constant-velocity policy on hand-made scenes: it hits the
stopped car of "brake" (a collision at policy step 26, see tests/evaluation/test_gallery.py) and passes "cruise"."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import scenariomax
from scenariomax.view import unpack_scene
from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario, cruising_scenario
from tests.policies.scenes import red_light_scenario
from tests.training.conftest import synthetic_shards  # noqa: F401, F811 - a fixture (12 enriched synthetic scenes)
from tests.view.browser import colour_mask, needs_browser, rgb, run_chromium, status
from vmax_cli.vmax_cli import main


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rollout_shards")
    scenariomax.write_shards([braking_scenario("brake"), cruising_scenario("cruise"), red_light_scenario("red")], out,
                             sizes=SMALL_SIZES)
    return out


@pytest.fixture(scope="module")
def page(shards, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rollout_page") / "rollouts.html"
    result = CliRunner().invoke(main, ["view", str(shards), "--policy", "constant", "--num-scenarios", "2",
                                       "--num-objects", "8", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == str(out)
    return out


def scenes(page: Path) -> dict[str, tuple[dict, dict]]:
    found = re.findall(r'<script type="application/octet-stream" id="scene-\d+">([^<]*)</script>', page.read_text())
    unpacked = [unpack_scene(base64.b64decode(text)) for text in found]
    return {meta["id"]: (meta, arrays) for meta, arrays in unpacked}


def test_only_the_first_scenarios_are_kept_with_each_policy_s_simulated_sdc(page):
    by_id = scenes(page)
    assert sorted(by_id) == ["brake", "cruise"]  # --num-scenarios 2: "red" was neither run nor kept
    meta, arrays = by_id["brake"]
    (sim,) = meta["sims"]
    assert sim["name"] == "constant" and sim["first_timestep"] == 10 and sim["num_steps"] == 80
    assert [(f["metric"], f["step"]) for f in sim["failures"]][:1] == [("overlap", 25)]  # policy step 26
    assert sim["episode"]["accurate"] == 0.0
    x = arrays["sim0_x"] * meta["scale"] + meta["origin"][0]
    valid = arrays["sim0_valid"].astype(bool)
    steps = np.flatnonzero(valid)
    assert steps[0] == 10 and steps[-1] == 10 + 26  # from reset to the terminating step, nothing after
    assert np.allclose(np.diff(x[steps[:10]]), 1.0, atol=0.02)  # 10 m/s, 0.1 s steps
    speed = arrays[f"sim0_m{sim['metrics'].index('speed')}"]
    assert speed.shape == (80,) and np.allclose(speed[:20], 10.0, atol=0.1)
    assert by_id["cruise"][0]["sims"][0]["failures"] == []


def test_bad_input_is_one_line(shards, tmp_path):
    for args, message in (([str(tmp_path / "nope")], "no such training run directory, evaluation directory"),
                          ([str(tmp_path)], "no .tfrecord files found"),
                          ([str(shards), "--policy", "bogus"], "unknown policy 'bogus'"),
                          ([str(shards), "--data", str(shards)], "--data goes with a training run directory")):
        result = CliRunner().invoke(main, ["view", *args, "--out", str(tmp_path / "x.html")])
        assert result.exit_code == 2 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output


@needs_browser
def test_the_rollout_page_overlays_the_policy_and_draws_the_metric_strip(page, tmp_path):
    url = f"{page.as_uri()}?scenario=brake&frame=30&metric=log_divergence"
    dom, console = run_chromium(url)
    state = status(dom)
    assert console == [] and state["ready"] == "1" and state["errors"] == "", (console, state)
    assert state["drawn"] == "3"  # the stopped car, the simulated SDC and the logged SDC
    assert '<div id="chartbox">' in dom and "constant - collision" in dom  # the chart is shown; the legend
    png = tmp_path / "rollout.png"  # kept as the test's artifact
    _, console = run_chromium(url, screenshot=png)
    image = rgb(png)
    assert console == []
    assert colour_mask(image, "#a6ff00").sum() > 100  # the simulated SDC (first policy colour)
    assert colour_mask(image, "#e8281e", 30).sum() > 20  # the failure marker on the strip chart
    assert colour_mask(image, "#5fa800", 30).sum() > 50  # the policy's metric line


@pytest.mark.slow  # trains a tiny SAC run first (about a minute on 2 cores)
def test_a_training_run_shows_its_own_policy_on_its_held_out_split(synthetic_shards, tmp_path):  # noqa: F811
    from tests.training.conftest import tiny_config
    from vmax_sim.training import train

    run = tmp_path / "run"
    train(tiny_config(synthetic_shards, "sac", "train.total_env_steps=40"), run, progress=False,
          print_fn=lambda line: None)
    out = tmp_path / "run.html"
    result = CliRunner().invoke(main, ["view", str(run), "--policy", "expert", "--num-scenarios", "2",
                                       "--num-objects", "16", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    by_id = scenes(out)
    held_out = [s.scenario_id for s in scenariomax.read_shards(synthetic_shards)][:2]  # tiny_config: data.eval
    assert sorted(by_id) == sorted(held_out)
    for meta, _ in by_id.values():
        assert [sim["name"] for sim in meta["sims"]] == ["sac-mlp@run", "expert"]


@pytest.fixture(scope="module")
def evaluation(shards, tmp_path_factory) -> Path:
    """`vmax-sim evaluate --out DIR --view`: constant and expert on brake, cruise, red (constant fails brake)."""
    out = tmp_path_factory.mktemp("evaluation")
    result = CliRunner().invoke(main, ["evaluate", "--policy", "constant,expert", "--data", str(shards),
                                       "--num-objects", "8", "--out", str(out), "--view", "--view-max", "1",
                                       "--quiet"])
    assert result.exit_code == 0, result.output
    assert f"wrote the rollout viewer {out / 'rollouts.html'}" in result.output
    return out


def failed_by_constant(evaluation: Path) -> list[str]:
    rows = (evaluation / "episodes-constant.csv").read_text().splitlines()
    keys = rows[0].split(",")
    return [row.split(",")[0] for row in rows[1:] if float(row.split(",")[keys.index("accurate")]) < 0.5]


@pytest.mark.slow  # its evaluation (~17 s) on 2 cores: kept out of the 10-minute default suite
def test_evaluate_view_writes_the_failed_episodes_first_with_every_policy(evaluation):
    by_id = scenes(evaluation / "rollouts.html")
    assert list(by_id) == ["brake"]  # --view-max 1: the first failed episode, not the first scenario
    meta, _ = by_id["brake"]
    assert [sim["name"] for sim in meta["sims"]] == ["constant", "expert"]
    assert meta["sims"][0]["failures"][0]["metric"] == "overlap" and meta["sims"][1]["failures"] == []


@pytest.mark.slow  # 8-38 s on 2 cores: the default suite stays under 10 minutes
def test_viewing_an_evaluation_directory_reruns_its_policies_on_its_failures_first(evaluation, tmp_path):
    failed = failed_by_constant(evaluation)
    assert "brake" in failed and "cruise" not in failed
    out = tmp_path / "eval.html"
    result = CliRunner().invoke(main, ["view", str(evaluation), "--num-scenarios", "3", "--out", str(out),
                                       "--quiet"])
    assert result.exit_code == 0, result.output
    page_ids = list(scenes(out))  # in page order
    assert page_ids[:len(failed)] == [i for i in ["brake", "cruise", "red"] if i in failed]  # failed first
    assert sorted(page_ids) == ["brake", "cruise", "red"]
    for meta, _ in scenes(out).values():
        assert [sim["name"] for sim in meta["sims"]] == ["constant", "expert"]
    assert "from the evaluation" in out.read_text()
