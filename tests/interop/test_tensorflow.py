"""Byte-level interoperability with TensorFlow (needs the `tf` extra; run with `pytest -m tf`)."""

import numpy as np
import pytest

from scenariomax import Sizes, read_shards, write_shards
from scenariomax.codec import scenario_to_features
from tests.conftest import realdata_file, straight_road_scenario

pytestmark = pytest.mark.tf
tf = pytest.importorskip("tensorflow", reason="the tf extra (tensorflow-cpu) is not installed")

SIZES = Sizes()  # Waymax's defaults: 128 objects, 30000 points, 16 lights, 10 paths x 300 points


def _waymax_feature_description(sizes: Sizes) -> dict:
    """The parsing spec Waymax's dataloader builds for include_sdc_paths=True (shapes from the WOMD layout)."""
    from scenariomax.schema import load_schema

    spec = {}
    for feature in load_schema().features:
        if feature.group != "waymax":
            continue
        dtype = {"float": tf.float32, "int64": tf.int64, "bytes": tf.string}[feature.dtype]
        shape = feature.resolved_shape(sizes.as_dict()) if feature.shape else [1]
        spec[feature.key] = tf.io.FixedLenFeature(list(shape), dtype)
    return spec


def test_tensorflow_reads_our_shards(tmp_path):
    scenario = straight_road_scenario()
    files = write_shards([scenario], tmp_path, SIZES)
    records = list(tf.data.TFRecordDataset([str(f) for f in files]))  # checks our CRCs
    assert len(records) == 1
    parsed = tf.io.parse_single_example(records[0], _waymax_feature_description(SIZES))
    ours = scenario_to_features(scenario, SIZES)
    for key, value in parsed.items():
        if key == "scenario/id":
            assert value.numpy()[0] == b"toy-0"
        else:
            np.testing.assert_array_equal(value.numpy(), ours[key].reshape(value.shape), err_msg=key)
    # Waymax's SDC path shapes.
    assert parsed["path_samples/xyz"].shape == (10, 300, 3)
    assert parsed["path_samples/valid"].shape == (10, 300)
    assert parsed["path_samples/on_route"].shape == (10, 1)


def test_we_read_tensorflow_written_records(tmp_path):
    data = next(iter(tf.data.TFRecordDataset([str(realdata_file("womd/motion_data_one_example.tfrecord"))])))
    path = tmp_path / "tf_written.tfrecord"
    with tf.io.TFRecordWriter(str(path)) as writer:
        writer.write(data.numpy())
        writer.write(data.numpy())
    scenarios = list(read_shards(path))
    assert len(scenarios) == 2 and scenarios[0].scenario_id == "a3bb37c25ce56418"
    assert scenarios[0].validate() == []


def test_tensorflow_reads_our_gzip_shards(tmp_path):
    """`--compression gzip` writes one gzip member per record; tf.data (>= 2.5) reads concatenated members."""
    scenarios = [straight_road_scenario(scenario_id=f"toy-{i}") for i in range(3)]
    files = write_shards(scenarios, tmp_path, SIZES, compression="gzip")
    records = list(tf.data.TFRecordDataset([str(f) for f in files], compression_type="GZIP"))
    assert len(records) == 3
    parsed = tf.io.parse_single_example(records[2], _waymax_feature_description(SIZES))
    assert parsed["scenario/id"].numpy()[0] == b"toy-2"
    np.testing.assert_array_equal(parsed["roadgraph_samples/xyz"].numpy(),
                                  scenario_to_features(scenarios[2], SIZES)["roadgraph_samples/xyz"].reshape(-1, 3))


def test_we_read_tensorflow_written_gzip_records(tmp_path):
    """A GZIP TFRecord from TensorFlow (one gzip stream for the whole file) reads without a flag, in order and
    by offset."""
    from scenariomax.shards import iter_shard_records

    data = next(iter(tf.data.TFRecordDataset([str(realdata_file("womd/motion_data_one_example.tfrecord"))])))
    path = tmp_path / "tf_written.tfrecord"
    with tf.io.TFRecordWriter(str(path), options=tf.io.TFRecordOptions(compression_type="GZIP")) as writer:
        writer.write(data.numpy())
        writer.write(data.numpy())
    assert path.read_bytes()[:2] == b"\x1f\x8b"
    scenarios = list(read_shards(path))
    assert len(scenarios) == 2 and scenarios[1].scenario_id == "a3bb37c25ce56418"
    located = list(iter_shard_records(path))
    assert [record.read().scenario_id for record in reversed(located)] == ["a3bb37c25ce56418"] * 2
