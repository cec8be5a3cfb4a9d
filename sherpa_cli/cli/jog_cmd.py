"""`sherpa jog JOINT`: move one joint inside the motion guard (ops/jog.py does the work for a plain
joint, ops/joint_jog.py for a Σ/Δ joint or one motor of a pair; both return ops/jog_result.py's
JogResult, rendered here)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import ApplyMotion
from sherpa_cli.errors import SherpaError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest
    from sherpa_cli.ops import joint_jog
    from sherpa_cli.ops.jog_result import JogResult


def parse_number(text: str | None, option: str) -> float | None:
    """A plain number in the joint's units (rad, rad/s, A, s)."""
    if text is None:
        return None
    if not text.isascii():  # float() reads other scripts' digits (U+FF13 -> 3.0)
        raise UsageError(f"{option} '{text}': expected a number with the ASCII digits 0-9")
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{option} '{text}': expected a number") from None
    if not math.isfinite(value):
        raise UsageError(f"{option} '{text}': expected a finite number")
    return value


def jog(
    ctx: typer.Context,
    joints: list[str] | None = typer.Argument(None, metavar="JOINT", show_default=False,
                                                 help="A plain joint, a Σ or Δ joint of a pair, or a drive (or "
                                                 "BUS:NODE). With --interactive: the joints to show (default all)."),
    to: str | None = typer.Option(None, "--to", metavar="POS", help="Move to this joint position: rad, or "
                                     "with a unit: 10deg, 200counts. Only inside the joint's normal range."),
    by: str | None = typer.Option(None, "--by", metavar="POS", help="Move by this much from where it is "
                                     "(rad, deg or counts)."),
    velocity: str | None = typer.Option(None, "--velocity", metavar="SPEED",
                                           help="Run at this speed (rad/s, or 5deg/s, 300counts/s) for --for "
                                           "seconds, or until Ctrl-C (a pair joint needs --for)."),
    torque: str | None = typer.Option(None, "--torque", metavar="A",
                                         help="Apply this motor current (A, or 800mA) for --for seconds (required); "
                                         "within the joint's continuous current limit."),
    duration: str | None = typer.Option(None, "--for", metavar="SECONDS", help="How long a velocity or torque "
                                           "jog runs."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow a position move of a joint that has no "
                                      "absolute encoder and was not homed since power-up."),
    force_limit: float | None = typer.Option(None, "--force-limit", metavar="N",
                                             help="Stop the motion when the F/T sensor reads a force above N "
                                                  "newtons (tightens the sensor's configured force_limit)."),
    apply: ApplyMotion = False,
    hold: bool = typer.Option(False, "--hold", help="After the move keep the motor on, holding where it ended, "
                              "the dead-man armed and the position shown, until Ctrl-C or `sherpa stop` "
                              "(a pair: both motors; a gravity-loaded joint then does not fall)."),
    interactive: bool = typer.Option(False, "--interactive", help="A full-screen view of the joints with keyboard "
                                     "control (docs/jog.md)."),
    joystick: bool = typer.Option(False, "--joystick", help="Drive the joints from a joystick as the config's "
                                  "`joystick:` maps it; a held dead-man button (docs/jog.md)."),
    device: str | None = typer.Option(None, "--device", metavar="PATH", help="The joystick's input device "
                                         "(default: joystick.device, else the first joystick found)."),
    list_joysticks: bool = typer.Option(False, "--list-joysticks", help="List the joysticks (evdev) and their "
                                        "axis and button names."),
) -> None:
    """Move one joint: to/by a position, at a velocity, or with a torque.

    JOINT is a plain joint, the Σ or Δ joint of a differential pair (both motors move through
    the pair's inverse transform and the other joint holds), or a drive. A joint that leaves
    its full range is stopped and brought back to the nearest edge of its normal range
    (exit 1). Position moves of a joint that is not calibrated are refused unless
    --uncalibrated (docs/motion.md).

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
      sherpa jog shoulder_pitch --by 10deg --apply
      sherpa jog shoulder_roll --velocity 5deg/s --for 2 --apply
      sherpa jog elbow_pitch --to 0.5 --hold --apply
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.motion.axis import resolve_axis
    from sherpa_cli.motion.request import parse_request
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops import jog as ops_jog
    from sherpa_cli.ops.jog import check_request

    st = state(ctx)
    st.use_force_limit(force_limit)
    if _live(st, joints or [], interactive, joystick, device, list_joysticks, apply, uncalibrated,
             [to, by, velocity, torque, duration]):
        return
    units = {"rad", "deg", "counts", "rad/s", "deg/s", "counts/s", "a"}
    stray = [j for j in (joints or [])[1:] if j.lower() in units]
    if stray:  # `--to 0.1 rad`: the shell split the value from its unit
        option = "--velocity" if stray[0].lower().endswith("/s") else "--torque" if stray[0].lower() == "a" else "--to"
        raise UsageError(f"'{stray[0]}' after the value is its unit: write it without a space "
                         f"({option} 0.1{stray[0]})",
                         hint="sherpa jog JOINT --to 0.1rad --apply")
    if len(joints or []) != 1:
        raise UsageError("name one JOINT to jog" + (f" (got {len(joints)})" if joints else ""),
                         hint="sherpa jog JOINT --to/--by/--velocity/--torque ...; several joints: --interactive")
    joint = (joints or [""])[0]
    cfg = st.load_config()
    given = [name for name, value in (("--to", to), ("--by", by), ("--velocity", velocity), ("--torque", torque))
             if value is not None]
    if len(given) != 1 and not (set(given) == {"--to", "--by"}):
        raise UsageError("give exactly one of --to, --by, --velocity or --torque"
                         + (f" (got {', '.join(given)})" if given else ""))
    mode = "position" if to is not None or by is not None else "velocity" if velocity is not None else "torque"
    target = resolve_axis(cfg, joint)  # the one resolver: plain joint, Σ/Δ joint, pair motor or drive
    seconds = parse_number(duration, "--for")
    pair = target.pair is not None  # ops/joint_jog.py moves what involves a pair (both motors, or Σ and Δ)
    if pair and mode == "velocity" and seconds is None:
        raise UsageError(f"a velocity jog of {target.name} needs --for SECONDS: a pair jog ends by itself, so the "
                         "other joint of the pair can be put back where it was",
                         hint=f"e.g. sherpa jog {target.name} --velocity {velocity} --for 1 --apply")
    # the one request, parsed once: units -> counts with the axis's cpr (motion/request.py)
    req = parse_request(target, mode, to=to, by=by, velocity=velocity, torque=torque, duration=seconds,
                        uncalibrated=uncalibrated, hold=hold)
    if pair:
        # a pair motor moves both joints of the pair: the notice names them (motion/gravity.py)
        _notice_gravity(st, cfg, [j.name for j in target.watched], hold=hold, apply=apply)
        _jog_pair(st, cfg, target, req, to if to is not None else by, apply)
        return
    check_request(target, req, max_torque_for=cfg.motion.max_torque_for)
    _notice_gravity(st, cfg, [target.joint.name] if target.joint is not None else [], hold=hold, apply=apply)
    if not apply:
        _dry_run(st, target, req, cfg)
        return
    settings = MotionSettings.from_config(cfg, [target.ref.bus])
    name = target.joint.name if target.joint is not None else target.ref.name

    def progress(p: object) -> None:
        if isinstance(p, ops_jog.JogProgress):
            rad = f"{p.rad:+.4f} rad " if p.rad is not None else ""
            st.out.progress(f"{name}: {rad}({p.counts} counts)  {p.elapsed:5.2f} s")

    with st.session(buses=[target.ref.bus]) as session:
        try:
            # the command is a layer over the Python API: the same move, rendered
            result = Arm(session).move(target, req, settings=settings, on_progress=progress)
        except BaseException as exc:
            st.out.progress(None)
            show_stop_report(st, exc, [target])
            raise
    st.out.progress(None)
    _render(st, name, result)
    if not result.ok:
        raise typer.Exit(1)


def _notice_gravity(st: AppState, cfg: ArmConfig, joints: Sequence[str], *, hold: bool, apply: bool) -> None:
    """Before a gravity-loaded joint moves: what the motor switched off at the end does to it, or
    that it is held after the move (--hold)."""
    from sherpa_cli.motion.gravity import gravity_notice

    text = gravity_notice(cfg, joints, holds=hold)
    if text is not None and apply:
        st.out.warn(text)


def _live(st: AppState, joints: list[str], interactive: bool, joystick: bool, device: str | None,
          list_joysticks: bool, apply: bool, uncalibrated: bool, values: Sequence[str | None]) -> bool:
    """--interactive, --joystick, --list-joysticks (cli/jog_live_cmd.py); False for a plain jog."""
    chosen = [name for name, on in (("--interactive", interactive), ("--joystick", joystick),
                                    ("--list-joysticks", list_joysticks)) if on]
    if not chosen:
        if device is not None:
            raise UsageError("--device goes with --joystick")
        return False
    if len(chosen) > 1:
        raise UsageError(f"{' and '.join(chosen)} exclude each other")
    if any(v is not None for v in values):
        raise UsageError(f"{chosen[0]} takes no --to, --by, --velocity, --torque or --for: the keys or the "
                         "joystick give the motion")
    from sherpa_cli.cli import jog_live_cmd

    if list_joysticks:
        jog_live_cmd.list_joysticks(st)
    elif interactive:
        if device is not None:
            raise UsageError("--device goes with --joystick")
        jog_live_cmd.interactive(st, joints, apply=apply, uncalibrated=uncalibrated)
    else:
        if joints:
            raise UsageError("--joystick drives the joints the config's `joystick:` section maps; name no JOINT")
        jog_live_cmd.joystick(st, device, apply=apply)
    return True


def _dry_run(st: AppState, target: Axis, req: MoveRequest, cfg: ArmConfig) -> None:
    ref = target.ref
    if req.mode == "position":
        plan = f"UM=5, PA=PX{req.counts:+d}, BG" if req.relative else f"UM=5, PA={req.counts}, BG"
    elif req.mode == "velocity":
        until = f"for {req.duration:g} s" if req.duration is not None else "until Ctrl-C"
        plan = f"UM={cfg.motion.velocity_unit_mode}, JV={req.velocity}, BG {until}"
    else:
        plan = f"UM=1, TC={req.amps:g} for {req.duration:g} s"
    if st.json_mode:
        st.out.json({"target": target.name, "drive": ref.name, "address": ref.address, "mode": req.mode,
                     "applied": False, "plan": plan})
        return
    st.out.line(f"dry run: would jog {target.name} ({ref.name}, {ref.address}): {plan}, then {_after(req)}")
    st.out.line("nothing sent; add --apply to move")


def _after(req: MoveRequest) -> str:
    return "hold where it stands until Ctrl-C or `sherpa stop`" if req.hold else "stop and switch off"


def _render(st: AppState, name: str, r: JogResult) -> None:
    """Any jog's result: how the guard stopped the motors, what a pair's motors were sent, the limit
    watch, a pair's hold, then where it ended. ``name``: the joint a one-drive jog moved."""
    from sherpa_cli.motion.axis import DRIVE, PLAIN

    if st.json_mode:
        st.out.json(r.as_json())
        return
    for line in r.stop.lines(st.verbose):
        st.out.line(f"stop: {line}")
    one_drive = r.kind in (PLAIN, DRIVE)
    if r.command and not one_drive:  # a one-drive jog's command is in its --json
        st.out.line(f"sent: {r.command}")
    for b in r.breaches:
        st.out.line(f"limit: {b.joint} left its full range [{b.full[0]}, {b.full[1]}] on the {b.side} side: "
                    f"stopped, nothing more sent, brought back to {r.recovered_to.get(b.joint)} counts "
                    f"(normal range edge {b.back_to})")
    for joint, fix in r.held_correction.items():
        st.out.line(f"held: {joint} was put back from {fix['from']} to {fix['to']} counts "
                    "(start/stop skew between the motors)")
    if r.held_at is not None and not one_drive:
        st.out.line(hold_line(r.held_at, r.held_until))
    st.out.line(_one_drive_end(name, r) if one_drive else _pair_end(r))


def _where(r: JogResult) -> str:
    rad, counts = r.end_rad, r.end_counts
    if counts is None:
        return "an unknown position (PX unreadable)"
    return f"{rad:+.4f} rad ({counts} counts)" if rad is not None else f"{counts} counts"


def _one_drive_end(name: str, r: JogResult) -> str:
    # no duration in the text: it varies from run to run (it is in --json as duration_s)
    text = f"{name} ({r.drives[0]}, {r.addresses[0]}): stopped at {_where(r)}, {r.ended_by}"
    err = r.error_counts
    if err is not None:
        err_rad = r.error_rad
        text += f"; error to target {err:+d} counts" + (f" ({err_rad:+.4f} rad)" if err_rad is not None else "")
    return text


def _pair_end(r: JogResult) -> str:
    err = r.error_counts
    if r.mode == "position" and r.ok:
        how = "target reached" if err is not None and abs(err) <= 1 else \
            f"{(r.end_counts or 0) - (r.target_counts or 0):+d} counts from the target"
    elif r.ok:
        how = f"after {r.for_s:g} s" if r.for_s is not None else "stopped"
    else:
        how = "the jog was stopped by the joint-limit watch"
    others = [f"{j} at {_pos(p, r.joint_cpr[j])}" for j, p in r.joints_end.items() if j != r.axis]
    text = f"{r.axis}: at {_where(r)}, {how}"
    if others:
        text += "; " + ", ".join(others)
    return text


# -- units and differential pairs (wave/jog) ------------------------------------------------------

def _jog_pair(st: AppState, cfg: ArmConfig, axis: Axis, req: MoveRequest, position_text: str | None,
              apply: bool) -> None:
    from sherpa_cli.api import Arm
    from sherpa_cli.ops import joint_jog

    offline = joint_jog.check_offline(cfg, axis, req)
    if not apply:
        _pair_dry_run(st, axis, req, offline, position_text)
        return
    buses = sorted({cfg.drives[d].bus for d in axis.sensed})

    def progress(joints: object) -> None:  # a live line on a terminal only (Output.progress)
        if isinstance(joints, Mapping):
            st.out.progress("  ".join(f"{j}: {p} counts" for j, p in joints.items()))

    with st.session(buses=buses) as session:
        try:
            result = Arm(session).move(axis, req, on_progress=progress)
        except BaseException as exc:
            st.out.progress(None)
            show_stop_report(st, exc, [axis, *(w for w in axis.watched if w.name != axis.name)])
            raise
    st.out.progress(None)
    _render(st, axis.name, result)
    if not result.ok:
        raise typer.Exit(1)


def _axis_label(axis: Axis) -> str:
    pair = axis.pair
    assert pair is not None  # resolve_axis: every axis is a joint or a motor of a pair
    if axis.kind == "motor":
        return f"{axis.name} (one motor of pair {pair.name}; moves {pair.sigma} and {pair.delta})"
    sign = "Σ" if axis.kind == "sigma" else "Δ"
    other = pair.delta if axis.kind == "sigma" else pair.sigma
    return f"{axis.name} ({sign} of pair {pair.name}: {pair.drive_a}, {pair.drive_b}; {other} holds)"


def _pos(counts: int, cpr: int) -> str:
    from sherpa_cli.joints.units import counts_to_rad

    return f"{counts_to_rad(counts, cpr):+.4f} rad ({counts} counts)"


def _pair_dry_run(st: AppState, axis: Axis, req: MoveRequest, plan: joint_jog.JogPlan | None,
                  position_text: str | None) -> None:
    a_b = ", ".join(axis.drives)
    if req.mode == "position":
        if plan is not None and axis.kind in ("sigma", "delta"):
            what = (f"{axis.name} to {plan.target} counts at {plan.speed} counts/s "
                    f"(PA of {a_b} from (Σ+Δ)/2 and (Σ-Δ)/2 with the other joint at its present value)")
        elif plan is not None:
            what = f"{axis.name} to {plan.target} counts at {plan.speed} counts/s"
        else:
            what = f"{axis.name} {'by' if req.relative else 'to'} {position_text} " \
                   f"(PA from the present positions)"
        cmds = "UM=5, SP, PA, BG"
    elif req.mode == "velocity":
        assert plan is not None  # check_offline plans every velocity and torque jog
        what = f"{axis.name} at {plan.speed} counts/s for {req.duration:g} s"
        cmds = ", ".join(f"{d} JV={v}" for d, v in plan.motor_speeds.items()) + ", BG"
    else:
        assert plan is not None  # check_offline plans every velocity and torque jog
        what = f"{axis.name} with {plan.current:g} A for {req.duration:g} s"
        cmds = "UM=1, " + ", ".join(f"{d} TC={v:g}" for d, v in plan.motor_currents.items())
    if st.json_mode:
        st.out.json({"target": axis.name, "kind": axis.kind, "drives": list(axis.drives), "mode": req.mode,
                     "applied": False, "plan": f"{what}: {cmds}"})
        return
    st.out.line(f"dry run: would jog {_axis_label(axis)}")
    st.out.line(f"  {what}: {cmds}, then {_after(req)}")
    st.out.line("nothing sent; add --apply to move")


def hold_line(held_at: Mapping[str, int], ended_by: str) -> str:
    """What --hold did, for a pair jog and `diffdrive move`: where each motor held, how it ended."""
    at = ", ".join(f"{d} PA={pa}" for d, pa in held_at.items())
    return f"hold: {at}; {ended_by or 'ended by the limit watch'}"


def show_stop_report(st: AppState, exc: BaseException, axes: Sequence[Axis] = ()) -> None:
    """How the guard stopped the motor, on an error path too: text lines, or with --json an error
    object on stdout (``error``, ``stop``); the error message itself still goes to stderr. ``axes``:
    what the command moved (the first is the one asked for), for where a force-limit stop left it."""
    from sherpa_cli.motion.report import report_of

    report = report_of(exc)
    if report is None:
        return
    if st.json_mode:
        message = str(exc) if isinstance(exc, SherpaError) else ("interrupted" if isinstance(exc, KeyboardInterrupt)
                                                                 else f"{type(exc).__name__}: {exc}")
        st.out.json({"error": message, "stop": report.as_json()})
        return
    for line in report.lines(st.verbose):
        st.out.info(f"stop: {line}")
    where = force_stop_line(exc, axes)
    if where is not None:
        st.out.line(where)


def force_stop_line(exc: BaseException, axes: Sequence[Axis]) -> str | None:
    """Where a force-limit stop left the joints, said as a normal stop says it: the arm pressed on
    something and the user moves it back from there. From the motors' PX the guard read once they
    stood (its report); None for any other error."""
    from sherpa_cli.motion.force_watch import ForceLimitError
    from sherpa_cli.motion.report import NOT_MOVED, report_of

    report = report_of(exc)
    if not isinstance(exc, ForceLimitError) or report is None or not axes:
        return None
    if all(d.stopped_by == NOT_MOVED for d in report.drives):
        return None  # refused before anything moved: the joint is where it was
    motors = {d.drive: d.position for d in report.drives}

    def where(axis: Axis) -> str:
        known = {d: p for d in axis.drives if (p := motors.get(d)) is not None}
        if len(known) != len(axis.drives):
            return "an unknown position (PX unreadable)"
        counts = axis.position(known)
        return _pos(counts, axis.cpr) if axis.cpr is not None else f"{counts} counts"

    first, *others = axes
    if first.drive_b is None and not others:
        ref = first.ref
        name = first.joint.name if first.joint is not None else ref.name
        return f"{name} ({ref.name}, {ref.address}): stopped at {where(first)}, force limit"
    text = f"{first.name}: at {where(first)}, stopped by the force limit"
    if others:
        text += "; " + ", ".join(f"{a.name} at {where(a)}" for a in others)
    return text
