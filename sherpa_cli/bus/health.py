"""Is a bus fit to move motors on or to save on? The one preflight every moving command and recipe runs.

:func:`findings` judges one :class:`~sherpa_cli.bus.linkstate.LinkStatus`: a missing interface, a
link that is down or stopped, BUS-OFF, ERROR-PASSIVE, a bit rate that differs from the config. A
figure the interface does not report (vcan has no controller, python-can-remote no netlink) is
never a refusal: nothing is guessed either way.

:func:`check_buses` refuses with :class:`BusStateError` (exit 3) naming the bus, what is wrong and
the fix; :func:`preflight` is what the motion guard calls on entry: the buses its drives are on, then
the drives' user programs (PS; refused unless the session allows them: ``--allow-user-program``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.bus.linkstate import BUS_OFF, PASSIVE, STOPPED, LinkStatus, read_link
from sherpa_cli.errors import CommunicationError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef


class BusStateError(CommunicationError):
    """A bus is not fit for motion or saving: missing, down, BUS-OFF, ERROR-PASSIVE, wrong bit rate (exit 3)."""

    def __init__(self, message: str, *, bus: str, problem: str, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.bus = bus
        self.problem = problem


@dataclass(frozen=True)
class Finding:
    """One thing wrong with a bus: a short key, the sentence, the fix."""

    problem: str  # missing | down | stopped | bus-off | error-passive | bitrate | unreadable
    text: str
    hint: str


def _where(s: LinkStatus) -> str:
    return f"bus {s.bus} ({s.interface or 'python-can config'}:{s.channel or '-'})"


def findings(s: LinkStatus) -> list[Finding]:
    """What makes this bus unfit for motion or SV; empty when nothing it reports is wrong."""
    out: list[Finding] = []
    chan = s.channel or s.bus
    if s.present is False:
        out.append(Finding("missing", f"no interface {chan}",
                           f"plug in the adapter and check `ip link show {chan}` (docs/bus.md)"))
        return out
    if s.up is False:
        out.append(Finding("down", "the link is down",
                           f"`sherpa bus up {s.bus}` (or as root: ip link set {chan} up)"))
        return out
    if s.can_state == BUS_OFF:
        out.append(Finding("bus-off", "the controller is BUS-OFF (it stopped sending after too many errors)",
                           "check wiring, termination and the bit rate of every node (`sherpa bus watch` shows the "
                           f"error frames); it restarts after restart-ms, or `sherpa bus down {s.bus}` then "
                           f"`sherpa bus up {s.bus}`"))
    elif s.can_state == PASSIVE:
        out.append(Finding("error-passive", "the controller is ERROR-PASSIVE "
                           f"(TEC {s.tec if s.tec is not None else '?'}, REC {s.rec if s.rec is not None else '?'})",
                           "the bus keeps failing: check termination (120 ohm at each end), wiring and that every "
                           "node has the same bit rate; `sherpa bus watch` names the error frames"))
    elif s.can_state == STOPPED:
        out.append(Finding("stopped", "the controller is STOPPED", f"`sherpa bus up {s.bus}`"))
    if s.bitrate_mismatch:
        out.append(Finding("bitrate", f"bit rate {s.bitrate} differs from the config's {s.configured_bitrate}",
                           f"`sherpa bus down {s.bus}` then `sherpa bus up {s.bus}` sets the config's bit rate; "
                           f"or correct buses.{s.bus}.bitrate"))
    return out


def check_status(statuses: Iterable[LinkStatus], what: str = "moving") -> None:
    """Raise BusStateError for the first bus with a finding (every finding of that bus in the message)."""
    for s in statuses:
        found = findings(s)
        if found:
            raise BusStateError(f"{_where(s)}: {'; '.join(f.text for f in found)}: refusing to start {what}",
                                bus=s.bus, problem=found[0].problem, hint=found[0].hint)


def check_buses(session: ArmSession, buses: Iterable[str] | None = None, what: str = "moving") -> list[LinkStatus]:
    """Read every named bus of an open session (default: all it has open) and refuse an unfit one."""
    names = sorted(buses) if buses is not None else sorted(getattr(session, "links", {}))
    statuses = [read_link(session, b) for b in names if b in session.cfg.buses]
    check_status(statuses, what)
    return statuses


def preflight(session: ArmSession, refs: Sequence[DriveRef]) -> None:
    """Before motion: the buses of ``refs`` (state, bit rate), then each Elmo drive's user program (PS).

    The drives are NMT-started for the PS query (the binary interpreter answers in Operational only;
    the guard starts them next anyway). A running program refuses the motion unless the session
    allows it (``session.allow_user_program``, set by ``sherpa --allow-user-program``)."""
    from sherpa_cli.elmo.userprog import refuse_motion_while_running

    check_buses(session, {r.bus for r in refs})
    allow = bool(getattr(session, "allow_user_program", False))
    for ref in refs:
        client = session.client(ref)
        client.nmt_start()
        drive = session.cfg.drives.get(ref.name)
        if drive is not None and drive.type != "elmo":
            continue  # user programs are Elmo's: another drive type runs none sherpa could see
        refuse_motion_while_running(client, allow=allow)
