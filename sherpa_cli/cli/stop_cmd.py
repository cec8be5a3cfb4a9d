"""`sherpa stop [TARGET...]`: stop every (or the named) drive now; no confirmation, no --apply."""

from __future__ import annotations

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import Targets
from sherpa_cli.errors import SafetyError


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
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.stop import stop_drives

    st = state(ctx)
    cfg = st.load_config()
    refs = drive_refs(cfg, targets)  # a pair or Σ/Δ joint means both motors; none: every drive
    buses = sorted({r.bus for r in refs}, key=list(cfg.buses).index)
    settings = MotionSettings.from_config(cfg, buses)
    # best effort: a bus that cannot be opened never keeps the drives of the others from being stopped
    with st.session(buses=buses, best_effort=True) as session:
        results = stop_drives(session, refs, settings)
    if st.json_mode:
        st.out.json({"drives": [r.as_json() for r in results]})
    else:
        rows = []
        for r in results:
            if not r.reached:
                state_text = "NOT REACHED"
            else:
                state_text = "motor off" if r.motor_off or r.stopped_by == "motor was off" else "MOTOR ON?"
            rows.append([r.drive, r.address, r.stopped_by, state_text, "; ".join(r.problems)])
        st.out.table("stop", ["drive", "address", "stopped by", "now", "problem"], rows)
    bad = [r for r in results if not r.ok]
    if bad:
        lost = [r.drive for r in bad if not r.reached]
        unconfirmed = [r.drive for r in bad if r.reached]
        parts = []
        if unconfirmed:
            parts.append(f"{len(unconfirmed)} drive(s) not confirmed stopped: {', '.join(unconfirmed)}")
        if lost:
            parts.append(f"{len(lost)} drive(s) not reached (bus could not be opened): {', '.join(lost)}")
        stopped = len(results) - len(bad)
        raise SafetyError(f"partly stopped ({stopped} of {len(results)} drive(s) stopped): " + "; ".join(parts),
                          hint="check them with `sherpa monitor --once`; cut the motor power if they still move")
