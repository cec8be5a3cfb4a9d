"""Plan, apply, verify, save -- with nothing printed: the one engine behind `program-limits` and
`params restore`, and behind :meth:`sherpa_cli.api.Arm.program_limits` / :meth:`~sherpa_cli.api.Arm.restore_params`.

The CLI shows the plan before it asks, and the outcome after; this module calls back at those two
points (``on_plan``, ``confirm_save``) and returns a :class:`ProgramReport` whose ``problem`` is the
error to end with, so a caller renders what was done *before* it raises (a refused apply still
shows its plan; an interrupted one still says what was written).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.errors import SafetyError, SherpaError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.errors import Location
    from sherpa_cli.ops.program import ApplyResult, DrivePlan, DriveTarget, FlashProof
    from sherpa_cli.ops.save_ledger import SaveLedger

#: ``confirm_save(drives, proof)``: may these drives be written and saved (SV)? ``proof``: they are
#: reset first to prove flash. Return False (or raise) to refuse; nothing is written then.
ConfirmSave = Callable[[Sequence[str], bool], bool]


@dataclass
class ProgramReport:
    """What one programming run found and did; ``problem`` is the error it ends with (None: fine)."""

    plans: list[DrivePlan]
    apply: bool
    save: bool
    verify_flash: bool = False
    warnings: list[str] = field(default_factory=list)
    result: ApplyResult | None = None  # None: a dry run, or refused before the first write
    proofs: list[FlashProof] = field(default_factory=list)  # flash proven before writing
    after: list[FlashProof] = field(default_factory=list)  # flash proven after SV
    problem: SherpaError | None = None

    @property
    def interrupted(self) -> bool:
        return self.result is not None and self.result.interrupted

    @property
    def ok(self) -> bool:
        return self.problem is None and not self.interrupted

    @property
    def changes(self) -> int:
        """Parameters the plan changes (on drives that could be read)."""
        return sum(len(p.changes) for p in self.plans if p.ok)

    def check(self) -> None:
        """Raise what the run ended with: KeyboardInterrupt when it was interrupted, else the problem."""
        if self.interrupted:
            raise KeyboardInterrupt
        if self.problem is not None:
            raise self.problem


def check_options(apply: bool, save: bool) -> None:
    """--save needs --apply; checked before files are read or targets derived."""
    if save and not apply:
        raise UsageError("--save needs --apply: only written and verified values are saved",
                         hint="add --apply, or leave out --save for a dry run")


def refuse_unconfirmed(drives: Sequence[str], proof: bool) -> bool:
    """The default of a caller that gave no ``confirm_save``: nobody said yes, so nothing is saved."""
    listed = ", ".join(drives)
    raise SafetyError(f"saving {listed} was not confirmed; nothing was written",
                      hint="pass confirm_save (the CLI: --yes) to save to flash")


def check(targets: Sequence[DriveTarget], warnings: Sequence[str] = (), *, allow_disabled: bool = False,
          where: Callable[[str], Location | None] | None = None) -> list[str]:
    """Every value fits its command and nothing switches a protection off (unless allowed): raises
    before any I/O; returns the warnings to show (``warnings`` first)."""
    from sherpa_cli.ops import program  # here, not above: `Arm` imports this module, `sherpa scan` too

    return [*warnings, *program.check_targets(targets, allow_disabled=allow_disabled, where=where)]


def run(session: ArmSession, targets: Sequence[DriveTarget], *, apply: bool, save: bool, motor_off: bool = False,
        need_serial: bool = False, verify_flash: bool = False, warnings: Sequence[str] = (),
        confirm_save: ConfirmSave = refuse_unconfirmed,
        on_plan: Callable[[Sequence[DrivePlan]], None] | None = None,
        ledger: SaveLedger | None = None) -> ProgramReport:
    """Plan; with ``apply`` write/verify/save the targets :func:`check` passed (``warnings``: what it
    returned, kept in the report). Everything after the plan is in the report, not raised.

    ``verify_flash`` (with ``apply``): every drive is reset first (NMT reset node), so RAM is what
    flash holds; the plan is read again from there, so only drives whose flash differs are written
    (and with ``save`` saved, then proven again).
    """
    from sherpa_cli.ops import program
    from sherpa_cli.ops.save_ledger import SaveLedger

    check_options(apply, save)
    # apply needs the serial too: the ledger remembers drives written but not saved
    plans = program.read_plans(session, targets, need_serial=need_serial or apply)
    report = ProgramReport(plans, apply=apply, save=save, verify_flash=verify_flash, warnings=list(warnings))
    if apply and ledger is None:
        ledger = SaveLedger()
    if ledger is not None and apply:
        ledger.check()  # a damaged ledger is reported before anything is written
        if save and not verify_flash:
            report.plans = plans = program.mark_save_due(plans, ledger)  # a flash proof supersedes the ledger's guess
    if on_plan is not None:
        on_plan(plans)  # the technician sees the plan before any question
    if not apply:
        report.problem = program.plan_error(plans)
        return report
    try:
        if verify_flash:
            program.check_proof(plans, motor_off=motor_off)
            if save and not confirm_save([p.drive for p in plans], True):
                raise SafetyError("save not confirmed; nothing was written")
        else:
            program.check_apply(plans, motor_off=motor_off)
            to_save = [p.drive for p in plans if p.needs_save]
            if save and to_save and not confirm_save(to_save, False):
                raise SafetyError("save not confirmed; nothing was written")
    except SherpaError as e:
        report.problem = e
        return report
    if verify_flash:
        report.proofs = program.prove_flash(session, plans, boot_timeout=session.cfg.protocol.boot_timeout)
        problem = program.proof_problem(report.proofs)
        if problem is not None and any(p.status == program.PROOF_FAILED for p in report.proofs):
            report.problem = problem  # flash unknown somewhere: nothing is written after an error
            return report
        # RAM now holds what flash holds: plan again from there
        report.plans = plans = program.read_plans(session, targets, need_serial=True)
        try:
            program.check_apply(plans, motor_off=False)
        except SherpaError as e:
            report.problem = e
            return report
    report.result = result = program.apply_plans(session, plans, save=save, ledger=ledger)
    if verify_flash and save and not result.interrupted:
        saved = [p for p, o in zip(plans, result.outcomes, strict=True) if o.status == program.SAVED]
        if saved:
            report.after = program.prove_flash(session, saved, boot_timeout=session.cfg.protocol.boot_timeout)
    if not result.interrupted:
        report.problem = program.exit_problem(result)
        if report.problem is None and verify_flash:
            report.problem = (program.proof_problem(report.after, after_save=True) if save
                              else program.proof_problem(report.proofs))
    return report
