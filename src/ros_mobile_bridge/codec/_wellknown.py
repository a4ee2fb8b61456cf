"""Definitions the codec knows without a server schema.

* every message type of rosbags' bundled ROS 2 Jazzy typestore;
* a few standard services (rosbags bundles no services), written here as
  ``.srv`` texts and registered as ``<service>_Request``/``<service>_Response``
  message types.

Both are parsed once, on first use, and shared read-only by every
:class:`CodecRegistry` (each registry builds its own rosbags typestore).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

from rosbags.typesys import Stores, get_typestore

from ._model import MsgDef, msgdef_from_rosbags
from ._parse import parse_srv

__all__ = [
    "BUILTIN_DEFAULTS",
    "SERVICE_DEFINITIONS",
    "builtin_definitions",
    "wellknown_definitions",
]

SERVICE_DEFINITIONS: Mapping[str, str] = {
    "std_srvs/srv/Empty": "---\n",
    "std_srvs/srv/Trigger": """\
---
bool success   # indicate successful run of triggered service
string message # informational, e.g. for error messages
""",
    "std_srvs/srv/SetBool": """\
bool data # e.g. for hardware enabling / disabling
---
bool success   # indicate successful run of triggered service
string message # informational, e.g. for error messages
""",
    "rcl_interfaces/srv/GetParameters": """\
# A list of parameter names to get.
string[] names
---
# List of values which is the same length and order as the provided names.
ParameterValue[] values
""",
    "rcl_interfaces/srv/SetParameters": """\
# A list of parameters to set.
Parameter[] parameters
---
# Indicates whether setting each parameter succeeded or not and why.
SetParametersResult[] results
""",
    "rcl_interfaces/srv/SetParametersAtomically": """\
# A list of parameters to set atomically.
Parameter[] parameters
---
# Indicates whether setting all of the parameters succeeded or not and why.
SetParametersResult result
""",
    "rcl_interfaces/srv/ListParameters": """\
# Recursively get parameters with unlimited depth.
uint64 DEPTH_RECURSIVE=0

# The list of parameter prefixes to query.
string[] prefixes

# Relative depth from given prefixes to return.
uint64 depth
---
# The list of parameter names and their prefixes.
ListParametersResult result
""",
    "rcl_interfaces/srv/DescribeParameters": """\
# A list of parameters of which to get the descriptor.
string[] names
---
# A list of the descriptors of all parameters requested in the same order.
ParameterDescriptor[] descriptors
""",
    "rcl_interfaces/srv/GetParameterTypes": """\
# A list of parameter names.
string[] names
---
# List of types which is the same length and order as the provided names.
# The type values are the constants of rcl_interfaces/msg/ParameterType.
uint8[] types
""",
    "action_msgs/srv/CancelGoal": """\
# Cancel one or more goals with the following policy:
# - If the goal ID is zero and timestamp is zero, cancel all goals.
# - If the goal ID is zero and timestamp is not zero, cancel all goals accepted
#   at or before the timestamp.
# - If the goal ID is not zero and timestamp is zero, cancel the goal with the
#   given ID regardless of the time it was accepted.
# - If the goal ID is not zero and timestamp is not zero, cancel the goal with
#   the given ID and all goals accepted at or before the timestamp.
GoalInfo goal_info
---
int8 ERROR_NONE=0
int8 ERROR_REJECTED=1
int8 ERROR_UNKNOWN_GOAL_ID=2
int8 ERROR_GOAL_TERMINATED=3

# Return code, see above definitions.
int8 return_code

# Goals that accepted the cancel request.
GoalInfo[] goals_canceling
""",
    "type_description_interfaces/srv/GetTypeDescription": """\
# REP-2011: what a node answers on ~/get_type_description
string type_name
string type_hash
bool include_type_sources true
---
bool successful
string failure_reason
TypeDescription type_description
TypeSource[] type_sources
KeyValue[] extra_information
""",
}
"""``.srv`` texts of the bundled services, by service type name."""


BUILTIN_DEFAULTS: Mapping[str, Mapping[str, object]] = {
    "geometry_msgs/msg/Quaternion": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
}
"""Field defaults of built-in messages. rosbags' bundled definitions do not
keep ``.msg`` default values; these are the ones that matter (an all-zero
quaternion is not a rotation)."""


@functools.cache
def builtin_definitions() -> Mapping[str, MsgDef]:
    """rosbags' ROS 2 Jazzy message definitions, by canonical name (with
    :data:`BUILTIN_DEFAULTS` applied)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    out: dict[str, MsgDef] = {}
    for name, (consts, fields) in store.fielddefs.items():
        patch = BUILTIN_DEFAULTS.get(name, {})
        defaults = [patch.get(fname) for fname, _ in fields]
        out[name] = msgdef_from_rosbags(name, consts, fields, defaults)
    return out


@functools.cache
def wellknown_definitions() -> Mapping[str, MsgDef]:
    """The bundled services' request and response types, by canonical name."""
    out: dict[str, MsgDef] = {}
    for name, text in SERVICE_DEFINITIONS.items():
        out.update(parse_srv(name, text))
    return out
