"""`sherpa cmd TARGET EXPR...`: the technician's raw terminal to one drive."""

from __future__ import annotations

from typing import List

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import ApplyRaw
from sherpa_cli.cli.output import fmt_value


def cmd(
    ctx: typer.Context,
    target: str = typer.Argument(..., metavar="TARGET", help="Drive or joint name from the config, or BUS:NODE."),
    exprs: List[str] = typer.Argument(..., metavar="EXPR...",
                                      help='Elmo commands: PX (query), "LL[3]" (query), AC=150000 (set), BG (execute).'),
    apply: ApplyRaw = False,
) -> None:
    """Send raw two-letter Elmo commands to one drive and show the answers, decoded where possible.

    The drive is NMT-started first (the binary interpreter answers only when Operational).
    Everything is parsed before anything is sent; the first error stops the rest.

    \b
    Examples:
      sherpa cmd shoulder_1a PX "LL[3]" MF SR
      sherpa cmd can0:10 AC=150000 --apply
    """
    from sherpa_cli.errors import SherpaError
    from sherpa_cli.ops.raw import parse_all, run_raw
    from sherpa_cli.ops.targets import single_drive

    st = state(ctx)
    cfg = st.load_config()
    ref = single_drive(cfg, target)
    parse_all(exprs)  # a typo must not reach the bus, not even the NMT start
    done: list = []
    error: SherpaError | None = None
    with st.session(buses=[ref.bus]) as session:
        client = session.client(ref)
        try:
            client.nmt_start()
            run_raw(client, ref.node, exprs, apply=apply, query_long=cfg.protocol.query_long, results=done)
        except SherpaError as exc:
            error = exc
    if done or error is None:
        _render(st, ref, apply, done)
    if error is not None:
        raise error


REGISTERS = ("SR", "MF", "IP")


def _render(st, ref, apply: bool, done: list) -> None:
    if st.json_mode:
        st.out.json({"drive": ref.name, "bus": ref.bus, "node": ref.node, "applied": apply,
                     "results": [r.as_json() for r in done]})
        return
    rows = []
    for r in done:
        if r.kind == "query":
            value = fmt_value(r.value)
            if r.text in REGISTERS and isinstance(r.value, int):
                value = f"0x{r.value & 0xFFFFFFFF:08X}"  # bit fields read best in hex
            rows.append([r.text, value, "; ".join(r.decoded)])
        elif r.sent:
            rows.append([r.text, "ok", "sent"])
        else:
            rows.append([r.text, "-", f"not sent (dry run): 0x{r.cob_id:03X}  {r.frame.hex(' ').upper()}"])
    st.out.table(f"{ref.name} ({ref.address})", ["command", "value", "meaning"], rows, right=(1,))
    unsent = sum(1 for r in done if not r.sent)
    if unsent:
        st.out.line(f"dry run: {unsent} command(s) not sent; add --apply to send them")
