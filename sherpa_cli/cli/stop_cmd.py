"""`sherpa stop [TARGET...]`: stop every (or the named) drive now; no confirmation, no --apply."""

from __future__ import annotations

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import Targets


def stop(ctx: typer.Context, targets: Targets = None) -> None:
    """Stop the motors now: ST (JV=0 + BG where ST is refused), wait for standstill, MO=0.

    No confirmation and no --apply: this is the emergency stop of the tool, for a second
    terminal while another command moves the arm. A drive whose motor is off gets no write.
    Best effort: a bus that cannot be opened or a drive that does not answer never keeps the
    others from being stopped. Exit 1 (partly stopped) if a drive could not be reached or
    confirmed stopped (no answer, no standstill); the table names each.

    \b
    Examples:
      sherpa stop
      sherpa stop elbow_pitch wrist_3
    """
    from sherpa_cli.api import Arm

    st = state(ctx)
    cfg = st.load_config()
    buses = Arm.buses_of(cfg, targets)
    from sherpa_cli.bus.session import NoBusError
    from sherpa_cli.errors import CommunicationError, ExitCode, SherpaError

    # best effort: a bus that cannot be opened never keeps the drives of the others from being stopped
    try:
        # --sim: a motor moved by another process's in-process arm is out of reach; waiting for that
        # command to end would report a stop that never happened
        with st.session(buses=buses, best_effort=True, sim_wait=0) as session:
            report = Arm(session).stop(targets, check=False)
    except NoBusError as exc:
        # nothing could be sent: say so plainly, bus by bus, and what is left to the technician
        for bus, why in exc.failed.items():
            st.out.error(f"bus {bus}: not reached: {why.message}")
        raise CommunicationError(
            f"NOTHING WAS STOPPED: no bus could be opened ({', '.join(exc.failed)}); a motor that moves goes "
            "on until its drive's own dead-man (if a sherpa command armed it) or the motor power stops it",
            hint="cut the motor power (the emergency stop) if anything may be moving; then check the "
                 "adapters and links (`sherpa bus status`)") from None
    except SherpaError as exc:
        if exc.exit_code != ExitCode.BUSY or not st.sim:
            raise
        raise type(exc)(f"NOTHING WAS STOPPED: {exc.message}", hint=exc.hint) from None
    if st.json_mode:
        st.out.json({"drives": [r.as_json() for r in report.drives]})
    else:
        rows = []
        for r in report.drives:
            if not r.reached:
                state_text = "NOT REACHED"
            else:
                state_text = "motor off" if r.motor_off or r.stopped_by == "motor was off" else "MOTOR ON?"
            rows.append([r.drive, r.address, r.stopped_by, state_text, "; ".join(r.problems)])
        st.out.table("stop", ["drive", "address", "stopped by", "now", "problem"], rows)
    problem = report.problem()
    if problem is not None:
        raise problem
