"""`sherpa tune show|set JOINT`: the drives' speed and position loop gains (docs/tune.md)."""

from __future__ import annotations

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import Apply, MotorOff, Save, Yes

app = typer.Typer(help="Read and write the drives' speed and position loop gains (docs/tune.md).",
                  no_args_is_help=True)


@app.command("show")
def show(ctx: typer.Context,
         target: str = typer.Argument(..., metavar="TARGET", help="A joint, pair or drive.")) -> None:
    """Read KP[], KI[], FF[] of the drives of TARGET. Meanings the sources do not confirm say so.

    \b
    Examples:
      sherpa tune show elbow_pitch
      sherpa tune show shoulder_diff
    """
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.elmo.commands import format_value
    from sherpa_cli.ops.tune import GAINS, read_gains

    st = state(ctx)
    cfg = st.load_config()
    refs = drive_refs(cfg, [target], configured_only=True)
    with st.session(buses=list(dict.fromkeys(r.bus for r in refs))) as session:
        readings = read_gains(session, refs)
    if st.json_mode:
        st.out.json({"drives": [{"drive": r.drive, "gains": r.values} for r in readings],
                     "unconfirmed": [k for k, (_, ok) in GAINS.items() if not ok]})
        return
    for r in readings:
        st.out.line(f"{r.drive}:")
        for key, value in r.values.items():
            st.out.line(f"  {key:<6} {format_value(value):>12}  {GAINS[key][0]}")


@app.command("set")
def set_gains(
    ctx: typer.Context,
    target: str = typer.Argument(..., metavar="TARGET", help="A joint, pair or drive."),
    gains: list[str] = typer.Argument(..., metavar="GAIN=VALUE...", help="e.g. KP[2]=0.8 KI[2]=150"),
    apply: Apply = False,
    save: Save = False,
    yes: Yes = False,
    motor_off: MotorOff = False,
) -> None:
    """Write gains to the drives of TARGET: a dry run unless --apply; --apply writes and reads
    back; --save (with --apply) saves with SV once every value is verified, counted in the save
    ledger -- the path of program-limits. Gains outside the config's `tuning:` bounds are refused.

    \b
    Examples:
      sherpa tune set elbow_pitch KP[2]=0.8 KI[2]=150
      sherpa tune set shoulder_diff KP[2]=0.6 --apply
      sherpa tune set shoulder_diff KP[2]=0.6 --apply --save --yes
    """
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.cli.limits_cmd import drive_moves
    from sherpa_cli.cli.program_cmd import check_options, run_program
    from sherpa_cli.ops.program import DriveTarget
    from sherpa_cli.ops.tune import parse_assignments

    st = state(ctx)
    check_options(apply, save)
    cfg = st.load_config()
    values = parse_assignments(cfg, gains)
    refs = drive_refs(cfg, [target], configured_only=True)
    targets = [DriveTarget(r.name, r.bus, r.node, values) for r in refs]
    run_program(st, "tune set", targets, [], apply=apply, save=save, yes=yes, motor_off=motor_off,
                need_serial=save, allow_disabled=False, title=lambda drive: drive_moves(cfg, drive))
