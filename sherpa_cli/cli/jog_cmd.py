"""`sherpa jog JOINT`: move one plain joint inside the motion guard (ops/jog.py does the work)."""

from __future__ import annotations

import math
from typing import Optional

import typer

from sherpa_cli.cli.context import state
from sherpa_cli.cli.options import ApplyMotion
from sherpa_cli.errors import UsageError


def parse_number(text: str | None, option: str) -> float | None:
    """A plain number in the joint's units (rad, rad/s, A, s)."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{option} '{text}': expected a number") from None
    if not math.isfinite(value):
        raise UsageError(f"{option} '{text}': expected a finite number")
    return value


def jog(
    ctx: typer.Context,
    joint: str = typer.Argument(..., metavar="JOINT", help="A plain joint, or a drive that moves one (or BUS:NODE)."),
    to: Optional[str] = typer.Option(None, "--to", metavar="RAD", help="Move to this joint position (rad)."),
    by: Optional[str] = typer.Option(None, "--by", metavar="RAD", help="Move by this much from where it is (rad)."),
    velocity: Optional[str] = typer.Option(None, "--velocity", metavar="RAD/S",
                                           help="Run at this speed (rad/s) for --for seconds, or until Ctrl-C."),
    torque: Optional[str] = typer.Option(None, "--torque", metavar="A",
                                         help="Apply this current (A) for --for seconds (required); within the "
                                         "joint's continuous current limit."),
    duration: Optional[str] = typer.Option(None, "--for", metavar="SECONDS", help="How long a velocity or torque "
                                           "jog runs."),
    apply: ApplyMotion = False,
) -> None:
    """Move one plain joint: to/by a position, at a velocity, or with a torque.

    The motion runs inside the motion guard: the drive's fault state is checked first, the
    dead-man (heartbeat consumer) is armed, and every way out -- the end, an error, Ctrl-C,
    SIGTERM, SIGHUP -- stops the motor, switches it off and puts back what was changed. A killed
    tool leaves the drive to stop itself within motion.consumer_time_ms. Parameter changes are
    RAM only. The live position goes to stderr on a terminal; the last line says where it stopped.

    \b
    Examples:
      sherpa jog elbow_pitch --to 0.5 --apply
      sherpa jog wrist_3 --by -0.1 --apply
      sherpa jog elbow_pitch --velocity 0.2 --for 2 --apply
      sherpa jog wrist_1 --torque 0.5 --for 1 --apply
    """
    from sherpa_cli.ops.jog import JogRequest, check_request, resolve_jog_target, run_jog
    from sherpa_cli.ops.motion import MotionSettings

    st = state(ctx)
    cfg = st.load_config()
    given = [name for name, value in (("--to", to), ("--by", by), ("--velocity", velocity), ("--torque", torque))
             if value is not None]
    if len(given) != 1 and not (set(given) == {"--to", "--by"}):
        raise UsageError("give exactly one of --to, --by, --velocity or --torque"
                         + (f" (got {', '.join(given)})" if given else ""))
    mode = "position" if to is not None or by is not None else "velocity" if velocity is not None else "torque"
    req = JogRequest(mode=mode, to=parse_number(to, "--to"), by=parse_number(by, "--by"),
                     velocity=parse_number(velocity, "--velocity"), torque=parse_number(torque, "--torque"),
                     duration=parse_number(duration, "--for"))
    target = resolve_jog_target(cfg, joint)
    check_request(target, req)
    if not apply:
        _dry_run(st, target, req, cfg)
        return
    settings = MotionSettings.from_config(cfg, [target.ref.bus])
    name = target.joint.name if target.joint is not None else target.ref.name

    def progress(p) -> None:
        rad = f"{p.rad:+.4f} rad " if p.rad is not None else ""
        st.out.progress(f"{name}: {rad}({p.counts} counts)  {p.elapsed:5.2f} s")

    with st.session(buses=[target.ref.bus]) as session:
        try:
            result = run_jog(session, target, req, settings=settings, on_progress=progress)
        except BaseException as exc:
            st.out.progress(None)
            report = getattr(exc, "motion_report", None)
            if report is not None and not st.json_mode:
                for line in report.lines():
                    st.out.info(f"stop: {line}")
            raise
    st.out.progress(None)
    _render(st, name, result)


def _dry_run(st, target, req, cfg) -> None:
    from sherpa_cli.joints.units import rad_per_s_to_counts_per_s, rad_to_counts

    ref = target.ref
    cpr = target.cpr
    if req.mode == "position":
        plan = (f"UM=5, PA={rad_to_counts(req.to, cpr)}, BG" if req.to is not None
                else f"UM=5, PA=PX{rad_to_counts(req.by, cpr):+d}, BG")
    elif req.mode == "velocity":
        until = f"for {req.duration:g} s" if req.duration is not None else "until Ctrl-C"
        plan = f"UM={cfg.motion.velocity_unit_mode}, JV={rad_per_s_to_counts_per_s(req.velocity, cpr)}, BG {until}"
    else:
        plan = f"UM=1, TC={req.torque:g} for {req.duration:g} s"
    if st.json_mode:
        st.out.json({"target": target.name, "drive": ref.name, "address": ref.address, "mode": req.mode,
                     "applied": False, "plan": plan})
        return
    st.out.line(f"dry run: would jog {target.name} ({ref.name}, {ref.address}): {plan}, then stop and switch off")
    st.out.line("nothing sent; add --apply to move")


def _render(st, name: str, result) -> None:
    if st.json_mode:
        st.out.json(result.as_json())
        return
    for line in result.stop.lines():
        st.out.line(f"stop: {line}")
    where = result.end_counts
    rad = result.rad(where)
    at = (f"{rad:+.4f} rad ({where} counts)" if rad is not None else f"{where} counts") if where is not None \
        else "an unknown position (PX unreadable)"
    text = f"{name} ({result.drive}, {result.address}): stopped at {at} after {result.duration:.2f} s, {result.ended_by}"
    err = result.error_counts
    if err is not None:
        err_rad = result.rad(err)
        text += f"; error to target {err:+d} counts" + (f" ({err_rad:+.4f} rad)" if err_rad is not None else "")
    st.out.line(text)
