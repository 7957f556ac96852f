"""`data.synthetic.*`: the training config carries `SyntheticKnobs`; only the embedded *training* split takes them,
in a cache folder of its own (default knobs: the folder as before)."""

import dataclasses
import json
import types

import pytest

pytest.importorskip("jax")

import scenariomax  # noqa: E402
from scenariomax import SyntheticKnobs  # noqa: E402
from vmax_sim.training import run as run_module  # noqa: E402
from vmax_sim.training.config import (  # noqa: E402
    TrainDataConfig,
    apply_overrides,
    config_from_dict,
    config_to_dict,
    preset_config,
)


def test_overrides_set_nested_knobs_and_round_trip():
    config = apply_overrides(preset_config("sac"), [
        "data.synthetic.traffic_density=2", "data.synthetic.lane_width_m=2.8,4.2",
        "data.synthetic.topology_weights=intersection4:2,merge:1", "data.synthetic.parked_fraction=0,0.3",
        "data.synthetic.parked_reach=0:1.5"])  # ranges as lo,hi or, as scenariomax's --synthetic-knob, lo:hi
    assert config.data.synthetic == SyntheticKnobs(traffic_density=2.0, lane_width_m=(2.8, 4.2),
                                                   topology_weights="intersection4:2,merge:1",
                                                   parked_fraction=(0.0, 0.3), parked_reach=(0.0, 1.5))
    values = json.loads(json.dumps(config_to_dict(config)))  # as config.json stores it
    assert config_from_dict(values) == config
    del values["data"]["synthetic"]  # a run directory from before the knobs
    assert config_from_dict(values).data.synthetic.is_default()
    assert TrainDataConfig().synthetic.is_default()


@pytest.mark.parametrize("override, words", [
    ("data.synthetic.traffic_density=-1", "traffic_density"),
    ("data.synthetic.lane_width_m=4,3", "lane_width_m"),
    ("data.synthetic.topology_weights=spaghetti:1", "spaghetti"),
    ("data.synthetic.bogus=1", "bogus"),
])
def test_bad_knob_overrides_are_one_line_errors(override, words):
    with pytest.raises(ValueError, match=words) as caught:
        apply_overrides(preset_config("sac"), [override])
    assert "\n" not in str(caught.value)


@pytest.fixture
def generated(monkeypatch, tmp_path):
    """Records the sources `synthetic_split` would convert (a fake `convert`), in a temporary cache."""
    monkeypatch.setenv("VMAX_CACHE_DIR", str(tmp_path))
    sources = {}

    def fake_convert(source, settings):
        sources[settings.out.name] = source
        return types.SimpleNamespace(num_scenarios=source.num_scenarios)

    monkeypatch.setattr(scenariomax, "convert", fake_convert)
    return sources


def test_training_split_takes_the_knobs_and_evaluation_split_does_not(generated):
    knobs = SyntheticKnobs(traffic_density=2.0, lane_width_m=(2.8, 4.2))
    config = preset_config("sac")
    config = dataclasses.replace(config, data=dataclasses.replace(config.data, synthetic=knobs,
                                                                  synthetic_train_scenarios=5,
                                                                  synthetic_eval_scenarios=3))
    train, evaluation = run_module.resolve_data(config, lambda _: None)
    train_name = next(name for name in generated if name.startswith("seed0-"))
    assert train_name.startswith("seed0-n5-objects64-knobs") and train.endswith(train_name)
    assert generated[train_name].knobs == knobs
    assert evaluation.endswith("seed1-n3-objects64")  # the held-out split: the default generator, as before
    assert generated["seed1-n3-objects64"].knobs is None


def test_cache_folder_names(generated):
    def name(knobs):
        return run_module.synthetic_split(4, 7, 32, lambda _: None, knobs=knobs).rsplit("/", 1)[-1]

    assert name(None) == name(SyntheticKnobs()) == "seed7-n4-objects32"  # as before the knobs
    dense = name(SyntheticKnobs(traffic_density=2.0))
    assert dense == name(SyntheticKnobs.from_items(["traffic_density=2"]))  # stable
    assert dense != name(SyntheticKnobs(traffic_density=3.0)) and dense.startswith("seed7-n4-objects32-knobs")
    assert generated["seed7-n4-objects32"].knobs is None and generated[dense].knobs.traffic_density == 2.0
