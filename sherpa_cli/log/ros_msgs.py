"""ROS 2 message definitions and builders for the MCAP recordings and the Foxglove live view.

The definitions are the standard ones of ROS 2's ``common_interfaces`` and ``rcl_interfaces``
(``sensor_msgs/msg/JointState``, ``diagnostic_msgs/msg/DiagnosticArray``, ``rcl_interfaces/msg/Log``,
``std_msgs/msg/String``, ``geometry_msgs/msg/WrenchStamped``), written the way rosbag2 stores them in an MCAP schema (``ros2msg``: the
message, then each nested type after a line of ``=``), so ``ros2 bag``, the ``rosbags`` library and
Foxglove read the files without extra schemas. The builders return plain dicts (the field names
of the messages), which ``mcap-ros2-support`` encodes to CDR and the live view sends as JSON.

Pure: no I/O, no third-party import.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

_SEP = "\n" + "=" * 80 + "\n"

_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"

JOINT_STATE = "sensor_msgs/msg/JointState"
JOINT_STATE_DEF = (
    "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
    + _SEP + _HEADER + _SEP + _TIME)

DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
DIAGNOSTIC_ARRAY_DEF = (
    "std_msgs/Header header\nDiagnosticStatus[] status\n"
    + _SEP + _HEADER + _SEP + _TIME + _SEP
    + "MSG: diagnostic_msgs/DiagnosticStatus\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n"
      "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n"
    + _SEP + "MSG: diagnostic_msgs/KeyValue\nstring key\nstring value\n")

LOG = "rcl_interfaces/msg/Log"
LOG_DEF = (
    "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n"
    "builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\nstring function\n"
    "uint32 line\n" + _SEP + _TIME)

STRING = "std_msgs/msg/String"
STRING_DEF = "string data\n"

_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
WRENCH_STAMPED_DEF = (
    "std_msgs/Header header\nWrench wrench\n"
    + _SEP + _HEADER + _SEP + _TIME + _SEP
    + "MSG: geometry_msgs/Wrench\nVector3 force\nVector3 torque\n" + _SEP + _VECTOR3)

DEFINITIONS = {JOINT_STATE: JOINT_STATE_DEF, DIAGNOSTIC_ARRAY: DIAGNOSTIC_ARRAY_DEF, LOG: LOG_DEF,
               STRING: STRING_DEF, WRENCH_STAMPED: WRENCH_STAMPED_DEF}

# diagnostic_msgs/DiagnosticStatus levels and rcl_interfaces/Log levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LOG_INFO, LOG_WARN, LOG_ERROR = 20, 30, 40

# Topics: the same in a recording and in the live view, so one Foxglove layout serves both.
TOPIC_JOINTS = "/joint_states"  # rad, rad/s, A
TOPIC_MOTORS = "/sherpa/motor_counts"  # JointState of the drives: counts, counts/s, A
TOPIC_STATUS = "/diagnostics"  # one DiagnosticStatus per drive: MO, SR and MF decoded
TOPIC_LOG = "/rosout"  # EMCY and notes
TOPIC_STEP = "/sherpa/step_metrics"  # std_msgs/String holding the metrics JSON of `log step`
TOPIC_BUS_LOAD = "/sherpa/bus_load"  # live only (JSON)
TOPIC_WRENCH = "/sherpa/wrench/"  # + the F/T sensor's device name: WrenchStamped, N and N·m in its frame


def stamp(ns: int) -> dict[str, int]:
    """builtin_interfaces/Time of a nanosecond UNIX time."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def joint_state(ns: int, names: Sequence[str], position: Sequence[float], velocity: Sequence[float] = (),
                effort: Sequence[float] = (), frame_id: str = "") -> dict[str, Any]:
    """sensor_msgs/JointState: ``velocity`` / ``effort`` either empty or one value per name (NaN: not sampled)."""
    return {"header": {"stamp": stamp(ns), "frame_id": frame_id}, "name": list(names),
            "position": [float(v) for v in position], "velocity": [float(v) for v in velocity],
            "effort": [float(v) for v in effort]}


def wrench_stamped(ns: int, frame_id: str, force: Sequence[float], torque: Sequence[float]) -> dict[str, Any]:
    """geometry_msgs/WrenchStamped: force (N) and torque (N·m) as x, y, z in ``frame_id``."""
    def vector(v: Sequence[float]) -> dict[str, float]:
        return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}
    return {"header": {"stamp": stamp(ns), "frame_id": frame_id}, "wrench": {"force": vector(force),
                                                                             "torque": vector(torque)}}


def key_values(pairs: Sequence[tuple[str, str]]) -> list[dict[str, str]]:
    return [{"key": k, "value": v} for k, v in pairs]


def diagnostic_status(level: int, name: str, message: str, hardware_id: str,
                      values: Sequence[tuple[str, str]]) -> dict[str, Any]:
    return {"level": level, "name": name, "message": message, "hardware_id": hardware_id,
            "values": key_values(values)}


def diagnostic_array(ns: int, status: Sequence[dict[str, Any]]) -> dict[str, Any]:
    return {"header": {"stamp": stamp(ns), "frame_id": ""}, "status": list(status)}


def log(ns: int, level: int, name: str, msg: str) -> dict[str, Any]:
    return {"stamp": stamp(ns), "level": level, "name": name, "msg": msg, "file": "", "function": "", "line": 0}


def json_safe(value: float) -> float | None:
    """NaN/inf are not JSON: None (null) in the live view's messages."""
    return value if math.isfinite(value) else None
