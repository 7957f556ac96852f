import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenariomax import Sizes, read_shards
from scenariomax.pipeline import ConversionError, ConvertSettings, convert
from tests.foundation.toy_source import CountedToySource, ToySource

SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_lanes=4)
ROOT = Path(__file__).resolve().parents[2]


def _settings(out, **kw):
    return ConvertSettings(out=out, sizes=SIZES, shard_size=5, progress=False, **kw)


def _shard_bytes(out: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(out.glob("*.tfrecord"))}


def test_progress_in_scenarios_counts_the_ones_that_failed_one_by_one(tmp_path, capsys):
    # 6 units x 4 = 24 expected; one fails in the source, one in validation (NaN), one unit is unreadable
    source = CountedToySource(bad_scenarios=((2, 0),), broken_units=(5,))
    result = convert(source, ConvertSettings(out=tmp_path / "o", sizes=SIZES, shard_size=5, workers=1))
    assert result.num_scenarios == 18
    # the unreadable unit's 4 scenarios never settle: 18 written + 2 failed one by one
    assert "converting: 20/24 scenarios" in capsys.readouterr().err


def test_conversion_writes_shards_and_manifest(tmp_path):
    result = convert(ToySource(), _settings(tmp_path / "o", workers=1))
    assert result.num_scenarios == 23 and result.num_failures == 1  # 6 units x 4, one failed in the source
    assert result.shards == tuple(f"train-0000{i}-of-00005.tfrecord" for i in range(5))
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["state"] == "complete" and manifest["counts"]["scenarios"] == 23
    assert manifest["schema"]["version"] == "1.0.0" and manifest["source_dataset"] == "toy"
    assert all(len(s["sha256"]) == 64 for s in manifest["shards"])
    assert manifest["failures"] == [{"unit": "toy:001", "scenario": "toy-001-1", "reason": "source could not build it"}]
    ids = [s.scenario_id for s in read_shards(tmp_path / "o")]
    assert len(ids) == len(set(ids)) == 23 and ids[0] == "toy-000-0"
    assert not (tmp_path / "o" / ".work").exists()


def test_worker_count_does_not_change_the_bytes(tmp_path):
    convert(ToySource(), _settings(tmp_path / "a", workers=1))
    convert(ToySource(), _settings(tmp_path / "b", workers=2))
    assert _shard_bytes(tmp_path / "a") == _shard_bytes(tmp_path / "b")


def test_bad_scenarios_and_broken_files_are_isolated(tmp_path):
    source = ToySource(broken_units=(2,), bad_scenarios=((4, 0),))
    result = convert(source, _settings(tmp_path / "o", workers=2))
    reasons = {(f["unit"], f["scenario"]): f["reason"] for f in result.failures}
    assert reasons[("toy:002", "*")] == "toy:002: not a toy file (bad magic)"
    assert "x has NaN" in reasons[("toy:004", "toy-004-0")]
    assert result.num_scenarios == 24 - 4 - 1 - 1 and not result.ok


def test_existing_output_needs_resume(tmp_path):
    convert(ToySource(num_units=1), _settings(tmp_path / "o", workers=1))
    with pytest.raises(ConversionError, match="already holds a conversion"):
        convert(ToySource(num_units=1), _settings(tmp_path / "o", workers=1))


def test_resume_with_other_settings_is_refused(tmp_path):
    convert(ToySource(num_units=1), _settings(tmp_path / "o", workers=1))
    with pytest.raises(ConversionError, match="settings differ"):
        convert(ToySource(num_units=2), _settings(tmp_path / "o", workers=1, resume=True))


_CHILD = """
import sys
sys.path.insert(0, {root!r})
from pathlib import Path
from scenariomax import Sizes
from scenariomax.pipeline import ConvertSettings, convert
from tests.foundation.toy_source import CountedToySource, ToySource
if __name__ == "__main__":  # worker processes re-import this module
    source = ToySource(num_units=8, per_unit=4, delay_s=float(sys.argv[2]))
    convert(source, ConvertSettings(out=Path(sys.argv[1]), sizes=Sizes(num_objects=8, num_roadgraph=2000, num_lanes=4),
            shard_size=5, workers=2, progress=False, resume=True))
"""


def test_kill_9_then_resume_gives_the_same_shards(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(_CHILD.format(root=str(ROOT)))
    reference, crashed = tmp_path / "ref", tmp_path / "crash"
    subprocess.run([sys.executable, str(script), str(reference), "0"], check=True)
    child = subprocess.Popen([sys.executable, str(script), str(crashed), "0.05"], start_new_session=True)
    deadline = time.time() + 60
    while time.time() < deadline:  # wait until at least two shards are sealed, then kill -9
        manifest = crashed / "manifest.json"
        if manifest.exists() and len(json.loads(manifest.read_text())["shards"]) >= 2:
            break
        time.sleep(0.05)
    os.killpg(child.pid, signal.SIGKILL)
    child.wait()
    state = json.loads((crashed / "manifest.json").read_text())
    assert state["state"] == "running"  # really interrupted mid-run
    subprocess.run([sys.executable, str(script), str(crashed), "0"], check=True)
    assert _shard_bytes(crashed) == _shard_bytes(reference)
    ids = [s.scenario_id for s in read_shards(crashed)]
    assert len(ids) == len(set(ids)) == 31
