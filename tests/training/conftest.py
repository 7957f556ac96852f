"""Small synthetic shards and tiny training configurations for the training tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from vmax_sim.training import apply_overrides, preset_config

NUM_OBJECTS = 16


@pytest.fixture(scope="session")
def synthetic_shards(tmp_path_factory) -> Path:
    """12 enriched synthetic scenarios (16 object slots) written by the real pipeline."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.schema import Sizes
    from scenariomax.sources.synthetic import SyntheticSource

    out = tmp_path_factory.mktemp("train_shards") / "shards"
    sizes = Sizes(num_objects=NUM_OBJECTS)
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=out, workers=1, sizes=sizes, progress=False, transform=transform,
                               transform_settings=transform_settings)
    convert(SyntheticSource(num_scenarios=12, seed=5, sizes=sizes), settings)
    return out


def tiny_config(shards: Path, algo: str = "sac", *extra: str):
    """A config that compiles and runs in seconds: small MLP encoder, 4 envs, short chunks."""
    overrides = [
        f"data.train={shards}", f"data.eval={shards}", f"data.num_objects={NUM_OBJECTS}",
        "data.num_roadgraph_points=5000", "data.num_paths=4", "data.max_num_lights=8",
        "algo_preset=debug", "network.embed_dim=16", "network.output_dim=32", "network.mlp_hidden=32",
        "obs.num_objects=4", "obs.num_history=2", "obs.num_path_targets=4",
        "train.chunk_steps=5", "train.pool_size=6", "train.pool_refresh=2", "train.eval_scenarios=4",
        "train.eval_batch_size=4", "train.eval_every=0", "train.checkpoint_every=40", "train.seed=3",
    ]
    config = apply_overrides(preset_config(f"{algo}-mlp"), overrides)
    return apply_overrides(config, list(extra))
