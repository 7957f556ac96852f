"""`validate_record` / `validate_shards`: good shards pass; each kind of damage gives its own one-line reason."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax import write_shards
from scenariomax.codec import scenario_to_features
from scenariomax.errors import InputError
from scenariomax.io.example import encode_example
from scenariomax.io.tfrecord import TFRecordWriter
from scenariomax.validate import format_validation, validate_record, validate_shards
from tests.conftest import realdata_file
from tests.inspect.scenes import SIZES, make_scenario


@functools.lru_cache(maxsize=1)
def _good_features() -> dict:
    return scenario_to_features(make_scenario(), SIZES)


def _record(**changes) -> bytes:
    """A record of the hand-made scene with features replaced (value None deletes the key)."""
    features = dict(_good_features())
    for key, value in changes.items():
        if value is None:
            features.pop(key)
        else:
            features[key] = value
    return encode_example(features)


def _only(problems: list[str]) -> str:
    assert len(problems) == 1, problems
    return problems[0]


def test_good_record_has_no_problems():
    assert validate_record(_record()) == []


def test_raw_womd_layout_without_paths_and_extras_is_acceptable():
    features = {k: v for k, v in _good_features().items()
                if not k.startswith(("path_samples/", "vmax/"))}
    assert validate_record(encode_example(features)) == []


def test_missing_required_key_is_named():
    assert _only(validate_record(_record(**{"state/past/x": None}))) == "missing required key state/past/x"


def test_partially_present_group_is_an_error():
    reason = _only(validate_record(_record(**{"path_samples/xyz": None})))
    assert reason == "partial path_samples/* group: missing path_samples/xyz (4 of 5 keys present)"


def test_wrong_element_count_names_key_and_expected_count():
    short = _good_features()["roadgraph_samples/type"][:-1]
    reason = _only(validate_record(_record(**{"roadgraph_samples/type": short})))
    assert reason == ("roadgraph_samples/type has 599 values, expected 600 (600) "
                      "for the sizes the record implies")


def test_wrong_dtype_kind_is_reported():
    as_float = _good_features()["state/is_sdc"].astype(np.float32)
    reason = _only(validate_record(_record(**{"state/is_sdc": as_float})))
    assert reason == "state/is_sdc is stored as float_list, the schema wants int64_list"


def test_unknown_extra_key_is_reported():
    assert _only(validate_record(_record(**{"my/extra": np.zeros(3, np.int64)}))) == "unknown key my/extra"


def test_nan_position_at_a_valid_step():
    x = _good_features()["state/current/x"].copy()
    x[0] = np.nan
    assert _only(validate_record(_record(**{"state/current/x": x}))) == "x has NaN or infinite values at valid steps"


def test_two_sdcs():
    is_sdc = _good_features()["state/is_sdc"].copy()
    is_sdc[1] = 1
    assert _only(validate_record(_record(**{"state/is_sdc": is_sdc}))) == "expected exactly one SDC, found 2"


def test_flag_with_other_values():
    valid = _good_features()["roadgraph_samples/valid"].copy()
    valid[0] = 2
    reason = _only(validate_record(_record(**{"roadgraph_samples/valid": valid})))
    assert reason == "flag roadgraph_samples/valid holds values other than 0 and 1"


def test_bytes_that_are_not_a_tf_example():
    problems = validate_record(b"\xff\xff\xff\xff not a protobuf")
    assert len(problems) == 1 and "tf.Example" in problems[0]


@functools.lru_cache(maxsize=1)
def _good_bytes() -> bytes:
    return _record()


@settings(max_examples=30, deadline=None)
@given(cut=st.integers(min_value=0, max_value=20_000), flip=st.integers(min_value=0, max_value=255),
       position=st.integers(min_value=0, max_value=20_000))
def test_damaged_bytes_give_problems_never_exceptions(cut, flip, position):
    data = bytearray(_good_bytes()[: max(cut, 1)])
    data[position % len(data)] ^= flip
    problems = validate_record(bytes(data))
    assert all(isinstance(p, str) and "\n" not in p for p in problems)


def test_validate_shards_passes_a_good_set(tmp_path):
    scenes = [make_scenario("a"), make_scenario("b", with_lights=False, with_paths=False)]
    write_shards(scenes, tmp_path, sizes=SIZES, shard_size=1)
    report = validate_shards(tmp_path)
    assert (report.num_records, report.num_files, report.bad, report.ok) == (2, 2, (), True)
    assert format_validation(report).endswith("2 records in 2 file(s): OK")


def test_bad_record_reported_with_file_index_and_id(tmp_path):
    is_sdc = _good_features()["state/is_sdc"].copy()
    is_sdc[2] = 1
    path = tmp_path / "mixed.tfrecord"
    with TFRecordWriter(path) as writer:
        writer.write(_record())
        writer.write(_record(**{"state/is_sdc": is_sdc, "scenario/id": [b"scene-b"]}))
    report = validate_shards(path)
    assert report.num_records == 2
    assert report.bad == ((str(path), 1, "scene-b", "expected exactly one SDC, found 2"),)


def test_truncated_file_is_reported_and_validation_continues(tmp_path):
    scenes = [make_scenario(f"s{i}") for i in range(4)]
    first, _ = write_shards(scenes, tmp_path, sizes=SIZES, shard_size=2)
    data = first.read_bytes()
    record_bytes = len(data) // 2  # both records have the same size
    first.write_bytes(data[: record_bytes + 100])  # the second record loses its tail
    report = validate_shards(tmp_path)
    assert report.num_files == 2
    assert report.num_records == 3  # 1 from the damaged file + 2 from the next one
    size_problem, entry = report.bad  # the manifest notices the size first, then the framing says where
    assert size_problem == (str(first), -1, "", f"{record_bytes + 100} bytes, manifest.json lists {len(data)}: "
                            "the file was changed or cut short after it was written")
    assert entry.file == str(first) and entry.record_index == 1 and entry.scenario_id == ""
    assert entry.reason == (f"{first}: truncated record at byte {record_bytes} "
                            f"(expected {record_bytes - 16} bytes of data)")
    assert "truncated record" in format_validation(report)


def test_missing_path_is_a_clean_input_error(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        validate_shards(tmp_path / "nowhere")


def test_real_womd_example_validates():
    path = realdata_file("womd/motion_data_one_example.tfrecord")
    report = validate_shards(path)
    assert (report.num_records, report.bad) == (1, ())
