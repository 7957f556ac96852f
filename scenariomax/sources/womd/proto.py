"""The WOMD `Scenario` message (scenario.proto + map.proto), built from its public field numbers.

No TensorFlow, no waymo-open-dataset package and no compiled .proto: the descriptors are written
here as data and turned into message classes by protobuf's message factory. The messages are
proto2, so fields this module does not declare (lidar, camera tokens, future additions) are kept
as unknown fields and never break parsing. Enums are declared as int32 so unexpected enum values
parse too (the converter maps them).
"""

from __future__ import annotations

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

_PACKAGE = "vmax.womd"
_F = descriptor_pb2.FieldDescriptorProto

_OPTIONAL, _REPEATED = _F.LABEL_OPTIONAL, _F.LABEL_REPEATED
_DOUBLE, _FLOAT, _BOOL = _F.TYPE_DOUBLE, _F.TYPE_FLOAT, _F.TYPE_BOOL
_INT32, _INT64, _STRING, _MESSAGE = _F.TYPE_INT32, _F.TYPE_INT64, _F.TYPE_STRING, _F.TYPE_MESSAGE

# Scenario.sdc_paths: after the lidar (12) and camera-token (13) fields. The public waymo-open-dataset tree
# we could read (99a4cb3, April 2025) predates the field, so this number is the one place to correct.
SDC_PATHS_FIELD = 14

# (message name, [(field name, number, type, label, message type name or None)]), from the public
# waymo-open-dataset protos (scenario.proto, map.proto). Enum fields are int32 on the wire.
_MESSAGES = (
    ("MapPoint", [("x", 1, _DOUBLE, _OPTIONAL, None), ("y", 2, _DOUBLE, _OPTIONAL, None),
                  ("z", 3, _DOUBLE, _OPTIONAL, None)]),
    ("TrafficSignalLaneState", [("lane", 1, _INT64, _OPTIONAL, None), ("state", 2, _INT32, _OPTIONAL, None),
                                ("stop_point", 3, _MESSAGE, _OPTIONAL, "MapPoint")]),
    ("BoundarySegment", [("lane_start_index", 1, _INT32, _OPTIONAL, None),
                         ("lane_end_index", 2, _INT32, _OPTIONAL, None),
                         ("boundary_feature_id", 3, _INT64, _OPTIONAL, None),
                         ("boundary_type", 4, _INT32, _OPTIONAL, None)]),
    ("LaneNeighbor", [("feature_id", 1, _INT64, _OPTIONAL, None), ("self_start_index", 2, _INT32, _OPTIONAL, None),
                      ("self_end_index", 3, _INT32, _OPTIONAL, None),
                      ("neighbor_start_index", 4, _INT32, _OPTIONAL, None),
                      ("neighbor_end_index", 5, _INT32, _OPTIONAL, None),
                      ("boundaries", 6, _MESSAGE, _REPEATED, "BoundarySegment")]),
    ("LaneCenter", [("speed_limit_mph", 1, _DOUBLE, _OPTIONAL, None), ("type", 2, _INT32, _OPTIONAL, None),
                    ("interpolating", 3, _BOOL, _OPTIONAL, None),
                    ("polyline", 8, _MESSAGE, _REPEATED, "MapPoint"),
                    ("entry_lanes", 9, _INT64, _REPEATED, None), ("exit_lanes", 10, _INT64, _REPEATED, None),
                    ("left_neighbors", 11, _MESSAGE, _REPEATED, "LaneNeighbor"),
                    ("right_neighbors", 12, _MESSAGE, _REPEATED, "LaneNeighbor"),
                    ("left_boundaries", 13, _MESSAGE, _REPEATED, "BoundarySegment"),
                    ("right_boundaries", 14, _MESSAGE, _REPEATED, "BoundarySegment")]),
    ("RoadEdge", [("type", 1, _INT32, _OPTIONAL, None), ("polyline", 2, _MESSAGE, _REPEATED, "MapPoint")]),
    ("RoadLine", [("type", 1, _INT32, _OPTIONAL, None), ("polyline", 2, _MESSAGE, _REPEATED, "MapPoint")]),
    ("StopSign", [("lane", 1, _INT64, _REPEATED, None), ("position", 2, _MESSAGE, _OPTIONAL, "MapPoint")]),
    ("Crosswalk", [("polygon", 1, _MESSAGE, _REPEATED, "MapPoint")]),
    ("SpeedBump", [("polygon", 1, _MESSAGE, _REPEATED, "MapPoint")]),
    ("Driveway", [("polygon", 1, _MESSAGE, _REPEATED, "MapPoint")]),
    ("MapFeature", [("id", 1, _INT64, _OPTIONAL, None), ("lane", 3, _MESSAGE, _OPTIONAL, "LaneCenter"),
                    ("road_line", 4, _MESSAGE, _OPTIONAL, "RoadLine"),
                    ("road_edge", 5, _MESSAGE, _OPTIONAL, "RoadEdge"),
                    ("stop_sign", 7, _MESSAGE, _OPTIONAL, "StopSign"),
                    ("crosswalk", 8, _MESSAGE, _OPTIONAL, "Crosswalk"),
                    ("speed_bump", 9, _MESSAGE, _OPTIONAL, "SpeedBump"),
                    ("driveway", 10, _MESSAGE, _OPTIONAL, "Driveway")]),
    ("ObjectState", [("center_x", 2, _DOUBLE, _OPTIONAL, None), ("center_y", 3, _DOUBLE, _OPTIONAL, None),
                     ("center_z", 4, _DOUBLE, _OPTIONAL, None), ("length", 5, _FLOAT, _OPTIONAL, None),
                     ("width", 6, _FLOAT, _OPTIONAL, None), ("height", 7, _FLOAT, _OPTIONAL, None),
                     ("heading", 8, _FLOAT, _OPTIONAL, None), ("velocity_x", 9, _FLOAT, _OPTIONAL, None),
                     ("velocity_y", 10, _FLOAT, _OPTIONAL, None), ("valid", 11, _BOOL, _OPTIONAL, None)]),
    ("Track", [("id", 1, _INT32, _OPTIONAL, None), ("object_type", 2, _INT32, _OPTIONAL, None),
               ("states", 3, _MESSAGE, _REPEATED, "ObjectState")]),
    ("DynamicMapState", [("lane_states", 1, _MESSAGE, _REPEATED, "TrafficSignalLaneState")]),
    ("RequiredPrediction", [("track_index", 1, _INT32, _OPTIONAL, None), ("difficulty", 2, _INT32, _OPTIONAL, None)]),
    # Waymo's own SDC paths (WOMD 1.3.1+): parallel per-point arrays plus the path's on-route flag. The
    # numbers below are ours to check against the released scenario.proto (see SDC_PATHS_FIELD).
    ("SDCPath", [("x", 1, _DOUBLE, _REPEATED, None), ("y", 2, _DOUBLE, _REPEATED, None),
                 ("z", 3, _DOUBLE, _REPEATED, None), ("arc_length", 4, _DOUBLE, _REPEATED, None),
                 ("ids", 5, _INT64, _REPEATED, None), ("valid", 6, _BOOL, _REPEATED, None),
                 ("on_route", 7, _BOOL, _OPTIONAL, None)]),
    ("Scenario", [("timestamps_seconds", 1, _DOUBLE, _REPEATED, None), ("tracks", 2, _MESSAGE, _REPEATED, "Track"),
                  ("objects_of_interest", 4, _INT32, _REPEATED, None),
                  ("scenario_id", 5, _STRING, _OPTIONAL, None), ("sdc_track_index", 6, _INT32, _OPTIONAL, None),
                  ("dynamic_map_states", 7, _MESSAGE, _REPEATED, "DynamicMapState"),
                  ("map_features", 8, _MESSAGE, _REPEATED, "MapFeature"),
                  ("current_time_index", 10, _INT32, _OPTIONAL, None),
                  ("tracks_to_predict", 11, _MESSAGE, _REPEATED, "RequiredPrediction"),
                  ("sdc_paths", SDC_PATHS_FIELD, _MESSAGE, _REPEATED, "SDCPath")]),
)
_ONEOF_FIELDS = {"MapFeature": ("lane", "road_line", "road_edge", "stop_sign", "crosswalk", "speed_bump", "driveway")}


# The bulk variant of the messages (the converter's fast path): the same wire format, but the many small
# messages (track states, map points) are kept as their serialised bytes, so that a whole log or map is joined
# and read with numpy in one go instead of one Python object per state or point.
_BULK_PACKAGE = "vmax.womd_bulk"
_AS_BYTES = {("Track", "states"), ("LaneCenter", "polyline"), ("RoadEdge", "polyline"), ("RoadLine", "polyline"),
             ("Crosswalk", "polygon"), ("SpeedBump", "polygon"), ("Driveway", "polygon"), ("StopSign", "position"),
             ("DynamicMapState", "lane_states")}


def _build_pool(package: str, as_bytes: set) -> descriptor_pool.DescriptorPool:
    file_proto = descriptor_pb2.FileDescriptorProto(name=f"{package.replace('.', '_')}_scenario.proto",
                                                    package=package, syntax="proto2")
    for name, fields in _MESSAGES:
        message = file_proto.message_type.add(name=name)
        oneof_members = _ONEOF_FIELDS.get(name, ())
        if oneof_members:
            message.oneof_decl.add(name="feature_data")
        for field_name, number, field_type, label, type_name in fields:
            if (name, field_name) in as_bytes:
                field_type, type_name = _F.TYPE_BYTES, None
            field = message.field.add(name=field_name, number=number, type=field_type, label=label)
            if type_name is not None:
                field.type_name = f".{package}.{type_name}"
            if field_name in oneof_members:
                field.oneof_index = 0
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_proto)
    return pool


_POOL = _build_pool(_PACKAGE, set())
_BULK_POOL = _build_pool(_BULK_PACKAGE, _AS_BYTES)


def _message_class(name: str, pool: descriptor_pool.DescriptorPool = _POOL, package: str = _PACKAGE):
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{package}.{name}"))


ScenarioProto = _message_class("Scenario")
MapFeatureProto = _message_class("MapFeature")
ObjectStateProto = _message_class("ObjectState")
MapPointProto = _message_class("MapPoint")
TrafficSignalLaneStateProto = _message_class("TrafficSignalLaneState")
ScenarioBulkProto = _message_class("Scenario", _BULK_POOL, _BULK_PACKAGE)


def _raw_pool(package: str) -> descriptor_pool.DescriptorPool:
    """A Scenario that declares only its tracks and map features, as their serialised bytes (the other fields are
    skipped)."""
    file_proto = descriptor_pb2.FileDescriptorProto(name=f"{package.replace('.', '_')}_scenario.proto",
                                                    package=package, syntax="proto2")
    message = file_proto.message_type.add(name="Scenario")
    message.field.add(name="tracks", number=2, type=_F.TYPE_BYTES, label=_REPEATED)
    message.field.add(name="map_features", number=8, type=_F.TYPE_BYTES, label=_REPEATED)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_proto)
    return pool


# The tracks and map features of a Scenario as bytes each: their states and points decoded a whole track or
# polyline at a time (bulk.py).
_RAW_PACKAGE = "vmax.womd_raw"
ScenarioRawProto = _message_class("Scenario", _raw_pool(_RAW_PACKAGE), _RAW_PACKAGE)


def is_bulk(message) -> bool:
    """Whether a Scenario message is the bulk variant (states and map points as bytes)."""
    return message.DESCRIPTOR.full_name.startswith(_BULK_PACKAGE + ".")

# Enum values (facts of the WOMD protos).
TRACK_TYPE_UNSET = 0
LANE_TYPE_UNDEFINED, LANE_TYPE_FREEWAY, LANE_TYPE_SURFACE_STREET, LANE_TYPE_BIKE = 0, 1, 2, 3
ROAD_EDGE_UNKNOWN, ROAD_EDGE_BOUNDARY, ROAD_EDGE_MEDIAN = 0, 1, 2
