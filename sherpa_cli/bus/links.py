"""Open the configured buses: a python-can bus and a paced canopen Network for each."""

from __future__ import annotations

import contextlib
import errno
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.busmap import bus_kwargs
from sherpa_cli.config.model import ArmConfig, BusConfig
from sherpa_cli.errors import CommunicationError

if TYPE_CHECKING:
    import can


def _paced_network_class():
    import can
    import canopen

    class PacedNetwork(canopen.Network):
        """canopen.Network that keeps the bus's send gap and retries a full socket buffer.

        Overriding send_message is canopen's documented seam; every SDO, NMT and interpreter
        frame of this tool goes through it.
        """

        #: canopen's receive thread wakes this often to see whether it must stop (canopen's
        #: documented class attribute; its default is 1 s). Closing a session waits for it once
        #: for all buses together (close_links), so a short cycle makes closing cost milliseconds;
        #: an idle wake-up is one empty queue/socket read.
        NOTIFIER_CYCLE = 0.02
        #: seconds between two frames sent by this tool on the bus (config: send_interval_us)
        gap: float = 0.0
        #: attempts when the kernel's socket buffer is full (ENOBUFS, python-can issue #2004)
        send_attempts: int = 5
        clock: Callable[[], float] = staticmethod(time.monotonic)
        sleep: Callable[[float], None] = staticmethod(time.sleep)

        def __init__(self, bus: can.BusABC | None = None) -> None:
            super().__init__(bus)
            self._last_send = float("-inf")

        def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
            if not self.bus:
                raise CommunicationError("bus is closed")
            msg = can.Message(is_extended_id=can_id > 0x7FF, arbitration_id=can_id, data=data,
                              is_remote_frame=remote)
            gap = self.gap
            with self.send_lock:
                if gap:  # unpaced (gap 0) skips the clock: every interpreter round trip passes here
                    wait = self._last_send + gap - self.clock()
                    if wait > 0:
                        self.sleep(wait)
                try:
                    self.bus.send(msg)
                except can.CanOperationError as exc:
                    self._resend(msg, exc)
                if gap:
                    self._last_send = self.clock()
            if self.notifier is not None and self.notifier.exception is not None:
                self.check()  # raises the receive thread's error

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
            network.sdo_timeout = cfg.protocol.sdo_timeout
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
    for link in links.values():
        notifier = getattr(link.network, "notifier", None)
        if notifier is not None:
            with contextlib.suppress(Exception):  # closing must not hide the error that made us close
                notifier.stop(timeout=0)
    for link in links.values():
        with contextlib.suppress(Exception):  # closing must not hide the error that made us close
            link.network.disconnect()
