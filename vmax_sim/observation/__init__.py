"""Observation of the SDC: nearby objects with history, map points ahead, lights, route targets."""

from vmax_sim.observation.config import ROADGRAPH_TYPE_SETS, NoiseConfig, ObservationConfig
from vmax_sim.observation.features import (
    LIGHT_FEATURES,
    OBJECT_FEATURES,
    ROADGRAPH_FEATURES,
    Observation,
    ObservationInputs,
    apply_noise,
    light_features,
    nearest_objects,
    object_feature_count,
    object_features,
    observe,
    path_targets,
    roadgraph_features,
    sdc_feature_count,
)

__all__ = [
    "LIGHT_FEATURES",
    "OBJECT_FEATURES",
    "ROADGRAPH_FEATURES",
    "ROADGRAPH_TYPE_SETS",
    "NoiseConfig",
    "Observation",
    "ObservationConfig",
    "ObservationInputs",
    "apply_noise",
    "light_features",
    "nearest_objects",
    "object_feature_count",
    "object_features",
    "observe",
    "path_targets",
    "roadgraph_features",
    "sdc_feature_count",
]
