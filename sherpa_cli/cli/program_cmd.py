"""`sherpa program-limits` (and the shared plan/apply/save front end of `sherpa params restore`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.limits_cmd import drive_moves
from sherpa_cli.cli.options import Apply, MotorOff, Save, Targets, VerifyFlash, Yes
from sherpa_cli.cli.output import fmt_value
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.api import Arm
    from sherpa_cli.api.programming import ConfirmSave, ProgramReport
    from sherpa_cli.errors import Location
    from sherpa_cli.ops.program import ApplyResult, DriveOutcome, DrivePlan, DriveTarget, FlashProof

#: a command's call of the `Arm` method it is a layer over: (arm, confirm_save, on_plan) -> report
ArmCall = Callable[["Arm", "ConfirmSave", Callable[[Sequence["DrivePlan"]], None]], "ProgramReport"]


def program_limits(
    ctx: typer.Context,
    names: Targets = None,
    apply: Apply = False,
    save: Save = False,
    yes: Yes = False,
    motor_off: MotorOff = False,
    verify_flash: VerifyFlash = False,
) -> None:
    """Program the Appendix C limits (as `limits show` derives them) into the drives.

    Reads the drives first and shows, per drive and parameter, the value now, the target and
    whether it changes. Without --apply that is all (a dry run). With --apply only the changes
    are written, in an order that keeps LL <= VL < VH <= HL and PL[1] >= CL[1] true at every
    step, and each is read back at once; a mismatch or error stops that drive (exit 1).
    Drives run concurrently. Ctrl-C stops each drive between two writes; no drive is saved
    after it, and the report says what was written, verified and saved.

    \b
    Saves made with --save are counted per drive serial number (0x1018:4) in
      $XDG_STATE_HOME/sherpa-cli/save-ledger.json
      (default ~/.local/state/sherpa-cli/save-ledger.json),
    with a warning every 100 saves of a drive and on every save above 1,000
    (the flash endures about 100,000 saves).

    The ledger cannot know what other machines, `cmd --apply` or a deleted ledger did:
    --verify-flash proves what flash holds by resetting each drive and reading it back.

    \b
    Examples:
      sherpa program-limits                      # plan only
      sherpa program-limits elbow_pitch --apply
      sherpa program-limits --apply --save --yes
      sherpa program-limits --apply --save --verify-flash --yes
    """
    from sherpa_cli.bus.targets import drive_names
    from sherpa_cli.joints.limits import derive_checked, left_as_they_are
    from sherpa_cli.ops.program import DriveTarget

    st = state(ctx)
    cfg = st.load_config()
    check_options(apply, save)
    derived, warnings = derive_checked(cfg, drive_names(cfg, names, elmo_only="program-limits"))
    targets = [DriveTarget(d.drive, d.bus, d.node, d.params) for d in derived]
    run_program(st, "program-limits", targets, warnings, apply=apply, save=save, yes=yes, motor_off=motor_off,
                need_serial=save, allow_disabled=False, title=lambda drive: drive_moves(cfg, drive),
                verify_flash=verify_flash, note=left_as_they_are(derived),
                via=lambda arm, confirm, on_plan: arm.program_limits(
                    names, apply=apply, save=save, verify_flash=verify_flash, motor_off=motor_off,
                    confirm_save=confirm, on_plan=on_plan, check=False))


def params_restore(
    ctx: typer.Context,
    file: Path = typer.Argument(..., metavar="FILE", help="A file written by `sherpa dump-params`."),
    apply: Apply = False,
    save: Save = False,
    yes: Yes = False,
    motor_off: MotorOff = False,
    other_serial: bool = typer.Option(False, "--other-serial", help="Allow a dump whose serial number "
                                      "(0x1018:4) differs from the drive's, or that has none."),
    verify_flash: VerifyFlash = False,
) -> None:
    """Write a parameter dump back into the drives (plan, apply, verify, save as program-limits).

    Restores every writable setting of the dump, UM and other non-Appendix-C parameters
    included; never the identity block, read-only values, or moment state (MO, PX, PY, PA,
    PR, JV, TC, HM, RM). A dump from a drive with another serial number is refused unless
    --other-serial is given. Saves are counted in the same ledger as program-limits.

    \b
    Examples:
      sherpa params restore arm-2024-05.yaml
      sherpa params restore arm-2024-05.yaml --apply --save --yes
      sherpa params restore arm-2024-05.yaml --apply --save --verify-flash --yes
    """
    from sherpa_cli.ops.params_file import read_dump
    from sherpa_cli.ops.restore import restore_targets

    st = state(ctx)
    cfg = st.load_config()
    check_options(apply, save)
    dump = read_dump(file)
    targets, warnings = restore_targets(cfg, dump, file, other_serial=other_serial)
    from sherpa_cli.errors import Location

    run_program(st, "params restore", targets, warnings, apply=apply, save=save, yes=yes, motor_off=motor_off,
                need_serial=True, allow_disabled=True, title=lambda drive: drive_moves(cfg, drive), source=file,
                where=lambda drive: Location(str(file), None, f"drives.{drive}.params"), verify_flash=verify_flash,
                via=lambda arm, confirm, on_plan: arm.restore(
                    file, apply=apply, save=save, motor_off=motor_off, other_serial=other_serial,
                    verify_flash=verify_flash, confirm_save=confirm, on_plan=on_plan, check=False))


def check_options(apply: bool, save: bool) -> None:
    from sherpa_cli.api.programming import check_options as check

    check(apply, save)


# --------------------------------------------------------------------------- shared front end

def run_program(st: AppState, command: str, targets: Sequence[DriveTarget], warnings: Sequence[str], *,
                apply: bool, save: bool, yes: bool, motor_off: bool, need_serial: bool, allow_disabled: bool,
                title: Callable[[str], str], where: Callable[[str], Location | None] | None = None,
                source: Path | None = None, verify_flash: bool = False, note: str | None = None,
                via: ArmCall | None = None) -> None:
    """The plan/apply/save engine (api/programming.py) with the plan shown before any question and
    the outcome after; raises the error to exit with.

    Callers run :func:`check_options` first, before they read files or derive targets, so a
    bad option combination is reported ahead of any other problem. ``via(arm, confirm_save,
    on_plan)``: the `Arm` method the command is a layer over (default: the engine on ``targets``).
    """
    from sherpa_cli.api import programming

    warnings = programming.check(targets, warnings, allow_disabled=allow_disabled, where=where)
    for w in warnings:
        st.out.warn(w)
    st.out.assume_yes = st.out.assume_yes or yes
    buses = sorted({t.bus for t in targets})

    def show_plan(plans: Sequence[DrivePlan]) -> None:
        if st.json_mode:
            return
        _render_plan_text(st, plans, title)
        if note:
            st.out.line(f"note: {note}")
            st.out.line("")
        if verify_flash:
            st.out.line(_reset_note(plans, apply))
            st.out.line("")

    def confirm(drives: Sequence[str], proof: bool) -> bool:
        _confirm_save(st, drives, proof=proof)
        return True

    with st.session(buses=buses) as session:
        if via is not None:
            from sherpa_cli.api import Arm

            report = via(Arm(session), confirm, show_plan)
        else:
            report = programming.run(session, targets, apply=apply, save=save, motor_off=motor_off,
                                     need_serial=need_serial, verify_flash=verify_flash, warnings=warnings,
                                     confirm_save=confirm, on_plan=show_plan)
    _render(st, command, report.plans, report.result, apply=apply, save=save and apply, source=source,
            verify_flash=verify_flash, proofs=report.proofs, after=report.after)
    if report.result is not None:
        for o in report.result.outcomes:
            if o.save_warning:
                st.out.warn(o.save_warning)
    report.check()


def _reset_note(plans: Sequence[DrivePlan], apply: bool) -> str:
    import textwrap

    names = ", ".join(p.drive for p in plans)
    what, read = ("resets", "reads") if apply else ("would reset", "read")
    text = (f"--verify-flash {what} {names} (NMT reset node) and {read} back what flash holds. A reset "
            f"loses unsaved RAM, restarts the position counter and clears any homing (calibration) mark: "
            f"home the joints afterwards.")
    if not apply:
        text += " Dry run: no drive is reset without --apply."
    return textwrap.fill(text, width=80, subsequent_indent="  ", break_on_hyphens=False, break_long_words=False)


def _confirm_save(st: AppState, drives: Sequence[str], *, proof: bool = False) -> None:
    """Ask before anything is written; refuse at once when nobody can answer (no tty, --json)."""
    from sherpa_cli.errors import SafetyError

    listed = ", ".join(drives)
    if proof:
        refusal = (f"--save --verify-flash would reset {listed} and write and save those whose flash differs, "
                   f"and there is no terminal to confirm it; no drive was reset, nothing was written")
        question = f"Reset {listed} to prove flash, then write and save (SV) those whose flash differs?"
    else:
        refusal = (f"--save would write and save {listed}, and there is no terminal to confirm it; "
                   f"nothing was written")
        question = f"Write and save to flash (SV): {listed}?"
    if not st.out.confirm(question, refusal=refusal, hint="add --yes to confirm in scripts"):
        raise SafetyError("save not confirmed; nothing was written")


# --------------------------------------------------------------------------- rendering

def _render(st: AppState, command: str, plans: Sequence[DrivePlan], result: ApplyResult | None, *, apply: bool,
            save: bool, source: Path | None, verify_flash: bool = False, proofs: Sequence[FlashProof] = (),
            after: Sequence[FlashProof] = ()) -> None:
    """JSON: plan and outcome in one document. Text: what follows the plan (already shown)."""
    outcomes = {o.drive: o for o in result.outcomes} if result is not None else {}
    proof_of = {p.drive: p for p in proofs}
    after_of = {p.drive: p for p in after}
    if st.json_mode:
        body: dict[str, Any] = {"command": command}
        if source is not None:
            body["file"] = str(source)
        body.update({"apply": apply, "save": save, "dry_run": not apply,
                     "drives": [_plan_json(p, outcomes.get(p.drive)) for p in plans],
                     "interrupted": bool(result is not None and result.interrupted)})
        if verify_flash:
            body["verify_flash"] = True
            for d in body["drives"]:
                first, second = proof_of.get(d["drive"]), after_of.get(d["drive"])
                d["flash_proof"] = first.as_json() if first is not None else None
                d["flash_proof_after_save"] = second.as_json() if second is not None else None
        st.out.json(body)
        return
    if proofs:
        st.out.line("flash proof (NMT reset node, every target read back):")
        for proof in proofs:
            st.out.line("  " + _proof_line(proof))
    if result is not None:
        st.out.line("result:")
        for p in plans:
            st.out.line("  " + _outcome_line(p, outcomes[p.drive], save, proof_of.get(p.drive)))
        if after:
            st.out.line("flash proof after SV:")
            for proof in after:
                st.out.line("  " + _proof_line(proof))
        if result.interrupted:
            st.out.line("interrupted: drives not saved above keep their old values in flash; "
                        "a power cycle brings them back")
        elif not save and any(o.status == "programmed" for o in result.outcomes):
            st.out.line("not saved: the new values are in RAM only and are lost at power-off "
                        "(run again with --save to keep them)")
        return
    if not apply:
        changes = sum(len(p.changes) for p in plans if p.ok)
        drives = sum(1 for p in plans if p.ok and p.changes)
        reset = "; no drive was reset" if verify_flash else ""
        if changes:
            st.out.line(f"dry run: nothing was written{reset}; {plural(changes, 'change')} on {plural(drives, 'drive')} "
                        f"-- add --apply to write them")
        else:
            st.out.line(f"dry run: nothing was written{reset}; nothing to change")


def _render_plan_text(st: AppState, plans: Sequence[DrivePlan], title: Callable[[str], str]) -> None:
    for p in plans:
        t = p.target
        head = f"{t.drive} ({t.bus}:{t.node})"
        extra = title(t.drive)
        if extra:
            head += f" - {extra}"
        if p.params:
            position = {k: i + 1 for i, k in enumerate(p.write_order)}
            rows = [[q.key, fmt_value(q.now), fmt_value(q.target), "yes" if q.changes else "-",
                     position.get(q.key, "")] for q in p.params]
            rows += [[k, "", "", "not written", ""] for k in t.skipped]
            st.out.line(head)  # not a table title: rich would fold a long one to the table's width
            st.out.table(None, ["param", "now", "target", "change", "order"], rows, right=(1, 2, 4))
        else:
            st.out.line(head)
            st.out.line("")
        for k, why in t.skipped.items():
            st.out.line(f"{t.drive}: {k} not written: {why}")
        st.out.line(_plan_line(p))
        st.out.line("")


def _plan_line(p: DrivePlan) -> str:
    if p.problems:
        return f"{p.drive}: cannot be written: " + "; ".join(p.problems)
    n, c = len(p.params), len(p.changes)
    serial = f" (serial 0x{p.serial:08X})" if p.serial is not None else ""
    text = f"{p.drive}{serial}: {plural(n, 'parameter')}, {c} to change, {n - c} already set"
    if p.motor_on:
        text += "; motor is ON"
    if p.save_due:
        text += "; written earlier and not saved (an --apply without --save, or a run that did not reach its SV): SV due"
    return text


PROOF_SHOWN = 2  # differences named per drive in the text (--json has them all)


def _proof_line(p: FlashProof) -> str:
    from sherpa_cli.ops import program as pr

    off = " (motor switched off, --motor-off)" if p.motor_switched_off else ""
    if p.status == pr.HOLDS:
        return f"{p.drive}: flash holds the targets ({p.checked} read back){off}"
    if p.status == pr.DIFFERS:
        shown = list(p.differences.items())[:PROOF_SHOWN]
        diffs = ", ".join(f"{k} = {fmt_value(f)} (target {fmt_value(t)})" for k, (f, t) in shown)
        more = f", {len(p.differences) - len(shown)} more" if len(p.differences) > len(shown) else ""
        return f"{p.drive}: flash differs in {len(p.differences)} of {p.checked}: {diffs}{more}{off}"
    if p.status == pr.NOT_STARTED:
        return f"{p.drive}: not reset (stopped before its turn)"
    return f"{p.drive}: flash NOT proven: {p.error}{off}"


def _outcome_line(p: DrivePlan, o: DriveOutcome, save: bool, proof: FlashProof | None = None) -> str:
    from sherpa_cli.ops import program as pr

    n = len(p.changes)
    off = "motor switched off (--motor-off); " if o.motor_switched_off else ""
    if o.status == pr.UNCHANGED:
        if not save:
            return f"{o.drive}: nothing to change, nothing written"
        if proof is not None and proof.holds:
            return f"{o.drive}: nothing to change: RAM and flash hold the targets (flash proven by reset), no SV"
        return f"{o.drive}: nothing to change: RAM holds the targets; flash NOT proven (--verify-flash), no SV sent"
    if o.status == pr.PROGRAMMED:
        return f"{o.drive}: {off}{n} written and verified, not saved"
    if o.status == pr.SAVED and not n:
        count = f" (save {o.save_count} of this drive by this tool)" if o.save_count is not None else ""
        return f"{o.drive}: values of an earlier --apply saved{count}, read back after SV"
    if o.status == pr.SAVED:
        count = f" (save {o.save_count} of this drive by this tool)" if o.save_count is not None else ""
        return f"{o.drive}: {off}{n} written and verified, saved{count}, read back after SV"
    if o.status == pr.NOT_STARTED:
        return f"{o.drive}: not started, nothing written"
    done = f"{len(o.written)} of {n} written ({_keys(o.written)}), {len(o.verified)} verified"
    saved = "saved" if o.saved else "SV sent, save NOT confirmed" if o.sv_sent else "NOT saved"
    if o.status == pr.INTERRUPTED:
        return f"{o.drive}: interrupted: {off}{done}, {saved}"
    return f"{o.drive}: FAILED: {o.error}; {off}{done}, {saved}"


def _keys(keys: Sequence[str]) -> str:
    return ", ".join(keys) if keys else "none"


def _plan_json(p: DrivePlan, o: DriveOutcome | None) -> dict[str, Any]:
    position = {k: i + 1 for i, k in enumerate(p.write_order)}
    params = []
    for q in p.params:
        entry = {"key": q.key, "now": q.now, "target": q.target, "changes": q.changes,
                 "order": position.get(q.key)}
        if o is not None:
            entry["result"] = o.param_result(q.key) if q.changes else "unchanged"
        params.append(entry)
    t = p.target
    return {"drive": t.drive, "bus": t.bus, "node": t.node, "serial": p.serial, "motor_on": p.motor_on,
            "problems": list(p.problems), "save_due": p.save_due, "params": params, "not_written": dict(t.skipped),
            "outcome": o.as_json() if o is not None else None}
