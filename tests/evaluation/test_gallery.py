"""The failure gallery (`evaluate --gallery`): GIF + PNG per failed episode, index.html, and the CLI with the
difficulty table. Constant velocity on hand-made scenes: it hits the stopped car and runs the red light."""

from __future__ import annotations

import csv
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import scenariomax
from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario, cruising_scenario
from tests.policies.scenes import red_light_scenario
from vmax_cli.vmax_cli import main
from vmax_sim.evaluation.gallery import GalleryCollector
from vmax_sim.evaluation.report import compare_policies

IMAGE_LINK = re.compile(r"(?:src|href)='([^']+\.(?:gif|png))'")


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    """cruise (constant velocity passes), brake (it hits the stopped car), red (it runs the red light)."""
    out = tmp_path_factory.mktemp("gallery_shards")
    scenariomax.write_shards([cruising_scenario("cruise"), braking_scenario("brake"), red_light_scenario("red")], out,
                             sizes=SMALL_SIZES)
    return out


@pytest.fixture(scope="module")
def gallery(shards, tmp_path_factory) -> Path:
    collector = GalleryCollector(max_failed=50, max_passed=5)
    runs = compare_policies(["constant"], str(shards), batch_size=2, num_objects=8, progress=False, on_batch=collector)
    assert collector.num_failed == {0: 2} and collector.num_episodes == {0: 3}
    out = tmp_path_factory.mktemp("gallery")
    collector.write(out, runs, progress=False)
    return out


@pytest.mark.slow  # with the next two, their gallery (~15 s) on 2 cores: kept out of the 10-minute default suite
def test_each_failed_episode_gets_a_gif_and_a_png_of_the_failing_step(gallery):
    files = sorted(p.name for p in (gallery / "constant").iterdir())
    assert files == ["000-brake.gif", "000-brake.png", "001-red.gif", "001-red.png", "002-cruise.gif", "002-cruise.png"]
    gif = Image.open(gallery / "constant" / "000-brake.gif")
    # the constant policy hits the car at policy step 26 (tests/integration_sim): frames 0..26, then it ends
    assert gif.format == "GIF" and gif.n_frames == 27 and gif.info.get("loop") == 0
    png = Image.open(gallery / "constant" / "000-brake.png")
    assert png.format == "PNG" and min(png.size) > 300
    # the SDC is drawn red (with a yellow outline) from the failing step: in the PNG, not in the first GIF frame
    def red_pixels(image):
        rgb = np.asarray(image.convert("RGB")).astype(int)
        return int(np.sum((rgb[..., 0] > 230) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)))
    gif.seek(0)
    assert red_pixels(png) > 100 and red_pixels(gif) < red_pixels(png) / 10


@pytest.mark.slow  # shares the gallery above on 2 cores: kept out of the 10-minute default suite
def test_index_lists_the_episodes_with_their_metrics_and_links_existing_images(gallery):
    page = (gallery / "index.html").read_text()
    links = IMAGE_LINK.findall(page)
    assert len(links) == 2 * 2 * 3  # a link and an <img> for each GIF and PNG
    assert all(not Path(link).is_absolute() and (gallery / link).is_file() for link in links)
    assert "constant/000-brake.gif" in links and "constant/001-red.png" in links
    for text in ("brake", "red", "cruise", "collision (overlap) at step 26", "red light (red_light)", "V-Max score",
                 "accuracy", "3 episodes, <b>2 failed</b>", "Mode non_reactive"):
        assert text in page, text


@pytest.mark.slow  # shares the gallery above on 2 cores: kept out of the 10-minute default suite
@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium is not installed (.ci/run installs it)")
def test_index_renders_in_a_headless_browser(gallery, tmp_path):
    def dump(index: Path) -> str:
        result = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
                                 index.as_uri()], capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr[-2000:]
        return result.stdout

    dom = dump(gallery / "index.html")
    assert 'src="constant/000-brake.gif"' in dom and 'src="constant/001-red.png"' in dom
    assert "overlap" in dom and "red_light" in dom and "V-Max score" in dom
    assert 'class="missing"' not in dom  # every image loaded (one that fails to gets class="missing")
    broken = tmp_path / "broken"
    shutil.copytree(gallery, broken)
    (broken / "constant" / "001-red.png").unlink()
    assert dump(broken / "index.html").count('class="missing"') == 1


def _evaluate(args: list[str]) -> str:
    result = CliRunner().invoke(main, ["evaluate", *args])
    assert result.exit_code == 0, result.output
    return result.output


def test_cli_prints_the_difficulty_table_and_honours_the_gallery_limits(shards, tmp_path):
    out, gallery = tmp_path / "report", tmp_path / "gallery"
    text = _evaluate(["--policy", "constant", "--data", str(shards), "--num-objects", "8", "--batch-size", "2",
                      "--gallery", str(gallery), "--gallery-max", "1", "--gallery-passed", "0", "--difficulty",
                      "--out", str(out)])
    assert text.index("accuracy_at_fault") < text.index("| Group | Bucket | Episodes | constant accuracy (%) |")
    assert "| difficulty | easy | 3 | 33.33 |" in text and "wrote the failure gallery" in text
    assert sorted(p.name for p in (gallery / "constant").iterdir()) == ["000-brake.gif", "000-brake.png"]
    assert "2 failed</b> (showing 1, limit 1)" in (gallery / "index.html").read_text()
    rows = list(csv.DictReader((out / "difficulty.csv").open()))
    assert {"group": "traffic light", "bucket": "yes", "policy": "constant", "episodes": "1", "accuracy": "0.000000",
            "vmax_score": "0.000000"} in rows
    tags = list(csv.DictReader((out / "difficulty-scenarios.csv").open()))
    assert [r["scenario_id"] for r in tags] == ["cruise", "brake", "red"] and tags[2]["has_traffic_light"] == "True"


@pytest.mark.slow  # compiles a second policy (~10 s)
def test_cli_gallery_has_one_section_per_policy(shards, tmp_path):
    gallery = tmp_path / "gallery"
    text = _evaluate(["--policy", "constant,expert", "--data", str(shards), "--num-objects", "8", "--batch-size", "2",
                      "--gallery", str(gallery), "--gallery-passed", "1", "--difficulty"])
    assert text.index("| Metric (%) | constant | expert |") < text.index("| Group | Bucket | Episodes |")
    assert sorted(p.name for p in (gallery / "constant").glob("*.gif")) == ["000-brake.gif", "001-red.gif",
                                                                            "002-cruise.gif"]
    # the logged SDC of "red" runs its red light, so the expert (replaying it) fails there too
    assert sorted(p.name for p in (gallery / "expert").glob("*.gif")) == ["000-red.gif", "001-cruise.gif"]
    page = (gallery / "index.html").read_text()
    assert "id='policy-constant'" in page and "id='policy-expert'" in page
    assert all((gallery / link).is_file() for link in IMAGE_LINK.findall(page))
