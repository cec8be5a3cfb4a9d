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
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from sherpa_cli.elmo.protocol import HEARTBEAT_BASE

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
