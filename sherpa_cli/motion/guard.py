"""The motion guard: the one place every command that moves a motor runs inside (docs/motion.md).

``with MotionGuard(session, refs, settings=...) as guard:``

- on entry: NMT start, read MO, UM, SR and MF of every drive and refuse a drive in fault with the
  decoded reason; arm the dead-man (heartbeat consumer 0x1016:1, 0x1029:1, 0x6007 in RAM) and start
  the host heartbeat from this process's own thread; SIGTERM and SIGHUP become a stop.
- the body moves the motors through :meth:`MotionGuard.enable` and :meth:`MotionGuard.client`, and
  calls :meth:`MotionGuard.check` in its loops (a sign of life for the heartbeat thread, and the
  place a signal or a failed heartbeat turns into an exception).
- on every exit (normal end, error, Ctrl-C, SIGTERM, SIGHUP): stop every drive (ST, or JV=0 + BG
  where ST is refused), wait for standstill (bounded), MO=0 where the guard switched the motor on,
  put back UM and the dead-man objects it changed, stop the heartbeat. :attr:`MotionGuard.report`
  names every drive, how it was stopped and what was restored.

The pieces live beside it: the dead-man objects and the host heartbeat thread (deadman.py, and why
that is a thread of this process), the per-drive lock (lock.py), the stop path (stopping.py), the
report (report.py).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import struct
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any, Literal

from sherpa_cli.bus import journal
from sherpa_cli.bus.health import preflight
from sherpa_cli.bus.machine_lock import wire_key
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.devices.drives import ELMO, is_elmo, open_drive
from sherpa_cli.devices.ft_sensor import open_reader
from sherpa_cli.drive import Drive, Mode, ModeObject, ObjectValue, Ramp, RampObjects
from sherpa_cli.elmo.drive import UNIT_MODES, mode_of
from sherpa_cli.elmo.faults import decode_sr, describe_mf, fault_reason
from sherpa_cli.elmo.protocol import UM_TORQUE
from sherpa_cli.errors import (
    CommunicationError,
    ExitCode,
    SafetyError,
    SdoError,
    SherpaError,
    UsageError,
    raise_if_signalled,
)
from sherpa_cli.motion.bus_watch import GuardBusWatch
from sherpa_cli.motion.deadman import COMM_ERROR, CONSUMER, LOSS_ACTION, OBJECT_NAMES, SIZES, HostHeartbeat
from sherpa_cli.motion.drive_watch import DriveWatch, DriveWatchError
from sherpa_cli.motion.force_watch import ForceLimitError, ForceWatch, SensorSilentError, tightened
from sherpa_cli.motion.host_ids import HostIdListener, OtherConsumers
from sherpa_cli.motion.lock import DriveLock, HostIdLock, drive_label
from sherpa_cli.motion.report import NOT_MOVED, RESET_DURING_STOP, DriveStop, GuardReport
from sherpa_cli.motion.settings import PROFILE_KEYS, MotionSettings
from sherpa_cli.motion.stopping import ask_patiently, stop_drive, stop_other, why
from sherpa_cli.motion.trip_clear import clear_heartbeat_trip

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient

log = logging.getLogger(__name__)

# an F/T sensor unanswered this many requests in a row is silent: the force limit cannot be watched
FORCE_SILENT_CHECKS = 5
MS_PROFILER_ACTIVE = 2
JOURNAL_OWNER = "motion command"
# the journal's owner of what a pair start inside the guard changes (motion/pair_start.py), which the
# guard's exit puts back if the start's own close could not
PAIR_START_OWNER = "pair start"


def _size(key: tuple[int, int]) -> int:
    return struct.calcsize(SIZES[key])


class MotionStopped(SherpaError):
    """A stop was requested by a signal (SIGTERM, SIGHUP) while motion ran; exit 130 like Ctrl-C."""

    exit_code = ExitCode.INTERRUPTED


class DeadManError(CommunicationError):
    """The host heartbeat could not be sent; the drives stop on their own (exit 3)."""


@dataclass
class _Drive:
    """The guard's record of one drive: what it found and what it changed."""

    ref: DriveRef
    client: DriveClient  # NMT, label, silence; the interpreter's letters only for an Elmo drive
    drive: Drive  # the drive seam: every other drive type moves through it alone
    mo: int = 0
    um: int = 0
    switched_on: bool = False
    um_changed_from: int | None = None
    profile_before: dict[str, int] = field(default_factory=dict)  # SP/AC/DC found at entry
    put_back: set[str] = field(default_factory=set)  # journal step names put back (or never changed)
    od_before: dict[tuple[int, int], int] = field(default_factory=dict)  # the dead-man objects it wrote
    mode: Mode | None = None  # another drive type: the mode found, then the one it was switched on in
    ramp_before: Ramp | None = None  # another drive type: the profile found at entry
    ramp_journal: set[str] = field(default_factory=set)  # its journal step names (RampObjects)
    mode_found: ObjectValue | None = None  # another drive type: the mode object found at entry (ModeObject)
    enabled_as: Mode | None = None  # another drive type: the mode this guard enabled it in

    @property
    def native(self) -> bool:
        """An Elmo drive: the guard speaks its interpreter (journaled UM/SP/AC/DC, ST/JV stop)."""
        return self.drive.kind == ELMO


class MotionGuard:
    """Context manager around anything that moves motors (see the module docstring)."""

    def __init__(self, session: ArmSession, refs: Sequence[DriveRef], *, settings: MotionSettings,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 keep: bool = False, on_event: Callable[[str], None] | None = None,
                 clears_fault: bool = False) -> None:
        seen: set[tuple[str, int]] = set()
        self.refs: list[DriveRef] = []
        for ref in refs:
            if (ref.bus, ref.node) not in seen:
                seen.add((ref.bus, ref.node))
                self.refs.append(ref)
        for ref in self.refs:
            if ref.node in settings.host_ids:
                raise UsageError(f"{drive_label(ref)}: its node id is a host heartbeat id "
                                 f"(motion.host_node_id / host_id_pool: {', '.join(map(str, settings.host_ids))}); "
                                 "choose other host ids")
        self.session = session
        self.settings = settings
        self.keep = keep
        self.clears_fault = clears_fault  # `cmd DRIVE MO=1 MO=0`: MO=1 to clear MF, no motion; not refused
        self._clock = clock
        self._sleep = sleep
        self._on_event = on_event
        self._drives: dict[tuple[str, int], _Drive] = {}
        self._released: dict[tuple[str, int], DriveStop] = {}  # handed over (release) and not taken back
        self._locks: dict[tuple[str, int], DriveLock] = {}  # the motion locks this guard holds
        self.report = GuardReport()
        # dead-man loop
        buses = sorted({ref.bus for ref in self.refs})
        self._heartbeat = HostHeartbeat(lambda: [session.links[b].network for b in buses], settings.host_node_id,
                                        settings.heartbeat_period, settings.liveness_timeout,
                                        realtime=settings.heartbeat_realtime)
        # the dead-man id of this command alone, taken on entry after listening (motion/host_ids.py,
        # motion/lock.py HostIdLock)
        self._host_lock = HostIdLock({b: wire_key(session.links[b].config.interface, session.links[b].config.channel)
                                      for b in buses}, settings.host_ids)
        self._host_ids = HostIdListener({b: session.links[b].network for b in buses}, settings.host_ids)
        mine = {ref.key for ref in self.refs}
        self._others = OtherConsumers([r for r in drive_refs(session.cfg, None) if r.bus in buses and r.key not in mine],
                                      settings.host_ids, lambda r: self._read_consumer(r))
        self.host_id = settings.host_node_id
        # the watch of the drives: error EMCYs, NMT commands of other nodes, the drives' heartbeats
        self._watch = DriveWatch(lambda bus: session.links[bus].network, warning_codes=settings.emcy_warning_codes,
                                 answered_codes=settings.emcy_answered_codes, min_silence=3 * settings.poll_interval)
        # the watch of the buses: bus-off / error-passive of a bus the command moves on (motion/bus_watch.py)
        self._bus = GuardBusWatch.for_session(session, buses, settings, now=clock, on_trip=self._abort_requests,
                                              on_event=self._event)
        self._next_deadman_check = 0.0
        # signals
        self._signal: str | None = None
        self._exiting = False
        self._late_signal: int | None = None  # arrived while stopping: delivered once everything is back
        self._old_handlers: dict[int, Any] = {}
        # requests the command's own thread sends are signs of life (ArmSession.watch_requests)
        self._owner: int | None = None
        self._unwatch_requests: Callable[[], None] | None = None
        self._exit_of: _Drive | None = None  # the drive whose exit runs now (_exit_drive)
        self._forces: list[tuple[ForceWatch, float]] = []  # the F/T sensors watched and their reply waits
        self._force_readers = contextlib.ExitStack()
        self._next_force_check = 0.0
        self._exit_boots = 0

    # -- public API -------------------------------------------------------------------------------

    def __enter__(self) -> MotionGuard:
        raise_if_signalled()  # a SIGTERM whose exception was lost before the guard (errors.py): no motion
        try:
            self._install_signals()
            self._watch_requests()
            for ref in self.refs:  # first, before anything is sent: a second command refuses here
                self._lock(ref)
            listen_until = self._clock() + self.settings.host_id_listen_for(self._host_lock.private)
            self._host_ids.start()  # listening to the pool's ids while the drives are read
            preflight(self.session, self.refs)  # bus state and bit rate, user programs (bus/health.py)
            self._pulse(extra=self._setup_bound())
            for ref in self.refs:
                self._leftovers(ref)
            for ref in self.refs:
                self._inspect(ref)
            self._others.read_all(between=self._pulse)
            self._watch_forces()
            while (left := listen_until - self._clock()) > 0:
                self._sleep(min(left, 0.05))
                raise_if_signalled()
            # before anything is armed: an id of our own nobody sends
            self.host_id = self._host_lock.acquire(self._host_ids.heard(), self._others.watched())
            self._heartbeat.use_host(self.host_id)
            self._start_heartbeat()
            self._event(f"heartbeat thread: {self._heartbeat.priority}, every {self.settings.heartbeat_period * 1000:g} ms")
            for d in self._drives.values():
                self._arm(d)
            self._beat_now()
            for d in self._drives.values():
                self._watch_drive(d)
            self._watch.start()
            self._bus.start()
            self._next_deadman_check = self._clock() + self.settings.deadman_check_interval
            self._pulse()
        except BaseException:
            self._exiting = True
            blocked = self._block_signals()
            try:
                # nothing was switched on yet: no stop to drives the guard never moved (another
                # host may be moving them), only what was armed is put back
                self._exit_all(reason="error", entering=True)
            finally:
                try:
                    self._unwatch()
                    self._unlock_all()
                    self._restore_signals()
                finally:
                    self._unblock_signals(blocked)
            raise
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> Literal[False]:
        self._exiting = True  # first thing: a signal from now on must not cut the stop short
        blocked = self._block_signals()
        if self._signal is not None:
            reason = self._signal
        elif exc_type is None:
            reason = "end"
        elif issubclass(exc_type, KeyboardInterrupt):
            reason = "interrupted"
        else:
            reason = "error"
        try:
            self._exit_all(reason=reason)
        finally:
            try:
                self._unwatch()
                self._unlock_all()
                self._restore_signals()
            finally:
                self._unblock_signals(blocked)
        problems = [f"{d.drive}: {p}" for d in self.report.drives for p in d.problems]
        if exc_type is None and not problems and self._late_signal is not None:
            # the motion ended by itself and a signal came during its stop: the stop was not cut
            # short, and now the signal is a signal outside the guard (its handler from before,
            # the CLI's 130/143/129), never a silent exit 0
            signal.raise_signal(self._late_signal)
        if exc_type is None and problems:
            raise SafetyError("the stop after the motion did not go cleanly: " + "; ".join(problems),
                              hint="check the drives with `sherpa monitor --once`; `sherpa stop` stops them all")
        return False

    def client(self, ref: DriveRef) -> DriveClient:
        """The interpreter client of an Elmo drive; another drive type is refused by name."""
        d = self._drive(ref)
        if not d.native:
            raise UsageError(f"{d.drive.label} is a {d.drive.kind} drive: this needs an Elmo drive's interpreter",
                             hint="docs/drives.md lists what each drive type supports")
        return d.client

    def drive(self, ref: DriveRef) -> Drive:
        """The drive behind the seam (sherpa_cli/drive.py), whatever its type."""
        return self._drive(ref).drive

    def position(self, ref: DriveRef) -> int:
        """The motor's actual position (counts): PX patiently for an Elmo drive (:meth:`query`)."""
        d = self._drive(ref)
        if d.native:
            return int(self.query(ref, "PX"))
        self._raise_if_tripped()
        self._pulse()
        try:
            return d.drive.position()
        finally:
            self._pulse()

    def enable(self, ref: DriveRef, unit_mode: int | Mode) -> None:
        """UM=unit_mode only if needed (with MO=0 first), then MO=1 confirmed by reading MO back.
        Another drive type: into the mode, its power stage on, through the seam."""
        self.check()
        d = self._drive(ref)
        if not d.native:
            self._enable_other(d, unit_mode if isinstance(unit_mode, Mode) else mode_of(unit_mode))
            return
        if isinstance(unit_mode, Mode):
            unit_mode = UNIT_MODES[unit_mode]
        c = d.client
        bound = c.settings.mo_confirm_timeout + 2 * self.settings.request_bound
        if d.um != unit_mode:
            if d.mo:
                self._pulse(extra=bound)
                self._event(f"{c.label}: MO=0 to change UM {d.um} -> {unit_mode}")
                c.motor_off()
                d.mo = 0
                self._watch.set_moving(ref.bus, ref.node, False)
            if d.um_changed_from is None:
                d.um_changed_from = d.um  # recorded first: a write that fails half-way is still put back
                journal.note(ref, journal.interp(JOURNAL_OWNER, "UM", 0, d.um))
            c.set("UM", 0, unit_mode)
            d.um = unit_mode
        if not d.mo:
            if unit_mode == UM_TORQUE and c.get("TC") != 0:
                c.set("TC", 0, 0.0)  # MO=1 in UM=1 applies TC at once: never an old torque command
            self._pulse(extra=bound)
            d.switched_on = True  # before the request: a lost confirmation must still end in MO=0
            self._watch.set_moving(ref.bus, ref.node, True)
            c.motor_on()
            d.mo = 1
            self._event(f"{c.label}: motor on (UM={unit_mode})")
        self._pulse()

    def _enable_other(self, d: _Drive, mode: Mode) -> None:
        if d.enabled_as is mode:
            self._pulse()
            return
        # a drive found powered is enabled all the same: the drive learns the mode it moves in (and
        # is taken out of a quick stop); the power-state walk is a few confirmed exchanges, each
        # within the request bound
        self._pulse(extra=8 * self.settings.request_bound + self.session.cfg.protocol.mo_confirm_timeout)
        d.switched_on = True  # before the request: a lost confirmation must still end switched off
        self._watch.set_moving(d.ref.bus, d.ref.node, True)
        d.drive.enable(mode)
        d.mo, d.mode, d.enabled_as = 1, mode, mode
        self._event(f"{d.drive.label}: motor on ({mode.value} mode)")
        self._pulse()

    def check(self) -> None:
        """A sign of life for the heartbeat thread; raises if a signal asked to stop or the dead-man failed."""
        if self._signal is not None:
            raise MotionStopped(f"{self._signal} received: motion stopped")
        bus_error = None if self._exiting else self._bus.poll()
        if bus_error is not None:  # before the heartbeat's: a send that failed on a bus-off bus names the bus
            raise bus_error
        if self._heartbeat.error is not None:
            raise DeadManError(f"host heartbeat failed: {self._heartbeat.error}",
                               hint="the drives stop on their own within the consumer time")
        if self._heartbeat.given_up is not None:
            raise DeadManError(f"host heartbeat stopped: {self._heartbeat.given_up}")
        self._raise_if_tripped()
        self._check_host_id()
        self._pulse()
        if self._clock() >= self._next_deadman_check:
            self._check_deadman()

    def _check_host_id(self) -> None:
        """Another node sends heartbeats as this command's own dead-man id (another host that took it
        at the same moment, a tool that uses it): its heartbeat would keep the drives on after this
        command ends or dies, so the command stops now."""
        if self._exiting:
            return
        buses = self._host_ids.foreign(self.host_id, self._heartbeat.sent)
        if buses:
            raise DriveWatchError(
                f"another node sends heartbeats as {self.host_id}, this command's dead-man id, on bus "
                f"{', '.join(buses)} ({max(self._host_ids.count(b, self.host_id) for b in buses)} heard, "
                f"{self._heartbeat.sent} sent): its heartbeat would keep the drives on; stopping every drive "
                "of the command",
                hint="find the other host or tool (`sherpa scan` lists the heartbeats of the pool's ids) and give "
                     "it ids outside motion.host_id_pool (docs/motion.md \"Heartbeat ids\")")

    def _raise_if_tripped(self) -> None:
        """The bus watch's or the drive watch's reason to stop, raised on the command's thread
        (motion/bus_watch.py, motion/drive_watch.py). The bus first: a dead bus also silences its drives."""
        if self._exiting:
            return
        error = self._bus.poll() or self._watch.poll()
        if error is not None:
            if error is self._watch.error:
                self._watch.told = True
            raise error
        if self._forces and self._clock() >= self._next_force_check:
            self._next_force_check = self._clock() + self.settings.force_check_interval
            for watch, wait_s in self._forces:
                self._pulse(extra=wait_s)  # an unanswered request waits on the bus: the loop is alive meanwhile
                error = watch.check()
                if error is not None:
                    raise error

    def _watch_forces(self) -> None:
        """Every F/T sensor of the arm with a limit (its own, or the command's tighter one) is
        watched while the command runs: its bus opened if the command's drives are elsewhere, and
        one sample read now -- a sensor that does not answer, or saturates, refuses the motion
        before anything moved; one that reads past its limit holds the motion to that reading
        (motion/force_watch.py ENTRY_MARGIN)."""
        s = self.session
        for dev in s.cfg.ft_sensors():
            assert dev.ft is not None
            if tightened(dev.ft.force_limit, s.force_limit, "--force-limit") is None and \
                    tightened(dev.ft.torque_limit, s.torque_limit, "--torque-limit") is None:
                continue
            s.open_bus(dev.bus)
            # the reader's wait is bounded in wall time: it waits on frames, not on the command's clock
            reader = self._force_readers.enter_context(open_reader(s, dev))
            watch = ForceWatch.for_device(reader, dev, force_limit=s.force_limit, torque_limit=s.torque_limit,
                                          silent_s=max(FORCE_SILENT_CHECKS * self.settings.force_check_interval,
                                                       FORCE_SILENT_CHECKS * reader.wait_s),
                                          clock=self._clock, max_misses=FORCE_SILENT_CHECKS)
            self._pulse(extra=reader.wait_s)
            error = watch.check()
            if isinstance(error, ForceLimitError):
                error = error.before_motion()
            if error is None and watch.last is None:
                error = SensorSilentError(f"{watch.name} does not answer: no motion without its force watch",
                                          hint="check the sensor's power and its CAN base address (sherpa ft show)")
            if error is not None:
                raise error
            assert watch.last is not None
            self._forces.append((watch, reader.wait_s))
            self._event(f"{watch.name}: watched: |F| {watch.last.force:.2f} N of {watch.force_limit} N, "
                        f"|T| {watch.last.torque:.3f} N·m of {watch.torque_limit} N·m")
            for label, low in watch.past_at_start.items():
                limit = watch.force_limit if label == "force" else watch.torque_limit
                unit = "N" if label == "force" else "N·m"
                assert limit is not None
                line = (f"{watch.name}: begins past its {label} limit ({low:.2f} {unit} > {limit:g} {unit}; "
                        f"still in contact?): held to its lowest reading + {watch.entry_margin:.0%} of the "
                        f"limit until it reads below {limit:g} {unit}: moving away is allowed, pressing harder "
                        "stops")
                self._event(line)
                self.report.notes.append(line)  # the technician must know the usual limit does not hold yet
        if (s.force_limit is not None or s.torque_limit is not None) and not self._forces:
            raise UsageError("--force-limit: this arm has no F/T sensor to watch (no device of type ft_sensor)",
                             hint="docs/devices.md says how to configure one")

    def _abort_requests(self, error: SherpaError) -> None:
        """The bus watch tripped (any thread): the request the command waits for ends now with ``error``."""
        for d in list(self._drives.values()):
            d.client.abort_pending(error)

    def _check_deadman(self) -> None:
        """Read 0x1016:1 of every drive whose motor is on, at ``deadman_check_interval``: another node
        that changed it (disarmed the dead-man, or pointed it elsewhere) stops the command. One drive
        the command does not arm is read too: one that watches this command's id stops it."""
        self._next_deadman_check = self._clock() + self.settings.deadman_check_interval
        self._pulse()
        foreign = self._others.check_one(self.host_id)
        if foreign is not None:
            raise DriveWatchError(foreign, hint="find the tool or host that armed that drive's heartbeat consumer; "
                                  "`sherpa recover --check-drives` reads every drive's entry")
        expected = self.settings.consumer_entry_for(self.host_id)
        for d in list(self._drives.values()):
            if not d.mo or d.client.silent:
                continue
            self._pulse()
            try:
                value = self._sdo_read(d, CONSUMER)
            except SherpaError as exc:
                if isinstance(exc, SdoError) and exc.reason == "timeout":
                    # no answer: the drive is silent like one that misses an interpreter reply; its partners
                    # get their stop now and the exit skips it (else: a stop, an MO=0 confirmation of
                    # mo_confirm_timeout and a restore, each waiting for the dead drive)
                    d.client.silent = True
                    self.stop_others(d.ref)
                self._raise_if_tripped()  # the watch knows why (a silent drive, NMT Stopped): say that
                raise
            if value != expected:
                raise DriveWatchError(
                    f"{d.client.label}: its dead-man entry 0x1016:1 reads 0x{value:08X}, not the 0x{expected:08X} "
                    "this command wrote: another node changed it; stopping every drive of the command",
                    hint="find which tool or node writes the drive's object dictionary (SDO) meanwhile")

    def _watch_drive(self, d: _Drive) -> None:
        self._watch.add(d.ref.bus, d.ref.node, d.client.label, d.client)
        self._watch.set_moving(d.ref.bus, d.ref.node, bool(d.mo))

    def keep_alive(self, seconds: float) -> None:
        """:meth:`check`, and a sign of life that lasts ``seconds`` more: for a caller that lets another
        motion guard work on drives it released (:meth:`release`) for a step of known bound between
        signs of life (that guard's entry, its motor-on confirmation). Bounded: if nothing comes
        after it, the heartbeat still stops ``seconds`` later."""
        self.check()
        self._pulse(extra=seconds)

    def check_motors_on(self, refs: Iterable[DriveRef], during: str) -> None:
        """:meth:`check`, then every given drive's motor still on: a trip or a `sherpa stop` from
        another terminal ends the command with the decoded reason (``during``: "the move", "the jog")."""
        self.check()
        for ref in refs:
            d = self._drive(ref)
            if not d.native:
                self._pulse()
                st = d.drive.status()
                if not st.enabled:
                    why = st.fault or "switched off from elsewhere (sherpa stop, another tool)"
                    raise SafetyError(f"{d.drive.label}: the motor was switched off during {during}: {why}")
                if st.stopping is not None:  # powered, but ramping down on its own: it follows nothing
                    why = st.fault or "a quick stop from elsewhere (another tool) or its own reaction"
                    raise SafetyError(f"{d.drive.label}: {st.stopping} during {during}: {why}")
                continue
            if not decode_sr(int(self.query(ref, "SR"))).motor_on:
                mf = int(self.query(ref, "MF"))
                why = "; ".join(describe_mf(mf)) if mf else "MO=0 from elsewhere (sherpa stop, another tool)"
                raise SafetyError(f"{self._drive(ref).client.label}: the motor was switched off during {during}: {why}")

    def explain_stall(self, refs: Iterable[DriveRef], during: str) -> None:
        """Before a position move's stall is called blocked: a motor switched off meanwhile is the
        reason (:meth:`check_motors_on`); and an Elmo motor whose profiler has ended short of its
        target was stopped, not blocked -- a stop (ST) from elsewhere: `sherpa stop` switches it off
        once it stands, so that MO=0 is waited for, up to the standstill timeout. Returns when
        the profiler still runs (blocked: the reference moves on, the motor does not) or an end
        switch is active (the drive stopped itself on it)."""
        refs = list(refs)
        self.check_motors_on(refs, during)
        elmo = [r for r in refs if self._drive(r).native]
        if len(elmo) != len(refs) or any(int(self.query(r, "MS")) == MS_PROFILER_ACTIVE for r in elmo):
            return  # another drive type's profiler is not asked here: its stall is called blocked
        from sherpa_cli.motion.blocked import active_switches

        if any(active_switches(self.session.cfg, r.name, self.client(r)) for r in elmo):
            return  # the drive's own end-switch stop: blocked, and the switch is named
        deadline = self._clock() + self.settings.standstill_timeout
        while self._clock() < deadline:
            self._sleep(self.settings.poll_interval)
            self.check_motors_on(refs, during)
        raise SafetyError(f"{during}: the motors stand short of the target with their profiles ended, still on: "
                          "stopped (ST) from elsewhere, by another tool, or blocked as the profile ended (a hard "
                          "stop or a load?)",
                          hint="check who else talks to the drives (`sherpa doctor`: host node id), and what "
                               "blocks the joint")

    @contextlib.contextmanager
    def motor_off_explains_failure(self, refs: Iterable[DriveRef], during: str) -> Iterator[None]:
        """Around the sets right after the motors went on (JV, SP/PA, TC): one that fails because a
        motor was switched off meanwhile (`sherpa stop` from another terminal, a trip) ends with that
        reason -- "MO=0 from elsewhere", exit 1 -- not with the set's own failure ("JV=15 not
        confirmed: JV reads back 0", exit 3)."""
        refs = list(refs)
        try:
            yield
        except CommunicationError:
            self.check_motors_on(refs, during)
            raise

    def query(self, ref: DriveRef, letters: str, index: int = 0) -> int | float:
        """A query that waits out a drive deaf for its MO settle window (another host switched the motor:
        `sherpa stop`), up to protocol.mo_confirm_timeout, keeping the dead-man fed meanwhile."""
        c = self.client(ref)  # an Elmo drive's letters: another drive type is refused by name
        # patient for the settle window only: one request's attempts already span it, so a drive that
        # stays silent costs one request, not the whole mo_confirm_timeout
        patience = c.settings.mo_settle

        def on_try() -> None:
            self._raise_if_tripped()
            self._pulse()

        try:
            # a sign of life per attempt, not one up-front extension for the whole patience; indexed
            # queries too (HM[1] while `sherpa stop` from elsewhere switched the motor off: home)
            return ask_patiently(c, letters, self._clock, self._sleep, patience, self.settings.poll_interval,
                                  on_try=on_try, index=index)
        except CommunicationError:
            if c.silent:
                self.stop_others(ref)
            raise
        finally:
            self._pulse()

    def stop_others(self, dead: DriveRef) -> None:
        """A drive of this command went silent: every other drive it moves gets its stop frames at
        once, without waiting for answers (the guard's exit then confirms them). Never raises."""
        self._event(f"{drive_label(dead)}: no answer; stopping every other drive of the command now")
        self._stop_pass(entering=False, skip={(dead.bus, dead.node)})

    def reset_communication(self, refs: Iterable[DriveRef], boot_timeout: float, why: str) -> None:
        """NMT reset communication of ``refs``, their motors off, then the dead-man armed again.

        CiA 301 puts the communication objects (0x1000-0x1FFF) back to their saved values: the
        heartbeat consumer 0x1016:1 and 0x1029:1 the guard armed are gone, so no motor may be on
        (refused otherwise), and each drive is armed again and read back before this returns; one
        heartbeat follows before anything else is sent. The journal's notes stay right: what the
        reset brought back is what they say to put back. The drive watch lets the expected boot-up
        and Pre-operational pass (the drive leaves the watch until it is Operational again)."""
        refs = list(refs)
        self.check()
        on = [drive_label(r) for r in refs if self._drive(r).mo]
        if on:
            raise SafetyError(f"{', '.join(on)}: motor on: no NMT reset communication ({why}); nothing was reset")
        for ref in refs:
            self._watch.remove(ref.bus, ref.node)
        for ref in refs:
            d = self._drive(ref)
            self._pulse(extra=boot_timeout + self.settings.request_bound)
            self._event(f"{d.client.label}: NMT reset communication ({why})")
            d.client.reset_communication(boot_timeout)
        for ref in refs:
            d = self._drive(ref)
            self._pulse()
            self._rearm(d)
        self._beat_now()
        for ref in refs:
            self._watch_drive(self._drive(ref))
        self._pulse()

    def _rearm(self, d: _Drive) -> None:
        """The dead-man objects written again after a reset communication, each read back."""
        s = self.settings
        for key, value in ((LOSS_ACTION, s.loss_action), (COMM_ERROR, s.comm_error_behaviour),
                           (CONSUMER, s.consumer_entry_for(self.host_id))):
            self._sdo_write(d, key, value)
            back = self._sdo_read(d, key)
            if back != value:
                raise SafetyError(f"{d.client.label}: {OBJECT_NAMES[key]} reads {back:#x} after it was armed again "
                                  f"with {value:#x}: the dead-man is not armed; nothing moves")
        self._event(f"{d.client.label}: dead-man armed again: host {self.host_id}, {s.consumer_time_ms} ms")

    def unit_mode(self, ref: DriveRef) -> int:
        return self._drive(ref).um

    def motor_on(self, ref: DriveRef) -> bool:
        """Whether the guard knows the motor to be on (MO=1): :meth:`enable` then switches it off
        before a UM change and waits the drive's settle window twice (log step's switch report)."""
        return bool(self._drive(ref).mo)

    def release(self, refs: Iterable[DriveRef]) -> list[DriveStop]:
        """Hand drives over to another motion guard (the interactive view's calibrate key runs
        `home`, which guards its drives itself: two guards on one drive would fight over the dead-man
        and its restore). Each drive leaves as on exit -- stopped, its motor off if this guard switched
        it on, UM and the dead-man objects put back -- and is no longer guarded; the others stay.
        :meth:`adopt` takes them back. A drive whose stop did not go cleanly stays guarded and
        SafetyError names it (nothing may take it over then)."""
        self.check()
        out: list[DriveStop] = []
        bad: list[str] = []
        for ref in refs:
            d = self._drive(ref)
            self._watch.remove(ref.bus, ref.node)  # its own stop must not be cut short
            try:
                r = self._exit_drive(d)
            except Exception as exc:  # noqa: BLE001 - reported; the drive stays guarded and SafetyError names it
                r = DriveStop(d.ref.name, f"{d.ref.bus}:{d.ref.node}", stopped_by="not stopped")
                r.problems.append(f"stop: {why(exc)}")
            out.append(r)
            if r.problems:
                bad += [f"{r.drive}: {p}" for p in r.problems]
                self._watch_drive(d)
                continue
            del self._drives[(ref.bus, ref.node)]
            self._released[(ref.bus, ref.node)] = r
            self._unlock(ref)
        self._pulse()
        if bad:
            raise SafetyError("the stop before the hand-over did not go cleanly: " + "; ".join(bad),
                              hint="check the drives with `sherpa monitor --once`; `sherpa stop` stops them all")
        return out

    def adopt(self, refs: Iterable[DriveRef]) -> None:
        """Take back drives :meth:`release` handed over: NMT start, the fault check of the entry (a
        drive in fault is refused with the decoded reason and stays unguarded), the dead-man armed."""
        self.check()
        for ref in refs:
            key = (ref.bus, ref.node)
            if key not in self._released:
                raise UsageError(f"{drive_label(ref)} was not released by this motion guard")
            try:
                self._lock(ref)
                self._pulse(extra=self._setup_bound())
                self._inspect(ref)
                self._arm(self._drives[key])
                self._watch_drive(self._drives[key])
            except BaseException:
                d = self._drives.pop(key, None)
                try:
                    if d is not None:  # put back what was armed; nothing was switched on. The report
                        # keeps how the drive left this guard (release), with any problem of this put-back
                        self._released[key].problems += self._exit_drive(d, stop=False).problems
                finally:
                    self._unlock(ref)
                raise
            del self._released[key]
        self._pulse()

    # -- entry ------------------------------------------------------------------------------------

    def _drive(self, ref: DriveRef) -> _Drive:
        d = self._drives.get((ref.bus, ref.node))
        if d is None:
            raise UsageError(f"{drive_label(ref)} is not guarded by this motion guard")
        return d

    def _lock(self, ref: DriveRef) -> None:
        key = (ref.bus, ref.node)
        if key in self._locks:
            return
        link = self.session.links[ref.bus].config
        lock = DriveLock(ref, key=wire_key(link.interface, link.channel))
        lock.acquire()
        self._locks[key] = lock

    def _unlock(self, ref: DriveRef) -> None:
        lock = self._locks.pop((ref.bus, ref.node), None)
        if lock is not None:
            lock.release()

    def _unlock_all(self) -> None:
        for lock in self._locks.values():
            try:
                lock.release()
            except Exception as exc:  # noqa: BLE001 - logged; never keeps the others held (the kernel frees it at exit anyway)
                log.warning("%s: motion lock not released: %s", lock.label, exc)
        self._locks.clear()
        try:
            self._host_lock.release()
        except Exception as exc:  # noqa: BLE001 - logged; the kernel frees it at exit anyway
            log.warning("dead-man host id %s not released: %s", self.host_id, exc)

    def _leftovers(self, ref: DriveRef) -> None:
        """What a killed command left on the drive (the journal): refused, or put back with --recover."""
        why = journal.damaged(ref)
        if why is not None:
            raise journal.LeftoverError(journal.damaged_text(ref, why) + "; refusing to move it",
                                        hint=f"`sherpa recover {ref.name}` shows what the drive says; `--apply` "
                                             "resets it (RAM from flash) and moves the journal aside")
        steps = journal.leftover(ref)
        if not steps:
            return
        text = journal.leftover_text(ref, steps)
        # another drive type than Elmo: its state (and a tripped dead-man's fault) through the seam
        other = None if is_elmo(self.session, ref) else open_drive(self.session, ref)
        if journal.still_changed(self.session, ref, steps, other) == []:
            # every noted value is already back (the drive was reset or power-cycled since, its RAM
            # at flash values): nothing to put back, and nothing to refuse for
            journal.forget_all(ref)
            self._event(f"{text}; the drive already holds every value (reset since?): notes dropped")
            return
        if not journal.auto_recover():
            raise journal.LeftoverError(text + "; refusing to move it",
                                        hint=f"`sherpa recover {ref.name}` shows it, `--apply` puts it back; or "
                                             "run this command as `sherpa --recover ...`")
        res = journal.restore(self.session, ref, apply=True, drive=other, clear_trip=lambda: clear_heartbeat_trip(
            self.session, ref, self.settings, clock=self._clock, sleep=self._sleep, drive=other))
        self._event(text)
        if res.tripped:
            self._event(f"{drive_label(ref)}: {res.tripped}")
        self._event(f"{drive_label(ref)}: put back: {', '.join(res.done or []) or 'nothing'}")
        if res.problems:
            raise journal.LeftoverError(f"{drive_label(ref)}: not recovered: {'; '.join(res.problems)}",
                                        hint=f"`sherpa recover {ref.name} --apply` tries again")

    def _setup_bound(self) -> float:
        return 12 * self.settings.request_bound * max(1, len(self.refs)) + 3.0

    def _inspect(self, ref: DriveRef) -> None:
        client = self.session.client(ref)
        client.nmt_start()
        d = _Drive(ref, client, open_drive(self.session, ref))
        self._drives[(ref.bus, ref.node)] = d
        if not d.native:
            self._inspect_other(d)
            return
        d.mo = int(client.get("MO"))
        d.um = int(client.get("UM"))
        sr = int(client.get("SR"))
        mf = int(client.get("MF"))
        reason = fault_reason(mf, sr)
        if reason is not None and self.clears_fault:
            self._event(f"{client.label}: in fault ({reason}); MO=1 is sent to clear it, under the dead-man")
        elif reason is not None:
            raise SafetyError(f"{client.label}: in fault, refusing to move it: {reason}",
                              hint=f"find the cause first; MO=1 clears MF: `sherpa cmd {ref.name} MO=1 MO=0 --apply`")
        self._event(f"{client.label}: MO={d.mo} UM={d.um} SR=0x{sr & 0xFFFFFFFF:08X} MF=0x{mf & 0xFFFFFFFF:08X}")
        # motion commands scale SP/AC/DC (pair profiles, limit recovery): RAM changes put back on
        # exit, so a later SV never flashes a jog's speed
        d.profile_before = {key: int(client.get(key)) for key in PROFILE_KEYS}
        # on disk before anything changes them (the journal; the dead-man objects follow)
        journal.note(ref, *(journal.interp(JOURNAL_OWNER, k, 0, v) for k, v in d.profile_before.items()))

    def _inspect_other(self, d: _Drive) -> None:
        """Another drive type: its state through the seam; its profile kept to be put back, and
        journaled where it lives in dictionary objects (RampObjects)."""
        st = d.drive.status()
        d.mo, d.mode = int(st.enabled), st.mode
        if st.fault is not None and self.clears_fault:
            self._event(f"{d.drive.label}: in fault ({st.fault})")
        elif st.fault is not None:
            raise SafetyError(f"{d.drive.label}: in fault, refusing to move it: {st.fault}",
                              hint="find the cause first, then reset the fault on the drive")
        self._event(f"{d.drive.label}: {d.drive.kind}, {'on' if st.enabled else 'off'}, {st.mode.value} mode")
        if isinstance(d.drive, ModeObject):  # on disk before anything changes it, as Elmo's UM
            o = d.mode_found = d.drive.mode_object()
            journal.note(d.ref, journal.sdo(JOURNAL_OWNER, o.index, o.sub, o.size, o.value))
        d.ramp_before = d.drive.ramp()
        if isinstance(d.drive, RampObjects):  # on disk before anything changes them, as Elmo's SP/AC/DC
            objects = d.drive.ramp_objects(d.ramp_before)
            d.ramp_journal = {f"0x{o.index:04X}:{o.sub}" for o in objects}
            journal.note(d.ref, *(journal.sdo(JOURNAL_OWNER, o.index, o.sub, o.size, o.value) for o in objects))

    def _read_consumer(self, ref: DriveRef) -> int:
        raw = self.session.sdo(ref).upload(*CONSUMER, name=OBJECT_NAMES[CONSUMER])
        return int.from_bytes((bytes(raw) + bytes(4))[:4], "little")

    def _sdo_read(self, d: _Drive, key: tuple[int, int]) -> int:
        """An SDO upload through the session's client of the drive (SdoError names drive and object)."""
        raw = self.session.sdo(d.ref).upload(*key, name=OBJECT_NAMES[key])
        fmt = SIZES[key]
        raw = (bytes(raw) + bytes(4))[:struct.calcsize(fmt)]
        return struct.unpack(fmt, raw)[0]

    def _sdo_write(self, d: _Drive, key: tuple[int, int], value: int) -> None:
        self.session.sdo(d.ref).download(key[0], key[1], struct.pack(SIZES[key], value), name=OBJECT_NAMES[key])

    def _arm(self, d: _Drive) -> None:
        """Dead-man on: loss action and error behaviour first, the consumer entry last (it starts the watch)."""
        s = self.settings
        pool = {i & 0x7F for i in s.host_ids}
        for key, value in ((LOSS_ACTION, s.loss_action), (COMM_ERROR, s.comm_error_behaviour),
                           (CONSUMER, s.consumer_entry_for(self.host_id))):
            before = self._sdo_read(d, key)
            if key == CONSUMER and before and (before >> 16) & 0x7F in pool:
                # a sherpa host id already watched: no other command can be moving this drive (its
                # motion lock is ours), so it is the leftover of a run killed before its exit. Its
                # "before" is unknown -- disarmed (0) is put back, so it does not outlive this run
                msg = (f"{d.client.label}: 0x1016:1 = 0x{before:08X} already watches host {(before >> 16) & 0x7F}: "
                       "left over from a run that did not exit cleanly; it is cleared (0) on exit")
                log.warning("%s", msg)
                self._event(msg)
                d.od_before[key] = 0
                journal.note(d.ref, journal.sdo(JOURNAL_OWNER, key[0], key[1], _size(key), 0))
                if before != value:
                    self._sdo_write(d, key, value)
                continue
            if before == value:
                continue
            d.od_before[key] = before  # recorded first: a write that fails half-way is still put back
            journal.note(d.ref, journal.sdo(JOURNAL_OWNER, key[0], key[1], _size(key), before))
            self._sdo_write(d, key, value)
        self._event(f"{d.client.label}: dead-man armed: host {self.host_id}, {s.consumer_time_ms} ms, "
                    f"0x6007={s.loss_action}")

    # -- dead-man heartbeat (motion/deadman.py) ----------------------------------------------------

    def _allowance(self) -> float:
        return max(self.settings.liveness_timeout, 3 * self.settings.request_bound)

    def _pulse(self, extra: float = 0.0, *, exact: bool = False) -> None:
        """A sign of life: the heartbeat goes on for the allowance (+ ``extra`` s). ``exact``: for the
        next step only, even if an earlier, longer extension is still running (the exit's steps)."""
        self._heartbeat.pulse(self._allowance() + extra, extend=bool(extra) and not exact)

    def _watch_requests(self) -> None:
        self._owner = threading.get_ident()
        self._unwatch_requests = self.session.watch_requests(self._request_sent)

    def _unwatch(self) -> None:
        self._host_ids.stop()
        if self._unwatch_requests is not None:
            self._unwatch_requests()
            self._unwatch_requests = None

    def _request_sent(self, key: tuple[str, int]) -> None:
        """A request to drive ``key`` about to go out. From the command's own thread it is a sign of
        life, so a step of many requests (a recorder's PDO set-up, its restore, a profile) never
        outlasts the allowance on a slow bus or machine; it never shortens a longer allowance. A
        request of another thread (a watch, a receive thread) says nothing about the command's loop:
        a hung loop still stops the heartbeat."""
        if threading.get_ident() != self._owner:
            return
        error = self._watch.error
        if error is not None and not self._watch.told and not self._exiting and key in self._drives:
            # the watch tripped between two requests: this one, to one of this guard's drives, would
            # go out after the reason to stop is known and wait out its reply timeouts on a deaf
            # drive (one reset by another node), its timeout hiding the reason. Once: the clean-up
            # that follows (a recorder's restore) must reach the drives. A drive released to another
            # guard (a home inside the live view) is that guard's to stop, not this one's.
            self._watch.told = True
            raise error
        self._heartbeat.pulse(self._allowance(), extend=True)

    def _beat_now(self) -> None:
        self._heartbeat.beat_now()

    def _start_heartbeat(self) -> None:
        self._heartbeat.start()

    def _stop_heartbeat(self) -> None:
        self._heartbeat.stop()

    @property
    def heartbeats_sent(self) -> int:
        return self._heartbeat.sent

    @property
    def _hb_thread(self) -> threading.Thread | None:
        return self._heartbeat.thread

    # -- exit -------------------------------------------------------------------------------------

    def _exit_all(self, reason: str, entering: bool = False) -> None:
        self._exiting = True
        self._watch.stop()  # first: nothing may cut the exit's own requests short (but a boot-up)
        self._bus.stop()
        self.report.reason = reason
        try:
            # a bus that cannot carry frames (bus-off, down) gets nothing yet: the drives on the other
            # buses are stopped first, then the dead bus is given its restart-ms to come back
            dead = self._bus.dead()
            self._stop_pass(entering, skip={k for k in self._drives if k[0] in dead})
            for d in sorted(self._drives.values(), key=lambda d: d.ref.bus in dead):
                try:
                    self.report.drives.append(self._exit_or_unreached(d, entering, dead))
                except Exception as exc:  # noqa: BLE001 - reported; never one drive's failure leaves the others unstopped
                    r = DriveStop(d.ref.name, f"{d.ref.bus}:{d.ref.node}", stopped_by="not stopped")
                    r.problems.append(f"stop: {why(exc)}")
                    self.report.drives.append(r)
            # drives handed over (release) and not taken back: how they left this guard
            self.report.drives.extend(self._released.values())
        finally:
            self.report.bus_faults = list(self._bus.faults)
            self._watch.close()
            self._force_readers.close()
            self._bus.close()
            self._stop_heartbeat()

    def _exit_or_unreached(self, d: _Drive, entering: bool, dead: set[str]) -> DriveStop:
        """The drive's exit; on a bus that went dead and did not come back: not reached (motion/bus_watch.py)."""
        if d.ref.bus in dead and not self._bus.back(d.ref.bus, sleep=self._sleep, pulse=self._step,
                                                    max_wait=self.settings.standstill_timeout):
            if self._bus.confirmed_dead(d.ref.bus):
                r = self._bus.unreached(d.ref.name, f"{d.ref.bus}:{d.ref.node}", d.ref.bus,
                                        self.settings.consumer_time_ms, motor_on=bool(d.mo or d.switched_on))
                self._event(r.line())
                return r
            d.client.silent = True  # only an error frame said so: one plain request tells (as a silent drive)
        return self._exit_drive(d, stop=not entering or d.switched_on)

    def _stop_pass(self, entering: bool, skip: set[tuple[str, int]] | None = None) -> None:
        """Every drive whose motor is on gets its stop at once, without waiting for replies; the
        careful per-drive exit (standstill, MO=0, restore) follows. Otherwise a drive that does not
        answer would hold back the stop of the drives after it by its timeouts."""
        method = self.settings.stop_method
        due = [d for key, d in self._drives.items()
               if d.mo and not (entering and not d.switched_on) and not (skip and key in skip)]
        for d in due:
            if not d.native:
                continue
            try:
                if d.um == UM_TORQUE:
                    d.client.send_only("TC", 0, 0.0)
                if method == "jv0":
                    d.client.send_only("JV", 0, 0)
                    d.client.send_only("BG")
                else:
                    d.client.send_only("ST")
            except Exception as exc:  # noqa: BLE001 - logged; the per-drive exit tries again and reports
                log.debug("motion guard: first stop pass to %s: %s", d.ref.name, exc)
        # then the drives that are told only by a confirmed exchange (CiA 402 over SDO): after every
        # frame that needs no answer, so a silent one holds back none of those; one known silent
        # would only cost its timeouts here (its exit says so)
        for d in due:
            if d.native or d.client.silent:
                continue
            try:
                d.drive.stop()
            except Exception as exc:  # noqa: BLE001 - logged; the per-drive exit tries again and reports
                log.debug("motion guard: first stop pass to %s: %s", d.ref.name, exc)

    def _step(self, extra: float = 0.0) -> None:
        """A sign of life before one exit step, bounded by that step (not by the whole exit); and an NMT
        start for the drive being stopped if it booted again since (:meth:`_exit_drive`)."""
        self._pulse(extra, exact=True)
        d = self._exit_of
        if d is not None and (boots := self._watch.boots(d.ref.bus, d.ref.node)) != self._exit_boots:
            self._exit_boots = boots
            self._await_boot(d)
            d.client.clear_abort()  # the boot-up ended the request it cut short, not the ones to come
            try:
                d.client.nmt_start()
            except Exception as exc:  # noqa: BLE001 - the step that follows fails and says why
                log.debug("motion guard: NMT start of %s after its boot-up: %s", d.ref.name, exc)

    def _await_boot(self, d: _Drive) -> None:
        """Until the boot-up of a drive another node reset (bounded by protocol.boot_timeout): it
        hears nothing while it boots, an NMT start included."""
        if not self._watch.resetting(d.ref.bus, d.ref.node):
            return
        deadline = self._clock() + self.session.cfg.protocol.boot_timeout
        while self._watch.resetting(d.ref.bus, d.ref.node) and self._clock() < deadline:
            self._pulse(exact=True)
            self._sleep(0.01)

    def _exit_drive(self, d: _Drive, stop: bool = True) -> DriveStop:
        """The drive's exit (:meth:`_exit_drive_once`). A drive that boots again during it (reset by
        another node) heard none of the steps after its boot-up until the next step's NMT start: its
        exit runs once more, on a drive whose motor its reset switched off."""
        start = self._watch.boots(d.ref.bus, d.ref.node)
        self._exit_of, self._exit_boots = d, start
        try:
            self._await_boot(d)
            # a boot-up heard after the watch stopped, before this drive's turn, cut short a request
            # of another drive's exit, not the ones to come (its first step starts it again)
            d.client.clear_abort()
            r = self._exit_drive_once(d, stop)
            if r.problems and self._watch.boots(d.ref.bus, d.ref.node) != start:
                self._event(f"{d.client.label}: booted again during its stop ({'; '.join(r.problems)}): "
                            "its stop once more")
                r = self._exit_drive_once(d, stop)
                if r.stopped_by == "motor was off":
                    r.stopped_by = RESET_DURING_STOP
            return r
        finally:
            self._exit_of = None

    def _exit_drive_once(self, d: _Drive, stop: bool) -> DriveStop:
        c, s = d.client, self.settings
        r = DriveStop(d.ref.name, f"{d.ref.bus}:{d.ref.node}")
        motor_confirmed_off = False
        if c.silent and stop and not self._answers(d):
            # no answer to its last request nor to one more: a try of each step would cost a timeout
            # each and hold back the command's end; the drive's own consumer stops it (the heartbeat ends)
            r.stopped_by = "not reached"
            r.problems.append(f"no answer (dead or silent): not confirmed stopped; its heartbeat consumer "
                              f"switches the motor off {s.consumer_time_ms} ms after the tool's heartbeat ends")
            r.kept.extend(f"{name} (no answer)" for name in ("0x1016:1", "0x1029:1", "0x6007:0"))
            r.kept.extend(f"{s.name} (no answer)" for s in journal.own_steps(d.ref, PAIR_START_OWNER))
            self._event(r.line())
            return r
        if stop and self._bus_lost(d.ref.bus):
            # the connection to its bus is gone (the error line names it once): every step would fail
            # the same way; the drive's own consumer stops it when the heartbeat, on that bus too, ends
            r.stopped_by = "not reached"
            r.problems.append(f"bus {d.ref.bus} lost: its heartbeat consumer switches the motor off "
                              f"{s.consumer_time_ms} ms after the tool's heartbeat ends")
            r.kept.extend(f"{name} (bus lost)" for name in ("0x1016:1", "0x1029:1", "0x6007:0")
                          if name in {f"0x{k[0]:04X}:{k[1]}" for k in d.od_before})
            r.kept.extend(f"{s.name} (bus lost)" for s in journal.own_steps(d.ref, PAIR_START_OWNER))
            self._event(r.line())
            return r
        if not stop:
            r.stopped_by = NOT_MOVED
            self._put_back_pair_start(d, r)
            self._restore_dead_man(d, r, stop_failed=False)
            # the profile and mode were never changed
            journal.forget(d.ref, JOURNAL_OWNER, d.put_back | set(PROFILE_KEYS) | d.ramp_journal | self._mode_name(d))
            self._event(r.line())
            return r
        try:
            # a drive whose consumer tripped went to NMT Stopped (0x1029:1 = 2) and its interpreter is
            # deaf until started again; starting it moves nothing
            self._step()
            try:
                c.nmt_start()
            except Exception as exc:  # noqa: BLE001 - reported; an NMT frame that could not be sent: still try the stop
                r.problems.append(f"NMT start: {why(exc)}")
            # before the careful stop: an RPDO2 left synchronous would hold that stop back until a SYNC
            self._put_back_pair_start(d, r)
            if d.native:
                how, standstill, problems = stop_drive(c, unit_mode=d.um, method=s.stop_method,
                                                       standstill_timeout=s.standstill_timeout,
                                                       poll_interval=s.poll_interval, clock=self._clock,
                                                       sleep=self._sleep, pulse=self._step,
                                                       standstill_velocity=s.standstill_velocity)
            else:
                how, standstill, problems = stop_other(d.drive, standstill_timeout=s.standstill_timeout,
                                                       poll_interval=s.poll_interval, clock=self._clock,
                                                       sleep=self._sleep, pulse=self._step,
                                                       standstill_velocity=s.standstill_velocity)
            r.stopped_by, r.standstill = how, standstill
            r.problems.extend(problems)
        except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
            r.stopped_by = "not stopped"
            r.problems.append(f"stop: {why(exc)}")
        if d.switched_on:
            try:
                self._step(c.settings.mo_confirm_timeout + 2 * s.request_bound)
                if d.native:
                    c.motor_off()
                else:
                    d.drive.disable()
                r.motor_off = motor_confirmed_off = True
            except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
                r.problems.append(f"MO=0: {why(exc)}")
        # the dead-man may only be switched off when nothing is left running: a motor the guard switched
        # on must be at standstill (or already off) and MO=0 confirmed; otherwise the heartbeat stops
        # with the consumer still armed, and the drive trips on its own
        stop_failed = d.switched_on and not (motor_confirmed_off and r.stopped_by != "not stopped"
                                             and r.standstill is not False)
        try:
            self._step()
            r.position = int(c.get("PX")) if d.native else d.drive.position()
        except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
            r.problems.append(f"PX: {why(exc)}")
        if d.um_changed_from is not None:
            if self.keep:
                r.kept.append(f"UM={d.um}")
            elif r.motor_off or not d.switched_on:
                try:
                    self._step()
                    c.set("UM", 0, d.um_changed_from)
                    r.restored.append(f"UM={d.um_changed_from}")
                    d.put_back.add("UM")
                except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
                    r.problems.append(f"UM={d.um_changed_from} not restored: {why(exc)}")
            else:
                r.kept.append(f"UM={d.um} (motor not confirmed off)")
                r.problems.append(f"UM={d.um_changed_from} not restored: the motor is not confirmed off")
        if d.mode_found is not None:
            self._restore_mode(d, r, d.mode_found)
        self._restore_profile(d, r)
        self._restore_dead_man(d, r, stop_failed)
        if self.keep:  # left as the motion left them on purpose: not a leftover of a killed command
            journal.forget(d.ref, JOURNAL_OWNER)
        else:
            journal.forget(d.ref, JOURNAL_OWNER, d.put_back)
        self._event(r.line())
        return r

    def _put_back_pair_start(self, d: _Drive, r: DriveStop) -> None:
        """What a pair start inside this guard changed (0x2040, 0x1401:2; motion/pair_start.py) and
        did not put back itself -- its close skips a drive that did not answer the stop, and that
        drive may answer again by now. Put back here, or reported: an exit never reads "settings put
        back" over a group id left set."""
        for s in journal.own_steps(d.ref, PAIR_START_OWNER):
            if s.kind != "sdo":
                continue
            try:
                self._step()
                self.session.sdo(d.ref).download(s.index, s.sub, int(s.old).to_bytes(s.size, "little"), name=s.name)
            except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report; the next step is tried
                r.problems.append(f"{s.text()} not put back (the pair start's): {why(exc)}; `sherpa recover` "
                                  "puts it back")
                continue
            journal.forget(d.ref, PAIR_START_OWNER, {s.name})
            r.restored.append(s.text())

    def _bus_lost(self, bus: str) -> bool:
        """The connection to ``bus`` went away (its receive thread ended: bus/links.py PacedNetwork.lost)."""
        link = self.session.links.get(bus)
        return link is not None and getattr(link.network, "lost", None) is not None

    def _answers(self, d: _Drive) -> bool:
        """One plain request (no patience) to a drive that went silent: True if it answers again (a
        passing fault or a loaded bus), then its exit goes on as usual."""
        c = d.client
        try:
            self._step()
            # a drive reset by another node is back in Pre-operational, deaf to the interpreter until
            # started: the same start every exit gives a tripped drive (it moves nothing)
            c.nmt_start()
            if d.native:
                c.get("MO")
            else:
                d.drive.status()
        except Exception:  # noqa: BLE001 - any failure means: still silent
            return False
        c.silent = False
        return True

    def _restore_profile(self, d: _Drive, r: DriveStop) -> None:
        if not d.native:
            self._restore_ramp(d, r)
            return
        if self.keep or not d.profile_before or r.stopped_by == "not stopped":
            return
        for key, before in d.profile_before.items():
            try:
                self._step()
                if int(d.client.get(key)) != before:
                    self._step()
                    d.client.set(key, 0, before)
                    r.restored.append(f"{key}={before}")
                d.put_back.add(key)
            except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
                r.problems.append(f"{key}={before} not restored: {why(exc)}")

    @staticmethod
    def _mode_name(d: _Drive) -> set[str]:
        o = d.mode_found
        return set() if o is None else {f"0x{o.index:04X}:{o.sub}"}

    def _restore_mode(self, d: _Drive, r: DriveStop, found: ObjectValue) -> None:
        """The mode object found at entry, put back once the power stage is off (as Elmo's UM)."""
        name = f"0x{found.index:04X}:{found.sub}"
        if self.keep:
            r.kept.append(name)
            return
        if not isinstance(d.drive, ModeObject):
            return
        try:
            self._step()
            if d.drive.mode_object().value == found.value:
                d.put_back.add(name)
                return
            self._step()
            if not (r.motor_off or not d.switched_on) or d.drive.status().enabled:
                r.kept.append(f"{name} (power stage not confirmed off)")
                r.problems.append(f"{name}={found.value} not restored: the power stage is not confirmed off")
                return
            self._step()
            d.drive.put_back(found)
            r.restored.append(f"{name}={found.value}")
            d.put_back.add(name)
        except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
            r.problems.append(f"{name}={found.value} not restored: {why(exc)}")

    def _restore_ramp(self, d: _Drive, r: DriveStop) -> None:
        before = d.ramp_before
        if self.keep or before is None or r.stopped_by == "not stopped":
            return
        try:
            self._step()
            if d.drive.ramp() != before:
                self._step()
                d.drive.set_ramp(before)
                r.restored.append(f"profile {before.speed}/{before.accel}/{before.decel}")
            d.put_back |= d.ramp_journal
        except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
            r.problems.append(f"profile not restored: {why(exc)}")

    def _restore_dead_man(self, d: _Drive, r: DriveStop, stop_failed: bool) -> None:
        # the consumer entry first: once it is back, the heartbeat may stop without a trip
        for key in (CONSUMER, COMM_ERROR, LOSS_ACTION):
            if key not in d.od_before:
                continue
            name = f"0x{key[0]:04X}:{key[1]}"
            if self.keep:
                r.kept.append(name)
                continue
            if stop_failed:
                r.kept.append(f"{name} (stop failed)")
                continue
            try:
                self._step()
                self._sdo_write(d, key, d.od_before[key])
                r.restored.append(name)
                d.put_back.add(name)
            except Exception as exc:  # noqa: BLE001 - reported in the drive's stop report
                r.problems.append(f"restore {name}: {why(exc)}")

    # -- signals ----------------------------------------------------------------------------------

    def _install_signals(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return  # handlers live in the main thread only; a worker's guard relies on check()
        for signum in (signal.SIGTERM, getattr(signal, "SIGHUP", None), signal.SIGINT):
            if signum is None:
                continue
            self._old_handlers[signum] = signal.getsignal(signum)
            signal.signal(signum, self._on_signal)

    def _block_signals(self) -> bool:
        """Hold SIGINT/SIGTERM/SIGHUP back for the exit sequence (main thread only); True if blocked."""
        if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
            return False
        sigs = {signal.SIGINT, signal.SIGTERM}
        if hasattr(signal, "SIGHUP"):
            sigs.add(signal.SIGHUP)
        signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
        return True

    def _unblock_signals(self, blocked: bool) -> None:
        if not blocked:
            return
        sigs = {signal.SIGINT, signal.SIGTERM}
        if hasattr(signal, "SIGHUP"):
            sigs.add(signal.SIGHUP)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, sigs)

    def _restore_signals(self) -> None:
        for signum, handler in self._old_handlers.items():
            with contextlib.suppress(TypeError, ValueError):
                signal.signal(signum, handler)
        self._old_handlers.clear()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if self._exiting:
            # already stopping: a second Ctrl-C or SIGTERM must not cut the stop sequence short.
            # Kept for after the stop: blocking the signal in this thread does not stop the kernel
            # handing it to another thread, whose Python handler still runs here.
            self._event(f"{name} received while stopping: still stopping")
            if self._late_signal is None:
                self._late_signal = signum
            return
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        self._signal = name
        raise MotionStopped(f"{name} received: motion stopped")

    def _event(self, text: str) -> None:
        log.info("%s", text)
        if self._on_event is not None:
            self._on_event(text)
