"""`sherpa recover --check-drives`: what a drive's RAM says about a command that did not finish,
without a journal.

The journal knows what a killed command changed only while it exists and is whole, and only for
commands of this state directory. A journal deleted by hand, another user's or another host's
command, or a tool killed before its note reached the disk leave nothing to read there. So this
reads the drive itself, for the temporary changes that can be recognised without knowing the old
value:

- 0x1016:1 watching a ``motion.host_id_pool`` id that no sherpa command of this machine holds (a
  dead-man left armed: any node sending that id keeps the motor on);
- MF 0x800 latched (a dead-man that tripped);
- HM[1] = 1 (homing left armed: the next switch or index event captures the position);
- on a pair's drive, 0x2040 = ``motion.pair_group_id`` (a pair start's group id) or RPDO2 left
  synchronous (0x1401:2 = 1: the interpreter's commands wait for a SYNC);
- the drive's recorder armed or recording (RR 1..3).

What cannot be recognised this way (UM, SP/AC/DC, 0x6007, 0x1029, TPDO settings, the recorder's
RC/RG/RL/RV/RP) has no "at rest" value but the flash's. ``--apply`` therefore does what proves
them all at once: NMT reset node (RAM reloaded from flash) on a drive with a finding and its motor
off, then reads everything again; a finding that survives the reset is held by the flash and is
reported as such, never as put back.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.bus import journal
from sherpa_cli.bus.machine_lock import MachineLock, wire_key
from sherpa_cli.elmo.protocol import GROUP_INDEX
from sherpa_cli.errors import SherpaError
from sherpa_cli.motion.host_ids import watched_host
from sherpa_cli.motion.pair_start import RPDO2_COMM, SYNC_RPDO_TYPE

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.config.model import ArmConfig

MF_HEARTBEAT_LOSS = 0x800
RECORDER_BUSY = (1, 2, 3)  # RR: waiting or recording (elmo/recorder.py)


@dataclass(frozen=True)
class Finding:
    """One sign of a temporary change on a drive: the object, the value read, what it means."""

    what: str
    value: str
    meaning: str

    def text(self) -> str:
        return f"{self.what}={self.value}: {self.meaning}"


@dataclass
class DriveRest:
    """What one drive's RAM showed, and with ``--apply`` what was done."""

    drive: str
    address: str
    findings: list[Finding] = field(default_factory=list)
    in_use: str | None = None  # a running command owns the drive: not judged
    done: list[str] = field(default_factory=list)
    after_reset: list[Finding] | None = None  # read again after the reset node
    problems: list[str] = field(default_factory=list)

    @property
    def at_rest(self) -> bool:
        return not self.findings and not self.problems


def _holder(session: ArmSession, ref: DriveRef, host: int) -> int | None:
    link = session.links[ref.bus].config
    return MachineLock(wire_key(link.interface, link.channel), f"host{host}").holder()


def read_findings(session: ArmSession, cfg: ArmConfig, ref: DriveRef) -> tuple[list[Finding], str | None]:
    """The findings on ``ref`` (NMT start first: a tripped drive is deaf in Stopped), and who uses it
    if a running sherpa command does. Raises SherpaError when the drive cannot be read."""
    client = session.client(ref)
    sdo = session.sdo(ref)
    client.nmt_start()
    out: list[Finding] = []
    entry = int.from_bytes((bytes(sdo.upload(0x1016, 1, name="consumer heartbeat time")) + bytes(4))[:4], "little")
    host = watched_host(entry)
    pool = {i & 0x7F for i in cfg.motion.host_ids}
    if host is not None and host in pool:
        pid = _holder(session, ref, host)
        if pid is not None:
            return [], f"its dead-man watches host {host}, held by sherpa" + (f" pid {pid}" if pid else "") + \
                ": a command is running on it"
        out.append(Finding("0x1016:1", f"0x{entry:08X}",
                           f"a dead-man on host {host} that no sherpa command of this machine holds (left by a "
                           "command that did not finish, or another host's): any node sending that id keeps "
                           "the motor on"))
    if cfg.pair_of_drive(ref.name) is not None:
        group = bytes(sdo.upload(GROUP_INDEX, 0, name="group id"))[0]
        if group == cfg.motion.pair_group_id:
            out.append(Finding("0x2040", str(group), "the pair start's group id left set"))
        rpdo2 = bytes(sdo.upload(RPDO2_COMM, 2, name="RPDO2 transmission type"))[0]
        if rpdo2 == SYNC_RPDO_TYPE:
            # the interpreter's requests would wait for a SYNC: what it would tell is left to the
            # read after the reset
            out.append(Finding("0x1401:2", str(rpdo2), "RPDO2 left synchronous: the interpreter's commands wait "
                               "for a SYNC (MF, HM[1] and RR not read)"))
            return out, None
    mf = int(client.get("MF"))
    if mf & MF_HEARTBEAT_LOSS:
        out.append(Finding("MF", f"0x{mf:X}", "its dead-man tripped (heartbeat loss latched)"))
    if int(client.get("HM", 1)) == 1:
        out.append(Finding("HM[1]", "1", "homing left armed: the next switch or index event captures the position"))
    rr = int(client.get("RR"))
    if rr in RECORDER_BUSY:
        out.append(Finding("RR", str(rr), "the drive's recorder left armed or recording"))
    return out, None


def check_drive(session: ArmSession, cfg: ArmConfig, ref: DriveRef, *, apply: bool,
                boot_timeout: float = 5.0, read: Callable[..., tuple[list[Finding], str | None]] = read_findings,
                ) -> DriveRest:
    """One drive: its findings; with ``apply``, a reset node where something was found, then a read again."""
    res = DriveRest(ref.name, ref.address)
    if journal.leftover(ref) or journal.damaged(ref) is not None:
        res.problems.append("its journal has notes: `sherpa recover` puts those back first")
        return res
    try:
        res.findings, res.in_use = read(session, cfg, ref)
    except SherpaError as exc:
        res.problems.append(f"not reached: {exc}")
        return res
    if res.in_use or not res.findings or not apply:
        return res
    if any(f.what == "0x1401:2" for f in res.findings):
        # the interpreter cannot say whether the motor is on, and a reset switches it off under a load
        res.problems.append("RPDO2 is synchronous: the interpreter cannot tell whether the motor is on, so no "
                            "reset; switch the drive's power off and on (the flash's RPDO2 type comes back)")
        return res
    client = session.client(ref)
    try:
        mo = int(client.get("MO"))
    except SherpaError as exc:
        res.problems.append(f"not reached: {exc}")
        return res
    problem = journal.reset_to_flash(client, mo, boot_timeout)
    if problem is not None:
        res.problems.append(problem)
        return res
    res.done.append(journal.RESET_DONE)
    try:
        res.after_reset, _ = read(session, cfg, ref)
    except SherpaError as exc:
        res.problems.append(f"not read after the reset: {exc}")
        return res
    for f in res.after_reset:
        res.problems.append(f"{f.what}={f.value} after the reset: the flash holds it ({f.meaning})")
    return res
