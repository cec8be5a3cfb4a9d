"""`sherpa recover`: put back what killed commands left on the drives (the journal, bus/journal.py),
and with ``check_drives`` read the other drives for what a command leaves (ops/drive_rest.py)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import DriveRef, drive_refs

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.drive import Drive
    from sherpa_cli.ops.drive_rest import DriveRest


@dataclass
class RecoverReport:
    """``results``: per drive the journal named, what was left and (``apply``) put back; ``checks``:
    per other drive read (``check_drives``), what it holds that a command leaves behind."""

    apply: bool
    results: list[journal.RecoverResult] = field(default_factory=list)
    checks: list[DriveRest] = field(default_factory=list)

    @property
    def not_recovered(self) -> list[str]:
        return [r.drive for r in self.results if r.problems] + [c.drive for c in self.checks if c.problems]


@dataclass(frozen=True)
class RecoverPlan:
    """What the journal says, read from the state directory alone (no bus)."""

    refs: tuple[DriveRef, ...]  # drives with a note left, or a damaged journal
    broken: dict[str, str]  # drive -> why its journal cannot be read
    others: tuple[DriveRef, ...]  # the other target drives (read with check_drives)

    def buses(self, cfg: ArmConfig, check_drives: bool) -> list[str]:
        refs = [*self.refs, *(self.others if check_drives else ())]
        return sorted({r.bus for r in refs}, key=list(cfg.buses).index)


def plan_recover(cfg: ArmConfig, targets: Sequence[str] | None) -> RecoverPlan:
    every = drive_refs(cfg, targets)
    broken = {r.name: why for r in every if (why := journal.damaged(r)) is not None}
    refs = tuple(r for r in every if r.name in broken or journal.leftover(r))
    noted = {r.name for r in refs}
    return RecoverPlan(refs, broken, tuple(r for r in every if r.name not in noted))


def recover(session: ArmSession, plan: RecoverPlan, *, apply: bool, check_drives: bool = False) -> RecoverReport:
    """Each journal drive put back (a damaged journal: reset from flash), dry run unless ``apply``;
    with ``check_drives`` every other drive read (and with ``apply`` one with a finding reset)."""
    from sherpa_cli.devices.drives import is_elmo, open_drive
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.motion.trip_clear import clear_heartbeat_trip
    from sherpa_cli.ops.drive_rest import check_drive

    cfg = session.cfg
    boot = cfg.protocol.boot_timeout
    report = RecoverReport(apply)
    for r in plan.refs:
        if r.name in plan.broken:
            report.results.append(journal.restore_damaged(session, r, plan.broken[r.name], apply=apply,
                                                          boot_timeout=boot))
        else:
            # another drive type than Elmo: its state and its fault reset through the drive seam
            drive = None if is_elmo(session, r) else open_drive(session, r)

            def clear(ref: DriveRef = r, drive: Drive | None = drive) -> None:
                clear_heartbeat_trip(session, ref, MotionSettings.from_config(cfg, [ref.bus]), drive=drive)

            report.results.append(journal.restore(session, r, apply=apply, clear_trip=clear, drive=drive))
    if check_drives:
        # what a command leaves is read in Elmo's interpreter (the journal covers every drive type)
        report.checks = [check_drive(session, cfg, r, apply=apply, boot_timeout=boot) for r in plan.others
                         if is_elmo(session, r)]
    return report
