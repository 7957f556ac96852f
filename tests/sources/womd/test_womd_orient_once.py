"""Road edges are oriented once: by the source without enrichment, by the enrichment with it (same bytes); a
conversion written before the source had the choice still resumes."""

from __future__ import annotations

import json

from scenariomax.enrich.transform import make_transform
from scenariomax.pipeline import ConvertSettings, convert, prepare_scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure
from scenariomax.sources.womd import WomdSource
from tests.sources.womd.fixtures import EDGE_ID, build_scenario, write_records

SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_paths=2, num_points_per_path=40)


def _scenarios(path, orient_edges):
    return [item for item in WomdSource(str(path), SIZES, orient_edges=orient_edges).read_unit(str(path))
            if not isinstance(item, Failure)]


def test_the_enrichment_orients_what_the_source_no_longer_does(tmp_path):
    path = write_records(tmp_path / "toy.tfrecord", [build_scenario()])
    oriented, raw = _scenarios(path, True)[0], _scenarios(path, False)[0]
    edge = oriented.roadgraph_id == EDGE_ID
    # the fixture's edge is written with the road on its right: the source turns it round only when asked
    assert (oriented.roadgraph_xyz[edge] != raw.roadgraph_xyz[edge]).any()
    transform, _ = make_transform(True)
    assert prepare_scenario(oriented, SIZES, transform) == prepare_scenario(raw, SIZES, transform)


def test_a_conversion_from_before_orient_edges_resumes(tmp_path):
    (tmp_path / "raw").mkdir()
    path = write_records(tmp_path / "raw" / "toy.tfrecord", [build_scenario()])
    out = tmp_path / "out"
    common = dict(sizes=SIZES, shard_size=5, progress=False, workers=1)
    before = convert(WomdSource(str(path), SIZES), ConvertSettings(out=out, **common))
    manifest = json.loads((out / "manifest.json").read_text())
    del manifest["settings"]["source"]["orient_edges"]
    (out / "manifest.json").write_text(json.dumps(manifest))
    again = convert(WomdSource(str(path), SIZES), ConvertSettings(out=out, resume=True, **common))
    assert again.num_scenarios == before.num_scenarios == 1
