"""Protobuf schemas of the step log, built in code (no protoc step) from compact field lists.

Rerun and Foxglove decode these from the FileDescriptorSet that mcap-protobuf-support embeds.
"""
from __future__ import annotations

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

PACKAGE = "ecodrive"
_T = descriptor_pb2.FieldDescriptorProto
_TYPES = {
    "double": _T.TYPE_DOUBLE, "float": _T.TYPE_FLOAT, "int32": _T.TYPE_INT32, "int64": _T.TYPE_INT64,
    "uint32": _T.TYPE_UINT32, "bool": _T.TYPE_BOOL, "string": _T.TYPE_STRING, "bytes": _T.TYPE_BYTES,
}

# message -> [(field, type, repeated)]; a type that is not a scalar names another message
MESSAGES: dict[str, list[tuple[str, str, bool]]] = {
    "RewardComponents": [(n, "double", False) for n in ("speed", "jerk", "lane_change", "distance", "energy", "terminal", "time")],
    "Signal": [("tls", "string", False), ("link", "int32", False), ("distance", "double", False),
               ("state", "string", False), ("in_range", "bool", False), ("red", "double", False),
               ("time_to_green", "double", False)],
    "Step": [
        ("time", "double", False), ("travel_time", "double", False), ("x", "double", False), ("y", "double", False),
        ("angle", "double", False), ("speed", "double", False), ("accel", "double", False),
        ("lane", "int32", False), ("edge", "string", False),
        ("grid", "bytes", False), ("grid_rows", "uint32", False), ("grid_cols", "uint32", False),
        ("logic", "float", True),
        ("has_request", "bool", False), ("requested_lateral", "int32", False), ("requested_accel", "double", False),
        ("applied_lateral", "int32", False), ("applied_accel", "double", False), ("clipped", "bool", False),
        ("action_mask", "int32", True), ("raw_action", "double", True),
        ("energy_step", "double", False), ("energy_total", "double", False), ("jerk", "double", False),
        ("reward", "double", False), ("components", "RewardComponents", False),
        ("signal", "Signal", False), ("neighbour_x", "double", True), ("neighbour_y", "double", True),
        ("neighbour_angle", "double", True), ("neighbour_length", "double", True), ("tls_states", "string", True),
        ("collisions", "uint32", False), ("teleports", "uint32", False),
    ],
    "Episode": [
        ("method", "string", False), ("signals", "string", False), ("case_index", "int32", False),
        ("sumo_seed", "int64", False), ("insert_time", "double", False), ("depart_time", "double", False),
        ("energy", "double", False), ("travel_time", "double", False), ("steps", "uint32", False),
        ("terminated", "bool", False), ("truncated", "bool", False), ("return_", "double", False),
        ("stops", "uint32", False), ("time_stopped", "double", False), ("lane_changes_requested", "uint32", False),
        ("lane_changes_applied", "uint32", False), ("clips", "uint32", False), ("jerk_exceedances", "uint32", False),
        ("collisions", "uint32", False), ("teleports", "uint32", False),
        ("battery_consumed", "double", False), ("battery_regenerated", "double", False),
    ],
    "TrainEpisode": [
        ("episode", "uint32", False), ("energy", "double", False), ("travel_time", "double", False),
        ("return_", "double", False), ("epsilon", "double", False), ("loss_q", "double", False),
        ("loss_param", "double", False), ("lane_changes", "uint32", False), ("collisions", "uint32", False),
        ("steps", "uint32", False), ("updates", "uint32", False), ("truncated", "bool", False),
    ],
    "FleetVehicle": [
        ("vid", "string", False), ("kind", "string", False), ("depart", "double", False),
        ("arrive", "double", False), ("finished", "bool", False), ("energy", "double", False),
    ],
    "FleetCell": [
        ("signals", "string", False), ("mpr", "double", False), ("demand", "double", False),
        ("rep", "uint32", False), ("seed", "int64", False), ("duration", "double", False),
        ("summary_json", "string", False), ("collisions", "uint32", False), ("teleports", "uint32", False),
        ("control_over_sim", "double", False), ("wall_s", "double", False),
    ],
    "Metadata": [
        ("config_json", "string", False), ("method", "string", False), ("signals", "string", False),
        ("case_index", "int32", False), ("sumo_seed", "int64", False), ("insert_time", "double", False),
        ("sumo_version", "string", False), ("git_sha", "string", False), ("packages_json", "string", False),
        ("agent_sha256", "string", False), ("geometry_json", "string", False),
    ],
}


def _file_proto() -> descriptor_pb2.FileDescriptorProto:
    fp = descriptor_pb2.FileDescriptorProto(name=f"{PACKAGE}/log.proto", package=PACKAGE, syntax="proto3")
    for name, flds in MESSAGES.items():
        mp = fp.message_type.add(name=name)
        for number, (fname, ftype, repeated) in enumerate(flds, start=1):
            f = mp.field.add(name=fname, number=number,
                             label=_T.LABEL_REPEATED if repeated else _T.LABEL_OPTIONAL)
            if ftype in _TYPES:
                f.type = _TYPES[ftype]
            else:
                f.type = _T.TYPE_MESSAGE
                f.type_name = f".{PACKAGE}.{ftype}"
    return fp


_POOL = descriptor_pool.DescriptorPool()
_POOL.Add(_file_proto())
RewardComponents, Signal, Step, Episode, TrainEpisode, FleetVehicle, FleetCell, Metadata = (
    message_factory.GetMessageClass(_POOL.FindMessageTypeByName(f"{PACKAGE}.{n}"))
    for n in ("RewardComponents", "Signal", "Step", "Episode", "TrainEpisode", "FleetVehicle", "FleetCell", "Metadata")
)
