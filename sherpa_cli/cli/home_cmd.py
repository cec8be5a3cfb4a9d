"""`sherpa home [JOINT...]`: calibrate joints (ops/home.py does the work); `--check-wiring JOINT`."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import YesMotion
from sherpa_cli.cli.output import stop_lines
from sherpa_cli.errors import SafetyError, UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.ops.home import HomePlan, UnitResult, WiringPrompt

KIND_TEXT = {"home_switch": "home switch", "end_switches": "end switches", "pair": "differential pair",
             "abs_encoder": "absolute encoder"}


def home(
    ctx: typer.Context,
    joints: list[str] | None = typer.Argument(None, metavar="[JOINT]...", help="Joints, pairs (or a Σ/Δ joint: "
                                                 "its pair) or drives; default: every joint that can be homed."),
    yes: YesMotion = False,
    dry_run: bool = typer.Option(False, "--dry-run", help="Only show the plan; nothing is sent."),
    measure_range: bool = typer.Option(False, "--measure-range", help="End-switch joints: also drive to the other "
                                       "end switch and report the measured travel against the configured range."),
    check_wiring: bool = typer.Option(False, "--check-wiring", help="No motion: show the joint's inputs and ask "
                                      "you to press each switch in turn; reports swapped, dead and inverted inputs."),
) -> None:
    """Calibrate joints: find their switches (or read their absolute encoder) and set the drive's
    position counter; then mark each drive calibrated until its next reset (UI[calibration_flag]).

    Shows what will move, in which direction, at what speed and how far at most, and asks first
    (without a terminal it refuses unless --yes). Kinds, chosen from the config: a home switch inside
    the range (search, back off, slow re-approach: the repeat difference is reported), end switches
    (to the switch calibration.speed points to, then back into the normal range), a differential pair
    (Σ then Δ, both motors together) and an absolute encoder (no motion). Every motion runs inside
    the motion guard. See docs/home.md.

    \b
    Examples:
      sherpa home --dry-run
      sherpa home shoulder_yaw
      sherpa home shoulder_diff --yes
      sherpa home elbow_stiffness --measure-range
      sherpa home --check-wiring shoulder_yaw_stiffness
    """
    from sherpa_cli.ops import home as ops_home

    st = state(ctx)
    cfg = st.load_config()
    if check_wiring:
        if not joints or len(joints) != 1:
            raise UsageError("--check-wiring takes exactly one JOINT", hint="e.g. sherpa home --check-wiring elbow_stiffness")
        _check_wiring(st, joints[0])
        return
    plan = ops_home.plan_home(cfg, joints or None, measure_range=measure_range)
    if not plan.units:
        raise UsageError("nothing to home: no configured joint has a switch or an absolute encoder to home with")
    if st.json_mode and dry_run:
        st.out.json({"applied": False, **plan.as_dict()})
        return
    if not st.json_mode:
        _show_plan(st, cfg, plan)
    if dry_run:
        if not st.json_mode:
            st.out.line("dry run: nothing sent")
        return
    if plan.moves:
        st.out.assume_yes = st.out.assume_yes or yes
        if not st.out.confirm("move these joints now?", refusal="home moves joints: refusing without a terminal",
                              hint="pass --yes to home in scripts, or --dry-run to see the plan"):
            raise SafetyError("not confirmed: nothing moved")
    buses = sorted({cfg.drives[d].bus for u in plan.units for d in u.drives}
                   | {cfg.devices[d].bus for u in plan.units for d in u.devices})

    def done(unit: UnitResult) -> None:
        if not st.json_mode:
            _render_unit(st, cfg, unit)

    def step(text: str) -> None:
        st.out.progress(f"home: {text}")  # a live line on a terminal only (never in logs or --json)

    from sherpa_cli.api import Arm

    partial = ops_home.HomeReport()
    with st.session(buses=buses) as session:
        try:  # the API plans the same units again from the config
            report = Arm(session).home(joints or None, measure_range=measure_range, on_unit=done, on_step=step,
                                       report=partial)
        except BaseException as exc:
            st.out.progress(None)
            from sherpa_cli.motion.report import report_of

            motion = report_of(exc) or partial.stop
            if motion is not None and not st.json_mode:
                for line in motion.lines(st.verbose):
                    st.out.info(f"stop: {line}")
            if partial.interrupted is not None and not st.json_mode:
                homed = [u.name for u in partial.units]
                st.out.info(f"not homed: {', '.join(partial.not_homed)} ({partial.interrupted} did not finish; "
                            "its calibration mark was cleared before the search: home it again)"
                            + (f"; homed before it: {', '.join(homed)}" if homed else ""))
            raise
        st.out.progress(None)
    if st.json_mode:
        st.out.json(report.as_dict())
    else:
        st.out.line(f"homed {plural(len(report.units), 'unit')}; marked calibrated until the drives reset "
                    f"(UI[{cfg.protocol.calibration_flag}]=1)")


def _show_plan(st: AppState, cfg: ArmConfig, plan: HomePlan) -> None:
    st.out.line("home plan:")
    for u in plan.units:
        st.out.line(f"  {u.name} ({KIND_TEXT[u.kind]}; {', '.join(u.drives)})")
        for s in u.switches:
            st.out.line(f"    uses {s}")
        if not u.moves:
            st.out.line("    no motion: reads the encoder and sets PX from it (immediate home event)")
        for m in u.moves:
            way = "up" if m.direction > 0 else "down"
            st.out.line(f"    {m.what}: {m.joint} {way} at {m.speed} counts/s, at most {m.max_distance} counts")
    for joint, why in plan.skipped:
        st.out.line(f"  skipped {joint}: {why}")


def _render_unit(st: AppState, cfg: ArmConfig, u: UnitResult) -> None:
    for line in stop_lines(st, u.motion_stop, u.motion_lines):
        st.out.line(f"stop: {line}")
    sets = ", ".join(f"{j} = {v}" for j, v in u.set_to.items())
    at = ", ".join(f"{j} at {v} counts" for j, v in u.positions.items())
    text = f"{u.name}: homed ({KIND_TEXT[u.kind]}): set {sets}; now {at}"
    if u.encoder:
        text += "; encoder read " + ", ".join(
            f"{d} {v}" + (f" ({u.encoder_via[d]})" if d in u.encoder_via else "") for d, v in u.encoder.items())
    if u.repeat_difference is not None:
        text += f"; repeat difference {u.repeat_difference:+d} counts"
    if u.measured_travel is not None and u.configured_travel is not None:  # set together
        text += (f"; measured travel {u.measured_travel} counts (configured {u.configured_travel}, "
                 f"{u.measured_travel - u.configured_travel:+d})")
    st.out.line(text)


def _check_wiring(st: AppState, name: str) -> None:
    from sherpa_cli.ops import home as ops_home

    cfg = st.load_config()
    plan = ops_home.wiring_plan(cfg, name)
    if not plan:  # an absolute-encoder joint: nothing to press, nothing is read
        joints = [cfg.joints[n] for n in ops_home.wiring_joints(cfg, name)]
        sources = [(j.name, j.abs_encoder.source) for j in joints if j.abs_encoder is not None]
        shown = sources[0][1] if len(sources) == 1 and sources[0][0] == name else \
            ", ".join(f"{j}: {s}" for j, s in sources)
        text = (f"{name} has an absolute encoder ({shown}) and no switches: there is no wiring to check; "
                "its position comes from the encoder (`sherpa home` reads it, no motion)")
        if st.json_mode:
            st.out.json({"joint": name, "ok": True, "switches": 0, "abs_encoder": True, "findings": [],
                         "note": text})
        else:
            st.out.line(text)
        return
    buses = sorted({cfg.drives[d].bus for _, _, drives in plan for d in drives})
    with st.session(buses=buses) as session:
        sim = getattr(session, "sim", None) if st.sim else None

        def ask(p: WiringPrompt) -> None:
            verb = "Press and hold" if p.action == "press" else "Release"
            text = f"{verb} {p.joint} {p.switch} (wired to {', '.join(p.drives)}), then Enter"
            if sim is not None:
                text += " (the simulator does it)"
            st.out.info(text)
            if sim is not None:
                for d in p.drives:
                    sim.press_switch(d, p.input, p.action == "press")
            line = sys.stdin.readline()
            if not line:
                raise SafetyError("no answer on stdin: the wiring check needs a technician at the arm",
                                  hint="run it on a terminal")

        def live(pins: dict[str, dict[int, bool]]) -> None:
            if st.json_mode:
                return
            for d, state_ in pins.items():
                shown = ", ".join(f"input {n} {'active' if v else 'inactive'}" for n, v in sorted(state_.items()))
                st.out.info(f"{d} now: {shown}")

        report = ops_home.check_wiring(session, name, ask, on_live=live)
        if sim is not None:
            for _, sw, drives in plan:
                for d in drives:
                    sim.press_switch(d, sw.input, None)
    if st.json_mode:
        st.out.json(report.as_dict())
    else:
        st.out.line(f"wiring check of {name}:")
        for f in report.findings:
            st.out.line(f"  {f.line()}")
        unchecked = sum(1 for f in report.findings if f.verdict == "already active")
        bad = sum(1 for f in report.findings if not f.ok) - unchecked
        st.out.line(f"{len(report.findings) - bad - unchecked} ok, {plural(bad, 'fault')}"
                    + (f", {unchecked} not checked" if unchecked else ""))
    if not report.ok:
        raise typer.Exit(1)

