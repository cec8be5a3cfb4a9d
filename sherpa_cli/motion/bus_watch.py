"""The motion guard's watch of its buses.

While the guard holds its drives, every bus they are on is watched through the two sources of the
bus layer, which the simulated arm's controllers (sim/buscontroller.py) and a real SocketCAN adapter
both feed:

- the bus's error frames (bus/errwatch.py ``watching``): controller warning / passive / back to
  active, bus-off, restarted -- on the receive thread, as they arrive;
- the link's controller state (bus/linkstate.py ``read_link``: netlink for SocketCAN, the simulated
  controller with --sim, python-can's ``state`` where a backend has one), read on the command's
  thread every ``motion.bus_check_interval``: the way to notice it with an adapter that hides error
  frames (python-can #2040) or while no frame arrives. A link whose first reading has no controller
  state (vcan, python-can-remote) is not read again: its error frames are all there is to watch.

A bus that goes BUS-OFF, STOPPED, down or missing cannot carry a frame: the command ends (exit 3,
:class:`BusFaultError` naming the bus, its state and what to check). ERROR-PASSIVE ends it too with
``motion.bus_error_passive: stop`` (the default: on bus-off or error-passive of any
bus it moves on, the motion stops on all buses), or is a warning with ``warn``. Only the
command's own buses are watched: a bus-off on a bus it does not move on leaves it running.

A trip cuts short the request the command waits for (as the drive watch does: a bus-off bus answers
nothing). The guard's exit then stops the drives on the buses that still carry frames first, waits a
bounded time for a dead bus to come back on its own (the controller's restart-ms), and reports the
drives of a bus whose link still reads dead as not reached: their heartbeat consumers switch them
off, since no host heartbeat reaches them. Where only an error frame said so (an interface that
reports no controller state, such as vcan), its drives get one plain request first, as a silent
drive does, and are stopped as usual if they answer. Nothing here sends a frame.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.bus.errwatch import BusWatch, SeenError, watching
from sherpa_cli.bus.health import BusStateError, findings
from sherpa_cli.bus.linkstate import ACTIVE, BUS_OFF, DOWN, MISSING, PASSIVE, STOPPED, WARNING, LinkStatus, read_link
from sherpa_cli.config.model import BUS_ERROR_PASSIVE_ACTIONS as ERROR_PASSIVE_ACTIONS
from sherpa_cli.motion.report import BusFault, DriveStop

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.errors import SherpaError
    from sherpa_cli.motion.settings import MotionSettings

log = logging.getLogger(__name__)

DEAD_STATES = (BUS_OFF, STOPPED, DOWN, MISSING)  # no frame passes: its drives cannot be reached
# what an error frame says about the controller's state, most severe first (a frame may name several)
FRAME_STATES = (("bus-off", BUS_OFF), ("passive", PASSIVE), ("warning", WARNING), ("restarted", ACTIVE),
                ("active", ACTIVE))
MAX_FAULTS = 20  # kept for the report: a bus flapping between states is not a growing list
STOPPED_THE_COMMAND, ALSO_SEEN, WARNED = ("stopped the command", "seen while the command stopped",
                                          "warned (motion.bus_error_passive: warn)")

FrameHook = Callable[[Callable[[SeenError], None]], AbstractContextManager[BusWatch]]


class BusFaultError(BusStateError):
    """A bus the command moves on went BUS-OFF (or stopped, down, missing; ERROR-PASSIVE with
    ``motion.bus_error_passive: stop``) during the motion: every drive was stopped (exit 3)."""


@dataclass
class _Bus:
    name: str
    where: str  # "socketcan:can1"
    state: str | None = None  # the last state known (None: the interface reports none)
    tec: int | None = None
    rec: int | None = None
    restart_ms: int | None = None
    gave_up: bool = False  # the exit waited for it to come back, in vain
    reads_state: bool = False  # its link reports a controller state (else only its error frames tell)
    # up, and no controller state to report (vcan, python-can-remote): not read again while moving --
    # a reading would say nothing, and netlink parsing costs the command's thread (a slow guest)
    stateless: bool = False


@dataclass
class _Hooked:
    manager: AbstractContextManager[BusWatch] | None = None
    collector: BusWatch | None = None
    error_frames: int = 0


def link_state(status: LinkStatus) -> str | None:
    """The controller state a reading says (missing, down or a CAN state), None when it says none."""
    if status.error is not None:
        return None
    if status.present is False:
        return MISSING
    if status.up is False:
        return DOWN
    return status.can_state


def frame_state(seen: SeenError) -> str | None:
    """The controller state an error frame reports, None for a frame that reports no state change."""
    for kind, state in FRAME_STATES:
        if kind in seen.frame.kinds:
            return state
    return None


class GuardBusWatch:
    """Watch the buses of one motion guard (see the module docstring). ``read(bus)``: one reading
    of a bus's link; ``frames(on_error)``: a context manager that calls ``on_error`` with each error
    frame of the buses (None: link readings only; tests call :meth:`feed`)."""

    def __init__(self, buses: Iterable[str], *, read: Callable[[str], LinkStatus], frames: FrameHook | None = None,
                 where: Mapping[str, str] | None = None, error_passive: str = "stop", interval: float = 0.1,
                 now: Callable[[], float] = time.monotonic, on_trip: Callable[[SherpaError], None] | None = None,
                 on_event: Callable[[str], None] | None = None) -> None:
        if error_passive not in ERROR_PASSIVE_ACTIONS:
            raise ValueError(f"bus_error_passive {error_passive!r}: expected one of {', '.join(ERROR_PASSIVE_ACTIONS)}")
        self._buses = {b: _Bus(b, (where or {}).get(b, b)) for b in sorted(set(buses))}
        self._read = read
        self._frames = frames
        self.error_passive = error_passive
        self.interval = interval
        self._now = now
        self._on_trip = on_trip
        self._on_event = on_event
        self._lock = threading.Lock()
        self._active = False
        self._next_read = 0.0
        self._hooked = _Hooked()
        self.error: BusFaultError | None = None  # the reason to stop, once found
        self.faults: list[BusFault] = []  # every fault seen while watching (the guard's report)

    @classmethod
    def for_session(cls, session: ArmSession, buses: Iterable[str], settings: MotionSettings, *,
                    now: Callable[[], float] = time.monotonic, on_trip: Callable[[SherpaError], None] | None = None,
                    on_event: Callable[[str], None] | None = None) -> GuardBusWatch:
        """The watch of ``buses`` of an open session: ``read_link`` and the receive threads' error frames."""
        names = sorted(set(buses))
        # named like the preflight names it: with --sim the configured adapter, not the virtual channel
        sim_cfg = getattr(getattr(session, "sim", None), "cfg", None)
        cfg = (sim_cfg or session.cfg).buses
        where = {b: f"{cfg[b].interface or 'python-can config'}:{cfg[b].channel or '-'}" for b in names if b in cfg}

        def frames(on_error: Callable[[SeenError], None]) -> AbstractContextManager[BusWatch]:
            return watching(session, names, on_error=on_error)

        return cls(names, read=lambda bus: read_link(session, bus), frames=frames, where=where,
                   error_passive=settings.bus_error_passive, interval=settings.bus_check_interval, now=now,
                   on_trip=on_trip, on_event=on_event)

    # -- set-up -----------------------------------------------------------------------------------

    def start(self) -> None:
        """Listen to the error frames, read every bus once, and trip from now on. Never raises for a
        bus it cannot read (that bus is then watched through its error frames only)."""
        with self._lock:
            self._active = True
            for b in self._buses.values():  # what was noted before counts as news: a dead bus trips now
                b.state = None
        if self._frames is not None and self._hooked.manager is None:
            try:
                manager = self._frames(self.feed)
                self._hooked.collector = manager.__enter__()
                self._hooked.manager = manager
            except Exception as exc:  # noqa: BLE001 - the link readings still watch the bus
                log.warning("bus watch: the error frames cannot be listened to (%s); the link state is still read", exc)
        self._read_all(first=True)

    def stop(self) -> None:
        """No more trips (the guard's exit begins); the error frames are still listened to until
        :meth:`close`, so the exit learns when a dead bus comes back."""
        with self._lock:
            self._active = False

    def close(self) -> None:
        self.stop()
        manager, self._hooked.manager = self._hooked.manager, None
        if manager is not None:
            try:
                manager.__exit__(None, None, None)
            except Exception as exc:  # noqa: BLE001 - a closed bus: nothing left to unhook
                log.debug("bus watch: unhook: %s", exc)

    @property
    def error_frames(self) -> int:
        """Error frames of the watched buses drained so far (each was acted on as it arrived)."""
        return self._hooked.error_frames

    # -- the command's thread ---------------------------------------------------------------------

    def poll(self) -> BusFaultError | None:
        """The reason to stop, if any: a trip by an error frame, or a link reading (every ``interval``)."""
        collector = self._hooked.collector
        if collector is not None:
            self._hooked.error_frames += len(collector.drain())  # already acted on: keep no list
        if self.error is None and self._now() >= self._next_read:
            self._read_all()
        return self.error

    def dead(self) -> set[str]:
        """The command's buses that cannot carry a frame now: seen dead, and not back in a fresh reading."""
        out: set[str] = set()
        for b in list(self._buses.values()):
            if b.state in DEAD_STATES:
                self._read_one(b.name)
                if b.state in DEAD_STATES:
                    out.add(b.name)
        return out

    def back(self, bus: str, *, sleep: Callable[[float], None], pulse: Callable[[], None], max_wait: float) -> bool:
        """Whether a bus seen dead carries frames again, waiting for the controller's own restart
        (its restart-ms, where known; at most ``max_wait`` s) first. Waited for once per bus."""
        b = self._buses[bus]
        if b.gave_up:
            return False
        wait = min(max_wait, b.restart_ms / 1000 + 2 * self.interval) if b.restart_ms else 0.0
        deadline = self._now() + wait
        while True:
            self._read_one(bus)
            if b.state not in DEAD_STATES:
                self._event(f"bus {bus}: back ({b.state or 'state not reported'}): its drives are stopped as usual")
                return True
            if self._now() >= deadline:
                b.gave_up = True
                return False
            pulse()
            sleep(min(self.interval, max(deadline - self._now(), 0.0)))

    def confirmed_dead(self, bus: str) -> bool:
        """Whether the bus's own link says it is dead (else only an error frame said so, and one
        request to a drive on it tells: the guard's exit of a silent drive)."""
        b = self._buses[bus]
        return b.reads_state and b.state in DEAD_STATES

    def unreached(self, name: str, address: str, bus: str, consumer_time_ms: int, *, motor_on: bool = True) -> DriveStop:
        """The report of a drive on a bus that stayed dead: nothing could be sent to it."""
        state = self._buses[bus].state or "dead"
        r = DriveStop(name, address, stopped_by="not reached")
        how = (f"not confirmed stopped; its heartbeat consumer switches the motor off {consumer_time_ms} ms after "
               "the last host heartbeat it heard" if motor_on else "its motor was off")
        r.problems.append(f"bus {bus} is {state}: no frame reaches the drive, {how}; `sherpa recover {name} --apply` "
                          "puts its settings back once the bus is up")
        r.kept.extend(f"{obj} (bus {state})" for obj in ("0x1016:1", "0x1029:1", "0x6007:0"))
        return r

    # -- what was seen (either thread) ------------------------------------------------------------

    def feed(self, seen: SeenError) -> None:
        """One error frame (the receive thread; tests call it directly)."""
        state = frame_state(seen)
        if state is not None and seen.bus in self._buses:
            self._note(seen.bus, state, "an error frame", seen.frame.tec, seen.frame.rec)

    def _read_all(self, *, first: bool = False) -> None:
        self._next_read = self._now() + self.interval
        for bus, b in self._buses.items():
            if first or not b.stateless:
                self._read_one(bus, first=first)

    def _read_one(self, bus: str, *, first: bool = False) -> None:
        try:
            status = self._read(bus)
        except Exception as exc:  # noqa: BLE001 - an unreadable link is no verdict: the error frames still count
            log.debug("bus watch: reading %s: %s", bus, exc)
            return
        if status.restart_ms is not None:
            self._buses[bus].restart_ms = status.restart_ms
        state = link_state(status)
        self._buses[bus].reads_state = state is not None
        if first:
            self._buses[bus].stateless = state is None
        if state is not None:
            self._note(bus, state, "the link state", status.tec, status.rec)

    def _note(self, bus: str, state: str, seen_in: str, tec: int | None, rec: int | None) -> None:
        stop = state in DEAD_STATES or (state == PASSIVE and self.error_passive == "stop")
        trip: BusFaultError | None = None
        text: str | None = None
        with self._lock:
            b = self._buses[bus]
            before = b.state
            b.state = state
            if tec is not None:
                b.tec, b.rec = tec, rec
            if state == before or not self._active:
                return
            if stop or state == PASSIVE:
                action = WARNED if not stop else STOPPED_THE_COMMAND if self.error is None else ALSO_SEEN
                fault = BusFault(bus, state, seen_in, action, b.tec, b.rec)
                if len(self.faults) < MAX_FAULTS:
                    self.faults.append(fault)
                text = fault.line()
                if stop and self.error is None:
                    trip = self.error = self._error(b, state, seen_in)
                    if self._on_trip is not None:  # under the lock: never once the exit has begun (stop())
                        self._on_trip(trip)
            elif before in DEAD_STATES or before == PASSIVE:
                text = f"bus {bus}: back to {state} ({seen_in})"
        if text is not None:
            # a warning only where the motion goes on: a trip is said by the error and the stop report
            (log.warning if trip is None and state == PASSIVE else log.info)("bus watch: %s", text)
            self._event(text)

    def _error(self, b: _Bus, state: str, seen_in: str) -> BusFaultError:
        counters = f"TEC {b.tec}, REC {b.rec}; " if b.tec is not None else ""
        status = LinkStatus(b.name, None, None, "watch", present=state != MISSING, up=state != DOWN,
                            can_state=state if state not in (MISSING, DOWN) else None, tec=b.tec, rec=b.rec)
        found = findings(status)
        hint = found[0].hint if found else None
        if state == PASSIVE:
            hint = (hint or "") + "; motion.bus_error_passive: warn lets a motion go on on an error-passive bus"
        return BusFaultError(f"bus {b.name} ({b.where}): went {state} during the motion ({counters}seen in {seen_in}): "
                             "stopping every drive of the command, those on the other buses first",
                             bus=b.name, problem=found[0].problem if found else state.lower(), hint=hint)

    def _event(self, text: str) -> None:
        if self._on_event is not None:
            self._on_event(text)

