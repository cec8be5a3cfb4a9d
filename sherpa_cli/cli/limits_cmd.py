"""`sherpa limits show`: the Appendix C parameter set each drive should hold."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import Targets
from sherpa_cli.cli.output import fmt_value

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig

app = typer.Typer(no_args_is_help=True, help="Drive limits derived from the config (seed Appendix C).")

# What each programmed parameter is for, in the words of Appendix C.
MEANING = {
    "LL[2]": "speed trip, low (motor off beyond it)",
    "HL[2]": "speed trip, high (motor off beyond it)",
    "VL[2]": "speed command limit, low (clipped)",
    "VH[2]": "speed command limit, high (clipped)",
    "LL[3]": "position trip, low = overshoot range",
    "HL[3]": "position trip, high = overshoot range",
    "VL[3]": "position command limit, low = full range",
    "VH[3]": "position command limit, high = full range",
    "AC": "acceleration, counts/s²",
    "DC": "deceleration, counts/s²",
    "CL[1]": "continuous current limit, A",
    "PL[1]": "peak current limit, A",
    "PL[2]": "peak current duration, s",
}


@app.command("show")
def show(ctx: typer.Context,
         names: Targets = None,
         software: bool = typer.Option(False, "--software", help="The software side instead (Tables C.1/C.2): "
                                       "cpr, pos_min/max, pos_margin, cal_sw_*, cal_pos, *_dd per joint.")) -> None:
    """Show the parameters Appendix C derives for each drive (nothing is sent to a drive).

    \b
    Examples:
      sherpa limits show shoulder_pitch
      sherpa --config configs/appendix-c/example3.yaml limits show --software
    """
    from sherpa_cli.bus.targets import drive_names
    from sherpa_cli.elmo.faults import describe_il
    from sherpa_cli.joints.limits import derive_checked, il_roles, left_as_they_are

    st = state(ctx)
    cfg = st.load_config()
    if software:
        _show_software(st, cfg, list(names or []))
        return
    derived, warnings = derive_checked(cfg, drive_names(cfg, names, elmo_only="limits"))
    for w in warnings:
        st.out.warn(w)
    note = left_as_they_are(derived)
    if st.json_mode:
        body: dict[str, Any] = {"drives": [{"drive": d.drive, "bus": d.bus, "node": d.node, "params": dict(d.params)}
                           for d in derived]}
        if note:
            body["note"] = note
        st.out.json(body)
        return
    roles = il_roles(cfg)
    for d in derived:
        moves = drive_moves(cfg, d.drive)
        rows = []
        for key, value in d.params.items():
            text = f"input: {describe_il(int(value), roles)}" if key.startswith("IL[") else MEANING.get(key, "")
            rows.append([key, fmt_value(value), text])
        st.out.table(f"{d.drive} ({d.bus}:{d.node}) - {moves}", ["param", "value", "meaning"], rows, right=(1,))
    if note:
        st.out.line(f"note: {note}")


def _show_software(st: AppState, cfg: ArmConfig, names: list[str]) -> None:
    """Tables C.1/C.2: the ROS parameters per plain joint and per differential pair."""
    from sherpa_cli.config.software import DESCRIPTIONS, software_params
    from sherpa_cli.errors import UsageError

    entries = software_params(cfg)
    if names:
        known = {n for e in entries for n in (*e.joints, *e.drives, e.title.split()[1])}
        unknown = [n for n in names if n not in known]
        if unknown:
            raise UsageError(f"unknown joint, drive or pair: {', '.join(unknown)}",
                             hint="see `sherpa config check` for the names")
        entries = [e for e in entries if {*e.joints, *e.drives, e.title.split()[1]} & set(names)]
    if st.json_mode:
        st.out.json({"joints": [{"title": e.title, "joints": list(e.joints), "drives": list(e.drives),
                                 "params": {k: v for k, v in e.params.items() if k != "ext_pos_input_dd"},
                                 "warnings": e.warnings} for e in entries]})
        return
    for e in entries:
        rows = [[key, fmt_value(e.params[key]), DESCRIPTIONS[key]] for key in DESCRIPTIONS if key in e.params]
        st.out.table(f"{e.title} - drive{'s' if len(e.drives) > 1 else ''} {', '.join(e.drives)}", ["param", "value", "description"], rows,
                     right=(1,))
    for e in entries:
        for w in e.warnings:
            st.out.warn(w)


def drive_moves(cfg: ArmConfig, drive: str) -> str:
    """What a drive moves, for a table or plan title: its joint, or its pair and motor."""
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return f"joint {joint.name}"
    pair = cfg.pair_of_drive(drive)
    if pair is not None:
        side = "a" if pair.drive_a == drive else "b"
        return f"pair {pair.name}, motor {side}"
    return "no joint"
