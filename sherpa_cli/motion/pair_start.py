"""Starting both motors of a differential pair together (``motion.pair_start``), and the stop that
runs before its restore. Shared by `diffdrive move`, the pair jog, the live jog and `home`."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from sherpa_cli.bus import journal, syncgate
from sherpa_cli.config.model import PAIR_START_METHODS, ArmConfig
from sherpa_cli.elmo.protocol import GROUP_INDEX, RPDO2_BASE, SYNC_ID, TPDO2_BASE
from sherpa_cli.errors import ConfigError, DriveTimeoutError
from sherpa_cli.motion.guard import PAIR_START_OWNER as JOURNAL_OWNER
from sherpa_cli.motion.settings import PROFILE_KEYS, MotionSettings

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.elmo.codec import Reply
    from sherpa_cli.motion.guard import MotionGuard

RPDO2_COMM = 0x1401  # RPDO2 (the binary interpreter's) communication parameter; sub 2 = transmission type
SYNC_RPDO_TYPE = 1  # synchronous: executed at the next SYNC ([IG] 5-4)
RPDO2_TYPE_NAME = "RPDO2 transmission type"


def group_reset(guard: MotionGuard, cfg: ArmConfig) -> Callable[[Sequence[DriveRef]], None] | None:
    """The reset communication a ``group`` start needs (``motion.pair_group_reset_comm``), under ``guard``."""
    if not cfg.motion.pair_group_reset_comm:
        return None
    return lambda refs: guard.reset_communication(refs, cfg.protocol.boot_timeout,
                                                  "the pair's group id 0x2040 takes effect")


def pair_settings(cfg: ArmConfig) -> tuple[str, int]:
    """(pair_start, pair_group_id) from ``motion:``, checked."""
    m = cfg.motion
    if m.pair_start not in PAIR_START_METHODS:
        raise ConfigError(f"motion.pair_start: '{m.pair_start}' is not one of {', '.join(PAIR_START_METHODS)}")
    if not 1 <= m.pair_group_id <= 127 or m.pair_group_id in m.host_ids:
        raise ConfigError(f"motion.pair_group_id: {m.pair_group_id} must be 1..127 and not one of the host "
                          f"ids {', '.join(map(str, m.host_ids))}")
    return m.pair_start, m.pair_group_id


class CommonStart:
    """Starts both motors of a pair together; restores what it changed (0x2040 or 0x1401:2, and the
    SP/AC/DC kept with :meth:`keep_profile`; RAM) on close.

    ``method`` (``motion.pair_start``): ``group`` (0x2040 = the group id on both drives, one BG to
    the group id), ``sync_rpdo`` (for each begin RPDO2 is made synchronous on both drives, 0x1401:2
    = 1; BG to each drive is then buffered until one SYNC the tool sends right after them, which
    both drives execute on the same frame -- the BGs and that SYNC are one critical section of the
    bus's SYNC gate (bus/syncgate.py), so no other SYNC of the tool falls between them; the old
    transmission type goes back at once and the BG answers are awaited), ``sequential`` (BG, BG). Use as a context manager inside the motion
    guard. ``stop`` (:func:`stop_motors`) runs on the way out before the restore, so no motor keeps
    moving through the restore's SDO timeouts."""

    def __init__(self, session: ArmSession, refs: Sequence[DriveRef], clients: Mapping[str, DriveClient], method: str,
                 group_id: int, stop: Callable[[], Sequence[str] | None] | None = None,
                 reset_comm: Callable[[Sequence[DriveRef]], None] | None = None) -> None:
        self.session, self.refs, self.clients, self.method, self.group_id = session, list(refs), clients, method, group_id
        # group: the NMT reset communication that makes 0x2040 take effect and arms the dead-man again
        # (MotionGuard.reset_communication); None where the drive needs none (motion.pair_group_reset_comm)
        self.reset_comm = reset_comm
        self._prepared = False
        self._old: dict[str, int] = {}
        self._rpdo_type: dict[str, int] = {}  # sync_rpdo: each drive's own 0x1401:2
        self._synchronous: set[str] = set()  # drives whose RPDO2 is synchronous right now
        self._profiles: dict[str, dict[str, int]] = {}
        self.stop = stop
        self.bus = refs[0].bus

    def __enter__(self) -> CommonStart:
        self.prepare()
        return self

    def prepare(self) -> None:
        """What the start needs on the drives before any motor is on: the group id written (and, with
        ``reset_comm``, made effective by a reset communication, which puts back the communication
        objects -- so it comes before a recording's PDO set-up), or RPDO2's own type read. Once; a
        caller that prepares early registers :meth:`close` for every way out."""
        if self._prepared:
            return
        self._prepared = True
        if self.method in ("group", "sync_rpdo") and len({r.bus for r in self.refs}) != 1:
            raise ConfigError(f"motion.pair_start={self.method} needs both drives of the pair on one bus; "
                              "use pair_start: sequential")
        if self.method == "group":
            clash = [n for n, d in self.session.cfg.drives.items()
                     if d.bus == self.bus and d.node == self.group_id]
            if clash:
                raise ConfigError(f"motion.pair_group_id {self.group_id} is the node id of {clash[0]} on bus "
                                  f"{self.bus}: choose an id no device uses")
        try:
            for r in self.refs:
                sdo = self.session.sdo(r)
                if self.method == "group":
                    old = (bytes(sdo.upload(GROUP_INDEX, 0, name="group id")) + b"\0")[0]
                    if old != self.group_id:
                        journal.note(r, journal.sdo(JOURNAL_OWNER, GROUP_INDEX, 0, 1, old))
                        sdo.download(GROUP_INDEX, 0, bytes([self.group_id]), name="group id")
                        self._old[r.name] = old
                elif self.method == "sync_rpdo":
                    self._rpdo_type[r.name] = (bytes(sdo.upload(RPDO2_COMM, 2, name=RPDO2_TYPE_NAME)) + b"\0")[0]
            if self.method == "group" and self.reset_comm is not None:
                self.reset_comm(self.refs)
        except BaseException:
            self.close()
            raise

    def begin(self, drives: Sequence[str] | None = None) -> None:
        """BG for the named drives (default both): one group frame, two BG executed at one SYNC, or
        one BG per drive."""
        from sherpa_cli.elmo import codec

        names = list(drives) if drives is not None else [r.name for r in self.refs]
        if self.method == "group" and len(names) == len(self.refs):
            self.session.links[self.bus].network.send_message(RPDO2_BASE + self.group_id,
                                                              codec.encode_execute("BG"))
            return
        if self.method == "sync_rpdo" and len(names) == len(self.refs):
            self._sync_begin()
            return
        for n in names:
            self.clients[n].execute("BG")

    def _sync_begin(self) -> None:
        import threading

        from sherpa_cli.elmo import codec
        from sherpa_cli.errors import DriveRefusedError, DriveTimeoutError

        network = self.session.links[self.bus].network
        answers: dict[str, Reply] = {}
        arrived = {r.name: threading.Event() for r in self.refs}
        subscribed: list[tuple[int, Callable[[int, bytes, float], None]]] = []

        def listener(name: str) -> Callable[[int, bytes, float], None]:
            def on_reply(can_id: int, data: bytes, timestamp: float) -> None:
                try:
                    reply = codec.decode_reply(bytes(data))
                except Exception:  # noqa: BLE001 - on the receive thread: a frame that is no reply is not the BG's answer
                    return
                if reply.letters == "BG" and name not in answers:
                    answers[name] = reply
                    arrived[name].set()
            return on_reply
        try:
            for r in self.refs:
                if self._rpdo_type[r.name] != SYNC_RPDO_TYPE:
                    self._synchronous.add(r.name)
                    journal.note(r, journal.sdo(JOURNAL_OWNER, RPDO2_COMM, 2, 1, self._rpdo_type[r.name]))
                    self.session.sdo(r).download(RPDO2_COMM, 2, bytes([SYNC_RPDO_TYPE]), name=RPDO2_TYPE_NAME)
            for r in self.refs:
                callback = listener(r.name)
                network.subscribe(TPDO2_BASE + r.node, callback)
                subscribed.append((TPDO2_BASE + r.node, callback))
            # one critical section: no other SYNC of this tool (the recorder's) between the BG frames,
            # or the first motor would start one SYNC before the second
            with syncgate.gate(self.session.links[self.bus].bus).exclusive():
                for r in self.refs:  # buffered by each drive until the SYNC
                    network.send_message(RPDO2_BASE + r.node, codec.encode_execute("BG"))
                network.send_message(SYNC_ID, b"")
            wait = 2 * max(getattr(c, "timeout", 0.1) for c in self.clients.values())
            for r in self.refs:
                arrived[r.name].wait(wait)
        finally:
            for cob, callback in subscribed:
                network.unsubscribe(cob, callback)
            self._restore_rpdo(quiet=False)
        for r in self.refs:
            reply = answers.get(r.name)
            if reply is None:
                raise DriveTimeoutError(f"{r.name}: no answer to the BG executed at the SYNC within {wait:g} s",
                                        hint="does the drive execute a synchronous RPDO2 (0x1401:2 = 1)? "
                                             "motion.pair_start: group or sequential starts it without SYNC")
            if not reply.ok:
                raise DriveRefusedError(f"{r.name}: BG at the SYNC refused: {reply.error_text}", drive=r.name,
                                        command="BG", code=reply.error_code)

    def _restore_rpdo(self, quiet: bool = True) -> None:
        for r in self.refs:
            if r.name in self._synchronous:
                try:
                    self._put_rpdo_type(r)
                except Exception:
                    if not quiet:
                        raise

    def _put_rpdo_type(self, ref: DriveRef) -> None:
        self.session.sdo(ref).download(RPDO2_COMM, 2, bytes([self._rpdo_type[ref.name]]), name=RPDO2_TYPE_NAME)
        journal.forget(ref, JOURNAL_OWNER, {f"0x{RPDO2_COMM:04X}:2"})
        self._synchronous.discard(ref.name)

    def keep_profile(self, drive: str) -> None:
        """Read ``drive``'s SP/AC/DC before they are changed; :meth:`close` puts them back:
        a scaled profile (SP=AC=DC=1 for a motor with no share) must not outlive the command."""
        if drive not in self._profiles:
            c = self.clients[drive]
            self._profiles[drive] = {k: int(c.get(k)) for k in PROFILE_KEYS}

    def close(self, deaf: Sequence[str] = ()) -> None:
        """Put back everything changed, drive by drive. A failure skips only that write (a drive
        that does not answer: the rest of that drive; ``deaf``, drives that did not answer the stop:
        all of it); a second Ctrl-C does not skip the rest of the restore, it is raised once the
        restore is done."""
        interrupted: BaseException | None = None
        for r in self.refs:
            writes: list[Callable[[], None]] = []
            if r.name in deaf:  # each write would only wait out its timeouts before the guard's exit
                self._profiles.pop(r.name, None)
                self._old.pop(r.name, None)
                self._synchronous.discard(r.name)
            if r.name in self._synchronous:  # first: a synchronous RPDO2 would hold back the sets below
                writes.append(functools.partial(self._put_rpdo_type, r))
            for key, value in self._profiles.pop(r.name, {}).items():
                writes.append(functools.partial(self.clients[r.name].set, key, 0, value))
            if r.name in self._old:
                writes.append(functools.partial(self._put_group_id, r, self._old.pop(r.name)))
            for write in writes:
                try:
                    write()
                except DriveTimeoutError:
                    break  # it does not answer: no more waits for it (the guard's exit reports the drive)
                except Exception:  # noqa: BLE001 - the next command's start writes it again; nothing was saved
                    pass
                except BaseException as exc:  # noqa: BLE001 - a second Ctrl-C: kept and raised once the restore is done
                    interrupted = interrupted or exc
        if interrupted is not None:
            raise interrupted

    def _put_group_id(self, ref: DriveRef, value: int) -> None:
        self.session.sdo(ref).download(GROUP_INDEX, 0, bytes([value]), name="group id")
        journal.forget(ref, JOURNAL_OWNER, {f"0x{GROUP_INDEX:04X}:0"})

    def __exit__(self, *exc: object) -> None:
        deaf: Sequence[str] = ()
        try:
            if self.stop is not None:
                deaf = self.stop() or ()  # every motor stopped before the restore
        finally:
            self.close(deaf)


def stop_motors(guard: MotionGuard, refs: Sequence[DriveRef], settings: MotionSettings) -> Callable[[], list[str]]:
    """The stop :class:`CommonStart` runs before its restore: the guard's stop to every motor
    (motion.stop_drive: TC=0 in torque mode, ST or JV=0 + BG as motion.stop_method says; a motor
    that is off gets nothing), one drive after the other, without waiting for standstill -- the
    guard's exit then waits for it, switches off and reports. Never raises (an error of one drive
    must not leave the next unstopped); no sign of life is asked of the guard here, since after a
    signal its check raises at once. Returns the drives that did not answer."""
    def stop() -> list[str]:
        from sherpa_cli.errors import CommunicationError
        from sherpa_cli.motion.stopping import stop_drive

        deaf: list[str] = []
        # a silent drive (no answer to its last request) gets nothing: its partner is stopped at once
        # instead of after that drive's timeouts; its own consumer stops it when the heartbeat ends
        for r in refs:
            if guard.client(r).silent:
                deaf.append(r.name)
        for r in refs:
            if r.name in deaf:
                continue
            try:
                # a drive reset by another node is in Pre-operational, deaf to the stop until started
                # (it moves nothing: a reset drive's motor is off)
                guard.client(r).nmt_start()
                stop_drive(guard.client(r), unit_mode=guard.unit_mode(r), method=settings.stop_method,
                           standstill_timeout=0.0, poll_interval=settings.poll_interval,
                           standstill_velocity=settings.standstill_velocity)
            except CommunicationError:
                deaf.append(r.name)
            except Exception:  # noqa: BLE001 - never raises: the guard's exit stops and reports every drive
                pass
        return deaf
    return stop
