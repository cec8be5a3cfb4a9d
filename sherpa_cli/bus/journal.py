"""The journal of temporary drive changes (docs/motion.md "After a crash").

Before a command changes a drive's RAM for its own use (the guard's UM, SP/AC/DC and dead-man objects,
the pair start's group id and RPDO2 type, homing's HM[1], the recorder's TPDO settings) it notes here
what it will change and the value to put back; once put back, the note is cleared. A command killed
in between (SIGKILL, a power loss of the host) leaves the note behind: one JSON file per drive in the
state directory, ``journal/<bus>-node<N>.json``, written atomically.

Each note is one undo step: an interpreter value (``UM=5``) or an SDO object (index, sub, size,
value), tagged with its owner. Steps are put back in reverse order (the recorder's PDO settings need
it). The next command that opens the drive finds them (:func:`leftover`); ``sherpa recover`` or
``--recover`` puts them back (:func:`restore`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.elmo.protocol import LOSS_ACTION
from sherpa_cli.errors import SafetyError, SherpaError
from sherpa_cli.paths import read_json, state_dir

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.drive import Drive
    from sherpa_cli.elmo.client import DriveClient

log = logging.getLogger(__name__)
_lock = threading.Lock()  # one read-modify-write of a drive's file at a time in this process
_auto_recover = False  # `sherpa --recover ...`: a motion command puts leftovers back itself


class LeftoverError(SafetyError):
    """A motion command found what a killed command left on a drive (exit 1): `sherpa recover`."""


@dataclass(frozen=True)
class Step:
    """One undo step: put ``old`` back into an interpreter value or an SDO object."""

    owner: str
    kind: str  # "interp" | "sdo"
    name: str  # "UM", "HM[1]", "0x1016:1"
    old: int | float
    letters: str = ""
    index: int = 0
    sub: int = 0
    size: int = 0
    pid: int = 0  # the process that made the change
    proc: str = ""  # that process's identity (process_identity): a pid reused later is not it

    def text(self) -> str:
        return f"{self.name}={self.old:#x}" if self.kind == "sdo" else f"{self.name}={self.old}"

    def as_json(self) -> dict[str, Any]:
        return {"owner": self.owner, "kind": self.kind, "name": self.name, "old": self.old,
                "letters": self.letters, "index": self.index, "sub": self.sub, "size": self.size,
                "pid": self.pid or os.getpid(), "proc": self.proc or (process_identity(os.getpid()) or "")}


def set_auto_recover(on: bool) -> None:
    global _auto_recover
    _auto_recover = on


def auto_recover() -> bool:
    return _auto_recover


def _write(path: Path, data: dict[str, Any]) -> None:
    """Atomic (a temporary file renamed over it) but without fsync: what a killed process wrote is in the
    kernel's page cache, and an fsync on a busy disk can stall a moving command past its liveness bound."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(json.dumps(data, indent=1))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def journal_dir() -> Path:
    return state_dir() / "journal"


def path_for(bus: str, node: int) -> Path:
    return journal_dir() / f"{bus}-node{node}.json"


def interp(owner: str, letters: str, index: int, old: int | float) -> Step:
    name = f"{letters}[{index}]" if index else letters
    return Step(owner, "interp", name, old, letters=letters, index=index)


def sdo(owner: str, index: int, sub: int, size: int, old: int) -> Step:
    return Step(owner, "sdo", f"0x{index:04X}:{sub}", int(old), index=index, sub=sub, size=size)


def _load(path: Path) -> dict[str, Any]:
    try:
        data = read_json(path, None)
    except (OSError, ValueError) as exc:
        log.warning("journal %s unreadable: %s", path, exc)
        return {}
    return data if isinstance(data, dict) else {}


def steps_of(data: dict[str, Any]) -> list[Step]:
    out = []
    for raw in data.get("steps", []):
        try:
            out.append(Step(str(raw["owner"]), str(raw["kind"]), str(raw["name"]), raw["old"],
                            str(raw.get("letters", "")), int(raw.get("index", 0)), int(raw.get("sub", 0)),
                            int(raw.get("size", 0)), int(raw.get("pid", 0)), str(raw.get("proc", ""))))
        except (KeyError, TypeError, ValueError):
            log.warning("journal: a damaged step skipped: %r", raw)
    return out


def note(ref: DriveRef, *steps: Step) -> None:
    """Before the change: add ``steps`` to the drive's journal (atomically, on disk before returning)."""
    if not steps:
        return
    path = path_for(ref.bus, ref.node)
    with _lock:
        data = _load(path) or {"drive": ref.name, "bus": ref.bus, "node": ref.node, "steps": []}
        data.setdefault("pids", [])
        if os.getpid() not in data["pids"]:
            data["pids"].append(os.getpid())
        data["steps"] = [*data.get("steps", []), *(s.as_json() for s in steps)]
        try:
            _write(path, data)
        except OSError as exc:
            # without its note a change could not be put back after a crash: it is not made
            raise SafetyError(f"{ref.name}: cannot write the journal {path}: {exc.strerror or exc}; "
                              f"the temporary change ({', '.join(s.name for s in steps)}) was not made",
                              hint=f"make {journal_dir()} a directory this user can write") from None


def own_steps(ref: DriveRef, owner: str) -> list[Step]:
    """``owner``'s notes on this drive that this process made and has not put back."""
    me = os.getpid()
    return [s for s in steps_of(_load(path_for(ref.bus, ref.node))) if s.owner == owner and s.pid == me]


def forget(ref: DriveRef, owner: str, names: set[str] | None = None) -> None:
    """The change was put back: drop ``owner``'s steps (only those named, if ``names``)."""
    path = path_for(ref.bus, ref.node)
    with _lock:
        data = _load(path)
        if not data:
            return
        keep = [s for s in data.get("steps", []) if not (s.get("owner") == owner and
                                                          (names is None or s.get("name") in names))]
        try:
            if keep:
                data["steps"] = keep
                _write(path, data)
            else:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
        except OSError as exc:  # the change is put back; a stale note only makes the next command ask for recover
            log.warning("journal %s: cannot drop %s's notes: %s", path, owner, exc.strerror or exc)


def process_identity(pid: int) -> str | None:
    """``<boot id>:<start time>`` of a process (Linux /proc): the same pid in another boot, or
    reused by a later process, reads differently. None where it cannot be read."""
    try:
        with open("/proc/sys/kernel/random/boot_id", encoding="ascii") as handle:
            boot = handle.read().strip()
        with open(f"/proc/{pid}/stat", encoding="utf-8", errors="replace") as handle:
            stat = handle.read()
        start = stat.rsplit(")", 1)[1].split()[19]  # field 22, counted after the command's name
    except (OSError, IndexError):
        return None
    return f"{boot}:{start}"


def _alive(pid: int, proc: str = "") -> bool:
    """Whether the process that made a change still runs: its pid exists and, where the note keeps
    the process's identity, it is that process (not a later one given the same pid, nor one of
    another boot)."""
    if pid <= 0:
        return False
    if pid != os.getpid():
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:  # another user's process: it exists
            pass
    if proc:
        now = process_identity(pid)
        if now is not None and now != proc:
            return False  # the pid was reused (or the machine rebooted since)
    return True


def leftover(ref: DriveRef) -> list[Step]:
    """What a command that did not finish left on this drive (empty: nothing). A drive another running
    command has changed (its process lives: a recording beside a jog) has no leftover."""
    steps = steps_of(_load(path_for(ref.bus, ref.node)))
    if any(_alive(s.pid, s.proc) for s in steps):
        return []
    return steps


def still_changed(session: ArmSession, ref: DriveRef, steps: list[Step],
                  drive: Drive | None = None) -> list[Step] | None:
    """The steps whose value on the drive is not the one to put back (NMT start first; reads only).
    Empty: the drive already holds every old value and no tripped dead-man is latched -- a drive
    reset or power-cycled since the note (its RAM back at flash values) leaves nothing to put back.
    None: the drive could not be read (a tripped drive, deaf in NMT Stopped until recover).
    ``drive``: a drive of another type than Elmo (the seam), whose state is read through it."""
    client = session.client(ref)
    out: list[Step] = []
    try:
        client.nmt_start()
        if drive is not None:
            if drive.status().fault is not None or any(s.kind == "interp" for s in steps):
                return None  # a latched fault (its consumer's?) is recover's to look at
        elif int(client.get("MF")) & MF_HEARTBEAT_LOSS:
            return None
        for s in steps:
            if s.kind == "interp":
                now = client.get(s.letters, s.index)
                if now != s.old:
                    out.append(s)
            else:
                raw = bytes(session.sdo(ref).upload(s.index, s.sub))[:s.size]
                mask = (1 << (8 * s.size)) - 1
                if int.from_bytes(raw, "little") & mask != int(s.old) & mask:
                    out.append(s)
    except (SherpaError, ValueError):
        return None
    return out


def damaged(ref: DriveRef) -> str | None:
    """What is wrong with the drive's journal file, if it exists and cannot be trusted: not JSON,
    truncated, not a journal, a step that cannot be read. None: no file, or a whole one. With a
    damaged file what a killed command changed is unknown: commands refuse the drive, and `recover`
    checks the drive itself (:func:`restore_damaged`)."""
    path = path_for(ref.bus, ref.node)
    if not path.exists():
        return None
    try:
        data = read_json(path, None)
    except (OSError, ValueError) as exc:
        return f"unreadable ({exc})"
    if not isinstance(data, dict) or not isinstance(data.get("steps"), list):
        return "not a journal (no list of steps)"
    for raw in data["steps"]:
        whole = (isinstance(raw, dict) and isinstance(raw.get("owner"), str) and isinstance(raw.get("name"), str)
                 and raw.get("kind") in ("interp", "sdo") and isinstance(raw.get("old"), (int, float))
                 and not isinstance(raw.get("old"), bool))
        if not whole:
            return f"a damaged step ({str(raw)[:60]})"
    return None


def damaged_text(ref: DriveRef, why: str) -> str:
    return (f"{ref.name} ({ref.bus}:{ref.node}): its journal {path_for(ref.bus, ref.node)} is damaged: {why}; "
            "what a command that did not finish changed is unknown")


def restore_damaged(session: ArmSession, ref: DriveRef, why: str, *, apply: bool,
                    boot_timeout: float = 5.0) -> RecoverResult:
    """A damaged journal: nothing says what to put back, but the drive's flash holds what the tool
    never changes for long. With ``apply`` and the motor off: NMT reset node (RAM reloaded from
    flash: unsaved values, the position counter and a homing mark are lost), then the file is moved
    aside (``.damaged``) for a look. Dry run: reads MO, MF and 0x1016:1 to say what is visible."""
    res = RecoverResult(ref.name, f"{ref.bus}:{ref.node}", [f"journal damaged: {why}"], done=[], problems=[])
    assert res.done is not None and res.problems is not None
    client = session.client(ref)
    try:
        client.nmt_start()
        mo, mf = int(client.get("MO")), int(client.get("MF"))
        raw = bytes(session.sdo(ref).upload(0x1016, 1))[:4]
    except SherpaError as exc:
        res.problems.append(f"not reached: {exc}")
        return res
    entry = int.from_bytes(raw, "little")
    seen = [f"0x1016:1=0x{entry:08X}" + (f" (watches host {entry >> 16 & 0x7F})" if entry & 0xFFFF else "")]
    if mf:
        seen.append(f"MF=0x{mf:X}")
    res.found.append("on the drive: " + ", ".join(seen))
    if mf & MF_HEARTBEAT_LOSS:
        res.tripped = "its dead-man tripped (MF 0x800 latched)"
    if not apply:
        return res
    problem = reset_to_flash(client, mo, boot_timeout)
    if problem is not None:
        res.problems.append(problem)
        return res
    res.done.append(RESET_DONE)
    path = path_for(ref.bus, ref.node)
    try:
        os.replace(path, path.with_name(path.name + ".damaged"))
        res.done.append(f"journal moved aside: {path.name}.damaged")
    except OSError as exc:
        res.problems.append(f"journal not moved aside: {exc.strerror or exc}")
    return res


RESET_DONE = "NMT reset node: RAM reloaded from flash (unsaved values, the position counter and a homing mark are lost)"


def reset_to_flash(client: DriveClient, mo: int, boot_timeout: float) -> str | None:
    """NMT reset node of a drive whose motor is off (``mo`` as read): None once it booted again, else
    the problem (the motor on: a reset would drop a load; no boot-up)."""
    if mo:
        return "the motor is on (MO=1): not reset; stop it first (`sherpa stop`)"
    try:
        client.reset_node(boot_timeout)
    except SherpaError as exc:
        return f"reset node: {exc}"
    return None


def leftover_text(ref: DriveRef, steps: list[Step]) -> str:
    owners = sorted({s.owner for s in steps})
    values = ", ".join(dict.fromkeys(s.text() for s in reversed(steps)))
    return (f"{ref.name} ({ref.bus}:{ref.node}): a {', '.join(owners)} that did not finish (killed?) left "
            f"temporary changes; to put back: {values}")


@dataclass
class RecoverResult:
    drive: str
    address: str
    found: list[str]
    tripped: str | None = None  # the aftermath of a tripped dead-man, when found
    already_back: bool = False  # the drive holds every noted value already (reset since): nothing to put back
    done: list[str] | None = None
    problems: list[str] | None = None


MF_HEARTBEAT_LOSS = 0x800


def restore(session: ArmSession, ref: DriveRef, *, apply: bool,
            clear_trip: Callable[[], None] | None = None, drive: Drive | None = None) -> RecoverResult:
    """Put back what the journal holds for ``ref`` (reverse order), NMT start first (a tripped dead-man
    leaves the drive in NMT Stopped, deaf to the interpreter and SDO), and clear a latched MF 0x800
    (heartbeat loss) once the objects are back with ``clear_trip`` (motion/trip_clear.py: MO=1, MO=0
    under a dead-man of its own; without it the MF stays and says so). The journal is dropped only
    when all of it is done: a recover killed half-way leaves it for the next. Dry run without
    ``apply``: only reads MF. Never raises for one step: problems are reported. ``drive``: a drive of
    another type than Elmo (the seam): :func:`restore_other`."""
    if drive is not None:
        return restore_other(session, ref, drive, apply=apply, clear_trip=clear_trip)
    steps = leftover(ref)
    done: list[str] = []
    problems: list[str] = []
    res = RecoverResult(ref.name, f"{ref.bus}:{ref.node}", list(dict.fromkeys(s.text() for s in reversed(steps))), done=done,
                        problems=problems)
    client = session.client(ref)
    try:
        client.nmt_start()
        mf = int(client.get("MF"))
        mo = int(client.get("MO"))
    except SherpaError as exc:
        problems.append(f"not reached: {exc}")
        return res
    armed = any(s.name == "0x1016:1" for s in steps)
    if mf & MF_HEARTBEAT_LOSS:
        res.tripped = ("its dead-man tripped: the drive's heartbeat consumer switched the motor off after the "
                       "command's heartbeat ended (MF 0x800 latched, NMT Stopped" +
                       (", the consumer still armed)" if armed else ")"))
    if steps and not mf & MF_HEARTBEAT_LOSS and still_changed(session, ref, steps) == []:
        res.already_back = True
        if apply:
            forget_all(ref)
        return res
    if not apply:
        return res
    if mo and steps:
        problems.append("the motor is on (MO=1): another tool moves it? nothing put back")
        return res
    failed = False
    for s in reversed(steps):
        try:
            if s.kind == "interp":
                client.set(s.letters, s.index, s.old)
            else:
                session.sdo(ref).download(s.index, s.sub, int(s.old).to_bytes(s.size, "little"))
            done.append(s.text())
        except (SherpaError, OverflowError) as exc:
            failed = True
            problems.append(f"{s.text()} not put back: {exc}")
    if res.tripped and not failed and mf == MF_HEARTBEAT_LOSS:
        if clear_trip is None:
            failed = True
            problems.append("MF 0x800 not cleared: nothing to arm a dead-man with here")
        else:
            try:
                clear_trip()  # MO=1 clears the latched MF, under a dead-man of its own; MO=0 confirmed
                done.append("MF 0x800 cleared (MO=1, MO=0 under a dead-man of its own)")
            except SherpaError as exc:
                failed = True
                problems.append(f"MF not cleared: {exc}")
    elif res.tripped and mf != MF_HEARTBEAT_LOSS:
        problems.append(f"MF=0x{mf:X} has more than the heartbeat loss: not cleared; find the cause first")
    if not failed:
        forget_all(ref)
    return res


def _loss_action(session: ArmSession, ref: DriveRef) -> int | None:
    """0x6007 as the drive holds it (what its consumer did when the heartbeat ended); None: unread."""
    try:
        raw = bytes(session.sdo(ref).upload(*LOSS_ACTION))[:2]
    except SherpaError:
        return None
    return int.from_bytes(raw.ljust(2, b"\0"), "little", signed=True)


LOSS_ACTIONS = {0: "no action", 1: "fault", 2: "disable voltage", 3: "quick stop"}


def restore_other(session: ArmSession, ref: DriveRef, drive: Drive, *, apply: bool,
                  clear_trip: Callable[[], None] | None = None) -> RecoverResult:
    """:func:`restore` for a drive of another type (the seam, sherpa_cli/drive.py; CiA 402): its
    state from the drive's own status, not the interpreter's MF/MO. A dead-man that tripped with
    0x6007 = 1 left it in Fault for the heartbeat loss: ``clear_trip`` resets that fault under a
    dead-man of its own once the objects are back (motion/trip_clear.py); with 0x6007 = 2 the drive
    was only disabled and the NMT start is all it needs. Any other fault is not reset."""
    steps = leftover(ref)
    done: list[str] = []
    problems: list[str] = []
    res = RecoverResult(ref.name, f"{ref.bus}:{ref.node}", list(dict.fromkeys(s.text() for s in reversed(steps))),
                        done=done, problems=problems)
    try:
        session.client(ref).nmt_start()  # 0x1029:1 may have stopped it: deaf to SDO until started
        st = drive.status()
    except SherpaError as exc:
        problems.append(f"not reached: {exc}")
        return res
    armed = any(s.name == "0x1016:1" for s in steps)
    action = _loss_action(session, ref) if armed else None
    how = f" (0x6007={action}: {LOSS_ACTIONS.get(action, 'unknown')})" if action is not None else ""
    if st.heartbeat_lost:
        res.tripped = (f"its dead-man tripped: the drive's heartbeat consumer put it in fault after the command's "
                       f"heartbeat ended{how}: {st.fault}" + ("; the consumer still armed" if armed else ""))
    elif st.fault is None and armed and not st.enabled:
        res.tripped = (f"the command's dead-man is still armed: when its heartbeat ended the drive's heartbeat "
                       f"consumer switched the power stage off{how}; nothing latched")
    if steps and st.fault is None and still_changed(session, ref, steps, drive) == []:
        res.already_back = True
        if apply:
            forget_all(ref)
        return res
    if st.fault is not None and not st.heartbeat_lost:
        res.found.append(f"in fault: {st.fault}")
    if not apply:
        return res
    if st.enabled and steps:
        # Operation enabled, or a quick stop / fault reaction still ramping (or held, 0x605A = 5..8):
        # the mode and profile objects are not written to a powered drive
        problems.append("the power stage is on: another tool moves it, or a quick stop holds it? nothing put back; "
                        f"`sherpa stop {ref.name}` switches it off at standstill")
        return res
    failed = False
    for s in reversed(steps):
        if s.kind != "sdo":
            failed = True
            problems.append(f"{s.text()} not put back: {drive.kind} drives have no interpreter")
            continue
        try:
            session.sdo(ref).download(s.index, s.sub, int(s.old).to_bytes(s.size, "little"))
            done.append(s.text())
        except (SherpaError, OverflowError) as exc:
            failed = True
            problems.append(f"{s.text()} not put back: {exc}")
    if st.heartbeat_lost and not failed:
        if clear_trip is None:
            failed = True
            problems.append("the fault not reset: nothing to arm a dead-man with here")
        else:
            try:
                clear_trip()  # the fault reset, under a dead-man of its own
                done.append(f"the heartbeat-loss fault reset ({st.fault}; controlword, under a dead-man of its own)")
            except SherpaError as exc:
                failed = True
                problems.append(f"the fault not reset: {exc}")
    elif st.fault is not None and not st.heartbeat_lost:
        problems.append(f"in fault ({st.fault}), more than the heartbeat loss: not reset; find the cause first")
    if not failed:
        forget_all(ref)
    return res


def forget_all(ref: DriveRef) -> None:
    with _lock, contextlib.suppress(FileNotFoundError):
        path_for(ref.bus, ref.node).unlink()
