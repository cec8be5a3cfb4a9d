"""Clearing a tripped dead-man (MF 0x800, heartbeat lost) under a dead-man of its own.

MO=1 is how an Elmo drive clears a latched MF, and it switches the motor on. `recover` used to send
it after putting the consumer entry back (0x1016:1 = 0): for the half second until its MO=0, a motor
was on with nothing watching, and a `recover` killed in that window left it on. Here the MO=1 comes
only after the rule every motion command keeps: an id of its own (listened for, machine lock), loss
action, error behaviour and consumer armed in RAM (journaled first, owner "recover"), the heartbeat
from this process's thread and one beat before MO=1. Then MO=0 confirmed, the objects put back, the
notes dropped.

The id is none another drive of the bus still watches (0x1016:1), the rule every motion command
keeps (motion/host_ids.py OtherConsumers): a killed pair command leaves both drives watching its id,
and a heartbeat on it re-armed the partner's consumer, which tripped again when this heartbeat ended
-- while the partner was being put back, on a slow enough computer. A drive a killed command left
is NMT-started first: its own trip may have left it deaf to that read.

A drive of another type (the seam; CiA 402) has no MO=1 to clear with: its consumer's 0x6007 = 1 left
it in Fault, and the fault reset (controlword bit 7) takes it to Switch on disabled, its power stage
still off. It is sent under the same dead-man all the same: the rule is that nothing is sent to clear
a trip without one, whatever the drive type does with it.
"""

from __future__ import annotations

import contextlib
import logging
import struct
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from sherpa_cli.bus import journal
from sherpa_cli.bus.machine_lock import wire_key
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.drive import Drive, FaultResettable
from sherpa_cli.errors import SafetyError, SherpaError, raise_if_signalled
from sherpa_cli.motion.deadman import COMM_ERROR, CONSUMER, LOSS_ACTION, OBJECT_NAMES, SIZES, HostHeartbeat
from sherpa_cli.motion.host_ids import HostIdListener, OtherConsumers
from sherpa_cli.motion.lock import HostIdLock

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.settings import MotionSettings

log = logging.getLogger(__name__)
OWNER = "recover"


def clear_heartbeat_trip(session: ArmSession, ref: DriveRef, settings: MotionSettings, *,
                         clock: Callable[[], float] = time.monotonic,
                         sleep: Callable[[float], None] = time.sleep, drive: Drive | None = None) -> None:
    """MO=1, MO=0 on ``ref`` with its dead-man armed for this process (see the module docstring);
    ``drive`` (another drive type, the seam): its fault reset instead, under the same dead-man.
    Raises SherpaError when it could not; whatever it armed and could not put back stays journaled."""
    if drive is not None and not isinstance(drive, FaultResettable):
        raise SafetyError(f"{drive.label}: a {drive.kind} drive's fault is not reset by sherpa",
                          hint="reset it on the drive once the cause is found")
    client = session.client(ref)
    link = session.links[ref.bus]
    sdo = session.sdo(ref)
    listener = HostIdListener({ref.bus: link.network}, settings.host_ids)
    ids = HostIdLock({ref.bus: wire_key(link.config.interface, link.config.channel)}, settings.host_ids)
    others = OtherConsumers([r for r in drive_refs(session.cfg, None) if r.bus == ref.bus and r.key != ref.key],
                            settings.host_ids, lambda r: _consumer_entry(session, r))
    heartbeat: HostHeartbeat | None = None
    armed: list[tuple[tuple[int, int], int]] = []
    switched = False
    allowance = max(settings.liveness_timeout, 3 * settings.request_bound)

    def read(key: tuple[int, int]) -> int:
        raw = (bytes(sdo.upload(*key, name=OBJECT_NAMES[key])) + bytes(4))[:struct.calcsize(SIZES[key])]
        return int(struct.unpack(SIZES[key], raw)[0])

    def write(key: tuple[int, int], value: int) -> None:
        sdo.download(key[0], key[1], struct.pack(SIZES[key], value), name=OBJECT_NAMES[key])

    listener.start()
    try:
        end = clock() + settings.host_id_listen_for(ids.private)
        for other in others.refs:
            if journal.leftover(other):
                # a drive a killed command left: its own trip may have put it in NMT Stopped, deaf to
                # the read of its consumer entry (recover NMT-starts it anyway)
                with contextlib.suppress(SherpaError):
                    session.client(other).nmt_start()
        others.read_all(between=raise_if_signalled)  # while listening
        while (left := end - clock()) > 0:
            sleep(min(left, 0.05))
            raise_if_signalled()
        host_id = ids.acquire(listener.heard(), others.watched())
        heartbeat = HostHeartbeat(lambda: [link.network], host_id, settings.heartbeat_period, allowance)
        for key, value in ((LOSS_ACTION, settings.loss_action), (COMM_ERROR, settings.comm_error_behaviour),
                           (CONSUMER, settings.consumer_entry_for(host_id))):
            before = read(key)
            if before == value:
                continue
            journal.note(ref, journal.sdo(OWNER, key[0], key[1], struct.calcsize(SIZES[key]), before))
            armed.append((key, before))
            write(key, value)
        heartbeat.start()
        heartbeat.beat_now()  # the consumer watches from the first heartbeat after its entry: before MO=1
        if listener.foreign(host_id, heartbeat.sent):
            raise SafetyError(f"{ref.name}: another node sends heartbeats as {host_id}, the dead-man id taken "
                              f"to clear the trip: {'fault not reset' if drive is not None else 'MF not cleared'}")
        if isinstance(drive, FaultResettable):
            heartbeat.pulse(allowance + client.settings.mo_confirm_timeout)
            drive.fault_reset()  # to Switch on disabled: the power stage stays off
        else:
            if int(client.get("UM")) == 1 and client.get("TC") != 0:
                client.set("TC", 0, 0.0)  # MO=1 in torque mode applies TC at once
            heartbeat.pulse(allowance + client.settings.mo_confirm_timeout)
            switched = True
            client.motor_on()
            heartbeat.pulse(allowance + client.settings.mo_confirm_timeout)
            client.motor_off()
            switched = False
    finally:
        problems: list[str] = []
        if switched:  # an error between MO=1 and its MO=0: off before anything is disarmed
            try:
                if heartbeat is not None:
                    heartbeat.pulse(allowance + client.settings.mo_confirm_timeout)
                client.motor_off()
            except SherpaError as exc:
                problems.append(f"MO=0 not confirmed: {exc}")
        if not problems:
            for key, before in reversed(armed):
                try:
                    write(key, before)
                except SherpaError as exc:
                    problems.append(f"0x{key[0]:04X}:{key[1]} not put back: {exc}")
            if not problems and armed:
                journal.forget(ref, OWNER)
        if heartbeat is not None:
            heartbeat.stop()
        with contextlib.suppress(Exception):
            ids.release()
        listener.stop()
        if problems:
            # the consumer stays armed: with this heartbeat gone, the drive switches itself off
            log.warning("%s: clearing the trip: %s", ref.name, "; ".join(problems))
            raise SafetyError(f"{ref.name}: clearing the trip: {'; '.join(problems)}",
                              hint=f"`sherpa recover {ref.name} --apply` tries again")


def _consumer_entry(session: ArmSession, ref: DriveRef) -> int:
    raw = session.sdo(ref).upload(*CONSUMER, name=OBJECT_NAMES[CONSUMER])
    return int.from_bytes((bytes(raw) + bytes(4))[:4], "little")
