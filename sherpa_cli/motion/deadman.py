"""The dead-man: the drive objects the guard arms (heartbeat consumer, error behaviour, loss action).

The consumer entry 0x1016:1 watches the host's heartbeat (``0x700 + host id``); when it stops for
``consumer_time_ms`` the drive applies 0x1029:1 / 0x6007 and switches its motor off on its own.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from sherpa_cli.elmo.protocol import COMM_ERROR, CONSUMER, HEARTBEAT_BASE, LOSS_ACTION, NMT_OPERATIONAL

__all__ = ["COMM_ERROR", "CONSUMER", "HEARTBEAT_BASE", "LOSS_ACTION", "NMT_OPERATIONAL", "OBJECT_NAMES", "SIZES",
           "HostHeartbeat", "raise_priority"]

log = logging.getLogger(__name__)

SIZES = {CONSUMER: "<I", COMM_ERROR: "<B", LOSS_ACTION: "<h"}
OBJECT_NAMES = {CONSUMER: "consumer heartbeat time", COMM_ERROR: "error behaviour",
                LOSS_ACTION: "abort connection option code"}


class Sender(Protocol):
    """Where a heartbeat frame goes: a bus's canopen.Network (``send_message``)."""

    def send_message(self, can_id: int, data: bytes) -> None: ...


RT_PRIORITY = 10  # SCHED_FIFO priority of the heartbeat thread: above every normal thread, low among RT ones


def raise_priority(priority: int = RT_PRIORITY) -> str:
    """Real-time (SCHED_FIFO) priority for the calling thread where the OS permits it (Linux, as root,
    with CAP_SYS_NICE or an rtprio limit), so its heartbeats keep their period on a loaded host; the
    thread sleeps between frames, so it never holds a CPU. What it got: ``"SCHED_FIFO 10"`` or
    ``"normal (why)"``."""
    setter = getattr(os, "sched_setscheduler", None)
    if setter is None or not hasattr(os, "SCHED_FIFO"):
        return "normal (no real-time scheduling on this system)"
    try:
        setter(0, os.SCHED_FIFO, os.sched_param(priority))  # 0: the calling thread (Linux)
    except OSError as exc:
        return f"normal (real-time priority not permitted: {exc.strerror or exc})"
    return f"SCHED_FIFO {priority}"


class HostHeartbeat:
    """The host heartbeat (``0x700 + host id``, state Operational) from a thread of this process.

    Why a Python thread and not python-can's ``send_periodic``: on SocketCAN that is the kernel's
    broadcast manager, which keeps sending while this process hangs (until the socket is released at
    exit) -- the drive would never notice a hung tool. This thread sends only while the command shows
    signs of life (:meth:`pulse`) and the main thread runs; SIGKILL ends it with the process, and the
    drive's own consumer switches the motor off ``consumer_time_ms`` later.
    """

    def __init__(self, networks: Callable[[], Sequence[Sender]], host_node_id: int, period: float,
                 first_allowance: float, *, realtime: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._networks = networks
        self._clock = clock
        self.held_up = 0.0  # s this thread woke late beyond a period (a loaded machine held it up)
        self.realtime = realtime  # ask for SCHED_FIFO for the sending thread (motion.heartbeat_realtime)
        self.priority = "normal"  # what the thread got (raise_priority), once it runs
        self.frame_id = HEARTBEAT_BASE + host_node_id
        self.period = period
        self._stop = threading.Event()
        self.thread: threading.Thread | None = None
        self.error: BaseException | None = None  # the send that failed (a dead bus)
        self.given_up: str | None = None  # why the thread stopped sending on its own
        self._alive_until = clock() + first_allowance
        self._alive_lock = threading.Lock()
        self.sent = 0

    def use_host(self, host_id: int) -> None:
        """Send as ``host_id`` (the command's own dead-man id); before :meth:`start`."""
        self.frame_id = HEARTBEAT_BASE + host_id

    def pulse(self, allowance: float, *, extend: bool = False) -> None:
        """A sign of life: keep sending for ``allowance`` s from now; ``extend`` never shortens an
        earlier, longer allowance."""
        with self._alive_lock:
            until = self._clock() + allowance
            self._alive_until = max(self._alive_until, until) if extend else until

    def _allow_held_up(self, late: float) -> None:
        """This thread woke ``late`` s after its period. Beyond a period, the machine held it up (a
        loaded host, the whole process descheduled), and the command's thread no less: that time is
        no sign of a hung command, so its allowance gets it back. A command that hangs while the
        machine runs it gets none, and its heartbeat still stops after the allowance."""
        if late > self.period:
            self.held_up += late
            with self._alive_lock:
                self._alive_until += late

    def beat_now(self) -> None:
        """One heartbeat at once after arming: a drive's consumer starts watching on the first
        heartbeat after its 0x1016 entry (CiA 301), so it must come before any MO=1, not a period later."""
        for network in self._networks():
            network.send_message(self.frame_id, bytes([NMT_OPERATIONAL]))
        self.sent += 1

    def start(self) -> None:
        networks = list(self._networks())
        main = threading.main_thread()

        started = threading.Event()

        def loop() -> None:
            if self.realtime:
                self.priority = raise_priority()
            started.set()
            due = self._clock()
            while True:
                self._allow_held_up(self._clock() - due)
                with self._alive_lock:
                    alive_until = self._alive_until
                if not main.is_alive():
                    self.given_up = "the command's main thread ended"
                    return
                if self._clock() > alive_until:
                    self.given_up = "the command showed no sign of life (hung?)"
                    log.warning("motion guard: %s; heartbeat stopped, drives stop on their own", self.given_up)
                    return
                try:
                    for network in networks:
                        network.send_message(self.frame_id, bytes([NMT_OPERATIONAL]))
                    self.sent += 1
                except BaseException as exc:  # noqa: BLE001 - a dead bus: recorded for check(); the drives' consumers will stop them
                    self.error = exc
                    return
                due = self._clock() + self.period
                if self._stop.wait(self.period):
                    return

        self.thread = threading.Thread(target=loop, name="sherpa-deadman", daemon=True)
        self.thread.start()
        started.wait(1.0)  # its priority is known before the first motor goes on

    def stop(self) -> None:
        self._stop.set()
        if self.thread is not None:
            self.thread.join(timeout=5)
