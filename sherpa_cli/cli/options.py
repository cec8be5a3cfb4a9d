"""Options and arguments several commands share, declared once (typer ``Annotated`` aliases).

A command takes one as ``apply: Apply = False``. Where a flag means something else in a
command (``cmd --apply`` sends raw commands, ``recipe run --apply`` lets writing steps write)
its own alias is here too, so every spelling of a flag and its help live in one place.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

# -- which drives ---------------------------------------------------------------------------------

TARGETS_HELP = "Drive, joint or pair names, or BUS:NODE; default: every configured drive."
Targets = Annotated[list[str] | None, typer.Argument(metavar="[TARGET]...", help=TARGETS_HELP)]

# -- writing to drives (program-limits, params restore) -------------------------------------------

Apply = Annotated[bool, typer.Option(
    "--apply", help="Write the changes; without it nothing is written (not one set, not one SDO download).")]
Save = Annotated[bool, typer.Option(
    "--save", help="With --apply: SV once per drive that changed, only after every write of it was read back, "
    "then read everything back again.")]
Yes = Annotated[bool, typer.Option(
    "--yes", "-y", help="Do not ask before saving (needed when stdin is not a terminal: without it --save "
    "refuses before writing anything).")]
MotorOff = Annotated[bool, typer.Option(
    "--motor-off", help="Switch off (MO=0) a drive whose motor is on instead of refusing it. Limits, UM and IL "
    "need the motor off.")]

ApplyRaw = Annotated[bool, typer.Option(
    "--apply", help="Send sets and execute commands; without it they are only shown as the frame that would be "
    "sent (queries are always sent).")]
RawSave = Annotated[bool, typer.Option(
    "--raw-save", help="Allow one SV (save RAM to flash) with --apply; it is counted in the save ledger. Without "
    "it SV is refused.")]
ApplyHeartbeat = Annotated[bool, typer.Option(
    "--apply", help="Let --heartbeat write 0x1017 (a write to the drives); without it --heartbeat is a dry run.")]
ApplyReset = Annotated[bool, typer.Option(
    "--apply", help="Let --reset send the NMT reset (it changes the drives' state); without it --reset is a dry "
    "run.")]
VerifyFlash = Annotated[bool, typer.Option(
    "--verify-flash", help="With --apply: prove flash -- reset each drive (NMT reset node; motor off), wait for its "
    "boot-up and read every target back. The reset clears the position counter and any homing mark. With --save "
    "only drives whose flash differs are written and saved, then proven again.")]

ApplyRecover = Annotated[bool, typer.Option(
    "--apply", help="Put back what a killed command left (NMT start, the journal's values, a tripped dead-man's MF "
    "cleared); without it only shown.")]
CheckDrives = Annotated[bool, typer.Option(
    "--check-drives", help="Also read every target drive's RAM for what a command leaves behind (a dead-man on a "
    "pool id nobody holds, HM[1], the pair's group id, RPDO2 synchronous, the recorder armed): no journal needed. "
    "With --apply, a drive with a finding gets a reset node (RAM from flash) and is read again.")]
ApplyMotion = Annotated[bool, typer.Option(
    "--apply", help="Move the motor; without it only show what would be sent (nothing is written).")]
ApplyMatch = Annotated[bool, typer.Option(
    "--apply", help="--measure, then write the proposal through `tune set`'s path (read back); without it "
    "nothing is written.")]
YesMotion = Annotated[bool, typer.Option(
    "--yes", "-y", help="Do not ask before moving (needed when stdin is not a terminal: without it `home` refuses "
    "before anything moves).")]

# -- recipes (recipe run, commission) -------------------------------------------------------------

ApplyRecipe = Annotated[bool, typer.Option(
    "--apply", help="Let writing steps write. Without it every step that has --apply/--save runs as a dry run.")]
ApplyCommission = Annotated[bool, typer.Option("--apply", help="Program and save the drives (default: dry run).")]
YesRecipe = Annotated[bool, typer.Option("--yes", "-y", help="Answer every confirm step with yes.")]
FromStep = Annotated[str | None, typer.Option(
    "--from", metavar="STEP", help="Start at this step (name or number).")]
Report = Annotated[Path | None, typer.Option("--report", metavar="FILE.json", help="Write a JSON report.")]
Junit = Annotated[Path | None, typer.Option("--junit", metavar="FILE.xml", help="Write a JUnit XML report.")]
# one line per step is the default now; --quiet stays accepted for old scripts
Quiet = Annotated[bool, typer.Option("--quiet", "-q", hidden=True, help="The default now: one line per step.")]
Verbose = Annotated[bool, typer.Option("--verbose", "-v", help="Show every step's command and output (default: "
                                       "one line per step; the output is in the --report file).")]
SetVars = Annotated[list[str] | None, typer.Option(
    "--set", metavar="KEY=VALUE", help="Set a recipe variable (repeat), e.g. backup=FILE (where dump-params "
    "writes in the commissioning recipe).")]


def name_list(values: list[str] | None) -> list[str] | None:
    """A repeatable option that also takes comma-separated names (``--joints a,b --joints c``);
    None when none was given."""
    if not values:
        return None
    return [name.strip() for item in values for name in item.split(",") if name.strip()] or None
