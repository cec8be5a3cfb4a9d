"""Raw CAN captures: read any python-can log format (and can-utils ``candump -L`` text) as
:class:`~sherpa_cli.log.candecode.Frame`, and capture every bus of a session into one file.

Formats by suffix through python-can's readers and writers: ``.log`` (candump, the channel on
every line), ``.asc``, ``.blf``, ``.csv``, ``.trc``, ``.mf4`` (when asammdf is installed), and
``.mcap`` (one channel per bus, log/mcap_out.py; with the robotics extra).
Formats that store a channel *number* (asc, blf, trc) get the bus's position in the config
(0 = the first configured bus) and are read back the same way; ``.csv`` keeps no channel.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from sherpa_cli.errors import UsageError, raise_if_signalled
from sherpa_cli.log.candecode import Frame, parse_candump_line

if TYPE_CHECKING:
    import can



class FrameSink(Protocol):
    """Where captured frames go: a python-can writer (can.Logger) or the MCAP FrameWriter."""

    def on_message_received(self, msg: can.Message) -> None: ...

    def stop(self) -> None: ...


CANDUMP_SUFFIXES = (".log", ".txt", ".candump")
WRITE_SUFFIXES = (".log", ".asc", ".blf", ".csv", ".trc", ".mf4", ".mcap")
NUMBERED_CHANNELS = (".asc", ".blf", ".trc", ".mf4")


def read_frames(path: Path, bus_names: Sequence[str] = ()) -> Iterator[Frame]:
    """The frames of a capture file in file order; ``bus_names`` maps channel numbers to buses."""
    if not path.is_file():
        raise UsageError(f"{path}: no such capture file")
    suffix = path.suffix.lower()
    if suffix in CANDUMP_SUFFIXES:
        yield from _read_candump(path)
        return
    if suffix == ".mf4":
        _need_asammdf(path)
    if suffix == ".mcap":
        from sherpa_cli.log import mcap_out

        yield from mcap_out.read_frames(path)
        return
    import can

    try:
        reader = can.LogReader(str(path))
    except Exception as exc:  # noqa: BLE001  python-can's readers raise their own parse errors (BLFParseError, ...)
        raise UsageError(f"{path}: cannot read this format ({exc})",
                         hint="formats: .log/.txt (candump -L), .asc, .blf, .csv, .trc, .mf4, .mcap") from None
    # python-can's TRC reader numbers channels from 1, its writer took them from 0
    shift = 1 if suffix == ".trc" else 0
    frames = 0
    try:
        for msg in reader:
            channel = msg.channel - shift if isinstance(msg.channel, int) and msg.channel >= shift else msg.channel
            frames += 1
            yield Frame(float(msg.timestamp), _bus_name(channel, bus_names), int(msg.arbitration_id),
                        bytes(msg.data), bool(msg.is_extended_id), bool(msg.is_remote_frame),
                        bool(msg.is_error_frame))
    except Exception as exc:  # noqa: BLE001  any reader's failure on a damaged file: one message naming it
        raise UsageError(f"{path}: not a readable {suffix} capture ({type(exc).__name__}: {exc})") from None
    finally:
        stop = getattr(reader, "stop", None)
        if stop is not None:
            stop()
    if not frames and _has_content(path):
        # python-can's text readers skip every line they do not understand: a file of anything else
        # (NUL bytes, a zip, another format) would read as "no frames matched" and exit 0
        raise UsageError(f"{path}: no CAN frame could be read from it: not a {suffix} capture",
                         hint="formats: .log/.txt (candump -L), .asc, .blf, .csv, .trc, .mf4, .mcap")


def _has_content(path: Path) -> bool:
    """Whether the file holds anything but blanks (an empty capture of a quiet bus is not an error)."""
    with path.open("rb") as fh:
        return bool(fh.read(65536).strip(b" \t\r\n"))


def _read_candump(path: Path) -> Iterator[Frame]:
    with path.open(encoding="utf-8", errors="replace") as fh:
        for number, line in enumerate(fh, 1):
            try:
                frame = parse_candump_line(line, f"{path}:{number}")
            except ValueError as exc:
                raise UsageError(str(exc), hint="candump -L lines look like '(1700000000.000000) can0 60A#4017100000000000'") from None
            if frame is not None:
                yield frame


def _bus_name(channel: object, bus_names: Sequence[str]) -> str:
    if channel is None:
        return bus_names[0] if len(bus_names) == 1 else "-"
    if isinstance(channel, int) and 0 <= channel < len(bus_names):
        return bus_names[channel]
    return str(channel)


def _need_asammdf(path: Path) -> None:
    import importlib.util

    if importlib.util.find_spec("asammdf") is None:
        raise UsageError(f"{path}: .mf4 needs the asammdf package", hint="pip install asammdf")


def channel_for(suffix: str, bus: str, bus_names: Sequence[str]) -> int | str:
    """What a writer of ``suffix`` gets as the channel of ``bus``."""
    if suffix in NUMBERED_CHANNELS and bus in bus_names:
        return list(bus_names).index(bus)
    return bus


def check_output(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise UsageError(f"{path}: unknown capture format {suffix or '(no suffix)'}",
                         hint="use .log (candump), .asc, .blf, .csv, .trc, .mf4 or .mcap")
    if suffix == ".mf4":
        _need_asammdf(path)
    if suffix == ".mcap":
        from sherpa_cli.log.mcap_out import require_mcap

        require_mcap(f"-o {path}")
    if not path.parent.exists():
        raise UsageError(f"{path}: directory {path.parent} does not exist")
    from sherpa_cli.output_files import check_output_path

    check_output_path(path, "-o", "the capture")
    return suffix


# -- live capture ---------------------------------------------------------------------------------

@dataclass
class BusCount:
    bus: str
    frames: int = 0
    bits: int = 0  # estimated bits on the wire (with stuffing), for the load
    errors: int = 0
    overruns: int = 0  # lost frames the adapter or the receive queue reported


@dataclass
class CaptureResult:
    path: Path
    seconds: float
    counts: dict[str, BusCount] = field(default_factory=dict)
    bitrates: dict[str, int | None] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return sum(c.frames for c in self.counts.values())

    @property
    def lost(self) -> int:
        return sum(c.overruns for c in self.counts.values())

    def load(self, bus: str) -> float | None:
        rate = self.bitrates.get(bus)
        if not rate or self.seconds <= 0:
            return None
        return self.counts[bus].bits / (rate * self.seconds)


def frame_bits(dlc: int, extended: bool = False) -> int:
    """Worst-case bits on the wire of one classic frame with stuffing (and 3 bits interframe space)."""
    if extended:
        return 67 + 8 * dlc + (54 + 8 * dlc - 1) // 4 + 3
    return 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4 + 3


def capture(buses: dict[str, can.BusABC], path: Path, bus_names: Sequence[str], *,
            stop: threading.Event, clock: Callable[[], float] = time.monotonic,
            frame_limit: int | None = None, on_frame: Callable[[], None] | None = None,
            bitrates: dict[str, int | None] | None = None) -> CaptureResult:
    """Write every frame of ``buses`` (name -> python-can bus) into ``path`` until ``stop`` is set
    (or ``frame_limit`` frames). A Notifier's reader threads fill one BufferedReader per bus; the
    writer drains them, so Ctrl-C (``stop`` set by the caller, or KeyboardInterrupt here) loses
    nothing already received: the buffers are drained and the file closed on every exit path.
    """
    import can

    suffix = check_output(path)
    result = CaptureResult(path, 0.0, {name: BusCount(name) for name in buses}, dict(bitrates or {}))
    readers = {name: can.BufferedReader() for name in buses}
    notifiers = [can.Notifier(bus, [readers[name]], timeout=0.05) for name, bus in buses.items()]
    start = clock()
    writer = _open_writer(path, suffix)
    try:
        try:
            while not stop.is_set():
                raise_if_signalled()  # a SIGTERM whose exception was lost (errors.py): no other ear for it
                if not _drain(readers, writer, result, suffix, bus_names, wait=0.05, on_frame=on_frame):
                    continue
                if frame_limit is not None and result.frames >= frame_limit:
                    break
        except KeyboardInterrupt:
            pass
    finally:
        for notifier in notifiers:
            notifier.stop()
        _drain(readers, writer, result, suffix, bus_names, wait=0.0, on_frame=None)
        # what the notifiers had not yet taken off the buses: read and write it here
        for name, bus in buses.items():
            msg = bus.recv(timeout=0.0)
            while msg is not None:
                _write(msg, name, writer, result, suffix, bus_names)
                msg = bus.recv(timeout=0.0)
        result.seconds = clock() - start
        writer.stop()
    return result


def _open_writer(path: Path, suffix: str) -> FrameSink:
    if suffix == ".mcap":
        from sherpa_cli.log.mcap_out import FrameWriter

        return FrameWriter(path)
    import can

    return can.Logger(str(path))


def _drain(readers: dict[str, can.BufferedReader], writer: FrameSink, result: CaptureResult, suffix: str, bus_names: Sequence[str], *, wait: float,
           on_frame: Callable[[], None] | None) -> bool:
    got = False
    for name, reader in readers.items():
        msg = reader.get_message(timeout=0.0)
        while msg is not None:
            got = True
            _write(msg, name, writer, result, suffix, bus_names)
            if on_frame is not None:
                on_frame()
            msg = reader.get_message(timeout=0.0)
    if not got and wait:
        time.sleep(wait)
    return got


def _write(msg: can.Message, name: str, writer: FrameSink, result: CaptureResult, suffix: str, bus_names: Sequence[str]) -> None:
    count = result.counts[name]
    if msg.is_error_frame:
        count.errors += 1
        # SocketCAN: class CAN_ERR_CRTL (0x4 in the id), data byte 1 = RX/TX overflow (0x01/0x02)
        if msg.arbitration_id & 0x4 and len(msg.data) > 1 and msg.data[1] & 0x03:
            count.overruns += 1
    count.frames += 1
    count.bits += frame_bits(msg.dlc, msg.is_extended_id)
    msg.channel = channel_for(suffix, name, bus_names)
    writer.on_message_received(msg)
