"""`sherpa cmd TARGET EXPR...`: the technician's raw terminal to one drive."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyRaw, RawSave
from sherpa_cli.cli.output import fmt_value
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.ops.raw import RawResult


def cmd(
    ctx: typer.Context,
    target: str = typer.Argument(..., metavar="TARGET", help="Drive or joint name from the config, or BUS:NODE."),
    exprs: list[str] = typer.Argument(..., metavar="EXPR...",
                                      help='Elmo commands: PX (query), "LL[3]" (query), AC=150000 (set), BG (execute).'),
    apply: ApplyRaw = False,
    raw_save: RawSave = False,
) -> None:
    """Send raw two-letter Elmo commands to one drive and show the answers, decoded where possible.

    The drive is NMT-started first (the binary interpreter answers only when Operational).
    Everything is parsed before anything is sent; the first error stops the rest.

    \b
    Examples:
      sherpa cmd shoulder_1a PX "LL[3]" MF SR
      sherpa cmd can0:10 AC=150000 --apply
      sherpa cmd can0:10 SV --apply --raw-save    # one flash write, counted in the save ledger

    \b
    MO=1 or BG with --apply run inside the motion guard, as every moving command: the drive's
    dead-man is armed first (heartbeat consumer, this command's own heartbeat id), and when the
    command ends the motor is stopped and switched off (MO=0). Nothing keeps a motor on after
    `cmd` returns; `sherpa jog JOINT --hold` holds a joint. A drive in fault is refused when the
    run has a BG; `cmd DRIVE MO=1 MO=0 --apply` clears its MF (under the dead-man too).

    \b
    SV writes the drive's flash (it endures about 100,000 saves): it is refused unless
    --apply and --raw-save are given, at most one SV per invocation, and each one is
    counted per drive serial number in the save ledger (as program-limits --save).
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import single_drive
    from sherpa_cli.ops.raw import check_raw_save, parse_all

    st = state(ctx)
    cfg = st.load_config()
    ref = single_drive(cfg, target, elmo_only="cmd")
    parse_all(exprs)  # a typo must not reach the bus, not even the NMT start
    check_raw_save(exprs, apply=apply, raw_save=raw_save)  # before anything is sent
    with st.session(buses=[ref.bus]) as session:
        run = Arm(session).command(target, exprs, apply=apply, raw_save=raw_save, check=False)
    if run.results or run.error is None:
        _render(st, ref, apply, run.results, run.stopped)
    for w in run.warnings:
        st.out.warn(w)
    if run.error is not None:
        raise run.error


REGISTERS = ("SR", "MF", "IP")


def _render(st: AppState, ref: DriveRef, apply: bool, done: list[RawResult], stopped: list[str]) -> None:
    if st.json_mode:
        st.out.json({"drive": ref.name, "bus": ref.bus, "node": ref.node, "applied": apply,
                     "results": [r.as_json() for r in done], "on_exit": stopped})
        return
    rows = []
    for r in done:
        if r.kind == "query":
            value = fmt_value(r.value)
            if r.text in REGISTERS and isinstance(r.value, int):
                value = f"0x{r.value & 0xFFFFFFFF:08X}"  # bit fields read best in hex
            rows.append([r.text, value, "; ".join(r.decoded)])
        elif r.sent:
            rows.append([r.text, "ok", "; ".join(r.decoded) or "sent"])
        else:
            rows.append([r.text, "-", f"not sent (dry run): 0x{r.cob_id:03X}  {r.frame.hex(' ').upper()}"])
    st.out.table(f"{ref.name} ({ref.address})", ["command", "value", "meaning"], rows, right=(1,))
    if any(r.text == "SV" and not r.sent for r in done):
        st.out.line("SV also needs --raw-save (one flash write, counted in the save ledger)")
    unsent = sum(1 for r in done if not r.sent)
    if unsent:
        st.out.line(f"dry run: {plural(unsent, 'command')} not sent; add --apply to send them")
    for line in stopped:
        st.out.line(line)
