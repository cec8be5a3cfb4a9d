"""`sherpa recover [TARGET...]`: what a killed command left on the drives (the journal), put back with --apply."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyRecover, CheckDrives, Targets
from sherpa_cli.errors import SafetyError

if TYPE_CHECKING:
    from sherpa_cli.ops.drive_rest import DriveRest
    from sherpa_cli.ops.recover import RecoverReport


def recover(ctx: typer.Context, targets: Targets = None, apply: ApplyRecover = False,
            check_drives: CheckDrives = False) -> None:
    """Show, and with --apply put back, what a command that did not finish left on the drives.

    A moving command or a recording notes every temporary change (UM, SP/AC/DC, the dead-man objects
    0x1016:1/0x1029:1/0x6007, the pair's group id or RPDO2 type, HM[1], TPDO settings) in a journal
    in the state directory before it makes it, and clears the note once it is put back. A killed
    command leaves the note: a motion command then refuses the drive (exit 1) until this puts it back.
    With --apply: NMT start, every value put back (last change first), and a dead-man that tripped
    (MF 0x800, heartbeat lost) cleared with MO=1, MO=0 under a dead-man of its own (the drive's
    consumer armed first, as in every motion command). The journal is kept until all of it is done.
    A damaged journal: the drive is reset (RAM from flash) and the file moved aside.

    The journal knows only this state directory's commands. --check-drives reads the drives themselves
    (a journal deleted by hand, another user's or host's command): a dead-man on a pool id no sherpa
    command holds, a tripped dead-man, HM[1] armed, the pair's group id or RPDO2 left synchronous,
    the recorder armed. With --apply such a drive (motor off) gets a reset node and is read again;
    what survives the reset is held by the flash and said so.
    Exit 1 if something was left and not put back.

    \b
    Examples:
      sherpa recover
      sherpa recover elbow_pitch --apply
      sherpa recover --check-drives
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.ops.recover import plan_recover

    st = state(ctx)
    cfg = st.load_config()
    pending = _sv_pending(st, [r.name for r in drive_refs(cfg, targets)])
    plan = plan_recover(cfg, targets)
    if check_drives:
        with st.session(buses=plan.buses(cfg, True)) as session:
            _show_checked(st, Arm(session).recover(targets, apply=apply, check_drives=True, check=False), apply)
        return
    if not plan.refs:
        if st.json_mode:
            st.out.json({"drives": [], "sv_pending": pending})
        else:
            st.out.line("nothing to recover: no drive has changes left by a command that did not finish "
                        "(the journal's view; `sherpa recover --check-drives --apply` reads each drive for a "
                        "dead-man that tripped, homing left armed, a recorder left on, and clears them)")
            _show_pending(st, pending)
        return
    with st.session(buses=plan.buses(cfg, False)) as session:
        results = Arm(session).recover(targets, apply=apply, check=False).results
    if st.json_mode:
        st.out.json({"apply": apply, "drives": [{"drive": r.drive, "address": r.address, "left": r.found,
                                                 "tripped": r.tripped, "already_back": r.already_back, "put_back": r.done,
                                                 "problems": r.problems} for r in results],
                     "sv_pending": pending})
    else:
        for r in results:
            st.out.line(f"{r.drive} ({r.address}): left by a command that did not finish: {', '.join(r.found)}")
            if r.tripped:
                st.out.line(f"  {r.tripped}")
            if r.already_back:
                st.out.line("  the drive already holds every value (reset or power-cycled since?): nothing to put back; "
                            + ("notes dropped" if apply else "--apply drops the notes"))
                continue
            if apply:
                st.out.line(f"  put back: {', '.join(r.done or []) or 'nothing'}")
            for p in r.problems or []:
                st.out.line(f"  problem: {p}")
        _show_pending(st, pending)
        if not apply:
            st.out.line("dry run: nothing sent but NMT start and reads; --apply puts it back")
    bad = [r.drive for r in results if r.problems]
    if bad:
        raise SafetyError(f"not recovered: {', '.join(bad)}", hint="see the problems above")


def _sv_pending(st: AppState, drives: list[str]) -> list[str]:
    """Drives written and not saved to flash (the save ledger): by an --apply without --save, or a
    programming run killed between its writes and its SV. Nothing to put back: their RAM holds the
    values; flash does not yet."""
    from sherpa_cli.errors import ConfigError
    from sherpa_cli.ops.save_ledger import SaveLedger

    try:
        marked = SaveLedger().unsaved_drives()
    except ConfigError:
        return []  # a damaged ledger is reported by the commands that write it
    return sorted({name for name, _ in marked if name in drives})


def _show_pending(st: AppState, pending: list[str]) -> None:
    for name in pending:
        st.out.line(f"{name}: values written and not saved to flash (SV pending): the next power-up loses them; "
                    "rerun the programming command with --apply --save (it saves although RAM holds the values)")


def _show_checked(st: AppState, report: RecoverReport, apply: bool) -> None:
    """--check-drives: the journal's drives as without it, then every other target drive read."""
    results, checks = report.results, report.checks
    if st.json_mode:
        st.out.json({"apply": apply,
                     "drives": [{"drive": r.drive, "address": r.address, "left": r.found, "tripped": r.tripped,
                                 "already_back": r.already_back, "put_back": r.done, "problems": r.problems}
                                for r in results],
                     "checked": [{"drive": c.drive, "address": c.address, "in_use": c.in_use,
                                  "found": [{"object": f.what, "value": f.value, "meaning": f.meaning}
                                            for f in c.findings],
                                  "done": c.done,
                                  "after_reset": None if c.after_reset is None else
                                  [{"object": f.what, "value": f.value} for f in c.after_reset],
                                  "problems": c.problems} for c in checks]})
    else:
        for r in results:
            st.out.line(f"{r.drive} ({r.address}): left by a command that did not finish: {', '.join(r.found)}")
            if apply:
                st.out.line(f"  put back: {', '.join(r.done or []) or 'nothing'}")
            for p in r.problems or []:
                st.out.line(f"  problem: {p}")
        for c in checks:
            _show_check(st, c)
        if not apply:
            st.out.line("dry run: nothing sent but NMT start and reads; --apply resets each drive with a finding")
    bad = report.not_recovered
    if bad:
        raise SafetyError(f"not recovered: {', '.join(bad)}", hint="see the problems above")


def _show_check(st: AppState, c: DriveRest) -> None:
    head = f"{c.drive} ({c.address}): "
    if c.in_use:
        st.out.line(head + f"in use: {c.in_use}; not judged")
    elif not c.findings and not c.problems:
        st.out.line(head + "at rest: nothing a command leaves behind")
    for f in c.findings:
        st.out.line(head + f.text())
    for d in c.done:
        st.out.line(f"  {d}")
    if c.after_reset == []:
        st.out.line("  after the reset: at rest")
    for p in c.problems:
        st.out.line(f"  problem: {p}")
