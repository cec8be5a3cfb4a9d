"""Open the configured buses: a python-can bus and a paced canopen Network for each."""

from __future__ import annotations

import contextlib
import errno
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.busmap import bus_kwargs
from sherpa_cli.bus.held_signals import signals_held
from sherpa_cli.config.model import ArmConfig, BusConfig
from sherpa_cli.errors import CommunicationError

if TYPE_CHECKING:
    import threading

    import can


#: ``protocol.pacing`` (docs/config.md): the gap between frames to the same drive, or (the tool's
#: earlier behaviour) between any two frames on the bus
PACING_MODES = ("per-drive", "per-bus")


def destination(can_id: int, data: bytes) -> int | None:
    """The node a frame this tool sends is for: RPDO1..4 (0x200..0x57F, the interpreter's RPDO2
    0x300 + node among them) and SDO requests (0x600 + node); None for a frame to every node (NMT
    0x000 with node 0 names its node in byte 1, SYNC, anything else)."""
    if 0x201 <= can_id <= 0x57F or 0x601 <= can_id <= 0x67F:
        return can_id & 0x7F or None
    if can_id == 0x000 and len(data) >= 2 and data[1]:
        return data[1]
    return None


def answering(can_id: int) -> int | None:
    """The node a received frame is an answer from: an interpreter reply (TPDO2, 0x280 + node) or
    an SDO response (0x580 + node); None for anything else (heartbeats, EMCY, other PDOs)."""
    if 0x281 <= can_id <= 0x2FF or 0x581 <= can_id <= 0x5FF:
        return can_id & 0x7F
    return None


class BusLostError(CommunicationError):
    """The connection to a bus went away while a command used it: a served simulator killed, an
    adapter unplugged, an interface deleted (exit 3)."""


def _paced_network_class():
    import can
    import canopen

    class _LostListener(can.Listener):
        """python-can's documented error path (``Listener.on_error``): the receive thread's error is
        noted on the network and the notifier is told to stop, instead of the thread dying with a
        traceback on stderr; the command's next frame raises :class:`BusLostError`."""

        def __init__(self, network: PacedNetwork) -> None:
            self.network = network

        def on_message_received(self, msg: can.Message) -> None:
            pass

        def on_error(self, exc: Exception) -> None:
            if self.network.lost is None:
                self.network.lost = exc
            notifier = self.network.notifier
            if notifier is not None:
                with contextlib.suppress(Exception):
                    notifier.stop(timeout=0)  # flags its thread; joins nothing (this is that thread)

    class PacedNetwork(canopen.Network):
        """canopen.Network that paces what this tool sends and retries a full socket buffer.

        Pacing (``pacing``, config ``protocol.pacing``; elmo-protocol.md §4.2: a drive's receive
        buffer is overwritten by the next frame *to the same buffer*):

        - ``per-drive``: frames to one drive keep ``gap`` between them, unless the drive has
          answered (interpreter reply or SDO response) since the previous one; frames to other
          drives go meanwhile. A frame to every drive (NMT to all) waits for every drive's gap.
        - ``per-bus``: ``gap`` between any two frames on the bus (the tool's earlier behaviour).

        Either way ``floor`` (``protocol.pacing_floor_us``, about one frame time) is kept between
        any two frames on the bus. Overriding send_message and notify is canopen's documented seam
        (``Network.notify`` is what its listener calls for every received frame); every SDO, NMT and
        interpreter frame of this tool goes through it.
        """

        #: canopen's receive thread wakes this often to see whether it must stop (canopen's
        #: documented class attribute; its default is 1 s). Closing a session waits for it once
        #: for all buses together (close_links), so a short cycle makes closing cost milliseconds;
        #: an idle wake-up is one empty queue/socket read.
        NOTIFIER_CYCLE = 0.02
        #: seconds between two frames sent by this tool on the bus (config: send_interval_us)
        gap: float = 0.0
        #: "per-drive" or "per-bus" (PACING_MODES)
        pacing: str = "per-drive"
        #: seconds between any two frames on the bus in per-drive mode (config: pacing_floor_us)
        floor: float = 0.0
        #: attempts when the kernel's socket buffer is full (ENOBUFS, python-can issue #2004)
        send_attempts: int = 5
        clock: Callable[[], float] = staticmethod(time.monotonic)
        sleep: Callable[[float], None] = staticmethod(time.sleep)
        #: how messages name this bus ("bus can1 (remote:127.0.0.1:5001)"), set by open_links
        where: str = "the bus"

        #: ``protocol.caller_reads``: a caller waiting for a reply reads the bus
        #: itself (bus/reader.py); False: python-can's Notifier thread reads and hands replies over
        caller_reads: bool = True

        def __init__(self, bus: can.BusABC | None = None) -> None:
            super().__init__(bus)
            self.lost: BaseException | None = None  # the error that ended the receive thread
            self._last_send = float("-inf")
            self._last_to: dict[int, float] = {}  # node -> when the last frame to it went
            self._answered: dict[int, bool] = {}  # node -> it answered since that frame
            self._messages: dict[tuple[int, bytes, bool], can.Message] = {}

        def connect(self, *args: Any, **kwargs: Any) -> PacedNetwork:
            """canopen's ``connect`` with the bus already set; with ``caller_reads`` the notifier is
            bus/reader.py's CallerReadNotifier (the same interface, installed as ``Network.notifier``)."""
            if not self.caller_reads or self.bus is None:
                super().connect(*args, **kwargs)
                if self.notifier is not None:  # python-can's Notifier reports a dead bus through on_error
                    self.notifier.add_listener(_LostListener(self))
                return self
            from sherpa_cli.bus.reader import CallerReadNotifier

            # the same interface as can.Notifier where canopen and this tool use it; a dead bus is kept
            # in its ``exception`` (lost_error reads it)
            self.notifier = CallerReadNotifier(self.bus, self.listeners, self.NOTIFIER_CYCLE,  # type: ignore[assignment]
                                               lost=self._bus_lost)
            return self

        def wait_for(self, arrived: threading.Lock, timeout: float) -> bool:
            """Wait for a listener to release ``arrived`` (a drive client's reply lock), reading the
            bus on this thread meanwhile when the notifier allows it (bus/reader.py)."""
            wait = getattr(self.notifier, "wait_for", None)
            if wait is None:
                return bool(arrived.acquire(timeout=timeout))
            return bool(wait(arrived, timeout))

        def _bus_lost(self, exc: BaseException) -> BaseException:
            """A caller's read of the bus failed: the bus is gone (:class:`BusLostError` naming it)."""
            if self.lost is None:
                self.lost = exc
            return self.lost_error() or exc

        def lost_error(self) -> BusLostError | None:
            """The bus's connection went away (the receive thread's error), as a message naming the bus."""
            exc = self.lost or (self.notifier.exception if self.notifier is not None else None)
            if exc is None:
                return None
            return BusLostError(f"{self.where}: the connection to the bus was lost ({_brief(exc)})",
                                hint="is the adapter plugged in, the interface up, the served simulator running?")

        def check(self) -> None:
            """canopen's check of the receive thread, its error named as a lost bus (exit 3)."""
            lost = self.lost_error()
            if lost is not None:
                raise lost

        def disconnect(self) -> None:
            bus = self.bus
            try:
                super().disconnect()
            except Exception:
                # a bus whose connection is gone may fail to close (python-can-remote: ENOTCONN);
                # mark it shut down (python-can's base shutdown) so nothing retries it at exit
                if bus is not None:
                    with contextlib.suppress(Exception):
                        can.BusABC.shutdown(bus)
                self.bus = None
                raise

        def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
            node = answering(can_id)
            if node is not None:
                self._answered[node] = True  # one dict store: atomic, no lock on the receive thread
            super().notify(can_id, data, timestamp)

        def _wait(self, node: int | None, now: float) -> float:
            """Seconds the next frame (to ``node``, None = every drive) must still wait."""
            if self.pacing == "per-bus":
                return self._last_send + self.gap - now
            wait = self._last_send + self.floor - now
            if self.gap:
                if node is None:
                    pending = [t for n, t in self._last_to.items() if not self._answered.get(n, False)]
                    last = max(pending, default=float("-inf"))
                else:
                    last = float("-inf") if self._answered.get(node, True) else self._last_to[node]
                wait = max(wait, last + self.gap - now)
            return wait

        def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
            if not self.bus:
                raise CommunicationError("bus is closed")
            data = bytes(data)
            key = (can_id, data, remote)
            msg = self._messages.get(key)
            if msg is None:
                # one Message per distinct frame: a poll loop sends the same few over and over, and
                # building one costs about as much as the rest of the send.
                # python-can's buses do not change the Message they send (virtual sends a copy).
                msg = can.Message(is_extended_id=can_id > 0x7FF, arbitration_id=can_id, data=data,
                                  is_remote_frame=remote)
                if len(self._messages) >= 1024:
                    self._messages.clear()
                self._messages[key] = msg
            if not (self.gap or self.floor):  # unpaced skips the clock: every round trip passes here
                with self.send_lock:
                    self._send(msg)
            else:
                node = destination(can_id, data)
                while True:
                    with self.send_lock:
                        wait = self._wait(node, self.clock())
                        if wait <= 0:
                            self._send(msg)
                            now = self._last_send = self.clock()
                            for n in (self._last_to if node is None else (node,)):
                                self._last_to[n] = now
                                self._answered[n] = False
                            break
                    # outside the lock: frames to other drives go meanwhile (per-drive)
                    self.sleep(wait)
            if self.notifier is not None and self.notifier.exception is not None:
                self.check()  # raises the receive thread's error

        def _send(self, msg: can.Message) -> None:
            assert self.bus is not None  # checked by send_message
            try:
                self.bus.send(msg)
            except can.CanOperationError as exc:
                self._resend(msg, exc)
            except OSError as exc:  # the connection went away (BrokenPipeError, ENETDOWN, ...)
                if self.lost is None:
                    self.lost = exc
                lost = self.lost_error()
                assert lost is not None
                raise lost from exc

        def _resend(self, msg: can.Message, exc: can.CanOperationError) -> None:
            for attempt in range(1, self.send_attempts + 1):
                if getattr(exc, "error_code", None) != errno.ENOBUFS or attempt == self.send_attempts:
                    raise CommunicationError(f"sending 0x{msg.arbitration_id:03X} failed: {exc}") from exc
                self.sleep(0.001 * attempt)
                assert self.bus is not None  # checked by send_message
                try:
                    self.bus.send(msg)
                    return
                except can.CanOperationError as again:
                    exc = again

    return PacedNetwork


def _brief(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@dataclass
class BusLink:
    """One open bus of the arm."""

    name: str
    config: BusConfig
    bus: can.BusABC
    # a PacedNetwork (canopen.Network); Any until ops/monitor.py's subscribe callbacks take
    # canopen's bytearray (typing it canopen.Network flags them)
    network: Any

    def describe(self) -> str:
        return f"bus {self.name} ({self.config.interface or 'python-can config'}:{self.config.channel or '-'})"


def open_bus(cfg: BusConfig) -> can.BusABC:
    import can

    kwargs = bus_kwargs(cfg)
    where = f"bus {cfg.name} ({kwargs.get('interface', 'python-can config')}:{kwargs.get('channel', '-')})"
    try:
        return can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError, TypeError) as exc:
        raise CommunicationError(f"{where}: cannot open: {exc}",
                                 hint="check the adapter is plugged in and up (ip link), or use --sim") from exc
    except Exception as exc:  # third-party backends raise anything; name the bus, keep the cause
        raise CommunicationError(f"{where}: cannot open: {type(exc).__name__}: {exc}") from exc


def open_links(cfg: ArmConfig, names: Iterable[str] | None = None, *,
               failed: dict[str, CommunicationError] | None = None) -> dict[str, BusLink]:
    """Open the named buses (default: all); on failure, close what was opened and raise.

    With ``failed`` (best effort, `sherpa stop`): a bus that cannot be opened is recorded there
    with its error and the others are opened anyway; only an interrupt still closes everything."""
    links: dict[str, BusLink] = {}
    network_cls = _paced_network_class()
    in_hand: Callable[[], Any] | None = None  # closes a bus opened but not yet in links (a signal can land there)
    try:
        for name in names if names is not None else cfg.buses:
            bus_cfg = cfg.buses[name]
            if failed is not None:
                try:
                    bus = open_bus(bus_cfg)
                except CommunicationError as exc:
                    failed[name] = exc
                    continue
            else:
                bus = open_bus(bus_cfg)
            in_hand = bus.shutdown
            network = network_cls(bus)
            in_hand = network.disconnect  # its notifier too, once connected, then the bus
            network.gap = bus_cfg.send_interval_us / 1e6
            network.pacing = cfg.protocol.pacing
            network.floor = cfg.protocol.pacing_floor_us / 1e6
            network.sdo_timeout = cfg.protocol.sdo_timeout
            network.where = f"bus {name} ({bus_cfg.interface or 'python-can config'}:{bus_cfg.channel or '-'})"
            network.caller_reads = cfg.protocol.caller_reads
            network.connect()
            links[name] = BusLink(name, bus_cfg, bus, network)
            in_hand = None
    except BaseException:
        close_links(links)
        if in_hand is not None:
            with contextlib.suppress(Exception):  # closing must not hide the error that made us close
                in_hand()
        raise
    return links


def close_links(links: Mapping[str, BusLink]) -> None:
    """Close every bus; the receive threads of all buses wind down together.

    First every network's notifier is told to stop without waiting (``Notifier.stop(timeout=0)``:
    it flags its threads and joins none), so each receive thread ends at its next wake-up, all
    at the same time; then each network disconnects (its own ``notifier.stop`` now finds the
    thread ending or gone) and shuts its bus down. One receive cycle for the session, not one
    per bus in turn.
    """
    with signals_held():  # a signal half-way would leave a bus open (bus/held_signals.py)
        _close_links(links)


def _close_links(links: Mapping[str, BusLink]) -> None:
    for link in links.values():
        notifier = getattr(link.network, "notifier", None)
        if notifier is not None:
            with contextlib.suppress(Exception):  # closing must not hide the error that made us close
                notifier.stop(timeout=0)
    for link in links.values():
        with contextlib.suppress(Exception):  # closing must not hide the error that made us close
            link.network.disconnect()
