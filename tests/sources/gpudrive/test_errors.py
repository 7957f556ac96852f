"""Bad GPUDrive / Nocturne files: one-line InputError naming the file, or a one-line Failure; never a crash."""

from __future__ import annotations

import copy
import json
import tempfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.gpudrive import GpuDriveSource
from tests.sources.gpudrive.fixtures import scene_document, write_document


def read(path: Path) -> list:
    return list(GpuDriveSource(str(path)).read_unit(str(path)))


def input_error(tmp_path, doc_or_bytes) -> str:
    path = tmp_path / "bad.json"
    if isinstance(doc_or_bytes, bytes):
        path.write_bytes(doc_or_bytes)
    else:
        path.write_text(json.dumps(doc_or_bytes))
    with pytest.raises(InputError) as info:
        read(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    return message


def failure(tmp_path, doc) -> str:
    items = read(write_document(tmp_path, doc))
    assert len(items) == 1 and isinstance(items[0], Failure), items
    assert "\n" not in items[0].reason
    return items[0].reason


def test_truncated_json(tmp_path):
    data = json.dumps(scene_document("gpudrive-metadata")).encode()
    assert "invalid JSON" in input_error(tmp_path, data[: len(data) // 2])


@pytest.mark.parametrize("data, expected", [
    (b"", "invalid JSON"), (b"\xff\xfe{}", "not UTF-8"), (b"[1, 2]", "found a JSON list"),
    (b"[" * 100_000, "invalid JSON"), (b'{"objects": [], "roads": [], "tl_states": [1]}', "'tl_states'"),
    (b'{"objects": [{"position": ' + b"1" * 5000 + b"}]}", "invalid JSON"),
])
def test_not_a_scenario(tmp_path, data, expected):
    assert expected in input_error(tmp_path, data)


def test_empty_objects_list(tmp_path):
    assert "objects: the list is empty" in input_error(tmp_path, scene_document(objects=[]))


def _mutated(change) -> dict:
    doc = copy.deepcopy(scene_document("gpudrive-metadata"))
    change(doc)
    return doc


def _set(path: tuple, value):
    def change(doc):
        target = doc
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return change


def _delete(path: tuple):
    def change(doc):
        target = doc
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
    return change


@pytest.mark.parametrize("change, expected", [
    (_set(("objects",), {"a": 1}), "expected a JSON object with an 'objects' list"),
    (_set(("objects", 0), "car"), "objects[0]: expected a JSON object, found a string"),
    (_set(("objects", 1, "position"), "abc"), "objects[1].position: expected a list, found a string"),
    (_set(("objects", 1, "position", 3), [1.0, 2.0]), "objects[1].position[3]: expected an object"),
    (_set(("objects", 1, "position", 3, "x"), "1.5"), "objects[1].position[3]: expected numeric coordinates"),
    (_set(("objects", 1, "heading", 2), None), "objects[1].heading[2]: expected a number, found null"),
    (_set(("objects", 1, "valid", 2), 2), "objects[1].valid[2]: expected true or false"),
    (_set(("objects", 1, "length"), "long"), "objects[1].length: expected a number, found a string"),
    (_set(("objects", 1, "type"), 5), "objects[1].type: expected a string, found an integer"),
    (_set(("objects", 1, "id"), 1.5), "objects[1].id: expected an integer"),
    (_set(("objects", 1, "heading"), [0.0] * 90), "objects[1]: per-step lists differ in length"),
    (_set(("objects", 2, "position"), []), "objects[2]: per-step lists differ in length"),
    (_set(("roads", 0), []), "roads[0]: expected a JSON object, found a list"),
    (_delete(("roads", 0, "geometry")), "roads[0]: missing 'geometry'"),
    (_set(("roads", 0, "geometry", 0), {"x": 1.0}), "roads[0].geometry[0]: expected an object"),
    (_set(("roads", 0, "map_element_id"), "lane"), "roads[0].map_element_id: expected an integer"),
    (_set(("roads", 0, "type"), 7), "roads[0].type: expected a string, found an integer"),
    (_delete(("objects", 1, "heading")), "objects[1]: missing 'heading'"),
    (_set(("tl_states",), {"lane7": {"state": []}}), "tl_states['lane7']: expected a lane id"),
    (_set(("tl_states",), {"7": {"state": [{"go": 1}], "x": [1.0], "y": [1.0]}}), "state[0]: expected a state name"),
    (_set(("tl_states",), {"7": {"state": ["go"], "x": [1.0], "y": [1.0], "time_index": [0.5]}}),
     "time_index: expected integer steps"),
    (_set(("metadata",), [1]), "expected 'metadata' to be a JSON object"),
])
def test_wrong_types_and_missing_keys(tmp_path, change, expected):
    assert expected in input_error(tmp_path, _mutated(change))


def test_number_beyond_float_range(tmp_path):
    text = json.dumps(scene_document("gpudrive-metadata")).replace('"length": 4.5', '"length": 1' + "0" * 400, 1)
    assert "objects[1].length: number out of range" in input_error(tmp_path, text.encode())


def test_nan_and_infinite_values_make_steps_invalid(tmp_path):
    doc = scene_document("gpudrive-metadata")
    doc["objects"][1]["position"][5] = {"x": float("nan"), "y": 0.0, "z": 0.0}
    doc["objects"][1]["heading"][6] = float("inf")
    doc["roads"][0]["geometry"][1] = {"x": float("nan"), "y": 0.0, "z": 0.0}
    items = read(write_document(tmp_path, doc))
    assert len(items) == 1 and isinstance(items[0], Scenario) and items[0].validate() == []
    notes = items[0].metadata[MANIFEST_NOTES]
    assert notes["valid_steps_dropped"] == 2 and notes["road_points_dropped"] == 1
    row = int((items[0].object_id == 12).nonzero()[0][0])
    assert not items[0].valid[row, 5] and not items[0].valid[row, 6] and items[0].valid[row, 7]


def test_sdc_invalid_at_the_current_step(tmp_path):
    doc = scene_document("gpudrive-metadata")
    doc["objects"][3]["position"][10]["x"] = float("nan")
    assert "the SDC (object 3) is not valid at the current step" in failure(tmp_path, doc)


def test_coordinate_lists_of_different_lengths(tmp_path):
    doc = scene_document("nocturne")
    xs = [p["x"] for p in doc["objects"][0]["position"]]
    doc["objects"][0]["position"] = {"x": xs, "y": xs[:-1]}
    assert "objects[0].position: coordinate lists differ in length (x 91, y 90)" in input_error(tmp_path, doc)


def test_no_sdc_candidate(tmp_path):
    doc = scene_document("nocturne")
    for obj in doc["objects"]:
        obj["valid"][0] = False
    assert "no vehicle is valid at every step" in failure(tmp_path, doc)


def test_missing_file_and_index_only_folder(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        list(GpuDriveSource(str(tmp_path)).read_unit(str(tmp_path / "gone.json")))
    (tmp_path / "valid_files.json").write_text("{}")
    with pytest.raises(InputError, match="no GPUDrive / Nocturne JSON scenarios"):
        GpuDriveSource(str(tmp_path)).list_units()


# --- fuzz: truncated and corrupted bytes --------------------------------------------------------------
PRISTINE = json.dumps(scene_document("gpudrive-metadata", num_steps=11)).encode()


def _check_bytes(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.json"
        path.write_bytes(data)
        try:
            items = read(path)
        except InputError as error:
            assert str(error).startswith(f"{path}: ") and "\n" not in str(error)
            return
        for item in items:
            if isinstance(item, Failure):
                assert "\n" not in item.reason and item.unit == str(path)
            else:
                assert isinstance(item, Scenario) and item.validate() == []


@settings(max_examples=40, deadline=None)
@given(cut=st.integers(min_value=0, max_value=len(PRISTINE)))
def test_truncated_bytes(cut):
    _check_bytes(PRISTINE[:cut])


@settings(max_examples=60, deadline=None)
@given(flips=st.lists(st.tuples(st.integers(min_value=0, max_value=len(PRISTINE) - 1),
                                st.sampled_from(b'0123456789-.eE,:[]{}"nulltrue ')), min_size=1, max_size=6))
def test_corrupted_bytes(flips):
    data = bytearray(PRISTINE)
    for position, value in flips:
        data[position] = value
    _check_bytes(bytes(data))
