"""`sherpa tune show|step|set JOINT`: the drives' speed and position loop gains (docs/tune.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import state, use_stepped
from sherpa_cli.cli.options import Apply, ApplyMotion, MotorOff, Save, Yes
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.log.plot import StepRun
    from sherpa_cli.ops.tune_step import TuneStepResult

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
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.elmo.commands import format_value
    from sherpa_cli.ops.tune import GAINS

    st = state(ctx)
    cfg = st.load_config()
    refs = drive_refs(cfg, [target], configured_only=True, elmo_only="tune")
    with st.session(buses=list(dict.fromkeys(r.bus for r in refs))) as session:
        readings = Arm(session).tune_show(target)
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
    refs = drive_refs(cfg, [target], configured_only=True, elmo_only="tune")
    targets = [DriveTarget(r.name, r.bus, r.node, values) for r in refs]
    run_program(st, "tune set", targets, [], apply=apply, save=save, yes=yes, motor_off=motor_off,
                need_serial=save, allow_disabled=False, title=lambda drive: drive_moves(cfg, drive),
                via=lambda arm, confirm, on_plan: arm.tune_set(target, values, apply=apply, save=save,
                                                               motor_off=motor_off, confirm_save=confirm,
                                                               on_plan=on_plan, check=False))


@app.command("step")
def step(
    ctx: typer.Context,
    joint: str = typer.Argument(..., metavar="JOINT", help="A plain joint (or its drive)."),
    gains: list[str] = typer.Argument(..., metavar="GAIN=VALUE...", help="The trial gains, e.g. KP[2]=0.8"),
    position: float | None = typer.Option(None, "--position", metavar="X", help="A position step of X rad "
                                          "(then back -X with the trial gains)."),
    velocity: float | None = typer.Option(None, "--velocity", metavar="V", help="A velocity step to V rad/s."),
    duration: float = typer.Option(2.0, "--for", metavar="S", help="Record at most S s after each command."),
    rate: float = typer.Option(500.0, "--rate", metavar="HZ", help="Samples per second."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow a position step of a joint that was "
                                      "not homed since power-up."),
    plot: str | None = typer.Option(None, "--plot", metavar="FILE.png", help="Draw both steps on one axes, "
                                    "each with its figures (needs matplotlib)."),
    apply: ApplyMotion = False,
) -> None:
    """Step JOINT with the gains its drive holds, then with trial gains (RAM only, put back on every
    exit path), and show the step metrics of both. Nothing is saved; `tune set` writes gains to keep.

    \b
    Examples:
      sherpa tune step elbow_pitch --velocity 0.1 KP[2]=0.8 --apply
      sherpa tune step elbow_pitch --position 0.2 KP[3]=40 --plot tune.png --apply
    """
    import math

    from sherpa_cli.cli.log_cmd import render_metrics, stepped_sim
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.step import resolve_step_target, step_request
    from sherpa_cli.ops.tune import parse_assignments

    st = state(ctx)
    given = [(m, v) for m, v in (("position", position), ("velocity", velocity)) if v is not None]
    if len(given) != 1:
        raise UsageError("give exactly one of --position X or --velocity V")
    mode, value = given[0]
    if not math.isfinite(value):
        raise UsageError(f"--{mode} {value}: expected a finite number")
    if not (math.isfinite(duration) and 0 < duration <= 60):
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= 60")
    if not (0 < rate <= 10000):
        raise UsageError(f"--rate {rate}: expected Hz > 0 and <= 10000")
    from sherpa_cli.log.plot import check_plot_path

    check_plot_path(plot)  # before the steps: a plot that cannot be drawn must not cost two motions
    cfg = st.load_config()
    trial = parse_assignments(cfg, gains)
    target = resolve_step_target(cfg, joint)
    step_request(target, mode, value, duration=duration, uncalibrated=uncalibrated)
    if not apply:
        text = " ".join(f"{k}={v:g}" for k, v in trial.items())
        if st.json_mode:
            st.out.json({"joint": target.name, "drive": target.ref.name, "mode": mode, "value": value,
                         "trial": trial, "applied": False})
            return
        st.out.line(f"dry run: would step {target.name} ({target.ref.name}) {mode} {value:g} with its own gains, "
                    f"then {'back ' if mode == 'position' else ''}with {text} (RAM only, put back after)")
        st.out.line("nothing sent; add --apply to move")
        return
    from sherpa_cli.api import Arm

    settings = MotionSettings.from_config(cfg, [target.ref.bus])
    stepped, sim_factory = stepped_sim(st)
    with st.session(buses=[target.ref.bus], sim_factory=sim_factory) as session:
        timebase = stepped if stepped is not None and use_stepped(session, stepped, cfg) else None
        result = Arm(session).tune_step(joint, mode, value, trial, duration=duration, rate=rate,
                                        uncalibrated=uncalibrated, settings=settings, timebase=timebase)
    held = " ".join(f"{k}={v:g}" for k, v in result.held.items())
    text = " ".join(f"{k}={v:g}" for k, v in result.trial.items())
    if plot is not None:
        from sherpa_cli.log.plot import plot_step_runs

        plot_step_runs(target.name, mode, result.before.signal, tune_runs(result), plot)
    if st.json_mode:
        st.out.json({**result.as_json(), **({"plot": plot} if plot else {})})
        return
    render_metrics(st, {(f"{result.before.joint} ({held})", result.before.signal): result.before.metrics})
    render_metrics(st, {(f"{result.after.joint} ({text})", result.after.signal): result.after.metrics})
    st.out.line(f"{target.ref.name}: the trial gains were RAM only and are put back ({held})")
    if plot is not None:
        st.out.line(f"plot: {plot}")


def tune_runs(result: TuneStepResult) -> list[StepRun]:
    """Both steps of `tune step` as the plot's runs, labelled with the gains each ran with."""
    from sherpa_cli.log.plot import StepRun

    held = " ".join(f"{k}={v:g}" for k, v in result.held.items())
    text = " ".join(f"{k}={v:g}" for k, v in result.trial.items())
    runs = []
    for label, step in ((f"own gains ({held})", result.before), (f"trial ({text})", result.after)):
        series = step.recording.series(step.joint, step.signal) or ([], [])
        runs.append(StepRun(label, step.value, series[0], series[1], step.metrics))
    return runs
