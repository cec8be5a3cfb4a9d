"""`sherpa diffdrive limits|convert`: the Σ/Δ maths of a differential pair, without a bus."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import typer

from sherpa_cli.cli.context import AppState, shared_stepped, state, use_stepped
from sherpa_cli.cli.options import ApplyMatch, ApplyMotion, Report, Save, Yes
from sherpa_cli.cli.output import stop_lines
from sherpa_cli.errors import UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig, PairConfig
    from sherpa_cli.ops.diffdrive import MoveResult, PairTarget
    from sherpa_cli.ops.pair_match import MatchResult

app = typer.Typer(no_args_is_help=True, help="Differential pairs: Σ = m_a + m_b, Δ = m_a - m_b.")

PairArg = typer.Argument(..., metavar="PAIR", help="Pair name, or its Σ/Δ joint or one of its drives.")


@app.command("limits")
def limits(ctx: typer.Context, pair: str = PairArg) -> None:
    """Show a pair's Σ/Δ ranges and the motor ranges derived from them, with the rule used."""
    from sherpa_cli.bus.targets import pair_of
    from sherpa_cli.joints.limits import explain_pair

    st = state(ctx)
    cfg = st.load_config()
    ex = explain_pair(cfg, pair_of(cfg, pair))
    if st.json_mode:
        st.out.json(ex.as_dict())
        return
    out = st.out
    out.line(f"pair {ex.pair}: drive a = {ex.drive_a} (lower node id), drive b = {ex.drive_b}")
    out.line(f"  Σ joint {ex.sigma} = m_a + m_b,  Δ joint {ex.delta} = m_a - m_b  (counts)")
    out.table("Joint ranges (counts)", ["joint", "full range", "overshoot range"],
              [[f"Σ {ex.sigma}", _rng(ex.sigma_full), _rng(ex.sigma_overshoot)],
               [f"Δ {ex.delta}", _rng(ex.delta_full), _rng(ex.delta_overshoot)]])
    out.table("Motor ranges (counts)", ["drive", "VL[3] .. VH[3] (full)", "LL[3] .. HL[3] (overshoot)"],
              [[f"a {ex.drive_a}", _rng(ex.motor_a_full), _rng(ex.motor_a_overshoot)],
               [f"b {ex.drive_b}", _rng(ex.motor_b_full), _rng(ex.motor_b_overshoot)]])
    out.table("Motor speed and acceleration (both motors)", ["limit", "value"],
              [["VH[2] = -VL[2] (counts/s)", _opt(ex.motor_speed_limit)],
               ["HL[2] = -LL[2] (counts/s)", _opt(ex.motor_speed_trip)],
               ["AC (counts/s²)", _opt(ex.motor_accel)],
               ["DC (counts/s²)", _opt(ex.motor_decel)]], right=(1,))
    out.line("Rule:")
    for line in ex.rule.splitlines():
        out.line(f"  {line}")
    for note in ex.notes:
        out.line(f"note: {note}")


def _rng(r: tuple[int, int]) -> str:
    return f"{r[0]} .. {r[1]}"


def _opt(v: int | None) -> str:
    return "-" if v is None else str(v)


@app.command("convert")
def convert(
    ctx: typer.Context,
    pair: str = PairArg,
    sigma: str | None = typer.Option(None, "--sigma", help="Σ joint position: a number in --unit, or with its "
                                     "unit as elsewhere (0.5rad, 10deg, 200counts)."),
    delta: str | None = typer.Option(None, "--delta", help="Δ joint position (as --sigma)."),
    motor_a: float | None = typer.Option(None, "--motor-a", help="Motor a position (counts)."),
    motor_b: float | None = typer.Option(None, "--motor-b", help="Motor b position (counts)."),
    unit: str = typer.Option("counts", "--unit", help="Unit of --sigma/--delta and of the output: counts or rad."),
) -> None:
    """Convert Σ/Δ joint positions to motor positions, or motor positions to Σ/Δ.

    Give either --sigma and --delta, or --motor-a and --motor-b. A bare joint position is in
    --unit (counts, or rad: each joint's own cpr); one with its unit (0.5rad, 10deg, 200counts)
    means what it says, as in `diffdrive move`. Motor positions are always counts.
    """
    from sherpa_cli.bus.targets import pair_of
    from sherpa_cli.joints import diffpair, units
    from sherpa_cli.joints.limits import explain_pair

    st = state(ctx)
    cfg = st.load_config()
    ex = explain_pair(cfg, pair_of(cfg, pair))
    if unit not in ("counts", "rad"):
        raise UsageError(f"--unit: '{unit}' is not a unit here; expected 'counts' or 'rad'")
    s_cpr, d_cpr = cfg.joints[ex.sigma].cpr, cfg.joints[ex.delta].cpr
    sigma_counts = _joint_counts(sigma, "--sigma", s_cpr, unit)
    delta_counts = _joint_counts(delta, "--delta", d_cpr, unit)
    # an angle given with its unit (rad, deg) is rounded to counts like --unit rad; 200counts is exact
    angles = any(t is not None and c is not None and not t.strip().lower().endswith("counts")
                 for t, c in ((sigma, sigma_counts), (delta, delta_counts)))
    if sigma_counts is not None or delta_counts is not None:
        def in_unit(text: str, option: str, cpr: int) -> int:
            # a bare number beside one with its unit is still in --unit
            value = _bare(text, option)
            assert value is not None
            _finite(value, option, unit)
            return units.rad_to_counts(value, cpr) if unit == "rad" else _whole(value, option)

        angles = angles or unit == "rad"
        sigma = None if sigma is None else str(sigma_counts if sigma_counts is not None else in_unit(sigma, "--sigma", s_cpr))
        delta = None if delta is None else str(delta_counts if delta_counts is not None else in_unit(delta, "--delta", d_cpr))
        unit = "counts"  # every position now in whole counts, converted once
    sigma_v, delta_v = _bare(sigma, "--sigma"), _bare(delta, "--delta")
    for option, value in (("--sigma", sigma_v), ("--delta", delta_v), ("--motor-a", motor_a), ("--motor-b", motor_b)):
        _finite(value, option, unit if option in ("--sigma", "--delta") else "counts")
    joint_given = sigma is not None or delta is not None
    motor_given = motor_a is not None or motor_b is not None
    if joint_given == motor_given:
        raise UsageError("diffdrive convert: give either --sigma and --delta, or --motor-a and --motor-b")
    if joint_given:
        if sigma_v is None or delta_v is None:
            raise UsageError("diffdrive convert: --sigma and --delta go together")
        if unit == "rad" or angles:
            s_exact, d_exact = (units.rad_to_counts(sigma_v, s_cpr), units.rad_to_counts(delta_v, d_cpr)) \
                if unit == "rad" else (_whole(sigma_v, "--sigma"), _whole(delta_v, "--delta"))
            # angles rarely land on a Σ/Δ pair of equal parity; take the nearest reachable one
            s_counts, d_counts = diffpair.nearest_reachable(s_exact, d_exact)
            if (s_counts, d_counts) != (s_exact, d_exact):
                st.out.warn(f"Σ={s_exact}, Δ={d_exact} counts differ in parity (no whole motor positions); "
                            f"using the nearest reachable Σ={s_counts}, Δ={d_counts}")
        else:
            s_counts, d_counts = _whole(sigma_v, "--sigma"), _whole(delta_v, "--delta")
        m_a, m_b = diffpair.to_motors(s_counts, d_counts)
    else:
        if motor_a is None or motor_b is None:
            raise UsageError("diffdrive convert: --motor-a and --motor-b go together")
        m_a, m_b = _whole(motor_a, "--motor-a"), _whole(motor_b, "--motor-b")
        s_counts, d_counts = diffpair.to_joints(m_a, m_b)
    inside_joints = diffpair.inside_joint_limits(m_a, m_b, ex.sigma_full, ex.delta_full)
    box = diffpair.motor_box(ex.sigma_full, ex.delta_full)
    result: dict[str, Any] = {
        "pair": ex.pair,
        "sigma": {"joint": ex.sigma, "counts": s_counts, "rad": round(units.counts_to_rad(s_counts, s_cpr), 6)},
        "delta": {"joint": ex.delta, "counts": d_counts, "rad": round(units.counts_to_rad(d_counts, d_cpr), 6)},
        "motor_a": {"drive": ex.drive_a, "counts": m_a},
        "motor_b": {"drive": ex.drive_b, "counts": m_b},
        "inside_joint_full_ranges": inside_joints,
        "inside_motor_box": box.contains(m_a, m_b),
    }
    if st.json_mode:
        st.out.json(result)
        return
    st.out.table(None, ["", "name", "counts", "rad"], [
        ["Σ", ex.sigma, s_counts, f"{result['sigma']['rad']:.6f}"],
        ["Δ", ex.delta, d_counts, f"{result['delta']['rad']:.6f}"],
        ["motor a", ex.drive_a, m_a, ""],
        ["motor b", ex.drive_b, m_b, ""],
    ], right=(2, 3))
    if not inside_joints:
        st.out.warn(f"outside the full ranges of {ex.sigma} {_rng(ex.sigma_full)} / {ex.delta} {_rng(ex.delta_full)}")


POSITION_LIMIT = 2**31  # counts: a drive position is a 32-bit integer


def _bare(text: str | None, option: str) -> float | None:
    """A joint position without a unit, as a number (None: not given)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"{option}: {text!r} is not a number; write a number in --unit, or one with its unit "
                         "(0.5rad, 10deg, 200counts)") from None


def _joint_counts(text: str | None, option: str, cpr: int, unit: str) -> int | None:
    """Whole counts of a joint position given with its unit (``10deg``, ``0.5rad``, ``200counts``);
    None for a bare number (it is in --unit) or no value."""
    from sherpa_cli.joints import units

    if text is None:
        return None
    try:
        float(text)
        return None
    except ValueError:
        pass
    return units.parse_position(text, cpr, what=option)


def _finite(value: float | None, option: str, unit: str) -> None:
    """NaN, infinity and positions no drive can hold are refused before any arithmetic."""
    import math

    if value is None:
        return
    if not math.isfinite(value):
        raise UsageError(f"{option}: {value} is not a finite number")
    limit = POSITION_LIMIT if unit == "counts" else 2 * math.pi * POSITION_LIMIT  # cpr >= 1
    if abs(value) > limit:
        raise UsageError(f"{option}: {value:g} {unit} is outside the drive's 32-bit position range")


def _whole(value: float, option: str) -> int:
    if value != int(value):
        raise UsageError(f"{option}: {value} is not a whole number of counts (use --unit rad for radians)")
    return int(value)


@app.command("move")
def move(
    ctx: typer.Context,
    pair: str = PairArg,
    sigma: str | None = typer.Option(None, "--sigma", metavar="POS", help="Σ joint target: rad, or 10deg, "
                                        "200counts. Left out: Σ holds."),
    delta: str | None = typer.Option(None, "--delta", metavar="POS", help="Δ joint target (same units). "
                                        "Left out: Δ holds."),
    relative: bool = typer.Option(False, "--relative", help="--sigma/--delta are offsets from where the joints are."),
    velocity: str | None = typer.Option(None, "--velocity", metavar="SPEED", help="Speed of the joint that moves "
                                           "farthest (rad/s, deg/s, counts/s); default: the joints' speed limits."),
    feedback: bool = typer.Option(False, "--feedback", help="Every cycle, slow the motor that is ahead from the "
                                  "recorded Σ/Δ error (bounded, never faster than planned, inside the guard)."),
    naive: bool = typer.Option(False, "--naive", help="The seed's way, for comparison: two separate BG and "
                               "unscaled profiles."),
    plot: str | None = typer.Option(None, "--plot", metavar="FILE.png", help="Draw both joints during the move."),
    report: Report = None,
    poll: bool = typer.Option(False, "--poll", help="Record by polling PX through the interpreter instead of "
                              "TPDOs on SYNC (changes no PDO settings; coarser, one motor a round trip after the other)."),
    source: str = typer.Option("can", "--source", metavar="can|drive",
                               help="drive: both motors recorded by the drives' own recorders at the servo rate, "
                               "started by the move's BG (RAM only, put back after; --poll does not apply)."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow the move although the pair was not "
                                      "homed since power-up (positions relative to power-up)."),
    hold: bool = typer.Option(False, "--hold", help="After the move keep both motors on, holding where they ended, "
                              "the dead-man armed and the joints shown, until Ctrl-C or `sherpa stop`."),
    force_limit: float | None = typer.Option(None, "--force-limit", metavar="N",
                                             help="Stop the motion when the F/T sensor reads a force above N "
                                                  "newtons (tightens the sensor's configured force_limit)."),
    apply: ApplyMotion = False,
) -> None:
    """Move the Σ and Δ joints of a pair together, both motors starting at once, and measure the coupling.

    Both motors get profiles of equal duration (SP/AC/DC scaled by each motor's share of the
    distance) and start together (motion.pair_start: one BG to a group id in 0x2040, or BG to
    both executed at one SYNC; RAM only, put back afterwards). Every move records both motors
    (TPDO on SYNC, or --poll; --source drive: the drives' own recorders) and reports how far the
    joint that should hold moved, and how far both left the straight Σ/Δ path (docs/diffdrive.md).
    """
    from sherpa_cli.bus.targets import pair_of
    from sherpa_cli.ops import diffdrive

    st = state(ctx)
    st.use_force_limit(force_limit)
    cfg = st.load_config()
    p = pair_of(cfg, pair)
    req = diffdrive.PairTarget(sigma=sigma, delta=delta, relative=relative, velocity=velocity, naive=naive,
                                feedback=feedback, uncalibrated=uncalibrated, poll=poll, source=source, hold=hold)
    diffdrive.check_source(req)
    if naive and feedback:
        raise UsageError("--naive and --feedback do not go together: --naive is the seed's way, for comparison")
    method, _ = diffdrive.pair_settings(cfg)
    from sherpa_cli.log.plot import check_plot_path

    check_plot_path(plot)  # before the move: a plot that cannot be drawn must not cost a motion
    if report is not None:
        from sherpa_cli.output_files import check_output_path

        check_output_path(report, "--report", "the move's report")
    # the values, and absolute targets against the normal ranges, are checked without the bus (a held
    # joint is taken at 0 here; the real check with the present positions follows on the bus)
    diffdrive.plan_move(cfg, p, req, {p.drive_a: 0, p.drive_b: 0})
    mode = "naive" if naive else method
    if not apply:
        what = ", ".join(f"{n} {'by' if relative else 'to'} {v}" for n, v in ((p.sigma, sigma), (p.delta, delta))
                         if v is not None)
        held = [n for n, v in ((p.sigma, sigma), (p.delta, delta)) if v is None]
        start = {"group": f"one BG to group id {cfg.motion.pair_group_id} (0x2040, RAM, put back after)",
                 "sync_rpdo": "BG to both buffered as synchronous RPDO2 (0x1401:2=1, RAM, put back after), one SYNC",
                 "sequential": "two BG back to back", "naive": "two BG back to back, unscaled profiles"}[mode]
        refused = _pair_would_refuse(st, cfg, p, req)
        if st.json_mode:
            st.out.json({"pair": p.name, "applied": False, "move": what, "holds": held, "start": mode,
                         "feedback": feedback,
                         "recording": "drive" if source == "drive" else "poll" if poll else "sync",
                         "checked": refused is not None, "would_be_refused": refused or []})
            if refused:
                raise typer.Exit(1)
            return
        if refused:
            st.out.line(f"dry run: would be refused: {'; '.join(refused)}")
            st.out.line(f"  (the plan: move pair {p.name} ({p.drive_a}, {p.drive_b}): {what})")
            st.out.line("nothing sent; --apply would refuse it too")
            raise typer.Exit(1)
        st.out.line(f"dry run: would move pair {p.name} ({p.drive_a}, {p.drive_b}): {what}"
                    + (f"; {held[0]} holds" if held else ""))
        st.out.line(f"  UM=5, SP/AC/DC of equal duration, PA, {start}"
                    + ("; --feedback slows the motor ahead every cycle" if feedback else "")
                    + (", then hold where they stand until Ctrl-C or `sherpa stop`" if hold else
                       ", then stop and switch off"))
        st.out.line("  records both motors: " + (
            "the drives' own recorders at the servo rate, started by the move's BG (RAM only, put back after)"
            if source == "drive" else "PX polled (--poll)" if poll else
            f"TPDO1 on SYNC at {cfg.motion.pair_record_rate:g} Hz (RAM only, put back after)"))
        st.out.line("nothing sent; add --apply to move")
        return
    from sherpa_cli.api import Arm
    from sherpa_cli.motion.gravity import gravity_notice

    notice = gravity_notice(cfg, [p.sigma, p.delta], holds=hold)
    if notice is not None:
        st.out.warn(notice)

    def progress(joints: Mapping[str, int]) -> None:  # the hold's live line, on a terminal only
        st.out.progress("  ".join(f"{j}: {c} counts" for j, c in joints.items()))

    # in a recipe with `sim_time: stepped` the shared simulated arm moves only while this command waits
    stepped = shared_stepped(st) if st.sim else None
    with st.session(buses=sorted({cfg.drives[d].bus for d in (p.drive_a, p.drive_b)})) as session:
        timebase = stepped if stepped is not None and use_stepped(session, stepped, cfg) else None
        try:
            result = Arm(session).diffdrive_move(p.name, sigma=sigma, delta=delta, relative=relative,
                                                 velocity=velocity, feedback=feedback, naive=naive,
                                                 uncalibrated=uncalibrated, poll=poll, source=source, hold=hold,
                                                 on_progress=progress, timebase=timebase)
        except BaseException as exc:
            st.out.progress(None)
            from sherpa_cli.motion.report import report_of

            stop_report = report_of(exc)
            if stop_report is not None and not st.json_mode:
                for line in stop_report.lines(st.verbose):
                    st.out.info(f"stop: {line}")
                from sherpa_cli.cli.jog_cmd import force_stop_line
                from sherpa_cli.motion.axis import resolve_axis

                where = force_stop_line(exc, [resolve_axis(cfg, p.sigma), resolve_axis(cfg, p.delta)])
                if where is not None:
                    st.out.line(where)
            raise
    st.out.progress(None)
    if plot is not None:
        diffdrive.plot(result, plot)
    if report is not None:
        import json

        from sherpa_cli.output_files import write_output

        write_output(report, json.dumps({**result.as_dict(), "plot": plot}, indent=2) + "\n", "--report",
                     what="the move's report")
    _render_move(st, result, plot)
    if not result.ok:
        raise typer.Exit(1)


def _pair_would_refuse(st: AppState, cfg: ArmConfig, p: PairConfig, req: PairTarget) -> list[str] | None:
    """What `--apply` would refuse (ops/dry_check.py), read from the drives; None when they cannot
    be read (the dry run then says it did not check)."""
    from sherpa_cli.errors import SherpaError
    from sherpa_cli.ops.dry_check import pair_would_refuse

    try:
        with st.session(buses=sorted({cfg.drives[d].bus for d in (p.drive_a, p.drive_b)})) as session:
            return pair_would_refuse(session, p, req)
    except SherpaError as exc:
        st.out.warn(f"not checked on the drives ({exc}): --apply checks calibration, ranges and faults first")
        return None


def _render_move(st: AppState, r: MoveResult, plot: str | None) -> None:
    from sherpa_cli.joints.units import counts_to_rad

    if st.json_mode:
        d = r.as_dict()
        if plot is not None:
            d["plot"] = plot
        st.out.json(d)
        return
    for line in stop_lines(st, r.stop, r.guard_lines):
        st.out.line(f"stop: {line}")
    cmds = "; ".join(f"{d} " + " ".join(f"{k}={v}" for k, v in c.items()) for d, c in r.motor_commands.items())
    if cmds:
        st.out.line(f"sent: {cmds}")
    mode = {"group": "common start (group BG)", "sync_rpdo": "common start (BG at one SYNC)",
            "sequential": "two BG back to back",
            "naive": "naive (two BG, unscaled profiles)"}[r.mode] + (", feedback" if r.feedback else "")
    st.out.line(f"pair {r.pair}: {mode}")
    for b in r.breaches:
        st.out.line(f"limit: {b.joint} left its full range [{b.full[0]}, {b.full[1]}] on the {b.side} side: "
                    f"stopped, nothing more sent, brought back into its normal range")
    rows = []
    for i, (name, cpr) in enumerate(((f"Σ {r.sigma}", r.sigma_cpr), (f"Δ {r.delta}", r.delta_cpr))):
        rows.append([name, r.start[i], r.target[i], r.end[i], f"{r.end[i] - r.target[i]:+d}",
                     f"{counts_to_rad(r.end[i], cpr):+.4f}"])
    st.out.table(None, ["joint", "start", "target", "end", "error", "end (rad)"], rows, right=(1, 2, 3, 4, 5))
    c = r.coupling
    if c is not None:
        if c.held is not None:
            cpr = c.held_cpr
            beyond = ""
            if c.held_planned:
                st.out.line(f"planned: {c.held} (held) gives way {c.held_planned:+d} "
                            f"count{'' if abs(c.held_planned) == 1 else 's'} "
                            f"(Σ and Δ of whole motor positions have equal parity)")
                beyond = " beyond that"
            st.out.line(f"coupling: {c.held} (held) moved up to {c.held_peak:.0f} counts{beyond} "
                        f"({counts_to_rad(c.held_peak, cpr):.4f} rad, {c.fraction(c.held_peak):.1%} of the move)")
        st.out.line(f"off the straight Σ/Δ path: Σ up to {c.peak_sigma:.0f} counts "
                    f"({counts_to_rad(c.peak_sigma, c.sigma_cpr):.4f} rad), Δ up to {c.peak_delta:.0f} counts "
                    f"({counts_to_rad(c.peak_delta, c.delta_cpr):.4f} rad)")
    st.out.line(f"recording: {r.trace_source}, {len(r.samples)} samples")
    if r.held_at is not None:
        from sherpa_cli.cli.jog_cmd import hold_line

        st.out.line(hold_line(r.held_at, r.held_until))
    if plot is not None:
        st.out.line(f"plot: {plot}")


@app.command("match")
def match(
    ctx: typer.Context,
    pair: str = PairArg,
    measure: bool = typer.Option(False, "--measure", help="Step the pair (small Σ steps inside the motion guard, "
                                 "trial gains in RAM, put back) and show the proposal; nothing lasting is written."),
    apply: ApplyMatch = False,
    save: Save = False,
    yes: Yes = False,
    speed: int | None = typer.Option(None, "--speed", metavar="COUNTS/S", help="Each motor's speed in the step "
                                     "(default: a quarter of the Σ joint's speed limit)."),
    rounds: int = typer.Option(5, "--rounds", help="Trial steps at most after the first."),
    plot: str | None = typer.Option(None, "--plot", metavar="FILE.png", help="Draw both motors' speeds and Δ "
                                    "before and after."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow the steps although the pair was not "
                                      "homed since power-up."),
) -> None:
    """Make both speed loops of PAIR equally fast (the seed's first cure for its coupled pair).

    Steps both motors together (a small Σ velocity step, one common BG), records them with the drives'
    own recorders, identifies each loop's delay, and proposes gains for the faster motor (KP[2], KP[3]
    x s, KI[2] x s^2) so both delays agree, trying them in RAM first. Without --measure or --apply
    nothing moves. docs/tune.md.

    \b
    Examples:
      sherpa diffdrive match shoulder_diff
      sherpa diffdrive match shoulder_diff --measure --plot match.png
      sherpa diffdrive match shoulder_diff --apply --save --yes
    """
    from sherpa_cli.bus.targets import pair_of
    from sherpa_cli.cli.program_cmd import check_options
    from sherpa_cli.ops import pair_match

    st = state(ctx)
    check_options(apply, save)
    if rounds < 1:
        raise UsageError(f"--rounds {rounds}: expected 1 or more")
    from sherpa_cli.log.plot import check_plot_path

    check_plot_path(plot)  # before the trial moves
    if apply and st.json_mode:
        raise UsageError("--json with --apply: the proposal and the write would be two reports",
                         hint="--measure --json shows the proposal; write it with `sherpa tune set ... --apply`")
    cfg = st.load_config()
    p = pair_of(cfg, pair)
    v = pair_match.step_speed(cfg, p, speed)
    settings = pair_match.MatchSettings(speed=v, uncalibrated=uncalibrated)
    if not (measure or apply):
        if st.json_mode:
            st.out.json({"pair": p.name, "measured": False, "speed": v, "step_s": settings.step_s,
                         "rounds": rounds, "tolerance": settings.tolerance})
            return
        st.out.line(f"dry run: would step pair {p.name} ({p.drive_a}, {p.drive_b}): both motors JV={v} counts/s "
                    f"for {settings.step_s:g} s from one common BG, recorded by their drives, then back to where "
                    f"they stood")
        st.out.line(f"  then up to {rounds} trial steps with the faster motor's KP[2], KP[3], KI[2] scaled in RAM "
                    f"(put back after), until both delays agree within {settings.tolerance:.0%}")
        st.out.line("nothing sent; add --measure to step and see the proposal, --apply to also write it")
        return
    from sherpa_cli.api import Arm

    with st.session(buses=sorted({cfg.drives[d].bus for d in (p.drive_a, p.drive_b)})) as session:
        result = Arm(session).match_pair(p.name, speed=speed, rounds=rounds, uncalibrated=uncalibrated)
    if plot is not None:
        pair_match.plot(result, plot)
    if st.json_mode:
        st.out.json({**result.as_dict(), **({"plot": plot} if plot else {})})
        return
    _render_match(st, result, plot)
    # a drive whose scaled gains all round to what it holds has nothing to write: no empty tune set
    changes = {d: values for d, values in result.proposal.changes.items() if values}
    if not changes:
        return
    if not result.reached:
        st.out.warn(f"the delays still differ by more than {result.proposal.tolerance:.0%} after {plural(rounds, 'trial')}: "
                    f"the best trial is proposed")
    if not apply:
        drive, values = next(iter(changes.items()))
        st.out.line("nothing written; add --apply to write it, or: sherpa tune set "
                    f"{drive} " + " ".join(f"{k}={x:g}" for k, x in values.items()) + " --apply")
        return
    from sherpa_cli.cli.limits_cmd import drive_moves
    from sherpa_cli.cli.program_cmd import run_program
    from sherpa_cli.ops.program import DriveTarget

    targets = [DriveTarget(d, cfg.drives[d].bus, cfg.drives[d].node, dict(values)) for d, values in changes.items()]
    (drive, values), = changes.items()  # the proposal changes the faster motor only
    run_program(st, "diffdrive match", targets, [], apply=True, save=save, yes=yes, motor_off=False,
                need_serial=save, allow_disabled=False, title=lambda drive: drive_moves(cfg, drive),
                via=lambda arm, confirm, on_plan: arm.tune_set(drive, values, apply=True, save=save,
                                                               confirm_save=confirm, on_plan=on_plan, check=False))


def _render_match(st: AppState, r: MatchResult, plot: str | None) -> None:
    prop = r.proposal
    rows = []
    for k, rnd in enumerate(r.rounds):
        for drive in prop.drives:
            m = rnd.models[drive]
            rows.append([("own gains" if k == 0 else f"trial {k}") + (" *" if k == r.chosen and k else ""), drive,
                         f"{m.delay_s * 1e3:.1f}", f"{m.rise_s * 1e3:.1f}", f"{m.overshoot:.1%}",
                         m.bandwidth_text(), f"{m.zeta:.2f}", f"{rnd.excursion:.0f}"])
    st.out.line(f"pair {r.pair}: Σ step, each motor {prop.speed:g} counts/s, recorded by the drives")
    st.out.table(None, ["round", "drive", "delay ms", "rise ms", "overshoot", "bandwidth Hz", "damping", "Δ peak"],
                 rows, right=(2, 3, 4, 5, 6, 7))
    notes = sorted({note for rnd in r.rounds for m in rnd.models.values() if (note := m.bandwidth_note)})
    for note in notes:
        st.out.line(f"bandwidth: {note}")
    before, after = r.rounds[0], r.rounds[r.chosen]
    st.out.line(f"Δ excursion of the Σ step (counts): predicted {prop.predicted_excursion(False):.1f} -> "
                f"{prop.predicted_excursion(True):.1f}, measured {before.excursion:.0f} -> {after.excursion:.0f}")
    if not prop.changes:
        st.out.line(f"no change: {prop.note}")
    else:
        for drive, values in prop.changes.items():
            held = prop.gains[drive]
            st.out.line(f"proposal: {drive} " + ", ".join(f"{k} {held[k]:g} -> {x:g}" for k, x in values.items())
                        + f" ({prop.note})")
    if plot is not None:
        st.out.line(f"plot: {plot}")
