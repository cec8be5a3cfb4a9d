"""A live view of the arm in Foxglove: foxglove-sdk's own WebSocket server (`monitor --foxglove`,
`log record --foxglove`).

The topics and field names are the recordings' (log/mcap_out.py, log/ros_msgs.py), so the layout
docs/foxglove/sherpa.json serves a live arm and an MCAP file alike. Live, every channel is JSON
(schema encoding ``jsonschema``; the schema names are the ROS 2 types, which Foxglove's panels
recognise); NaN, which JSON cannot carry, is ``null``:

- ``/joint_states`` sensor_msgs/msg/JointState (rad, rad/s, A);
- ``/sherpa/motor_counts`` sensor_msgs/msg/JointState of the drives (counts, counts/s);
- ``/diagnostics`` diagnostic_msgs/msg/DiagnosticArray (MO, UM, SR, MF decoded per drive);
- ``/rosout`` rcl_interfaces/msg/Log (every EMCY heard, with its Elmo text; notes of the command);
- ``/sherpa/bus_load`` sherpa.BusLoad: per bus the frames the tool heard per second and their
  share of the bit rate (worst-case stuffing, log/capture.py ``frame_bits``), and for
  `log record` the load its SYNC and TPDOs were budgeted at.

The server binds 127.0.0.1:8765 unless told otherwise; a non-loopback address needs
``allow_remote`` (the commands' ``--allow-remote``), as `sim --serve` does. foxglove-sdk is
imported only here, when asked for; without it :func:`require_foxglove` says in one line what to
install (exit 2).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from sherpa_cli import netaddr
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.faults import Emcy
from sherpa_cli.errors import UsageError
from sherpa_cli.joints.jointmap import joint_maps
from sherpa_cli.joints.units import counts_per_s_to_rad_per_s, counts_to_rad
from sherpa_cli.log import ros_msgs
from sherpa_cli.log.capture import frame_bits
from sherpa_cli.log.mcap_out import EXTRA, DriveState, diagnostic, emcy_log

if TYPE_CHECKING:
    import can

    from sherpa_cli.bus.links import BusLink

DEFAULT_BIND = "127.0.0.1:8765"

_NUMBERS = {"type": "array", "items": {"type": ["number", "null"]}}
_STAMP = {"type": "object", "properties": {"sec": {"type": "integer"}, "nanosec": {"type": "integer"}}}
_HEADER = {"type": "object", "properties": {"stamp": _STAMP, "frame_id": {"type": "string"}}}
SCHEMAS: dict[str, dict[str, Any]] = {
    ros_msgs.TOPIC_JOINTS: {
        "title": ros_msgs.JOINT_STATE, "type": "object",
        "properties": {"header": _HEADER, "name": {"type": "array", "items": {"type": "string"}},
                       "position": _NUMBERS, "velocity": _NUMBERS, "effort": _NUMBERS}},
    ros_msgs.TOPIC_STATUS: {
        "title": ros_msgs.DIAGNOSTIC_ARRAY, "type": "object",
        "properties": {"header": _HEADER, "status": {"type": "array", "items": {"type": "object", "properties": {
            "level": {"type": "integer"}, "name": {"type": "string"}, "message": {"type": "string"},
            "hardware_id": {"type": "string"}, "values": {"type": "array", "items": {
                "type": "object", "properties": {"key": {"type": "string"}, "value": {"type": "string"}}}}}}}}},
    ros_msgs.TOPIC_LOG: {
        "title": ros_msgs.LOG, "type": "object",
        "properties": {"stamp": _STAMP, "level": {"type": "integer"}, "name": {"type": "string"},
                       "msg": {"type": "string"}, "file": {"type": "string"}, "function": {"type": "string"},
                       "line": {"type": "integer"}}},
    ros_msgs.TOPIC_BUS_LOAD: {
        "title": "sherpa.BusLoad", "type": "object",
        "properties": {"header": _HEADER, "buses": {"type": "array", "items": {"type": "object", "properties": {
            "bus": {"type": "string"}, "bitrate": {"type": "integer"},
            "frames_per_s": {"type": "number"}, "heard_load": {"type": "number"},
            "budget_load": {"type": ["number", "null"]}}}}}},
}
SCHEMAS[ros_msgs.TOPIC_MOTORS] = SCHEMAS[ros_msgs.TOPIC_JOINTS]


def require_foxglove(what: str = "--foxglove") -> None:
    """One clear UsageError (exit 2) when foxglove-sdk cannot be imported."""
    try:
        import foxglove  # noqa: F401
    except ImportError:
        raise UsageError(f"{what} needs the foxglove-sdk package (the robotics extra): {EXTRA}") from None


def parse_bind(text: str) -> tuple[str, int]:
    return netaddr.parse_host_port(text, "--foxglove-at", example=DEFAULT_BIND)


is_loopback = netaddr.is_loopback


def check_bind(host: str, allow_remote: bool) -> None:
    netaddr.check_bind(host, allow_remote, "--foxglove-at", "show the arm")


def _clean(values: Sequence[float | None]) -> list[float | None]:
    return [None if v is None else ros_msgs.json_safe(float(v)) for v in values]


def joint_states_from_counts(cfg: ArmConfig, counts: Mapping[str, tuple[int, int]]) -> tuple[
        list[str], list[float], list[float]]:
    """Joint names (config order), positions (rad) and velocities (rad/s) from drive -> (PX, VX):
    a plain joint from its drive, a Σ/Δ joint from both motors of its pair."""
    names: list[str] = []
    pos: list[float] = []
    vel: list[float] = []
    for m in joint_maps(cfg):
        if not all(d in counts for d in m.drives):
            continue
        (pa, va), (pb, vb) = counts[m.a], (counts[m.b] if m.b is not None else (None, None))
        names.append(m.joint)
        pos.append(counts_to_rad(m.value(pa, pb), m.cpr))
        vel.append(counts_per_s_to_rad_per_s(m.value(va, vb), m.cpr))
    return names, pos, vel


class HeardLoad:
    """Counts the frames a bus's receive thread hears (a python-can Notifier listener, added with
    the Notifier's documented ``add_listener``): frames per second and share of the bit rate."""

    def __init__(self, bitrate: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.bitrate, self.clock = bitrate, clock
        self._lock = threading.Lock()
        self._frames = 0
        self._bits = 0
        self._since = clock()

    def __call__(self, msg: can.Message) -> None:
        with self._lock:
            self._frames += 1
            self._bits += frame_bits(int(msg.dlc), bool(msg.is_extended_id))

    def take(self) -> tuple[float, float]:
        """(frames/s, load) since the last take."""
        now = self.clock()
        with self._lock:
            frames, bits, since = self._frames, self._bits, self._since
            self._frames, self._bits, self._since = 0, 0, now
        span = max(now - since, 1e-9)
        return frames / span, bits / (self.bitrate * span)


class _Notifier(Protocol):
    """What the live view uses of a bus's notifier (python-can's ``Notifier`` or bus/reader.py's)."""

    def add_listener(self, listener: Callable[[can.Message], None]) -> None: ...

    def remove_listener(self, listener: Callable[[can.Message], None]) -> None: ...


@dataclass
class _Listening:
    notifier: _Notifier
    meter: HeardLoad


class LiveView:
    """foxglove-sdk's WebSocket server and the arm's channels; a context manager (stops the server)."""

    def __init__(self, host: str, port: int, *, name: str = "sherpa") -> None:
        require_foxglove()
        import foxglove

        self.host = host
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context)
        except Exception as exc:  # noqa: BLE001 - the SDK's error for a taken port or a bad address is its own type
            raise UsageError(f"--foxglove-at {host}:{port}: cannot listen there ({exc})",
                             hint="choose another port with --foxglove-at") from None
        self.channels = {topic: foxglove.Channel(topic, schema=schema, context=self.context)
                         for topic, schema in SCHEMAS.items()}
        self._buses: dict[str, _Listening] = {}
        self._budget: dict[str, float] = {}
        self._lock = threading.Lock()

    @property
    def port(self) -> int:
        return int(self.server.port)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for listening in self._buses.values():
            with contextlib.suppress(ValueError):  # already gone with its bus
                listening.notifier.remove_listener(listening.meter)
        self._buses.clear()
        for channel in self.channels.values():
            channel.close()
        self.server.stop()

    def _log(self, topic: str, msg: dict[str, Any], ns: int) -> None:
        with self._lock:  # one writer at a time: the poll thread, the receive threads (EMCY)
            self.channels[topic].log(msg, log_time=ns)

    # -- what is published ----------------------------------------------------------------------
    def joint_states(self, names: Sequence[str], position: Sequence[float | None],
                     velocity: Sequence[float | None] = (), effort: Sequence[float | None] = (), *,
                     ns: int | None = None) -> None:
        ns = time.time_ns() if ns is None else ns
        msg = ros_msgs.joint_state(ns, names, [], [], [])
        msg.update(position=_clean(position), velocity=_clean(velocity), effort=_clean(effort))
        self._log(ros_msgs.TOPIC_JOINTS, msg, ns)

    def motor_counts(self, drives: Sequence[str], px: Sequence[float | None], vx: Sequence[float | None] = (), *,
                     ns: int | None = None) -> None:
        ns = time.time_ns() if ns is None else ns
        msg = ros_msgs.joint_state(ns, drives, [], [], [], frame_id="counts")
        msg.update(position=_clean(px), velocity=_clean(vx))
        self._log(ros_msgs.TOPIC_MOTORS, msg, ns)

    def status(self, states: Sequence[DriveState], *, ns: int | None = None) -> None:
        ns = time.time_ns() if ns is None else ns
        self._log(ros_msgs.TOPIC_STATUS, ros_msgs.diagnostic_array(ns, [diagnostic(s) for s in states]), ns)

    def emcy(self, drive: str, emcy: Emcy, *, ns: int | None = None) -> None:
        ns = time.time_ns() if ns is None else ns
        self._log(ros_msgs.TOPIC_LOG, emcy_log(ns, drive, emcy), ns)

    def note(self, text: str, *, level: int = ros_msgs.LOG_INFO, name: str = "sherpa") -> None:
        ns = time.time_ns()
        self._log(ros_msgs.TOPIC_LOG, ros_msgs.log(ns, level, name, text), ns)

    # -- bus load -------------------------------------------------------------------------------
    def listen(self, links: Mapping[str, BusLink], budget: Mapping[str, float] | None = None,
               clock: Callable[[], float] = time.monotonic) -> None:
        """Count what each bus's receive thread hears (``links``: bus -> BusLink of the session)."""
        self._budget = dict(budget or {})
        for name, link in links.items():
            notifier = getattr(link.network, "notifier", None)
            if notifier is None:
                continue
            meter = HeardLoad(link.config.bitrate or 1_000_000, clock)
            notifier.add_listener(meter)
            self._buses[name] = _Listening(notifier, meter)

    def bus_load(self, *, ns: int | None = None) -> None:
        ns = time.time_ns() if ns is None else ns
        rows = []
        for name, listening in self._buses.items():
            rate, load = listening.meter.take()
            rows.append({"bus": name, "bitrate": listening.meter.bitrate, "frames_per_s": round(rate, 3),
                         "heard_load": round(load, 6), "budget_load": self._budget.get(name)})
        self._log(ros_msgs.TOPIC_BUS_LOAD, {"header": {"stamp": ros_msgs.stamp(ns), "frame_id": ""}, "buses": rows},
                  ns)


class RecorderFeed:
    """`log record --foxglove`: a thread that publishes the newest sample every drive answered
    (``sample()``: drive -> (PX, VX), or None) and the bus load, ``hz`` times a second, until closed."""

    def __init__(self, view: LiveView, cfg: ArmConfig, sample: Callable[[], Mapping[str, tuple[int, int]] | None],
                 *, hz: float = 20.0) -> None:
        self.view, self.cfg, self.sample, self.period = view, cfg, sample, 1.0 / hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sherpa-foxglove-feed", daemon=True)

    def __enter__(self) -> RecorderFeed:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.publish()  # the last sample

    def publish(self) -> None:
        counts = self.sample()
        if counts:
            names, pos, vel = joint_states_from_counts(self.cfg, counts)
            ns = time.time_ns()
            if names:
                self.view.joint_states(names, pos, vel, ns=ns)
            drives = list(counts)
            self.view.motor_counts(drives, [counts[d][0] for d in drives], [counts[d][1] for d in drives], ns=ns)
        self.view.bus_load()

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            with contextlib.suppress(Exception):  # the live view must never end a recording
                self.publish()
