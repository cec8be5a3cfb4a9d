"""`sherpa log record --source drive`: the drives' own recorders (ops/drive_record.py, docs/log.md)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sherpa_cli.cli.context import AppState
from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.log.plot import StepMarks
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.step import StepResult, StepTime


def record_from_drive(st: AppState, targets: Sequence[str] | None, duration: float, output: Sequence[Path], *,
                      source: str, trigger: str, poll: bool, live: bool) -> None:
    """Check the options, record, write the CSV only once every drive's upload is in."""
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import drive_refs
    from sherpa_cli.elmo.recorder import RecorderSettings, plan_recording
    from sherpa_cli.log.recording import write_csv

    if source != "drive":
        raise UsageError(f"--source {source}: expected can or drive")
    if trigger not in ("now", "bg"):
        raise UsageError(f"--trigger {trigger}: expected now or bg")
    if poll or live:
        raise UsageError("--source drive records in the drives, not over the bus: --poll and --foxglove do not apply")
    paths = list(output)
    if len(paths) != 1 or paths[0].suffix.lower() != ".csv":
        raise UsageError("--source drive writes one CSV file: give one -o FILE.csv")
    if not paths[0].parent.is_dir():
        raise UsageError(f"{paths[0]}: the directory does not exist")
    plan_recording(duration, RecorderSettings())  # a time the recorder cannot hold: refused before the bus opens
    cfg = st.load_config()
    refs = drive_refs(cfg, targets, configured_only=True, elmo_only="log record --source drive")
    with st.session(buses=list(dict.fromkeys(r.bus for r in refs))) as session:
        if trigger == "bg":
            st.out.info("armed: waiting for the next BG (start the move now)")
        result = Arm(session).record_drives(targets, duration, trigger=trigger)
    write_csv(result.recording, paths[0])
    rate = 1.0 / result.period_s
    if st.json_mode:
        st.out.json({"file": str(paths[0]), "rows": len(result.recording.times), "rate_hz": round(rate, 3),
                     "gap": result.plan.gap, "drives": [{"drive": n, "samples": c} for n, c in result.samples.items()]})
        return
    for name, count in result.samples.items():
        st.out.line(f"{name}: {count} samples at {rate:.1f} Hz (RG={result.plan.gap})")
    st.out.line(f"wrote {paths[0]} ({len(result.recording.times)} rows)")




def drive_step(st: AppState, session: ArmSession, target: Axis, mode: str, value: float, *, duration: float,
               rate: float, settings: MotionSettings, uncalibrated: bool, timebase: StepTime | None, output: Path,
               render_metrics: Callable[[AppState, Any], None], png: bool = False) -> None:
    """`log step --source drive`: the step recorded by the drive's recorder and over the bus at once
    (ops/drive_step.py); both recordings, both metrics and their differences; ``png``: also
    step.png, the drive's recording with the bus's drawn beside it (matplotlib was checked before
    the step moved)."""
    import json

    from sherpa_cli.api import Arm
    from sherpa_cli.log.recording import write_csv

    result, drive = Arm(session).log_step_with_drive(target.name, mode, value, duration=duration, rate=rate,
                                                     uncalibrated=uncalibrated, settings=settings,
                                                     timebase=timebase)
    write_csv(drive.recording, output / "recording.csv")
    write_csv(result.recording, output / "can-recording.csv")
    keys = ("dead_time", "rise_time", "settling_time")
    diff = {k: _diff(getattr(drive.metrics, k), getattr(result.metrics, k)) for k in keys}
    report = {**result.as_json(), "source": "drive",
              "drive": {"metrics": drive.metrics.as_json(), "period_s": drive.period_s, "gap": drive.gap,
                        "samples": drive.samples, "t0": round(drive.t0, 6)},
              "can_period_s": 1.0 / rate, "drive_minus_can_s": diff}
    (output / "metrics.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    files = {"csv": str(output / "recording.csv"), "can csv": str(output / "can-recording.csv"),
             "metrics": str(output / "metrics.json")}
    if png:
        from sherpa_cli.log.plot import plot_recording, step_title

        marks = step_marks(result)
        plot_recording(drive.recording, [result.joint], output / "step.png",
                       metrics={(result.joint, result.signal): drive.metrics}, marks=marks,
                       title=step_title(result.joint, marks),
                       label=f"drive recorder ({drive.period_s * 1e6:.0f} us)", overlay=(f"CAN ({rate:g} Hz)",
                                                                                         result.recording))
        files["png"] = str(output / "step.png")
    if st.json_mode:
        st.out.json({**report, "files": files})
        return
    st.out.line(f"{result.joint} ({result.drive}): {mode} step {value:g} -> {result.command}; "
                f"MO/UM switch {1000 * result.switch_s:.0f} ms; {result.ended_by}")
    st.out.line(f"drive recorder: {drive.samples} samples every {drive.period_s * 1e6:.0f} us (RG={drive.gap}), "
                f"first at {drive.t0 * 1e3:.1f} ms")
    render_metrics(st, {(f"{result.joint} (drive)", result.signal): drive.metrics})
    st.out.line(f"CAN: {result.samples} of {result.expected} samples at {rate:g} Hz")
    render_metrics(st, {(f"{result.joint} (CAN)", result.signal): result.metrics})
    st.out.line("drive - CAN: " + ", ".join(f"{k.replace('_', ' ')} {_ms(v)}" for k, v in diff.items())
                + f" (CAN sample period {1e3 / rate:g} ms)")
    for line in result.stop.lines(st.verbose):
        st.out.line(line)
    for key, path in files.items():
        st.out.line(f"{key}: {path}")


def step_marks(result: StepResult) -> StepMarks:
    """What a step's plot draws and its title says, from the step's own result: the value asked,
    the switch, and where it went (the target the legend's line shows)."""
    from sherpa_cli.log.plot import StepMarks

    return StepMarks(result.mode, result.value, result.switch_s, target=result.target)


def _diff(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else round(a - b, 6)


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v * 1e3:+.1f} ms"
