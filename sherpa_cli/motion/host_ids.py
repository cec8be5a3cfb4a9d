"""Listening to the dead-man host ids before taking one, and while it is used.

A drive armed by a command watches ``0x700 + host id``; any node that sends that heartbeat keeps the
drive's motor on. So a command takes an id only after listening on every bus it will move for
:attr:`MotionSettings.host_id_listen` -- longer than any drive armed on an id waits for its
heartbeat, so a drive still watching the id of a command killed a moment ago has tripped before the
new command sends it -- and only an id nobody was heard sending. While the command runs, more
heartbeats on its own id than it sent itself mean another node sends as that id: the command stops.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from sherpa_cli.elmo.protocol import HEARTBEAT_BASE
from sherpa_cli.errors import SherpaError

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef

log = logging.getLogger(__name__)

# heartbeats on the command's own id beyond those it sent that are still taken for its own echo (an
# interface that loops frames back, a frame received before its send was counted)
ECHO_SLACK = 2


class HostIdListener:
    """Counts the heartbeats heard on every id of the pool, per bus, from the receive threads."""

    def __init__(self, networks: Mapping[str, Any], ids: Iterable[int]) -> None:
        self._networks = dict(networks)  # bus name -> canopen.Network (subscribe / unsubscribe)
        self.ids = tuple(ids)
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, int], int] = {}
        self._subs: list[tuple[Any, int, Callable[..., None]]] = []

    def start(self) -> None:
        for bus, network in self._networks.items():
            for host_id in self.ids:
                def on_beat(can_id: int, data: bytearray, timestamp: float, key: tuple[str, int] = (bus, host_id)) -> None:
                    with self._lock:
                        self._counts[key] = self._counts.get(key, 0) + 1

                network.subscribe(HEARTBEAT_BASE + host_id, on_beat)
                self._subs.append((network, HEARTBEAT_BASE + host_id, on_beat))

    def stop(self) -> None:
        subs, self._subs = self._subs, []
        for network, can_id, cb in subs:
            with contextlib.suppress(Exception):  # a closed network: nothing left to undo
                network.unsubscribe(can_id, cb)

    def count(self, bus: str, host_id: int) -> int:
        with self._lock:
            return self._counts.get((bus, host_id), 0)

    def heard(self) -> dict[str, set[int]]:
        """Per bus, the ids some node sent a heartbeat as since :meth:`start`."""
        out: dict[str, set[int]] = {}
        with self._lock:
            for (bus, host_id), n in self._counts.items():
                if n:
                    out.setdefault(bus, set()).add(host_id)
        return out

    def foreign(self, host_id: int, sent: int) -> list[str]:
        """The buses on which more heartbeats of ``host_id`` came than this command sent (``sent``)."""
        with self._lock:
            return sorted(bus for (bus, hid), n in self._counts.items()
                          if hid == host_id and n > sent + ECHO_SLACK)


def watched_host(entry: int) -> int | None:
    """The node a consumer heartbeat entry (0x1016:n) watches, or None for a disabled entry (time 0)."""
    return (entry >> 16) & 0x7F if entry & 0xFFFF else None


class OtherConsumers:
    """The dead-man entries (0x1016:1) of the drives on a command's buses that it does not arm.

    A drive that watches a pool id is kept on by any heartbeat on that id: the entry of a tool that
    armed it and died, or another host's command. So an id one of them watches is not taken (read
    once on entry, during the listening), and while the command runs one of them is read again at
    each dead-man check: a drive that starts watching the command's own id is one its heartbeat
    would keep on, and the command stops. A drive that does not answer on entry (powered off, not
    on the bus) is left out, so it costs one SDO timeout once, not one per check.
    """

    def __init__(self, refs: Sequence[DriveRef], ids: Iterable[int], read: Callable[[DriveRef], int]) -> None:
        self.refs = list(refs)
        self.ids = {i & 0x7F for i in ids}
        self._read = read
        self._by_key = {ref.key: ref for ref in self.refs}
        self.entries: dict[tuple[str, int], int] = {}  # (bus, node) -> the entry last read
        self._turn = 0

    def read_all(self, between: Callable[[], None] = lambda: None) -> None:
        for ref in self.refs:
            between()
            try:
                self.entries[ref.key] = self._read(ref)
            except (SherpaError, ValueError, OSError) as exc:
                log.info("%s (%s): 0x1016:1 not read: %s", ref.name, ref.address, exc)

    def watched(self) -> dict[str, dict[int, list[str]]]:
        """Per bus, the pool ids a drive not armed by the command watches, with the drives' names."""
        out: dict[str, dict[int, list[str]]] = {}
        for key, entry in self.entries.items():
            ref = self._by_key[key]
            host = watched_host(entry)
            if host is not None and host in self.ids:
                out.setdefault(ref.bus, {}).setdefault(host, []).append(ref.name)
        return out

    def check_one(self, host_id: int) -> str | None:
        """Read the next drive's entry again (round robin); a message if it now watches ``host_id``."""
        answered = list(self.entries)
        if not answered:
            return None
        ref = self._by_key[answered[self._turn % len(answered)]]
        self._turn += 1
        try:
            entry = self._read(ref)
        except (SherpaError, ValueError, OSError) as exc:
            log.info("%s (%s): 0x1016:1 not read again: %s", ref.name, ref.address, exc)
            return None
        self.entries[ref.key] = entry
        if watched_host(entry) == host_id & 0x7F:
            return (f"{ref.name} ({ref.address}), a drive this command does not arm, watches its dead-man id "
                    f"{host_id} (0x1016:1 = 0x{entry:08X}): this command's heartbeat would keep that drive's "
                    "motor on; stopping every drive of the command")
        return None
