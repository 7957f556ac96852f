"""Pickle bombs: small files that ask for huge arrays or reference one value thousands of times must
end in a one-line error, fast and in little memory."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.sources.scenarionet import (
    PickleLimitError,
    PickleLimits,
    expanded_size,
    load_pickle,
    loads_restricted,
)
from scenariomax.sources.scenarionet.unpickle import _multiarray
from tests.sources.scenarionet.fixtures import build_description, write_pickle

REPO = Path(__file__).resolve().parents[3]

# Runs one conversion in a fresh interpreter and reports its own time and peak memory.
_CHILD = """
import resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))  # if the caps regress, fail here, not the machine
from scenariomax.errors import InputError
from scenariomax.sources.scenarionet import ScenarioNetSource
path = sys.argv[1]
start = time.perf_counter()
try:
    list(ScenarioNetSource(path).read_unit(path))
    print("RESULT converted")
except InputError as error:
    print("RESULT", error)
print("SECONDS", time.perf_counter() - start)
# VmHWM is this process image's own peak; ru_maxrss would carry over the forking parent's (pytest's) peak
print("PEAK_KIB", [line.split()[1] for line in open("/proc/self/status") if line.startswith("VmHWM")][0])
"""


def run_child(path: Path) -> dict[str, str]:
    done = subprocess.run([sys.executable, "-c", _CHILD, str(path)], cwd=REPO, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return dict(line.split(" ", 1) for line in done.stdout.splitlines() if " " in line)


def shared_array_bomb(path: Path) -> Path:
    """~1.1 MB on disk: one 1 MiB array used as the polyline of 5000 lanes (5 GB if materialised)."""
    polyline = np.linspace(0.0, 1.0, 131_072).reshape(-1, 2)
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["map_features"] = {f"lane-{i}": {"type": "LANE_SURFACE_STREET", "polyline": polyline} for i in range(5000)}
    return write_pickle(path, desc)


def shared_list_bomb(path: Path) -> Path:
    """~1.3 MB: one list of 60k points shared by 2000 lanes (3.6e8 values if materialised)."""
    points = [[float(i), 0.0] for i in range(60_000)]
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["map_features"] = {f"lane-{i}": {"type": "LANE_SURFACE_STREET", "polyline": points} for i in range(2000)}
    return write_pickle(path, desc)


@pytest.mark.parametrize("make, message", [(shared_array_bomb, "bytes of array data"),
                                           (shared_list_bomb, "values")])
def test_memo_sharing_bomb_fails_fast_and_small(tmp_path, make, message):
    path = make(tmp_path / "sd_bomb.pkl")
    assert 0.5e6 < path.stat().st_size < 2e6
    report = run_child(path)
    assert report["RESULT"].startswith(f"{path}: expands to more than") and message in report["RESULT"]
    assert "\n" not in report["RESULT"]
    assert float(report["SECONDS"]) < 10.0
    assert int(report["PEAK_KIB"]) * 1024 < 1 << 30


@pytest.mark.parametrize("value, message", [
    ("laughs", "values"),
    ("deep", "nested more than 100 levels"),
])
def test_expansion_shapes_are_refused(value, message):
    if value == "laughs":
        value = [0]
        for _ in range(60):
            value = [value, value]  # 2^60 leaves from 61 lists
    else:
        value = []
        for _ in range(300):
            value = [value]
    with pytest.raises(PickleLimitError, match=message):
        loads_restricted(pickle.dumps(value, protocol=4))


def test_reference_cycle_is_read_and_counted_once():
    """Writers made cycles (MetaDrive's speed bump whose type is itself): legitimate, not a bomb; the
    back-reference counts as one value, so the caps still bound what is built."""
    bump = {"polygon": np.zeros((4, 3))}
    bump["type"] = bump
    loaded = loads_restricted(pickle.dumps({"map_features": {"7": bump}}, protocol=4))
    assert loaded["map_features"]["7"]["type"] is loaded["map_features"]["7"]
    # root, 3 dicts' 4 keys, features dict, bump, polygon, the back-reference: 9 values; 96 array + 24 key bytes
    assert expanded_size(loaded) == (9, 120)
    ring = [[0] * 10]
    ring.append(ring)
    with pytest.raises(PickleLimitError, match="values"):
        loads_restricted(pickle.dumps(ring, protocol=4), PickleLimits(max_nodes=5))


class Reduces:
    def __init__(self, func, args, state=None):
        self.func, self.args, self.state = func, args, state

    def __reduce__(self):
        return (self.func, self.args) if self.state is None else (self.func, self.args, self.state)


def empty_array(state=None) -> Reduces:
    return Reduces(_multiarray._reconstruct, (np.ndarray, (0,), b"b"), state)


@pytest.mark.parametrize("payload", [
    Reduces(_multiarray._reconstruct, (np.ndarray, (10 ** 12,), b"b")),  # a terabyte, uninitialised
    empty_array((1, (10 ** 12,), np.dtype("f8"), False, b"")),  # the BUILD state claims a terabyte
    Reduces(_multiarray._reconstruct, (np.ndarray, (10 ** 6, 10 ** 6), np.dtype("V100"))),
])
def test_huge_arrays_are_refused_before_allocation(payload):
    with pytest.raises(PickleLimitError, match="builds more than"):
        loads_restricted(pickle.dumps(payload, protocol=4))


def test_calls_on_a_shared_input_are_charged_each_time():
    """A few bytes per call, a large object each time: charged per call, not per file byte."""
    shared = list(range(100_000))
    many_sets = [Reduces(set, (shared,)) for _ in range(200)]
    limits = PickleLimits(max_built_bytes=64 << 20)
    with pytest.raises(PickleLimitError, match="builds more than"):
        loads_restricted(pickle.dumps(many_sets, protocol=4), limits)
    many_arrays = [empty_array((1, (len(shared),), np.dtype("O"), False, shared)) for _ in range(200)]
    with pytest.raises(PickleLimitError, match="builds more than"):
        loads_restricted(pickle.dumps(many_arrays, protocol=4), limits)


def test_file_and_opcode_caps(tmp_path):
    data = pickle.dumps(build_description(), protocol=4)
    with pytest.raises(PickleLimitError, match="opcodes"):
        loads_restricted(data, PickleLimits(max_opcodes=1000))
    path = write_pickle(tmp_path / "sd_x.pkl", build_description())
    with pytest.raises(Exception, match="more than the 1000 a pickle may have") as info:
        load_pickle(path, PickleLimits(max_file_bytes=1000))
    assert str(path) in str(info.value)


# --- expanded_size against a naive count -----------------------------------------------------------
def naive_size(value) -> tuple[int, int]:
    nodes, data = 1, 0
    if isinstance(value, np.ndarray):
        data += value.nbytes
    elif isinstance(value, (str, bytes)):
        data += len(value)
    children = (list(value.keys()) + list(value.values())) if isinstance(value, dict) else (
        value if isinstance(value, (list, tuple)) else [])
    for child in children:
        child_nodes, child_data = naive_size(child)
        nodes, data = nodes + child_nodes, data + child_data
    return nodes, data


leaves = st.one_of(st.integers(), st.text(max_size=5), st.builds(np.zeros, st.integers(0, 4)))
trees = st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.tuples(inner, inner),
    st.dictionaries(st.text(max_size=3), inner, max_size=3),
    inner.map(lambda shared: [shared, shared, (shared,)])), max_leaves=20)


@settings(max_examples=60, deadline=None)
@given(tree=trees)
def test_expanded_size_counts_every_reference(tree):
    assert expanded_size(tree) == naive_size(tree)
    assert expanded_size(loads_restricted(pickle.dumps(tree, protocol=4))) == naive_size(tree)
