"""Loading shards into fixed-shape SimulatorState batches."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REALDATA, SMALL_SIZES, make_scenario, small_config

import scenariomax
from scenariomax.errors import InputError
from scenariomax.shards import RecordError, ShardReadError
from vmax_sim.data import (
    DataConfig,
    iter_scenarios,
    load_batch,
    make_data_iterator,
    scenario_to_numpy_state,
    scenario_to_state,
)


def test_scenario_to_state_pads_objects_and_keeps_the_log(shard_dir):
    scenario = make_scenario(0)
    state = scenario_to_numpy_state(scenario, small_config())
    assert state.log_trajectory.shape == (8, 91)
    assert state.timestep == 10
    meta = state.object_metadata
    assert meta.is_sdc.tolist() == [True] + [False] * 7
    assert meta.is_valid.tolist() == [True] * 5 + [False] * 3
    assert meta.is_controllable.tolist() == [False, True, False, False, True, False, False, False]
    assert meta.ids[:5].tolist() == [10, 11, 12, 13, 14] and meta.ids[5:].tolist() == [-1] * 3
    np.testing.assert_allclose(state.log_trajectory.x[1], scenario.x[1], rtol=1e-6)
    # The late car is invalid (and zeroed) before step 30.
    assert not state.log_trajectory.valid[4, :30].any() and state.log_trajectory.valid[4, 30:].all()
    assert (state.log_trajectory.x[4, :30] == 0).all()
    assert state.log_traffic_light.state.shape == (4, 91)
    assert state.log_traffic_light.valid[:, 0].tolist() == [True, False, False, False]
    assert state.sdc_paths.valid[0].all() and not state.sdc_paths.valid[1].any()
    assert state.sdc_paths.on_route.tolist() == [True, False]


def test_roadgraph_crop_keeps_points_nearest_the_sdc():
    scenario = make_scenario(0)  # 4 lines x 360 points along x in [-60, 300)
    state = scenario_to_numpy_state(scenario, small_config(num_roadgraph_points=1000))
    rg = state.roadgraph_points
    assert rg.valid.sum() == 1000
    # Every line keeps 250 points, a contiguous run along x in map order.
    for line in (100, 101, 200, 201):
        xs = rg.x[rg.valid & (rg.ids == line)]
        assert len(xs) == 250 and np.all(np.diff(xs) == 1.0)
    # No dropped point is nearer the SDC track than a kept one.
    track = np.stack([scenario.x[0], scenario.y[0]], 1)

    def distance(xy):
        return np.sqrt(((xy[:, None] - track[None]) ** 2).sum(-1)).min(1)

    kept = distance(np.stack([rg.x[rg.valid], rg.y[rg.valid]], 1))
    kept_keys = set(zip(rg.x[rg.valid].tolist(), rg.y[rg.valid].tolist()))
    all_xy = scenario.roadgraph_xyz[:, :2]
    dropped = np.array([p for p in all_xy if (float(p[0]), float(p[1])) not in kept_keys])
    assert len(dropped) == 440
    assert kept.max() <= distance(dropped).min() + 2.5  # the crop measures to every 5th track point
    padded = scenario_to_numpy_state(scenario, small_config(num_roadgraph_points=2000)).roadgraph_points
    assert padded.valid.sum() == 1440 and not padded.valid[1440:].any()
    assert (padded.ids[1440:] == -1).all()


def test_sdc_beyond_the_object_budget_moves_to_slot_zero():
    scenario = make_scenario(0)
    order = np.array([1, 2, 3, 4, 0])  # the SDC is now the last slot
    fields = {name: getattr(scenario, name)[order] for name in (
        "object_id", "object_type", "is_sdc", "x", "y", "z", "bbox_yaw", "length", "width", "height",
        "velocity_x", "velocity_y", "valid", "speed", "vel_yaw", "timestamp_micros", "is_controllable",
        "objects_of_interest", "tracks_to_predict", "difficulty_level")}
    state = scenario_to_numpy_state(scenario.replace(**fields), small_config(num_objects=3))
    assert state.object_metadata.is_sdc.tolist() == [True, False, False]
    assert state.object_metadata.ids.tolist() == [10, 11, 12]


def test_iterator_yields_fixed_shape_device_batches_in_file_order(shard_dir):
    batches = list(make_data_iterator(small_config(shard_dir, prefetch=2)))
    assert len(batches) == 2
    for batch in batches:
        assert batch.log_trajectory.shape == (3, 8, 91)
        assert batch.roadgraph_points.x.shape == (3, 1000)
        assert batch.timestep.tolist() == [10, 10, 10]
    ids = [float(b.log_trajectory.y[i, 0, 0]) for b in batches for i in range(3)]
    expected = [float(make_scenario(seed).y[0, 0]) for seed in range(6)]
    np.testing.assert_allclose(ids, expected, rtol=1e-6)


def test_shuffling_is_seeded_and_repeat_goes_on(shard_dir):
    def order(seed, count):
        config = small_config(shard_dir, shuffle_seed=seed, shuffle_buffer=4, repeat=True)
        stream = iter_scenarios(config)
        return [next(stream).scenario_id for _ in range(count)]

    first, again, other = order(1, 12), order(1, 12), order(2, 12)
    assert first == again
    assert first != other
    assert sorted(first[:6]) == [f"straight-{i}" for i in range(6)]  # one full pass, each once
    assert sorted(first[6:]) == sorted(first[:6])
    assert first[:6] != [f"straight-{i}" for i in range(6)]


def test_the_shuffle_buffer_holds_record_locations_not_scenarios(shard_dir, monkeypatch):
    """A 256-scenario shuffle buffer used to hold 256 decoded scenarios (~0.5 GB at full budget) before the
    first batch; it now decodes a scenario only when it leaves the buffer."""
    decoded = []
    read = scenariomax.ShardRecord.read
    monkeypatch.setattr(scenariomax.ShardRecord, "read", lambda self, *a: decoded.append(self) or read(self, *a))
    stream = iter_scenarios(small_config(shard_dir, shuffle_seed=3, shuffle_buffer=256, repeat=True))
    first = next(stream)
    assert len(decoded) == 1 and first.scenario_id == f"straight-{decoded[0].index}"


def test_remainder_is_dropped_or_kept(shard_dir):
    dropped = list(make_data_iterator(small_config(shard_dir, batch_size=4)))
    kept = list(make_data_iterator(small_config(shard_dir, batch_size=4, drop_remainder=False)))
    assert [b.timestep.shape[0] for b in dropped] == [4]
    assert [b.timestep.shape[0] for b in kept] == [4, 2]


def test_map_index_is_built_per_scenario(shard_dir):
    pytest.importorskip("vmax_sim.map_index", reason="part B's map index is not in this checkout")
    batches = make_data_iterator(small_config(shard_dir, include_map_index=True, prefetch=1))
    batch = next(batches)
    batches.close()  # the thread building the next batch stops here, not during a later test
    leaves = [leaf for leaf in __import__("jax").tree.leaves(batch.map_index)]
    assert leaves and all(leaf.shape[0] == 3 for leaf in leaves)


def test_load_batch_takes_the_first_scenarios(shard_dir):
    batch = load_batch(small_config(shard_dir), num_scenarios=4)
    assert batch.timestep.shape == (4,)


def test_bad_paths_and_broken_records_give_one_line_errors(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        make_data_iterator(small_config(tmp_path / "missing"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no .tfrecord files"):
        load_batch(small_config(tmp_path / "empty"))
    good = tmp_path / "good"
    scenariomax.write_shards([make_scenario(0)], good, sizes=SMALL_SIZES)
    data = next(good.glob("*.tfrecord")).read_bytes()
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "train-00000-of-00001.tfrecord").write_bytes(data[: len(data) // 2])
    iterator = make_data_iterator(small_config(broken, batch_size=1, prefetch=2))
    with pytest.raises((ShardReadError, RecordError)) as error:
        next(iter(iterator))
    assert "broken" in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize("field, bad", [("x", np.nan), ("length", -4.5)])
def test_a_record_validate_rejects_stops_the_loader_naming_file_and_record(tmp_path, field, bad):
    import dataclasses

    good = make_scenario(1)
    values = getattr(good, field).copy()
    values[0, 3] = bad  # the SDC, a valid step
    scenariomax.write_shards([make_scenario(0), dataclasses.replace(good, **{field: values})], tmp_path / "bad",
                             sizes=SMALL_SIZES)
    with pytest.raises(InputError) as error:
        list(iter_scenarios(small_config(tmp_path / "bad")))
    message = str(error.value)
    assert "train-00000-of-00001.tfrecord record 1" in message and field in message and "\n" not in message


def test_config_rejects_nonsense():
    with pytest.raises(ValueError, match="batch_size"):
        DataConfig(path="x", batch_size=0)


def test_the_real_womd_record_loads():
    record = REALDATA / "womd" / "motion_data_one_example.tfrecord"
    if not record.is_file():
        pytest.skip(f"real WOMD sample not found at {record} (only present in the project workspace)")
    scenario = next(scenariomax.read_shards(record))
    state = scenario_to_state(scenario, DataConfig(path=str(record), num_objects=64, num_roadgraph_points=5000,
                                                   include_map_index=False))
    assert state.log_trajectory.shape == (64, 91)
    assert int(state.object_metadata.is_sdc.sum()) == 1
    sdc = int(np.argmax(state.object_metadata.is_sdc))
    assert bool(state.log_trajectory.valid[sdc, 10])
    assert int(state.roadgraph_points.valid.sum()) == min(5000, int(scenario.roadgraph_valid.sum()))


def test_worker_processes_give_the_same_batches(shard_dir):
    pytest.importorskip("vmax_sim.map_index", reason="part B's map index is not in this checkout")
    import jax

    serial = list(make_data_iterator(small_config(shard_dir, include_map_index=True)))
    parallel = list(make_data_iterator(small_config(shard_dir, include_map_index=True, num_workers=2)))
    assert len(serial) == len(parallel) == 2
    for a, b in zip(serial, parallel):
        for leaf_a, leaf_b in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
            np.testing.assert_array_equal(leaf_a, leaf_b)


def test_closing_a_prefetching_iterator_stops_its_loader_thread(shard_dir):
    batches = make_data_iterator(small_config(shard_dir, include_map_index=True, prefetch=1, repeat=True))
    next(batches)
    batches.close()
    assert not batches._thread.is_alive()  # nothing keeps building map indices after the close
    with pytest.raises(StopIteration):
        next(batches)
