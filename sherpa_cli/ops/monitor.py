"""`sherpa monitor`: what every drive is doing, polled over the binary interpreter, plus what the
drives say on their own (heartbeat, EMCY).

What the monitor sends, and why (nothing else reaches a drive):
- NMT start to each drive, as `sherpa cmd` does: the binary interpreter answers only in
  Operational. It is sent again before polling a drive that did not answer last time (it may
  have rebooted into Pre-operational).
- Queries MO, UM, PX, SR, MF; SDO reads of 0x1017 (producer heartbeat time) and 0x1003:1
  (the one error a SimplIQ stores: the last EMCY from before the monitor started).
- 0x1017 is written only when the caller asks for it (``heartbeat_ms``, `--heartbeat`), in RAM
  (never SV), and the old value is written back on close. By default the monitor listens to
  whatever heartbeat the drive already produces, and says "off" when it produces none.

Drives on different buses are polled at the same time (one thread per bus); a drive that does
not answer is reported as such with how long it has been silent, never with its last values.
Nothing here prints; the CLI renders :class:`DriveStatus` rows.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.bus.canopen_names import NMT_STATES, nmt_text
from sherpa_cli.bus.parallel import run_concurrently
from sherpa_cli.bus.targets import DriveRef
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.devices.drives import is_elmo, open_drive
from sherpa_cli.elmo.faults import Emcy, Fault, decode_error_field, decode_mf, sr_problems
from sherpa_cli.elmo.protocol import HEARTBEAT_BASE
from sherpa_cli.errors import SdoError, SherpaError, UsageError, raise_if_signalled
from sherpa_cli.motion.calibration import encoder_on_drive
from sherpa_cli.ops.identify import JointPosition, joint_positions, row_joint

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.elmo.client import DriveClient

POLLED = ("MO", "UM", "PX", "SR", "MF")
PRODUCER_HEARTBEAT = (0x1017, 0)
ERROR_FIELD = (0x1003, 1)
NO_ANSWER = "no answer"


@dataclass
class _Watch:
    """Everything known about one drive; written by poll threads and the bus's receive thread."""

    ref: DriveRef
    heartbeat_ms: int | None = None  # 0x1017 as read (None: could not be read)
    heartbeat_set_from: int | None = None  # the value we replaced, to write back on close
    heartbeat_at: float | None = None
    heartbeat_state: int | None = None
    emcy: Emcy | None = None
    emcy_at: float | None = None  # None with an emcy: read from 0x1003, raised before we listened
    values: dict[str, int | float] = field(default_factory=dict)
    polled: bool = False
    answering: bool = False
    answered_at: float | None = None
    problem: str | None = None


@dataclass(frozen=True)
class DriveStatus:
    """One drive in one snapshot; ages are seconds before the snapshot, None when unknown."""

    drive: str
    bus: str
    node: int
    nmt: str
    heartbeat_ms: int | None
    heartbeat_age: float | None
    answering: bool
    silent_for: float | None
    mo: int | None
    um: int | None
    px: int | None
    sr: int | None
    mf: int | None
    joint: str | None
    position_rad: float | None
    sr_problems: tuple[Fault, ...]
    mf_faults: tuple[Fault, ...]
    emcy: Emcy | None
    emcy_age: float | None
    emcy_before_start: bool
    problem: str | None
    uncalibrated: str | None = None  # its joint's counter does not mean the joint's absolute encoder

    @property
    def address(self) -> str:
        return f"{self.bus}:{self.node}"

    def as_json(self, *, ages: bool = True) -> dict[str, Any]:
        """``ages=False`` leaves out every time-dependent number (``--once``: stable output)."""
        emcy = None
        if self.emcy is not None:
            e = self.emcy
            emcy = {"code": f"0x{e.code:04X}", "error_register": e.error_register, "elmo_code": e.elmo_code,
                    "text": e.text, "before_start": self.emcy_before_start}
            if ages:
                emcy["age_s"] = self.emcy_age
        out: dict[str, Any] = {
            "drive": self.drive, "bus": self.bus, "node": self.node, "nmt": self.nmt,
            "heartbeat_ms": self.heartbeat_ms, "answering": self.answering,
            "MO": self.mo, "UM": self.um, "PX": self.px,
            "SR": None if self.sr is None else f"0x{self.sr & 0xFFFFFFFF:08X}",
            "MF": None if self.mf is None else f"0x{self.mf & 0xFFFFFFFF:08X}",
            "joint": self.joint, "position_rad": self.position_rad,
            "sr_problems": [f.line() for f in self.sr_problems], "mf_faults": [f.line() for f in self.mf_faults],
            "last_emcy": emcy, "problem": self.problem,
        }
        if self.uncalibrated is not None:
            out["uncalibrated"] = self.uncalibrated
        if ages:
            out["heartbeat_age_s"] = self.heartbeat_age
            out["silent_for_s"] = self.silent_for
        return out


class Monitor:
    """Watches drives of an open session; use as a context manager (close writes 0x1017 back)."""

    def __init__(self, session: ArmSession, refs: Iterable[DriveRef], *, heartbeat_ms: int | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if heartbeat_ms is not None and not 0 < heartbeat_ms <= 0xFFFF:
            raise UsageError(f"--heartbeat {heartbeat_ms}: expected 1..65535 ms (0x1017 is 16 bits)")
        self.session = session
        self.cfg: ArmConfig = session.cfg
        self.heartbeat_ms = heartbeat_ms
        self.clock = clock
        self.watches = [_Watch(ref) for ref in refs]
        self._lock = threading.Lock()
        self._subscriptions: list[tuple[Any, int, Callable]] = []
        self._emcy_subscriptions: list[tuple[DriveRef, Callable[[Emcy], None]]] = []

    # -- life cycle -------------------------------------------------------------------------------

    def __enter__(self) -> Monitor:
        try:
            self.start()
        except BaseException:
            self.close()  # a failed start may already have changed 0x1017 of some drives
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Listen, NMT-start, and read 0x1017 / 0x1003:1 of every drive (buses at the same time)."""
        for w in self.watches:
            network = self.session.links[w.ref.bus].network
            on_heartbeat = self._heartbeat_callback(w)
            network.subscribe(HEARTBEAT_BASE + w.ref.node, on_heartbeat)
            self._subscriptions.append((network, HEARTBEAT_BASE + w.ref.node, on_heartbeat))
            on_emcy = self._emcy_callback(w)
            self.session.client(w.ref).on_emcy(on_emcy)
            self._emcy_subscriptions.append((w.ref, on_emcy))
        self._per_bus(self._start_drive)

    def close(self) -> None:
        for network, can_id, callback in self._subscriptions:
            with contextlib.suppress(KeyError, ValueError):  # the bus is already gone
                network.unsubscribe(can_id, callback)
        self._subscriptions.clear()
        for ref, on_emcy in self._emcy_subscriptions:  # a long-lived session's client outlives this monitor
            self.session.client(ref).remove_emcy(on_emcy)
        self._emcy_subscriptions.clear()
        restore = [w for w in self.watches if w.heartbeat_set_from is not None]
        if restore:
            self._per_bus(self._restore_heartbeat, restore)

    # -- polling ----------------------------------------------------------------------------------

    def poll(self) -> None:
        """Query every drive once; buses at the same time, the drives of one bus one after another."""
        self._per_bus(self._poll_drive)

    def wait_for_heartbeats(self, *, limit_s: float = 2.0, sleep: Callable[[float], None] = time.sleep) -> None:
        """Until every drive that produces a heartbeat was heard once (1.5 periods, at least 0.5 s, at most ``limit_s``)."""
        producing = [w for w in self.watches if w.heartbeat_ms]
        if not producing:
            return
        # 1.5 periods, but never under 0.5 s: on a loaded host a beat can be a little late
        deadline = self.clock() + min(limit_s, max(0.5, 1.5 * max(w.heartbeat_ms or 0 for w in producing) / 1000))
        while self.clock() < deadline:
            with self._lock:
                if all(w.heartbeat_at is not None for w in producing):
                    return
            sleep(0.01)

    def snapshot(self) -> list[DriveStatus]:
        now = self.clock()
        with self._lock:
            positions = self._joint_positions()
            return [self._status(w, now, positions) for w in self.watches]

    # -- per drive --------------------------------------------------------------------------------

    def _per_bus(self, job: Callable[[_Watch], None], watches: Sequence[_Watch] | None = None) -> None:
        by_bus: dict[str, list[_Watch]] = {}
        for w in watches if watches is not None else self.watches:
            by_bus.setdefault(w.ref.bus, []).append(w)

        def run(ws: list[_Watch]) -> Callable[[], None]:
            def each() -> None:
                for w in ws:
                    job(w)
            return each

        for outcome in run_concurrently({bus: run(ws) for bus, ws in by_bus.items()}).values():
            if outcome.error is not None:
                raise outcome.error

    def _start_drive(self, w: _Watch) -> None:
        client = self.session.client(w.ref)
        client.nmt_start()
        sdo = self.session.sdo(w.ref)
        try:
            w.heartbeat_ms = int.from_bytes(sdo.upload(*PRODUCER_HEARTBEAT)[:2], "little")
        except SdoError as exc:
            w.problem = exc.detail  # the row already names the drive
            return  # no SDO answer: nothing else to ask at start; polling tells the rest
        if self.heartbeat_ms is not None and w.heartbeat_ms != self.heartbeat_ms:
            sdo.download(*PRODUCER_HEARTBEAT, self.heartbeat_ms.to_bytes(2, "little"))
            w.heartbeat_set_from, w.heartbeat_ms = w.heartbeat_ms, self.heartbeat_ms
        try:
            stored = int.from_bytes(sdo.upload(*ERROR_FIELD)[:4], "little")
        except SdoError:
            stored = 0  # no stored error, or the object is absent: nothing to show
        if stored:
            with self._lock:
                if w.emcy is None:  # one heard meanwhile is newer and carries its data fields
                    w.emcy = decode_error_field(stored)

    def _restore_heartbeat(self, w: _Watch) -> None:
        assert w.heartbeat_set_from is not None  # only drives whose 0x1017 was replaced get here
        try:
            self.session.sdo(w.ref).download(*PRODUCER_HEARTBEAT, w.heartbeat_set_from.to_bytes(2, "little"))
            w.heartbeat_set_from = None
        except SherpaError:
            pass  # the drive went away; its next power-up restores 0x1017 from flash anyway

    def _poll_drive(self, w: _Watch) -> None:
        client = self.session.client(w.ref)
        if w.polled and not w.answering:
            client.nmt_start()  # it may have rebooted into Pre-operational
        if not is_elmo(self.session, w.ref):
            self._poll_other(w)
            return
        joint = self.cfg.joint_of_drive(w.ref.name)
        # a drive that reads its joint's absolute encoder: PY too, to tell a counter that restarted
        values, problem = query(client, (*POLLED, "PY") if joint is not None and encoder_on_drive(joint) else POLLED)
        with self._lock:
            w.polled = True
            w.problem = problem
            w.answering = problem is None
            if problem is None:
                w.values = values
                w.answered_at = self.clock()
            else:
                w.values = {}  # never show frozen values of a drive that stopped answering

    def _poll_other(self, w: _Watch) -> None:
        """A drive of another type, through the seam: its power stage (the MO column) and position;
        a fault it reports is the row's problem. It has no UM, SR or MF to show."""
        drive = open_drive(self.session, w.ref)
        fault: str | None = None
        try:
            st = drive.status()
            values: dict[str, int | float] = {"MO": int(st.enabled), "PX": drive.position()}
            problem, fault = None, st.fault
        except SherpaError as exc:
            values, problem = {}, str(exc).removeprefix(f"{drive.label}: ")
        with self._lock:
            w.polled = True
            w.answering = problem is None
            w.problem = problem if problem is not None else (f"fault: {fault}" if fault else None)
            w.values = values
            if problem is None:
                w.answered_at = self.clock()

    def _heartbeat_callback(self, w: _Watch) -> Callable[[int, bytes, float], None]:
        def on_heartbeat(can_id: int, data: bytes, timestamp: float) -> None:
            if len(data) >= 1:
                with self._lock:
                    w.heartbeat_at = self.clock()
                    w.heartbeat_state = data[0]
        return on_heartbeat

    def _emcy_callback(self, w: _Watch) -> Callable[[Emcy], None]:
        def on_emcy(emcy: Emcy) -> None:
            with self._lock:
                w.emcy, w.emcy_at = emcy, self.clock()
        return on_emcy

    # -- snapshot ---------------------------------------------------------------------------------

    def _joint_positions(self) -> dict[str, JointPosition]:
        return joint_positions(self.cfg, {w.ref.name: int(w.values["PX"]) for w in self.watches
                                          if w.answering and isinstance(w.values.get("PX"), int)})

    def _status(self, w: _Watch, now: float, positions: dict[str, JointPosition]) -> DriveStatus:
        v = w.values if w.answering else {}
        sr, mf = v.get("SR"), v.get("MF")
        position = positions.get(w.ref.name)
        configured = self.cfg.joint_of_drive(w.ref.name)
        if position is not None and configured is not None:
            position = position.with_encoder(configured, _int(v.get("PY")))
        uncalibrated = position.uncalibrated if position is not None else None
        joint, rad = (position.joint, None if uncalibrated else position.rad) if position else (None, None)
        if joint is None and w.ref.config is not None:
            joint = row_joint(self.cfg, w.ref.name)
        return DriveStatus(
            drive=w.ref.name, bus=w.ref.bus, node=w.ref.node, nmt=self._nmt_text(w),
            heartbeat_ms=w.heartbeat_ms,
            heartbeat_age=None if w.heartbeat_at is None else max(0.0, now - w.heartbeat_at),
            answering=w.answering,
            silent_for=None if w.answering or w.answered_at is None else max(0.0, now - w.answered_at),
            mo=_int(v.get("MO")), um=_int(v.get("UM")), px=_int(v.get("PX")), sr=_int(sr), mf=_int(mf),
            joint=joint, position_rad=rad,
            sr_problems=decoded_sr(sr), mf_faults=decoded_mf(mf),
            emcy=w.emcy, emcy_age=None if w.emcy_at is None else max(0.0, now - w.emcy_at),
            emcy_before_start=w.emcy is not None and w.emcy_at is None, problem=w.problem,
            uncalibrated=uncalibrated)

    @staticmethod
    def _nmt_text(w: _Watch) -> str:
        if w.heartbeat_state is not None and w.heartbeat_ms:
            return nmt_text(w.heartbeat_state)
        if not w.polled:
            return "unknown"
        # no heartbeat to tell: the interpreter answers only in Operational
        return NMT_STATES[0x05] if w.answering else NO_ANSWER


def query(client: DriveClient, keys: Sequence[str]) -> tuple[dict[str, int | float], str | None]:
    """Query ``keys`` of one drive in order: (values, None), or (what was read, the problem) when a
    query fails -- one silent query is enough, the others are not waited out. The problem's text
    leaves out the drive's name: whoever shows it names the drive already."""
    values: dict[str, int | float] = {}
    for letters in keys:
        try:
            values[letters] = client.get(letters)
        except SherpaError as exc:
            return values, str(exc).removeprefix(f"{client.label}: ")
    return values, None


def decoded_sr(sr: object) -> tuple[Fault, ...]:
    """What in a status register (SR) needs a look; nothing when SR was not read."""
    return tuple(sr_problems(sr)) if isinstance(sr, int) else ()


def decoded_mf(mf: object) -> tuple[Fault, ...]:
    """The motor failures latched in MF; nothing when MF was not read."""
    return decode_mf(mf).faults if isinstance(mf, int) else ()


def _int(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


@dataclass(frozen=True)
class MonitorSnapshot:
    """Every watched drive at one poll (`Arm.monitor`): ``at`` is the monitor's clock, ``number`` counts
    the polls from 1. Each :class:`DriveStatus` holds the joint's position in rad beside PX in counts,
    the decoded SR and MF, the NMT state, the heartbeat and the last EMCY."""

    at: float
    number: int
    drives: tuple[DriveStatus, ...]

    def __getitem__(self, drive: str) -> DriveStatus:
        for d in self.drives:
            if d.drive == drive:
                return d
        raise KeyError(drive)

    def __iter__(self) -> Iterator[DriveStatus]:
        return iter(self.drives)

    def __len__(self) -> int:
        return len(self.drives)

    @property
    def ok(self) -> bool:
        """Every drive answered and none has a motor failure latched nor reports a fault (a drive of
        another type: its problem); what `monitor --once` exits 1 on."""
        return all(d.answering and not d.mf and not d.problem for d in self.drives)


def _snapshots(monitor: Monitor, interval: float, count: int | None, duration: float | None,
               clock: Callable[[], float], sleep: Callable[[float], None],
               first_waits_for_heartbeats: bool) -> Generator[MonitorSnapshot, None, None]:
    with monitor as mon:
        start = clock()
        number = 0
        while True:
            if number:
                sleep(interval)
            raise_if_signalled()  # a SIGTERM whose exception was lost (errors.py): no other ear for it
            mon.poll()
            if number == 0 and first_waits_for_heartbeats:
                mon.wait_for_heartbeats(sleep=sleep)
            number += 1
            yield MonitorSnapshot(clock(), number, tuple(mon.snapshot()))
            if count is not None and number >= count:
                return
            if duration is not None and clock() + interval - start > duration + 1e-9:
                return


class MonitorStream:
    """Snapshots of a :class:`Monitor`, one per poll, ``interval`` s apart on ``sleep``: at most
    ``count``, or until ``duration`` s have passed on ``clock`` (the first at once, none started
    after that), else until the caller stops. An iterator and a context manager: the monitor starts
    at the first snapshot and closes (0x1017 written back) when the stream ends, is closed, or the
    ``with`` is left. ``first_waits_for_heartbeats``: the first snapshot waits until every drive
    that produces a heartbeat was heard (`monitor --once`)."""

    def __init__(self, session: ArmSession, refs: Iterable[DriveRef], *, interval: float = 0.5,
                 count: int | None = None, duration: float | None = None, heartbeat_ms: int | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 first_waits_for_heartbeats: bool = False) -> None:
        if not (0 < interval <= MAX_INTERVAL_S):  # also refuses nan and inf (time.sleep(inf) overflows)
            raise UsageError(f"--interval {interval}: expected a number of seconds > 0 and <= {MAX_INTERVAL_S:g}")
        if count is not None and count < 1:
            raise UsageError(f"count {count}: expected at least 1 snapshot")
        if duration is not None and not 0 < duration <= MAX_DURATION_S:
            raise UsageError(f"--for {duration}: expected seconds > 0 and <= {MAX_DURATION_S:g}")
        self.monitor = Monitor(session, refs, heartbeat_ms=heartbeat_ms, clock=clock)
        self.interval, self.count, self.duration = interval, count, duration
        self.clock, self.sleep = clock, sleep
        self.first_waits_for_heartbeats = first_waits_for_heartbeats
        # a module-level generator that holds nothing of this stream: a stream dropped without
        # close() (a `for ... break` outside a `with`) takes the generator with it, whose exit then
        # closes the monitor (0x1017 written back); a bound method would keep both alive in a cycle
        self._run = _snapshots(self.monitor, interval, count, duration, clock, sleep, first_waits_for_heartbeats)

    def __iter__(self) -> MonitorStream:
        return self

    def __next__(self) -> MonitorSnapshot:
        return next(self._run)

    def close(self) -> None:
        """Stop polling; the monitor puts 0x1017 back."""
        self._run.close()

    def __enter__(self) -> MonitorStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


MAX_INTERVAL_S = 3600.0  # s between polls
MAX_DURATION_S = 86400.0
