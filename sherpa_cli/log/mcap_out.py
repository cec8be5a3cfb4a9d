"""MCAP files: joint recordings as ROS 2 messages, and raw CAN captures with a JSON schema.

Recordings (`log record -o run.mcap`, `log step -o step.mcap`) are written with
``mcap-ros2-support`` in the ``ros2`` profile, every channel a CDR-encoded ROS 2 message whose
``ros2msg`` schema is in the file (log/ros_msgs.py), so ``ros2 bag``, ``rosbags`` and Foxglove read
them without a ROS installation or extra schemas:

- ``/joint_states`` sensor_msgs/JointState per sample: the recorded joints (Σ/Δ joints of a pair
  too) in config order, position rad, velocity rad/s, effort A (current; NaN for Σ/Δ joints and
  when not sampled; empty when no current was recorded). A joint a sample lacks is NaN; a sample
  without any joint value gets no message.
- ``/sherpa/motor_counts`` sensor_msgs/JointState of the drives (``frame_id`` ``counts``): PX in
  counts, VX in counts/s, current in A.
- ``/sherpa/wrench/<device>`` geometry_msgs/WrenchStamped per sample of each recorded F/T sensor
  (``frame_id`` its config ``frame``): force in N, torque in N·m (columns ``<device>.fx_n`` ..
  ``<device>.tz_nm``); a sample the sensor did not answer gets no message.
- ``/sherpa/abs_encoders`` sensor_msgs/JointState of the joints whose CANopen encoder was recorded:
  the encoder's reading in rad (with ``abs_encoder.offset``).
- ``/diagnostics`` diagnostic_msgs/DiagnosticArray: per drive MO, UM, SR and MF decoded, as read
  before and after the recording.
- ``/rosout`` rcl_interfaces/Log: every EMCY heard while recording, with its Elmo text.
- ``/sherpa/step_metrics`` std_msgs/String (`log step`): the metrics JSON of the step.
- Metadata ``sherpa.recording`` (time zero, rate, source, command), ``sherpa.config`` (file, joint
  names) and one ``joint.<name>`` per configured joint (role, drive or pair, cpr, ranges in rad,
  speed and current limits).

Message times: ``log_time`` = ``publish_time`` = header stamp = ``time_zero_ns`` + ``time_s`` of
the CSV, so ``(log_time - time_zero_ns) / 1e9`` is the CSV's ``time_s``.

Captures (`log capture -o bus.mcap`) are written with the ``mcap`` library, one channel per bus
(topic ``/can/<bus>``, message encoding ``json``, schema ``sherpa.CanFrame`` in ``jsonschema``):
``{"bus", "id", "extended", "remote", "error", "dlc", "data"}`` (``data`` hex), ``log_time`` the
frame's receive time in ns. :func:`read_frames` reads them back for `log decode`.

The third-party packages are imported inside the functions only (`sherpa --help` stays fast);
without them :func:`require_mcap` says in one line what to install (exit 2).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig, JointConfig
from sherpa_cli.devices.ft_sensor import FT_COLUMNS
from sherpa_cli.elmo.faults import Emcy, decode_mf, sr_problems
from sherpa_cli.errors import SherpaError, UsageError
from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.log import ros_msgs
from sherpa_cli.log.candecode import Frame
from sherpa_cli.log.recording import Recording

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.session import ArmSession

EXTRA = "pip install 'sherpa-cli[robotics]'"
CAN_FRAME_SCHEMA: dict[str, Any] = {
    "title": "sherpa.CanFrame",
    "description": "One classic CAN frame as received on one bus of the arm (sherpa log capture).",
    "type": "object",
    "properties": {
        "bus": {"type": "string", "description": "the configured bus name"},
        "id": {"type": "integer", "minimum": 0, "maximum": 0x1FFFFFFF, "description": "arbitration id"},
        "extended": {"type": "boolean", "description": "29-bit id"},
        "remote": {"type": "boolean", "description": "remote transmission request"},
        "error": {"type": "boolean", "description": "an error frame of the interface"},
        "dlc": {"type": "integer", "minimum": 0, "maximum": 15},
        "data": {"type": "string", "pattern": "^([0-9A-F]{2})*$", "description": "payload, hex, upper case"},
    },
    "required": ["bus", "id", "extended", "remote", "error", "dlc", "data"],
}
CAN_TOPIC_PREFIX = "/can/"


def _missing(what: str, packages: str) -> UsageError:
    return UsageError(f"{what} needs {packages} (the robotics extra): {EXTRA}")


def require_mcap(what: str) -> None:
    """Raise one clear UsageError (exit 2) when ``mcap`` / ``mcap-ros2-support`` cannot be imported."""
    try:
        import mcap.reader
        import mcap.writer  # noqa: F401
        import mcap_ros2.decoder
        import mcap_ros2.writer  # noqa: F401
    except ImportError:
        raise _missing(what, "the mcap and mcap-ros2-support packages") from None


# -- drive status ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class DriveState:
    """What one drive said about itself (MO, UM, SR, MF through the interpreter); None: not read."""

    drive: str
    bus: str
    node: int
    mo: int | None = None
    um: int | None = None
    sr: int | None = None
    mf: int | None = None
    problem: str | None = None  # why it did not answer

    @property
    def address(self) -> str:
        return f"{self.bus}:{self.node}"


STATUS_QUERIES = ("MO", "UM", "SR", "MF")


def read_states(session: ArmSession, refs: Sequence[DriveRef]) -> tuple[DriveState, ...]:
    """MO, UM, SR and MF of each drive through the interpreter (NMT start first: it answers only
    when Operational). Only queries; a drive that does not answer gets its ``problem``."""
    out = []
    for ref in refs:
        client = session.client(ref)
        values: dict[str, int] = {}
        try:
            client.nmt_start()
            for letters in STATUS_QUERIES:
                values[letters] = int(client.get(letters))
        except SherpaError as exc:
            out.append(DriveState(ref.name, ref.bus, ref.node, problem=str(exc).removeprefix(f"{client.label}: ")))
            continue
        out.append(DriveState(ref.name, ref.bus, ref.node, mo=values["MO"], um=values["UM"], sr=values["SR"],
                              mf=values["MF"]))
    return tuple(out)


def diagnostic(state: DriveState) -> dict[str, Any]:
    """One diagnostic_msgs/DiagnosticStatus: ERROR for a silent drive or a latched motor failure,
    WARN for SR problems, else OK; MO, UM, SR, MF and every decoded fault as key/values."""
    values: list[tuple[str, str]] = [("bus", state.bus), ("node", str(state.node))]
    if state.problem is not None:
        return ros_msgs.diagnostic_status(ros_msgs.ERROR, state.drive, state.problem, state.address, values)
    sr_found = sr_problems(state.sr) if state.sr is not None else []
    mf_found = decode_mf(state.mf).faults if state.mf else ()
    for key, value in (("MO", state.mo), ("UM", state.um)):
        values.append((key, "-" if value is None else str(value)))
    values.append(("SR", "-" if state.sr is None else f"0x{state.sr & 0xFFFFFFFF:08X}"))
    values.append(("MF", "-" if state.mf is None else f"0x{state.mf & 0xFFFFFFFF:08X}"))
    values += [("SR problem", f.line()) for f in sr_found]
    values += [("MF fault", f.line()) for f in mf_found]
    if mf_found:
        level, message = ros_msgs.ERROR, f"MF: {mf_found[0].text}"
    elif state.mf:
        level, message = ros_msgs.ERROR, f"MF 0x{state.mf & 0xFFFFFFFF:08X}"
    elif sr_found:
        level, message = ros_msgs.WARN, f"SR: {sr_found[0].text}"
    else:
        level = ros_msgs.OK
        message = "motor on" if state.mo else ("motor off" if state.mo is not None else "ok")
    return ros_msgs.diagnostic_status(level, state.drive, message, state.address, values)


def emcy_log(ns: int, drive: str, emcy: Emcy) -> dict[str, Any]:
    """rcl_interfaces/Log of an EMCY: ERROR with the Elmo text (and what to check)."""
    text = emcy.text + (f" - check {emcy.check}" if emcy.check else "")
    return ros_msgs.log(ns, ros_msgs.LOG_ERROR, drive, text)


# -- recordings ------------------------------------------------------------------------------------

def _fmt(value: float | int | None) -> str:
    return "" if value is None else f"{value:g}"


def joint_metadata(cfg: ArmConfig, joint: JointConfig) -> dict[str, str]:
    """The config's facts about a joint as MCAP metadata (strings): ranges in rad and counts."""
    cpr = joint.cpr
    out = {"role": joint.role.value, "drive": joint.drive or "", "pair": joint.pair or "", "cpr": str(cpr)}
    for name, (lo, hi) in (("full", joint.full_range), ("normal", joint.normal_range),
                           ("overshoot", joint.overshoot_range)):
        out[f"{name}_min_counts"], out[f"{name}_max_counts"] = str(lo), str(hi)
        out[f"{name}_min_rad"] = f"{counts_to_rad(lo, cpr):.9g}"
        out[f"{name}_max_rad"] = f"{counts_to_rad(hi, cpr):.9g}"
    for name, value in (("vel_limit", joint.vel_limit), ("vel_trip", joint.vel_trip), ("accel", joint.accel),
                        ("decel", joint.decel)):
        out[f"{name}_rad_s{'2' if name in ('accel', 'decel') else ''}"] = (
            "" if value is None else f"{counts_per_s_to_rad_per_s(value, cpr):.9g}")
    current = joint.current
    if current is None and joint.pair is not None and joint.pair in cfg.pairs:
        current = cfg.pairs[joint.pair].current
    out["current_continuous_a"] = _fmt(current.continuous if current else None)
    out["current_peak_a"] = _fmt(current.peak if current else None)
    return out


@dataclass(frozen=True)
class TimedStatus:
    ns: int
    states: tuple[DriveState, ...]


@dataclass(frozen=True)
class TimedEmcy:
    ns: int
    drive: str
    emcy: Emcy


def _column(rec: Recording, name: str) -> list[float] | None:
    return rec.columns.get(name)


def _pick(values: list[float] | None, i: int) -> float:
    return math.nan if values is None else values[i]


def write_recording(path: Path, rec: Recording, cfg: ArmConfig, *, time_zero_ns: int,
                    info: Mapping[str, str] | None = None, status: Sequence[TimedStatus] = (),
                    emcy: Sequence[TimedEmcy] = (), step_metrics: Mapping[str, Any] | None = None,
                    config_file: str = "") -> None:
    """Write ``rec`` (log/recording.py) as a ROS 2 MCAP (module docstring)."""
    require_mcap(f"-o {path}")
    from mcap_ros2.writer import Writer

    joints = rec.joints()
    drives = list(dict.fromkeys(name[:-3] for name in rec.columns if name.endswith(".px")))
    encoders = [j for j in joints if f"{j}.ext_pos_rad" in rec.columns]
    with_current = any(f"{j}.cur_a" in rec.columns for j in joints)
    with_iq = any(f"{d}.iq_a" in rec.columns for d in drives)
    cols = {name: _column(rec, name) for name in rec.columns}
    # the F/T sensors whose columns the recording holds: (device, sensor frame)
    sensors = [(d.name, d.ft.frame) for d in cfg.ft_sensors() if d.ft is not None and f"{d.name}.fx_n" in rec.columns]

    with path.open("wb") as fh:
        writer = Writer(fh)
        schemas = {name: writer.register_msgdef(name, text) for name, text in ros_msgs.DEFINITIONS.items()}
        js = schemas[ros_msgs.JOINT_STATE]
        samples = set(rec.sample_rows())  # the /joint_states messages, and the count the metadata gives
        meta = {"time_zero_ns": str(time_zero_ns), "samples": str(len(samples)), **(info or {})}
        writer.add_metadata("sherpa.recording", meta)
        writer.add_metadata("sherpa.config", {"file": config_file, "joints": ",".join(cfg.joints),
                                              "recorded_joints": ",".join(joints), "drives": ",".join(drives)})
        for joint in cfg.joints.values():
            writer.add_metadata(f"joint.{joint.name}", joint_metadata(cfg, joint))
        events: list[tuple[int, int, str, Any, dict[str, Any]]] = []  # (ns, order, topic, schema, msg)
        for s in status:
            events.append((s.ns, 0, ros_msgs.TOPIC_STATUS, schemas[ros_msgs.DIAGNOSTIC_ARRAY],
                           ros_msgs.diagnostic_array(s.ns, [diagnostic(d) for d in s.states])))
        for e in emcy:
            events.append((e.ns, 1, ros_msgs.TOPIC_LOG, schemas[ros_msgs.LOG], emcy_log(e.ns, e.drive, e.emcy)))
        if step_metrics is not None:
            events.append((time_zero_ns, 2, ros_msgs.TOPIC_STEP, schemas[ros_msgs.STRING],
                           {"data": json.dumps(step_metrics, sort_keys=True)}))
        events.sort(key=lambda e: (e[0], e[1]))
        pending = iter(events)
        nxt = next(pending, None)
        for i, t in enumerate(rec.times):
            ns = time_zero_ns + round(t * 1e9)
            while nxt is not None and nxt[0] <= ns:
                writer.write_message(nxt[2], nxt[3], nxt[4], log_time=nxt[0], publish_time=nxt[0])
                nxt = next(pending, None)
            if joints and i in samples:
                pos = [_pick(cols.get(f"{j}.pos_rad"), i) for j in joints]
                vel = [_pick(cols.get(f"{j}.vel_rad_s"), i) for j in joints]
                eff = [_pick(cols.get(f"{j}.cur_a"), i) for j in joints] if with_current else []
                writer.write_message(ros_msgs.TOPIC_JOINTS, js, ros_msgs.joint_state(ns, joints, pos, vel, eff),
                                     log_time=ns, publish_time=ns)
            px = [_pick(cols.get(f"{d}.px"), i) for d in drives]
            if drives and not all(math.isnan(v) for v in px):
                vx = [_pick(cols.get(f"{d}.vx"), i) for d in drives]
                iq = [_pick(cols.get(f"{d}.iq_a"), i) for d in drives] if with_iq else []
                writer.write_message(ros_msgs.TOPIC_MOTORS, js,
                                     ros_msgs.joint_state(ns, drives, px, vx, iq, frame_id="counts"),
                                     log_time=ns, publish_time=ns)
            for name, frame_id in sensors:
                values = [_pick(cols.get(f"{name}.{column}"), i) for _, column in FT_COLUMNS]
                if not any(math.isnan(v) for v in values):
                    writer.write_message(ros_msgs.TOPIC_WRENCH + name, schemas[ros_msgs.WRENCH_STAMPED],
                                         ros_msgs.wrench_stamped(ns, frame_id, values[:3], values[3:]),
                                         log_time=ns, publish_time=ns)
            ext = [_pick(cols.get(f"{j}.ext_pos_rad"), i) for j in encoders]
            if encoders and not all(math.isnan(v) for v in ext):
                writer.write_message("/sherpa/abs_encoders", js, ros_msgs.joint_state(ns, encoders, ext),
                                     log_time=ns, publish_time=ns)
        while nxt is not None:
            writer.write_message(nxt[2], nxt[3], nxt[4], log_time=nxt[0], publish_time=nxt[0])
            nxt = next(pending, None)
        writer.finish()


# -- raw captures ----------------------------------------------------------------------------------

class FrameWriter:
    """A python-can style writer (``on_message_received``, ``stop``) of raw frames into an MCAP:
    one channel per bus, named by the message's ``channel`` (capture.py sets the bus name)."""

    def __init__(self, path: Path) -> None:
        require_mcap(f"-o {path}")
        from mcap.writer import Writer

        self._file = path.open("wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="sherpa-cli")
        self._schema = self._writer.register_schema(
            "sherpa.CanFrame", "jsonschema", json.dumps(CAN_FRAME_SCHEMA, sort_keys=True).encode())
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._stopped = False

    def _channel(self, bus: str) -> int:
        channel = self._channels.get(bus)
        if channel is None:
            channel = self._writer.register_channel(f"{CAN_TOPIC_PREFIX}{bus}", "json", self._schema, {"bus": bus})
            self._channels[bus] = channel
            self._sequence[bus] = 0
        return channel

    def on_message_received(self, msg: can.Message) -> None:
        bus = "-" if msg.channel is None else str(msg.channel)
        channel = self._channel(bus)
        ns = round(float(msg.timestamp) * 1e9)
        body = {"bus": bus, "id": int(msg.arbitration_id), "extended": bool(msg.is_extended_id),
                "remote": bool(msg.is_remote_frame), "error": bool(msg.is_error_frame), "dlc": int(msg.dlc),
                "data": bytes(msg.data).hex().upper()}
        self._sequence[bus] += 1
        self._writer.add_message(channel, log_time=ns, data=json.dumps(body).encode(), publish_time=ns,
                                 sequence=self._sequence[bus])

    def stop(self) -> None:
        if self._stopped:
            return
        self._stopped = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def read_frames(path: Path) -> Iterator[Frame]:
    """The frames of a capture MCAP in log-time order; one clear message for a file that is not one."""
    require_mcap(str(path))
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    with path.open("rb") as fh:
        try:
            reader = make_reader(fh)
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                if not channel.topic.startswith(CAN_TOPIC_PREFIX) or schema is None \
                        or schema.name != "sherpa.CanFrame":
                    continue  # other channels (a recording's) are not frames
                yield _frame(path, message.log_time, message.data)
        except (McapError, ValueError, KeyError, TypeError, EOFError, OSError) as exc:
            raise UsageError(f"{path}: not a readable .mcap capture ({type(exc).__name__}: {exc})") from None


def _frame(path: Path, log_time: int, data: bytes) -> Frame:
    body = json.loads(data)
    return Frame(log_time / 1e9, str(body["bus"]), int(body["id"]), bytes.fromhex(body["data"]),
                 bool(body["extended"]), bool(body["remote"]), bool(body["error"]))
