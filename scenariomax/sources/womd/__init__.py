"""Waymo Open Motion Dataset: Scenario protos (and motion tf.Examples) in TFRecord files."""

from scenariomax.enrich.orientation import lane_side_vote, orient_road_edges
from scenariomax.sources.womd.convert import (
    ScenarioBuildError,
    map_polylines,
    parse_scenario,
    scenario_windows,
)
from scenariomax.sources.womd.proto import MapFeatureProto, ScenarioProto
from scenariomax.sources.womd.source import WomdSource, expand_src
from scenariomax.sources.womd.tfexample import looks_like_tf_example, tf_example_to_scenario
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE, window_starts, wrap_angle

__all__ = [
    "DEFAULT_WINDOW_STRIDE",
    "MapFeatureProto",
    "ScenarioBuildError",
    "ScenarioProto",
    "WomdSource",
    "expand_src",
    "lane_side_vote",
    "looks_like_tf_example",
    "map_polylines",
    "orient_road_edges",
    "parse_scenario",
    "scenario_windows",
    "tf_example_to_scenario",
    "window_starts",
    "wrap_angle",
]
