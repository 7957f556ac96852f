"""The conversion never touches files it does not own, keeps its progress, and leaves no process behind."""

import errno
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
from scenariomax.sources.base import InputError
from scenariomax.sources.registry import nuplan_locations
from tests.foundation.toy_source import ToySource

SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_lanes=4)
ROOT = Path(__file__).resolve().parents[2]


def _settings(out, **kw):
    return ConvertSettings(out=out, sizes=SIZES, shard_size=kw.pop("shard_size", 5), progress=False,
                           workers=kw.pop("workers", 1), **kw)


def _snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


def _shard_bytes(out: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(out.glob("*.tfrecord"))}


@pytest.fixture
def users_folder(tmp_path):
    """A folder of a user's files, including a shard-like file and a hidden work folder of the same name."""
    folder = tmp_path / "mine"
    (folder / ".work").mkdir(parents=True)
    (folder / ".work" / "notes.txt").write_text("my notes")
    (folder / "train-00000-of-00001.tfrecord").write_bytes(b"my 100 scenarios")
    (folder / ".sealed-train-00000.tfrecord").write_bytes(b"not yours")
    return folder


@pytest.mark.parametrize("flags", [{}, {"resume": True}, {"overwrite": True}])
def test_a_folder_of_someone_elses_files_is_refused_untouched(users_folder, flags):
    before = _snapshot(users_folder)
    with pytest.raises(ConversionError, match="not empty and holds no manifest.json") as refused:
        convert(ToySource(num_units=1), _settings(users_folder, **flags))
    assert "\n" not in str(refused.value) and str(users_folder) in str(refused.value)
    assert _snapshot(users_folder) == before


def test_overwrite_replaces_only_what_the_manifest_lists(tmp_path):
    out = tmp_path / "o"
    convert(ToySource(num_units=2), _settings(out))
    (out / "README.txt").write_text("a user's file")
    before = _snapshot(out)
    with pytest.raises(ConversionError, match="also holds README.txt"):
        convert(ToySource(num_units=3), _settings(out, overwrite=True))
    assert _snapshot(out) == before
    (out / "README.txt").unlink()
    result = convert(ToySource(num_units=3), _settings(out, overwrite=True))
    assert result.num_scenarios == 11 and len(list(read_shards(out))) == 11  # 3 x 4, one failed in the source
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", *result.shards]


def test_resume_with_other_inputs_is_refused(tmp_path):
    out = tmp_path / "o"
    convert(ToySource(num_units=2), _settings(out))

    class MoreFiles(ToySource):  # same settings, one input more: a different --src
        def list_units(self):
            return [*super().list_units(), "toy:099"]

    with pytest.raises(ConversionError, match=r"inputs differ .*1 new, 0 missing, e.g. toy:099"):
        convert(MoreFiles(num_units=2), _settings(out, resume=True))


@pytest.mark.parametrize("text", ["", "{\"state\": ", "[1, 2]", "{\"a\": 1}"])
def test_a_broken_manifest_gives_one_line(tmp_path, text):
    out = tmp_path / "o"
    out.mkdir()
    (out / "manifest.json").write_text(text)
    with pytest.raises(ConversionError, match="manifest.json: .*the manifest is damaged") as error:
        convert(ToySource(num_units=1), _settings(out, resume=True))
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(("flags", "message"), [
    ({"split": "../x"}, "--split '../x'"),
    ({"shard_size": 0}, "--shard-size 0"),
    ({"workers": 0}, "--workers 0"),
    ({"resume": True, "overwrite": True}, "exclude each other"),
])
def test_bad_option_values_are_refused_before_anything_is_written(tmp_path, flags, message):
    with pytest.raises(ConversionError, match=message):
        convert(ToySource(num_units=1), _settings(tmp_path / "o", **flags))
    assert not (tmp_path / "o").exists() and not (tmp_path / "x").exists()


def test_an_output_folder_holding_the_inputs_is_refused(tmp_path):
    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "a.bin").write_bytes(b"x")

    class FileSource(ToySource):
        def list_units(self):
            return [str(raw / "a.bin")]

    with pytest.raises(ConversionError, match="holds the inputs of this conversion"):
        convert(FileSource(), _settings(raw, overwrite=True))
    assert (raw / "a.bin").read_bytes() == b"x"


def test_a_full_disk_is_one_line_and_stays_resumable(tmp_path, monkeypatch):
    import scenariomax.pipeline as pipeline

    out = tmp_path / "o"
    real_close = pipeline._OpenShard.close
    calls = {"n": 0}

    def full_after_two_shards(shard):  # the disk fills as the third shard is flushed to be sealed
        calls["n"] += 1
        if calls["n"] > 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(shard.path))
        return real_close(shard)

    monkeypatch.setattr(pipeline._OpenShard, "close", full_after_two_shards)
    with pytest.raises(ConversionError) as error:
        convert(ToySource(), _settings(out))
    message = str(error.value)
    assert "No space left on device; free some space, then rerun with --resume" in message
    assert "\n" not in message and message.count(str(out)) == 1
    monkeypatch.setattr(pipeline._OpenShard, "close", real_close)
    resumed = convert(ToySource(), _settings(out, resume=True))
    convert(ToySource(), _settings(tmp_path / "ref"))
    assert resumed.num_scenarios == 23 and _shard_bytes(out) == _shard_bytes(tmp_path / "ref")


def test_a_kill_between_listing_a_shard_and_creating_it_stays_resumable(tmp_path, monkeypatch):
    """The manifest names the next shard before its file exists (no unlisted file is ever left); a kill in
    between (found by tests/interop/test_ray_cluster.py) must resume, not ask for --overwrite."""
    import scenariomax.pipeline as pipeline

    class Killed(BaseException):
        pass

    real_open = pipeline._OpenShard

    def killed_at_the_third_shard(path, *args, **kwargs):
        if path.name.endswith("-00002.tfrecord") and not kwargs and not args:
            raise Killed
        return real_open(path, *args, **kwargs)

    out = tmp_path / "o"
    monkeypatch.setattr(pipeline, "_OpenShard", killed_at_the_third_shard)
    with pytest.raises(Killed):
        convert(ToySource(), _settings(out))
    assert not list(out.glob(".sealing-*")) and json.loads((out / "manifest.json").read_text())["open_shard"]
    monkeypatch.setattr(pipeline, "_OpenShard", real_open)
    resumed = convert(ToySource(), _settings(out, resume=True))
    convert(ToySource(), _settings(tmp_path / "ref"))
    assert resumed.num_scenarios == 23 and _shard_bytes(out) == _shard_bytes(tmp_path / "ref")


def test_a_source_with_no_scenarios_is_not_a_success(tmp_path):
    result = convert(ToySource(num_units=2, per_unit=0), _settings(tmp_path / "o"))
    assert result.num_scenarios == 0 and not result.ok


def test_nuplan_locations_default_to_the_devkit_variables(tmp_path):
    env = {"NUPLAN_DATA_ROOT": "/data/nuplan", "NUPLAN_DB_FILES": "/data/nuplan/splits/mini",
           "NUPLAN_MAPS_ROOT": "/data/maps"}
    assert nuplan_locations(None, None, env) == ("/data/nuplan/splits/mini", "/data/maps")
    assert nuplan_locations(None, None, {"NUPLAN_DATA_ROOT": "/d"}) == ("/d", "/d/maps")
    assert nuplan_locations("/x", "/m", env) == ("/x", "/m")
    with pytest.raises(InputError) as missing:
        nuplan_locations(None, None, {})
    assert "--src (or NUPLAN_DB_FILES / NUPLAN_DATA_ROOT) and --maps (or NUPLAN_MAPS_ROOT)" in str(missing.value)


# --------------------------------------------------------------------------------------------------
# kill -9 of the main process only: durable progress, no process left behind.

_CHILD = """
import sys
sys.path.insert(0, {root!r})
from pathlib import Path
from scenariomax import Sizes
from scenariomax.pipeline import ConvertSettings, convert
from tests.foundation.toy_source import ToySource
if __name__ == "__main__":  # worker processes re-import this module
    source = ToySource(num_units=int(sys.argv[3]), per_unit=4, delay_s=float(sys.argv[2]))
    convert(source, ConvertSettings(out=Path(sys.argv[1]), sizes=Sizes(num_objects=8, num_roadgraph=2000, num_lanes=4),
            shard_size=1000, workers=2, progress=False, resume=True))
"""


def _descendants(pid: int) -> set[int]:
    """Every process whose ancestry leads to `pid` (read from /proc: Linux)."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            parents[int(entry.name)] = int(fields[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _wait_gone(pids: set[int], timeout_s: float = 15.0) -> None:
    """Workers still importing when the main process died exit once their watch starts (seconds on a busy box)."""
    deadline = time.time() + timeout_s
    while time.time() < deadline and any(_alive(pid) for pid in pids):
        time.sleep(0.1)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:200]
    except OSError:
        return "?"


def _kill_main_when(script: Path, out: Path, units: int, ready) -> set[int]:
    """Starts a conversion, SIGKILLs its main process (only) once `ready(manifest)`; returns its children."""
    child = subprocess.Popen([sys.executable, str(script), str(out), "0.05", str(units)])
    deadline, children = time.time() + 120, set()
    while time.time() < deadline:
        children |= _descendants(child.pid)
        manifest = out / "manifest.json"
        if manifest.exists():
            try:
                if ready(json.loads(manifest.read_text())):
                    break
            except json.JSONDecodeError:
                pass
        time.sleep(0.02)
    children |= _descendants(child.pid)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    return children


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the process tree from /proc")
def test_kill_9_of_the_main_process_keeps_progress_and_leaves_no_process(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(_CHILD.format(root=str(ROOT)))
    reference, crashed = tmp_path / "ref", tmp_path / "crash"
    subprocess.run([sys.executable, str(script), str(reference), "0", "60"], check=True)

    def saved_some(manifest):  # one big shard (1000) never fills: progress must come from checkpoints
        return sum(u["saved_records"] for u in manifest["units"].values()) >= 12

    children = _kill_main_when(script, crashed, 60, saved_some)
    assert children, "the conversion started no worker process"
    _wait_gone(children)
    assert not [pid for pid in children if _alive(pid)], "workers outlived the killed conversion"
    state = json.loads((crashed / "manifest.json").read_text())
    assert state["state"] == "running" and state["open_shard"]["num_records"] >= 12  # kept, though no shard sealed
    subprocess.run([sys.executable, str(script), str(crashed), "0", "60"], check=True)
    assert _shard_bytes(crashed) == _shard_bytes(reference)
    # The shard's sha256 is hashed while writing: the resumed run hashed the kept bytes it did not write.
    from scenariomax.manifest import check_output

    assert check_output(crashed) == []


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the process tree from /proc")
def test_ten_random_kills_of_a_300_scenario_conversion(tmp_path):
    """Each kill leaves no process and an output that validation rejects; resuming gives the same bytes."""
    import random

    from scenariomax.manifest import check_output

    script = tmp_path / "child.py"
    script.write_text(_CHILD.replace("shard_size=1000", "shard_size=40").format(root=str(ROOT)))
    reference, crashed = tmp_path / "ref", tmp_path / "crash"
    subprocess.run([sys.executable, str(script), str(reference), "0", "75"], check=True)
    assert check_output(reference) == []
    moments = sorted(random.Random(7).uniform(0.3, 4.0) for _ in range(10))
    interrupted = 0
    for moment in moments:
        started = time.time()
        children = _kill_main_when(script, crashed, 75, lambda _, t0=started, m=moment: time.time() - t0 >= m)
        _wait_gone(children)
        left = [_cmdline(pid) for pid in children if _alive(pid)]
        assert not left, f"processes outlived the kill at {moment:.1f} s: {left}"
        manifest = crashed / "manifest.json"
        if manifest.exists() and json.loads(manifest.read_text())["state"] != "complete":
            interrupted += 1
            assert check_output(crashed), f"an output interrupted at {moment:.1f} s passed validation"
    assert interrupted >= 5
    subprocess.run([sys.executable, str(script), str(crashed), "0", "75"], check=True)
    assert _shard_bytes(crashed) == _shard_bytes(reference) and check_output(crashed) == []


def test_the_cli_fails_on_inputs_without_scenarios_and_refuses_a_finished_output(tmp_path):
    empty = tmp_path / "empty.tfrecord"
    empty.write_bytes(b"")
    command = [sys.executable, "-m", "vmax_cli.scenariomax_cli", "convert"]
    nothing = subprocess.run([*command, "--dataset", "womd", "--src", str(empty), "--out", str(tmp_path / "o")],
                             capture_output=True, text=True, cwd=ROOT)
    assert nothing.returncode == 1 and "no scenario could be converted" in nothing.stderr
    again = subprocess.run([*command, "--num-scenarios", "2", "--out", str(tmp_path / "o")],
                           capture_output=True, text=True, cwd=ROOT)
    assert again.returncode != 0 and again.stderr.count("\n") == 1 and "--overwrite to replace it" in again.stderr
    assert "converting: " not in again.stderr  # refused before any work


@pytest.mark.parametrize(("code", "advice"), [(errno.ENOSPC, "free some space"), (errno.EROFS, "a folder you can"),
                                              (errno.EACCES, "a folder you can"), (errno.ENOENT, "check the path")])
def test_os_errors_are_one_line_with_the_path_once(code, advice):
    from scenariomax.errors import one_line

    line = one_line(OSError(code, os.strerror(code), "/data/out/train-00000.tfrecord"))
    assert line.startswith("/data/out/train-00000.tfrecord: ") and advice in line
    assert line.count("/data/out") == 1 and "\n" not in line and "Errno" not in line


def test_unwritable_outputs_of_other_commands_are_one_line(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    target = blocker / "doc.md"  # its parent is a file: no user can write there, root included
    done = subprocess.run([sys.executable, "-m", "vmax_cli.scenariomax_cli", "schema-doc", "--out", str(target)],
                          capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert "a file stands where a folder is needed" in done.stderr
    assert "Traceback" not in done.stderr and "Errno" not in done.stderr
