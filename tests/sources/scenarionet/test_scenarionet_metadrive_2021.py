"""MetaDrive 2021-2022 pickles (its `waymo_utils.py` era): enum members of classes from the writer's
`__main__` are read as (class, value) without importing anything, and converted with the WOMD enums."""

from __future__ import annotations

import pickletools
import re

import numpy as np
import pytest
from click.testing import CliRunner

from scenariomax import schema as sch
from scenariomax.errors import InputError
from scenariomax.shards import read_shards
from scenariomax.sources.base import Failure
from scenariomax.sources.scenarionet import RefusedGlobalError, ScenarioNetSource, load_pickle, loads_restricted
from scenariomax.sources.scenarionet.unpickle import WRITER_ENUMS, EnumValue
from tests.sources.scenarionet.fixtures import metadrive_2021_description, pickle_from_main, writer_enums

ENUMS = writer_enums()
MODULES = ("__main__", "metadrive.utils.waymo_map_utils", "metadrive.utils.waymo_utils.waymo_utils",
           "metadrive.utils.waymo_utils.utils")


def _pickled(protocol: int = 4, desc: dict | None = None) -> bytes:
    return pickle_from_main(desc or metadrive_2021_description(ENUMS), ENUMS, protocol)


def _read(tmp_path, data: bytes, name: str = "0.pkl") -> list:
    path = tmp_path / name
    path.write_bytes(data)
    return list(ScenarioNetSource(str(path)).read_unit(str(path)))


def test_enum_member_pickles_as_a_call_of_its_class_with_its_value():
    ops = [(op.name, arg) for op, arg, _ in pickletools.genops(_pickled(2, {"t": ENUMS["AgentType"].CYCLIST}))]
    names = [name for name, _ in ops]
    assert ("GLOBAL", "__main__ AgentType") in ops
    assert names[names.index("GLOBAL") + 1:names.index("REDUCE")] == ["BINPUT", "BININT1", "TUPLE1", "BINPUT"]


@pytest.mark.parametrize("protocol", [0, 2, 3, 4, 5])
def test_writer_enum_members_load_as_class_and_value(protocol):
    value = {"a": ENUMS["AgentType"].PEDESTRIAN, "l": [ENUMS["RoadLineType"].PASSING_DOUBLE_YELLOW] * 2,
             "e": ENUMS["RoadEdgeType"].MEDIAN}
    loaded = loads_restricted(pickle_from_main(value, ENUMS, protocol))
    assert loaded == {"a": EnumValue("AgentType", 2), "l": [EnumValue("RoadLineType", 8)] * 2,
                      "e": EnumValue("RoadEdgeType", 2)}


@pytest.mark.parametrize("module", MODULES[1:])
def test_module_paths_the_classes_had_in_metadrive(module):
    data = pickle_from_main(ENUMS["RoadEdgeType"].BOUNDARY, ENUMS, 2)
    data = data.replace(b"c__main__\nRoadEdgeType\n", f"c{module}\nRoadEdgeType\n".encode())
    assert loads_restricted(data) == EnumValue("RoadEdgeType", 1)


@pytest.mark.parametrize("protocol", [3, 4])
def test_2021_pickle_converts(tmp_path, protocol):
    (scenario,) = _read(tmp_path, _pickled(protocol))
    assert not isinstance(scenario, Failure), scenario
    rows = {int(i): row for row, i in enumerate(scenario.object_id)}
    assert scenario.object_id[scenario.sdc_index] == 7
    assert [scenario.object_type[rows[i]] for i in (7, 8, 9)] == [sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_PEDESTRIAN,
                                                                 sch.OBJECT_TYPE_CYCLIST]
    np.testing.assert_allclose(scenario.x[rows[7], 10], 2.0, atol=1e-5)
    valid_types = scenario.roadgraph_type[scenario.roadgraph_valid]
    assert {sch.RG_SOLID_DOUBLE_YELLOW, sch.RG_ROAD_EDGE_MEDIAN, sch.RG_ROAD_EDGE_BOUNDARY, sch.RG_CROSSWALK,
            sch.RG_STOP_SIGN, sch.RG_SPEED_BUMP, sch.RG_LANE_SURFACE_STREET} <= set(valid_types.tolist())
    xyz = scenario.roadgraph_xyz[scenario.roadgraph_valid]
    np.testing.assert_allclose(xyz[valid_types == sch.RG_SOLID_DOUBLE_YELLOW, 1], 2.0)
    np.testing.assert_allclose(xyz[valid_types == sch.RG_ROAD_EDGE_MEDIAN, 1], -2.0)


def test_2021_pickle_converts_with_the_cli(tmp_path):
    from vmax_cli.scenariomax_cli import main

    src = tmp_path / "waymo_processed"
    src.mkdir()
    for index in range(2):
        (src / f"{index}.pkl").write_bytes(_pickled())
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["convert", "--dataset", "scenarionet", "--src", str(src), "--out", str(out),
                                       "--workers", "1", "--no-enrich"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    scenarios = list(read_shards(out))
    assert len(scenarios) == 2
    assert sorted(scenarios[0].object_type[scenarios[0].valid[:, 10]].tolist()) == [1, 2, 3]


# --- still refused -------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["TrafficLightState", "LaneType", "Enum", "system", "eval"])
def test_other_main_classes_are_refused_with_one_line_naming_the_file(tmp_path, name):
    data = _pickled(2).replace(b"c__main__\nAgentType\n", f"c__main__\n{name}\n".encode())
    path = tmp_path / "0.pkl"
    path.write_bytes(data)
    with pytest.raises(InputError) as info:
        load_pickle(path)
    message = str(info.value)
    assert str(path) in message and f"refused pickle global __main__.{name}" in message and "\n" not in message


def test_enum_names_from_other_modules_are_refused():
    data = pickle_from_main(ENUMS["AgentType"].VEHICLE, ENUMS, 2).replace(b"c__main__\n", b"cos\n")
    with pytest.raises(RefusedGlobalError, match="os.AgentType"):
        loads_restricted(data)


@pytest.mark.parametrize("args, shown", [
    (b"K\x05\x85", "(5)"),  # AgentType has values 0-4
    (b"J\xff\xff\xff\xff\x85", "(-1)"),
    (b"X\x01\x00\x00\x001\x85", "('1')"),  # a string, not the value
    (b"G?\xf0\x00\x00\x00\x00\x00\x00\x85", "(1.0)"),
    (b"\x88\x85", "(True)"),
    (b"K\x01K\x02\x86", "(1, 2)"),
    (b")", "()"),
])
def test_enum_stand_in_accepts_only_one_of_its_values(args, shown):
    data = b"\x80\x02c__main__\nAgentType\n" + args + b"R."
    with pytest.raises(RefusedGlobalError, match=re.escape(f"__main__.AgentType called with {shown}")):
        loads_restricted(data)


def test_enum_values_cannot_be_built_on_or_instantiated():
    member = b"\x80\x02c__main__\nAgentType\nK\x01\x85R"
    with pytest.raises(RefusedGlobalError, match="BUILD"):
        loads_restricted(member + b"}b.")  # BUILD on the EnumValue
    with pytest.raises(RefusedGlobalError, match="NEWOBJ"):
        loads_restricted(b"\x80\x02c__main__\nAgentType\n)\x81.")  # NEWOBJ of the class


def test_the_allow_list_names_only_the_known_classes():
    assert set(WRITER_ENUMS) == {"AgentType", "RoadLineType", "RoadEdgeType"}
    assert [WRITER_ENUMS[name] for name in ENUMS] == [range(len(cls)) for cls in ENUMS.values()]
