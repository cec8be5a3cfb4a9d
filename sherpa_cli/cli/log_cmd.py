"""`sherpa log ...`: capture raw traffic, decode captures, plot recordings (docs/log.md)."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, NoReturn

import typer

from sherpa_cli.cli.context import AppState, shared_stepped, state, use_stepped
from sherpa_cli.cli.options import ApplyMotion, Targets
from sherpa_cli.cli.robotics import DEFAULT_AT, AllowRemote, Foxglove, FoxgloveAt
from sherpa_cli.errors import SherpaError, UsageError, raise_if_signalled
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.log.capture import CaptureResult
    from sherpa_cli.log.record import Gaps
    from sherpa_cli.log.recording import Recording
    from sherpa_cli.log.step_metrics import StepMetrics
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.request import MoveRequest
    from sherpa_cli.ops.step import StepResult
    from sherpa_cli.sim.arm import SimArm
    from sherpa_cli.sim.stepped import SteppedTime

app = typer.Typer(help="Record, capture, decode and plot CAN traffic and joint motion (docs/log.md).",
                  no_args_is_help=True)


def _names(st: AppState) -> tuple[list[str], dict[tuple[str, int], str]]:
    """Bus names in config order and (bus, node) -> drive name, when a config is there to say."""
    if not st.config_given and not st.config_path.exists():
        return [], {}
    cfg = st.load_config()
    return list(cfg.buses), {(d.bus, d.node): d.name for d in cfg.drives.values()}


@app.command("decode")
def decode(
    ctx: typer.Context,
    file: Path = typer.Argument(..., metavar="FILE", help="A capture: .log/.txt (candump -L), .asc, .blf, .csv, "
                                ".trc, .mf4 (with asammdf), .mcap (robotics extra)."),
    bus: list[str] | None = typer.Option(None, "--bus", metavar="BUS", help="Only frames of this bus (repeat)."),
    node: list[int] | None = typer.Option(None, "--node", metavar="ID", help="Only frames of this node (repeat)."),
    kind: list[str] | None = typer.Option(
        None, "--kind", metavar="KIND",
        help="Only frames of this kind (repeat): nmt, sync, emcy, heartbeat, sdo, interp, pdo, other."),
) -> None:
    """Print what each frame of a capture means: NMT, SYNC, heartbeat, EMCY with the Elmo text, SDO
    requests and responses with object names and values (segmented transfers joined), interpreter
    requests and replies with command names, values and error texts, and PDOs by their mapping
    when the capture contains the SDO writes that set it.

    Times are seconds from the capture's first frame. Formats that keep only a channel number
    (asc, blf, trc) name the bus by its position in the config (0 = first bus).

    \b
    Examples:
      sherpa log decode run.log
      sherpa log decode run.asc --node 40 --kind interp
      sherpa --json log decode run.blf --kind emcy
    """
    from sherpa_cli.log.candecode import KINDS, FrameDecoder
    from sherpa_cli.log.capture import read_frames

    st = state(ctx)
    for k in kind or []:
        if k not in KINDS:
            raise UsageError(f"--kind {k}: expected one of {', '.join(KINDS)}")
    for n in node or []:
        if not 0 <= n <= 127:  # 0: NMT/SYNC; a CANopen node id is 1..127
            raise UsageError(f"--node {n}: expected a node id 0..127")
    bus_names, nodes = _names(st)
    decoder = FrameDecoder(nodes)
    wanted_bus, wanted_node, wanted_kind = set(bus or []), set(node or []), set(kind or [])
    rows = []
    t0 = None
    # Every frame goes through the decoder (segments and PDO mappings need the whole story);
    # the filters only choose what is shown.
    for item in decoder.decode_all(read_frames(file, bus_names)):
        if t0 is None:
            t0 = item.frame.timestamp
        if wanted_bus and item.frame.bus not in wanted_bus:
            continue
        if wanted_node and item.node not in wanted_node:
            continue
        if wanted_kind and item.kind not in wanted_kind:
            continue
        rows.append(item)
    if st.json_mode:
        st.out.json({"file": str(file), "frames": [r.as_json(t0 or 0.0) for r in rows]})
        return
    width = max((len(r.frame.bus) for r in rows), default=4)
    for r in rows:
        st.out.line(f"{r.frame.timestamp - (t0 or 0.0):11.6f}  {r.frame.bus:<{width}}  {r.frame.raw():<20}  "
                    f"{r.kind:<9}  {r.text}")
    if not rows:
        st.out.info("no frames matched")


@app.command("capture")
def capture(
    ctx: typer.Context,
    output: Path = typer.Option(..., "--output", "-o", metavar="FILE",
                                help="Where to write: .log (candump, channel per line), .asc, .blf, .csv, .trc, "
                                ".mf4 (with asammdf), .mcap (a JSON channel per bus; robotics extra)."),
    bus: list[str] | None = typer.Option(None, "--bus", metavar="BUS",
                                            help="Capture only this configured bus (repeat); default: every bus."),
    duration: float | None = typer.Option(None, "--for", metavar="S", help="Stop after S seconds (default: Ctrl-C)."),
) -> None:
    """Capture every frame of the configured buses into one file until Ctrl-C (or --for),
    then print the frame count per bus, frames lost (adapter or queue overruns) and bus load.

    Only listens: nothing is sent. Ctrl-C ends the capture without losing buffered frames.

    \b
    Examples:
      sherpa log capture -o run.log
      sherpa log capture -o can1.asc --bus can1 --for 10
    """
    from sherpa_cli.bus.busmap import apply_bus_map, parse_bus_map
    from sherpa_cli.bus.links import open_bus
    from sherpa_cli.log.capture import capture as run_capture
    from sherpa_cli.log.capture import check_output

    st = state(ctx)
    if st.sim:
        # an in-process arm answers only the command that opened it, and sends nothing unasked (no
        # heartbeat: 0x1017 = 0): a capture there would write an empty file, and while it ran it would
        # hold the arm, so every other `--sim` command would wait for it
        raise UsageError("log capture --sim: the in-process simulated arm talks only with the command that opens "
                         "it, so a capture here would hear nothing of your other commands (and hold the arm: they "
                         "would wait for it); nothing captured",
                         hint="capture a simulated bus through a served simulator: `sherpa sim --serve "
                              "127.0.0.1:54701` in one terminal, then `sherpa --bus-map ... log capture -o bus.log` "
                              "and the commands to capture with the same --bus-map it prints (docs/simulator.md)")
    if duration is not None and not 0 < duration <= 86400:
        raise UsageError(f"--for {duration}: expected seconds > 0 and <= 86400")
    check_output(output)
    cfg = st.load_config()
    mapping = parse_bus_map(st.bus_map)
    if mapping:
        cfg = apply_bus_map(cfg, mapping)
    names = list(bus or cfg.buses)
    for name in names:
        if name not in cfg.buses:
            raise UsageError(f"--bus {name}: not a configured bus (configured: {', '.join(cfg.buses)})")
    opened = {}
    stop = threading.Event()
    timer = None
    try:
        for name in names:
            opened[name] = open_bus(cfg.buses[name])
        if duration is not None:
            timer = threading.Timer(duration, stop.set)
            timer.daemon = True
            timer.start()
        st.out.info(f"capturing {', '.join(names)} into {output} (Ctrl-C to stop)")
        result = run_capture(opened, output, list(cfg.buses), stop=stop,
                             bitrates={n: cfg.buses[n].bitrate for n in names})
    finally:
        if timer is not None:
            timer.cancel()
        for b in opened.values():
            b.shutdown()
    _render_capture(st, result)


def _render_capture(st: AppState, result: CaptureResult) -> None:
    if st.json_mode:
        st.out.json({"file": str(result.path), "seconds": round(result.seconds, 3), "frames": result.frames,
                     "lost": result.lost,
                     "buses": [{"bus": c.bus, "frames": c.frames, "error_frames": c.errors, "lost": c.overruns,
                                "load": None if (load := result.load(c.bus)) is None else round(load, 4)}
                               for c in result.counts.values()]})
        return
    rows = []
    for c in result.counts.values():
        load = result.load(c.bus)
        rows.append([c.bus, c.frames, c.errors, c.overruns, "-" if load is None else f"{100 * load:.1f} %"])
    st.out.table(f"{result.path}: {result.frames} frames in {result.seconds:.1f} s, {result.lost} lost",
                 ["bus", "frames", "error frames", "lost", "load"], rows, right=(1, 2, 3, 4))


@app.command("plot")
def plot(
    ctx: typer.Context,
    file: Path = typer.Argument(..., metavar="FILE.csv", help="A recording of `log record` or `log step`."),
    output: Path = typer.Option(..., "--output", "-o", metavar="FILE.png", help="Where to write the PNG."),
    joint: list[str] | None = typer.Option(None, "--joint", metavar="JOINT",
                                              help="Plot this joint (repeat); default: every joint in the file."),
    signal: str = typer.Option("pos", "--signal", metavar="pos|vel|cur",
                               help="The signal whose step metrics are computed."),
    step_at: float = typer.Option(0.0, "--step-at", metavar="S", help="Time of the step's command in the file."),
    target: float | None = typer.Option(None, "--target", metavar="X",
                                           help="The commanded value (rad, rad/s or A), for the steady-state error."),
) -> None:
    """Plot position and velocity (and current) over time into a PNG, with step metrics (dead time,
    rise time 10-90 %, overshoot, settling time to 2 %, steady-state error) printed and drawn.

    Needs matplotlib (pip install 'sherpa-cli[plot]').

    \b
    Examples:
      sherpa log plot run.csv -o run.png
      sherpa log plot step/recording.csv -o elbow.png --joint elbow_pitch --signal vel --target 0.1
    """
    from sherpa_cli.log.plot import MISSING, MISSING_HINT, have_matplotlib, plot_recording
    from sherpa_cli.log.recording import SIGNALS, UNITS, read_csv
    from sherpa_cli.log.step_metrics import MIN_STEP

    st = state(ctx)
    if signal not in SIGNALS:
        raise UsageError(f"--signal {signal}: expected one of {', '.join(SIGNALS)}")
    import math

    for what, number in (("--step-at", step_at), ("--target", target)):
        if number is not None and not math.isfinite(number):
            raise UsageError(f"{what} {number}: expected a finite number")
    if output.suffix.lower() != ".png":
        raise UsageError(f"-o {output}: expected a .png file")
    if not have_matplotlib():
        raise UsageError(MISSING, hint=MISSING_HINT)
    rec = read_csv(file)
    joints = list(joint or rec.joints())
    for j in joints:
        if j not in rec.joints():
            raise UsageError(f"--joint {j}: not in {file} (it has {', '.join(rec.joints()) or 'no joints'})")
    still: list[str] = []
    metrics = _metrics(rec, joints, signal, step_at, target, still)
    plot_recording(rec, joints, output, metrics=metrics, title=f"{file.name}: {', '.join(joints)}")
    render_metrics(st, metrics, extra={"png": str(output), "not_stepped": [f"{j}.{signal}" for j in still]})
    if not st.json_mode:
        for j in still:
            st.out.line(f"{j} {signal}: did not step (changed less than {MIN_STEP[SIGNALS[signal]]:g} "
                        f"{UNITS[SIGNALS[signal]]}): no step metrics")


def _metrics(rec: Recording, joints: Sequence[str], signal: str, step_at: float, target: float | None,
             still: list[str] | None = None) -> dict[tuple[str, str], StepMetrics]:
    """Step metrics of the joints whose ``signal`` stepped; the others are listed in ``still``."""
    from sherpa_cli.log.recording import SIGNALS
    from sherpa_cli.log.step_metrics import MIN_STEP, step_metrics, stepped

    out = {}
    for j in joints:
        series = rec.series(j, signal)
        if series is None or len(series[0]) < 2:
            continue
        if not stepped(series[0], series[1], threshold=MIN_STEP[SIGNALS[signal]], t_step=step_at):
            if still is not None:
                still.append(j)
            continue
        try:
            out[(j, signal)] = step_metrics(series[0], series[1], t_step=step_at, target=target)
        except ValueError as exc:
            raise UsageError(f"{j} {signal}: {exc}") from None
    return out


def _ms(seconds: float | None) -> str:
    return "-" if seconds is None else f"{1000 * seconds:.1f} ms"


def render_metrics(st: AppState, metrics: Mapping[tuple[str, str], StepMetrics],
                   extra: Mapping[str, Any] | None = None) -> None:
    from sherpa_cli.log.recording import SIGNALS, UNITS

    if st.json_mode:
        st.out.json({**(extra or {}), "metrics": [{"joint": j, "signal": s, **m.as_json()}
                                                  for (j, s), m in metrics.items()]})
        return
    for (j, s), m in metrics.items():
        unit = UNITS[SIGNALS[s]]
        if not m.settled or m.overshoot is None:
            # a step cut off before it settled: its "final" value is only where the record ended
            st.out.line(f"{j} {s}: not settled: {m.initial:.4f} -> {m.final:.4f} {unit} at the end; dead time "
                        f"{_ms(m.dead_time)}, rise (10-90 %) {_ms(m.rise_time)}; no overshoot or steady-state error")
            continue
        # round + 0.0: a rounding's -0.00001 reads 0.0000, never "-0.0000"
        sse = "" if m.steady_state_error is None else \
            f", steady-state error {round(m.steady_state_error, 4) + 0.0:.4f} {unit}"
        st.out.line(f"{j} {s}: {m.initial:.4f} -> {m.final:.4f} {unit}; dead time {_ms(m.dead_time)}, "
                    f"rise (10-90 %) {_ms(m.rise_time)}, overshoot {m.overshoot:.1f} %, "
                    f"settling (2 %) {_ms(m.settling_time)}{sse}")
    for key, value in (extra or {}).items():
        if isinstance(value, (list, tuple)):  # a list reads as words, never as Python's repr
            value = ", ".join(map(str, value)) or "none"
        st.out.line(f"{key.replace('_', ' ')}: {value}")


# Seconds to wait while recording; tests replace it (the recorder's SYNC runs on its own).
import time as _time  # noqa: E402

sleep = _time.sleep


@app.command("record")
def record(
    ctx: typer.Context,
    targets: Targets = None,
    rate: float = typer.Option(100.0, "--rate", metavar="HZ", help="Samples per second (SYNC rate)."),
    duration: float = typer.Option(..., "--for", metavar="S", help="How long to record, in seconds."),
    output: list[Path] = typer.Option(..., "--output", "-o", metavar="FILE",
                                      help="Where to write the samples: .csv, or .mcap (ROS 2 JointState and more, "
                                      "docs/log.md; robotics extra). Repeat for both from one run."),
    current: bool | None = typer.Option(
        None, "--current/--no-current",
        help="Also sample the motor current (a second TPDO every 2nd SYNC). Default: when the bus budget allows."),
    poll: bool = typer.Option(False, "--poll", help="Sample through the interpreter (PX, VX, IQ queries) every "
                              "bus's poll_interval_ms (the seed's scheduler_interval) instead of TPDOs: "
                              "changes nothing on the drives, but slow and jittery."),
    foxglove: Foxglove = False,
    foxglove_at: FoxgloveAt = DEFAULT_AT,
    allow_remote: AllowRemote = False,
    source: str = typer.Option("can", "--source", metavar="can|drive",
                               help="drive: the drives' own recorders at the servo rate (docs/log.md; --rate, "
                               "--current, --poll do not apply)."),
    trigger: str = typer.Option("now", "--trigger", metavar="now|bg",
                                help="With --source drive: start now, or at the next BG (a move started elsewhere)."),
) -> None:
    """Record position and velocity (and current) of joints, in joint units (rad, rad/s, A; Σ/Δ for
    pairs) plus the motor counts, with one timestamp per sample, into a CSV file.

    Sampling uses TPDOs sent on SYNC: TPDO1 maps position and velocity (0x6064, 0x6069), TPDO3 the
    current, transmission type 1 (every SYNC). SYNC comes from the kernel where the interface has
    one (SocketCAN), else from a thread. The bus load is computed and printed before anything is
    sent; a rate the bus cannot carry is refused, naming the highest rate it can.

    The PDO changes are RAM only: the old settings are read first and written back on every exit
    path (end, error, Ctrl-C, SIGTERM, SIGHUP: exit 130); nothing is ever saved (no SV). After a
    kill -9 they stay in the drives' RAM until the next power cycle or NMT reset; SYNC stops with
    the process, so the drives send nothing meanwhile.

    \b
    Examples:
      sherpa log record elbow_pitch --rate 1000 --for 5 -o elbow.csv
      sherpa log record shoulder_diff --rate 500 --for 10 --current -o pair.csv
      sherpa log record --poll --for 5 -o slow.csv
      sherpa log record --rate 500 --for 10 -o run.csv -o run.mcap --foxglove
      sherpa log record shoulder_diff --source drive --for 0.5 -o pair.csv
      sherpa log record shoulder_diff --source drive --trigger bg --for 2 -o move.csv

    With --source drive the drives' own recorders sample at the servo rate (position, velocity,
    active current, position error, speed command), both motors of a pair with the same settings;
    the recorder settings are RAM only and restored on every exit path (docs/log.md).
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.cli.robotics import check_live, live_view, record_outputs
    from sherpa_cli.log.record import MAX_LOAD
    from sherpa_cli.log.record_run import check_budget, check_record_values, plan_record

    st = state(ctx)
    if source != "can":
        from sherpa_cli.cli.log_drive import record_from_drive

        record_from_drive(st, targets, duration, output, source=source, trigger=trigger, poll=poll, live=foxglove)
        return
    check_record_values(duration, rate)
    outputs = record_outputs(output)
    check_live(foxglove, foxglove_at, allow_remote)
    cfg = st.load_config()
    plan = plan_record(cfg, targets, rate, current=current, poll=poll)
    for b in plan.budget:
        st.out.info(f"bus {b.bus}: {plural(b.drives, 'drive')} at {rate:g} Hz"
                    f"{' with current' if b.current else ''}: {100 * b.load:.1f} % of "
                    f"{b.bitrate / 1e6:g} Mbit/s{' (assumed)' if b.bitrate_assumed else ''} "
                    f"(limit {100 * MAX_LOAD:.0f} %, highest rate {b.max_rate} Hz)")
    check_budget(plan)
    # a CSV-only recording goes to the file row by row as it comes (constant memory; a killed
    # recording leaves its rows so far); the MCAP writer is given the whole recording at the end
    stream_to = outputs[".csv"] if ".csv" in outputs and ".mcap" not in outputs and not poll else None
    with live_view(st, foxglove, foxglove_at, allow_remote) as view, st.session(buses=list(plan.buses)) as session:
        # the wait is the command's, which a SIGTERM or SIGHUP ends too
        result = Arm(session).record(targets, rate, duration, current=plan.current, poll=poll, plan=plan,
                                     stream_to=stream_to, status=".mcap" in outputs, view=view,
                                     wait=lambda d, failed: _wait_for(d, failed), check=False)
    if ".csv" in outputs and result.streamed is None:
        result.write_csv(outputs[".csv"])
    if ".mcap" in outputs:
        result.write_mcap(outputs[".mcap"], config_file=str(st.config_path),
                          info={"command": "log record", "source": "poll" if poll else "TPDO on SYNC",
                                "rate_hz": "" if poll else f"{rate:g}", "current": str(plan.current).lower(),
                                **{f"budget_load.{bus}": f"{load:g}" for bus, load in plan.loads().items()}})
    _render_record(st, list(outputs.values()), result.samples, result.expected, result.rows, result.late,
                   gaps=None if poll else result.gaps, period=result.period)
    if result.unplaced:
        st.out.warn(f"{result.unplaced} frame(s) answered no SYNC this tool sent: not in the file")
    if result.failure is not None:
        st.out.warn("the samples up to the stop are written; the drives' PDO settings are restored")
        raise result.failure
    if result.interrupted:
        st.out.warn("interrupted: the samples up to the interruption are written; the drives' PDO settings "
                    "are restored")
        raise typer.Exit(130)


class _Stopped(Exception):
    """SIGTERM or SIGHUP during a recording: ends it like Ctrl-C, so the PDO settings go back."""


WAKE_EVERY_S = 0.1  # how often the wait looks at what the receive threads found


def _wait_for(duration: float, failed: Callable[[], bool] = lambda: False) -> bool:
    """Sleep while sampling; True when Ctrl-C, SIGTERM or SIGHUP ended it early. Ends early (False)
    once ``failed()`` (the recorder found another SYNC producer)."""
    import signal

    def stop(signum: int, frame: FrameType | None) -> NoReturn:
        raise _Stopped(signal.Signals(signum).name)

    # a SIGTERM whose exception was lost while the session opened (errors.py) would otherwise be
    # heard by nothing: the recording ran its whole --for, and a second SIGTERM is ignored
    raise_if_signalled()
    old: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
            if sig is not None:
                old[sig] = signal.signal(sig, stop)
    try:
        end = _time.monotonic() + duration
        while (rest := end - _time.monotonic()) > 0 and not failed():
            sleep(min(rest, WAKE_EVERY_S))
    except (KeyboardInterrupt, _Stopped):
        return True
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return False


def _percent(part: int, whole: int) -> str:
    """``part`` of ``whole`` in %, rounded down: 4999 of 5000 is 99.98 %, never 100.00 %."""
    return f"{math.floor(10000 * part / whole) / 100:.2f} %"


def _render_record(st: AppState, outputs: Sequence[Path], counts: Mapping[str, int], expected: int | None,
                   rows: int, late: int = 0, *, gaps: Mapping[str, Gaps] | None = None, period: float = 0.0) -> None:
    """What is in the file: samples per drive (cells written), rows; SYNCs with no row are gaps, and
    per drive where its samples are missing (``gaps``: time_s of the first few runs, as in the file)."""
    holes = gaps or {}
    no_row = max(0, expected - rows) if expected else 0
    if st.json_mode:
        extra = {"files": [str(p) for p in outputs]} if len(outputs) > 1 else {}

        def drive(n: str, c: int) -> dict[str, Any]:
            g = holes.get(n)
            if g is None:
                return {"drive": n, "samples": c}
            return {"drive": n, "samples": c, "missing": g.missing, "more_gaps": g.more_spans,
                    "gaps": [{"t_s": round(k * period, 6), "syncs": length} for k, length in g.spans]}

        st.out.json({"file": str(outputs[0]), **extra, "rows": rows, "expected": expected, "gaps": no_row,
                     "late_frames": late, "drives": [drive(n, c) for n, c in counts.items()]})
        return
    for name, c in counts.items():
        share = "" if not expected else f" of {expected} ({_percent(c, expected)})"
        st.out.line(f"{name}: {c} samples{share}")
    for output in outputs:
        st.out.line(f"wrote {output} ({rows} rows)")
    if no_row:
        st.out.warn(f"{no_row} of {expected} SYNCs {'has' if no_row == 1 else 'have'} no row: no drive's sample "
                    f"arrived for {'it' if no_row == 1 else 'them'}")
    for name, g in holes.items():
        if g.missing:
            where = ", ".join(f"{k * period:.3f} s ({length} SYNC{'s' if length > 1 else ''})" for k, length in g.spans)
            more = f" and {g.more_spans} more {'gap' if g.more_spans == 1 else 'gaps'}" if g.more_spans else ""
            st.out.warn(f"{name}: {plural(g.missing, 'sample')} missing (empty cells) at time_s {where}{more}")
    if late:
        st.out.warn(f"{plural(late, 'frame')} came after their row was written: not in the file")


def stepped_sim(st: AppState) -> tuple[SteppedTime | None, Callable[[ArmConfig, Mapping[str, str]], SimArm] | None]:
    """With --sim: the in-process arm on stepped time (sim/stepped.py), so a step's figures are the
    simulated drive's and the same on every run and machine; else (None, None). In a recipe with
    `sim_time: stepped` the recipe's shared arm already runs on stepped time: that one, no factory."""
    if not st.sim:
        return None, None
    shared = shared_stepped(st)
    if shared is not None:
        return shared, None
    from sherpa_cli.sim.arm import SimArm
    from sherpa_cli.sim.stepped import SteppedTime

    stepped = SteppedTime()
    return stepped, lambda cfg, channels: SimArm.for_session(cfg, channels, clock=stepped.clock)


@app.command("step")
def step(
    ctx: typer.Context,
    args: list[str] = typer.Argument(..., metavar="JOINT | RUN...",
                                     help="A plain joint (or the drive of one); not a Σ/Δ joint. With --compare: "
                                     "the directories of earlier runs."),
    position: float | None = typer.Option(None, "--position", metavar="X",
                                             help="A position step of X rad from where the joint stands."),
    velocity: float | None = typer.Option(None, "--velocity", metavar="V", help="A velocity step to V rad/s."),
    torque: float | None = typer.Option(None, "--torque", metavar="A", help="A torque (current) step to A amperes."),
    duration: float = typer.Option(2.0, "--for", metavar="S",
                                   help="Record at most S seconds after the command (position and velocity steps "
                                   "end earlier once settled; velocity and torque stop the motor at S)."),
    rate: float = typer.Option(1000.0, "--rate", metavar="HZ", help="Samples per second."),
    output: Path = typer.Option(..., "--output", "-o", metavar="DIR|FILE.mcap",
                                help="Directory for recording.csv, step.png and metrics.json (created); or one "
                                ".mcap file with the recording and the metrics (robotics extra); with --compare "
                                "the .png of the runs."),
    uncalibrated: bool = typer.Option(False, "--uncalibrated", help="Allow a position step of a joint that has no "
                                      "absolute encoder and was not homed since power-up."),
    source: str = typer.Option("can", "--source", metavar="can|drive",
                               help="drive: also record the step with the drive's own recorder (servo rate); "
                               "recording.csv is the drive's, can-recording.csv the bus's, the report shows both."),
    mode_first: bool = typer.Option(False, "--mode-first", help="Put the drive in the step's unit mode with its "
                                    "motor on before t = 0 and wait its settle window: the step itself has no "
                                    "MO/UM switch (seed Fig. 9.2)."),
    from_mode: str | None = typer.Option(None, "--from-mode", metavar="position|velocity",
                                         help="Hold the drive in this other mode with its motor on (standing "
                                         "still) before t = 0: the step's switch is MO=0, UM, MO=1 with the "
                                         "settle window after each MO (seed Fig. 9.1)."),
    hold: float = typer.Option(0.0, "--hold", metavar="S", help="Go on recording S seconds once the step has "
                               "settled (a velocity step's constant speed, seed Figs. 9.3/9.6); within --for."),
    compare_runs: bool = typer.Option(False, "--compare", help="Compare earlier runs (the RUN directories "
                                      "of `log step -o DIR`): one plot (-o FILE.png) and their figures; moves nothing."),
    apply: ApplyMotion = False,
) -> None:
    """The seed's Section 9 step experiment in one command: start recording, command the step at
    t = 0 through the motion guard, record until settled (or --for), stop the motor, and write
    the recording (CSV), the plot (PNG, with matplotlib) and the step metrics (JSON).

    t = 0 is when the step was asked for: if the drive must first switch its unit mode or its
    motor on (MO/UM switch, seed Fig. 9.1), that time shows in the dead time and on its own as
    "switch". The motion guard stops the motor on every exit path; the recording's PDO changes
    are RAM only and restored.

    The checks are jog's: nothing moves without --apply; a position step must end inside the
    joint's normal range and needs a calibrated joint (or --uncalibrated); a joint that leaves
    its full range is stopped and brought back to the nearest edge of its normal range (exit 1).

    A step that has not settled within --for is reported as "not settled within S s", with no
    overshoot, settling time or steady-state error. --compare RUN... overlays earlier runs (for
    example the 1 A and 20 A supply runs of seed Fig. 9.4) and lists their figures.

    \b
    Examples:
      sherpa log step elbow_pitch --position 1 -o steps/pos --apply
      sherpa log step elbow_pitch --position -1 --mode-first -o steps/pos2 --apply
      sherpa log step elbow_pitch --velocity 0.1 --for 5 --hold 3 -o steps/vel --apply
      sherpa log step --compare steps/pos steps/pos2 -o steps/compare.png
      sherpa log step elbow_pitch --velocity 0.1 --for 1 -o steps/vel --apply
      sherpa log step elbow_pitch --torque 1 --for 0.3 -o steps/torque --apply
    """
    import json

    from sherpa_cli.cli.robotics import record_outputs, write_mcap
    from sherpa_cli.log.plot import have_matplotlib, plot_recording, step_title
    from sherpa_cli.log.record_extras import RecordExtras
    from sherpa_cli.log.recording import write_csv
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.step import UM_OF, check_from_mode_switches, check_mode_first, resolve_step_target, step_request

    st = state(ctx)
    if compare_runs:
        if position is not None or velocity is not None or torque is not None or apply:
            raise UsageError("--compare reads earlier runs: it takes no --position/--velocity/--torque or --apply")
        _step_compare(st, [Path(a) for a in args], output)
        return
    if len(args) != 1:
        raise UsageError(f"log step steps one joint; got {len(args)} ({' '.join(args)})",
                         hint="to compare earlier runs: sherpa log step --compare RUN... -o FILE.png")
    joint = args[0]
    given = [(m, v) for m, v in (("position", position), ("velocity", velocity), ("torque", torque)) if v is not None]
    if len(given) != 1:
        raise UsageError("give exactly one of --position X, --velocity V or --torque A")
    mode, value = given[0]
    import math

    if not math.isfinite(value):
        raise UsageError(f"--{mode} {value}: expected a finite number")
    from sherpa_cli.ops.step import check_step_values

    check_step_values(duration, rate, hold)  # before any bus is opened; run_step checks them again
    to_mcap = output.suffix.lower() == ".mcap" and not output.is_dir()
    if source not in ("can", "drive"):
        raise UsageError(f"--source {source}: expected can or drive")
    if source == "drive" and from_mode is not None:
        raise UsageError("--from-mode is for --source can: the drive recorder's step starts from the drive as it is")
    if source == "drive" and to_mcap:
        raise UsageError("--source drive writes a directory (recording.csv, can-recording.csv, metrics.json): "
                         "give -o DIR")
    if to_mcap:
        record_outputs([output])  # the directory, the robotics extra
    elif output.exists() and not output.is_dir():
        raise UsageError(f"-o {output}: exists and is not a directory")
    else:
        from sherpa_cli.output_files import check_output_dir

        check_output_dir(output, "-o", "the step's files")  # before the step moves anything
    cfg = st.load_config()
    if mode == "torque":
        from sherpa_cli.motion.settings import check_torque_for

        check_torque_for(duration, cfg.motion.max_torque_for)  # no drive limit acts in torque mode
    target = resolve_step_target(cfg, joint)
    req = step_request(target, mode, value, duration=duration, uncalibrated=uncalibrated,
                       max_torque_for=cfg.motion.max_torque_for)
    check_mode_first(mode, mode_first, from_mode)
    check_from_mode_switches(from_mode, UM_OF.get(mode, cfg.motion.velocity_unit_mode))
    if not apply:
        refused = _step_would_refuse(st, target, req)
        _step_dry_run(st, cfg, target, mode, value, duration, rate, mode_first=mode_first, hold=hold, refused=refused,
                      from_mode=from_mode)
        if refused:
            raise typer.Exit(1)
        return
    settings = MotionSettings.from_config(cfg, [target.ref.bus])
    if not to_mcap:
        output.mkdir(parents=True, exist_ok=True)
    # said before the step moves, not after it: the plot is decided while nothing has moved yet
    png = not to_mcap and have_matplotlib()
    if not to_mcap and not png:
        st.out.warn(NO_PNG)
    stepped, sim_factory = stepped_sim(st)
    with st.session(buses=[target.ref.bus], sim_factory=sim_factory) as session:
        timebase = stepped if stepped is not None and use_stepped(session, stepped, cfg) else None
        if source == "drive":
            from sherpa_cli.cli.log_drive import drive_step

            drive_step(st, session, target, mode, value, duration=duration, rate=rate, settings=settings,
                       uncalibrated=uncalibrated, timebase=timebase, output=output, render_metrics=render_metrics,
                       png=png)
            return
        extras = RecordExtras(session, [target.ref], mcap=to_mcap, view=None)
        extras.start()
        zero_ns = _time.time_ns()  # t = 0 (the step's command) is placed at the wall time the step began
        from sherpa_cli.api import Arm

        try:
            result = Arm(session).log_step(joint, mode, value, duration=duration, rate=rate, settings=settings,
                                           uncalibrated=uncalibrated, timebase=timebase, mode_first=mode_first,
                                           hold=hold, from_mode=from_mode)
        except BaseException as exc:
            # how the guard stopped the motor, on Ctrl-C, SIGTERM and errors too (without it a
            # Ctrl-C during `log step` printed nothing)
            from sherpa_cli.cli.jog_cmd import show_stop_report

            show_stop_report(st, exc, [target])
            raise
        extras.read_status()
    if to_mcap:
        write_mcap(output, result.recording, cfg, time_zero_ns=zero_ns, extras=extras,
                   config_file=str(st.config_path), step_metrics=result.as_json(),
                   info={"command": "log step", "source": "TPDO on SYNC", "rate_hz": f"{rate:g}", "mode": mode,
                         "value": f"{value:g}", "joint": result.joint})
        _render_step(st, result, mode, value, {"mcap": str(output)})
        return
    write_csv(result.recording, output / "recording.csv")
    (output / "metrics.json").write_text(json.dumps(result.as_json(), indent=2) + "\n", encoding="utf-8")
    files = {"csv": str(output / "recording.csv"), "metrics": str(output / "metrics.json")}
    if png:
        from sherpa_cli.cli.log_drive import step_marks

        marks = step_marks(result)
        plot_recording(result.recording, [result.joint], output / "step.png",
                       metrics={(result.joint, result.signal): result.metrics}, marks=marks,
                       title=step_title(result.joint, marks))
        files["png"] = str(output / "step.png")
    _render_step(st, result, mode, value, files)


NO_PNG = "no PNG: matplotlib is not installed (pip install 'sherpa-cli[plot]')"



def _render_step(st: AppState, result: StepResult, mode: str, value: float, files: dict[str, str]) -> None:
    if st.json_mode:
        st.out.json({**result.as_json(), "files": files})
        return
    steps = result.switch_steps
    switch = (f"MO/UM switch {1000 * result.switch_s:.0f} ms ({', '.join(steps)})" if steps else
              "no MO/UM switch" + (" (--mode-first)" if result.mode_first else ""))
    ended = result.ended_by if result.settled or result.breach is not None else \
        f"not settled within {result.within:g} s"
    st.out.line(f"{result.joint} ({result.drive}): {mode} step {value:g} -> {result.command}; "
                f"{switch}; {ended}; {result.samples} of {result.expected} samples")
    render_metrics(st, {(result.joint, result.signal): result.metrics})
    for line in result.stop.lines(st.verbose):
        st.out.line(line)
    if result.breach is not None:
        b = result.breach
        st.out.line(f"limit: {b.joint} left its full range [{b.full[0]}, {b.full[1]}] on the {b.side} side: "
                    f"stopped, nothing more sent, brought back to {result.recovered_to} counts "
                    f"(normal range edge {b.back_to})")
    for key, path in files.items():
        st.out.line(f"{key}: {path}")
    if result.breach is not None:
        raise typer.Exit(1)


def _step_compare(st: AppState, runs: Sequence[Path], output: Path) -> None:
    """`log step --compare RUN... -o FILE.png`: the runs' figures (log/step_compare.py) and one plot."""
    from sherpa_cli.log.plot import have_matplotlib
    from sherpa_cli.log.step_compare import compare, plot_compare

    if output.suffix.lower() != ".png":
        raise UsageError(f"-o {output}: --compare writes one plot: expected a .png file name")
    loaded = compare(runs)
    written = False
    if have_matplotlib():
        output.parent.mkdir(parents=True, exist_ok=True)
        plot_compare(loaded, output)
        written = True
    elif not st.json_mode:
        st.out.warn(NO_PNG)
    if st.json_mode:
        st.out.json({"runs": [f.as_json() for f, _ in loaded], "png": str(output) if written else None})
        return

    def num(v: float | None, fmt: str, scale: float = 1.0) -> str:
        return "-" if v is None else format(v * scale, fmt)

    # a position move has no steady speed: its steady columns stay empty
    rows = [[f.name, f"{f.mode} {f.value:+g}", f"{1000 * f.switch_s:.0f}", "yes" if f.settled else "no",
             num(f.metrics.get("dead_time"), ".0f", 1000), num(f.peak_speed, "+.3f"),
             num(f.peak_speed_after_s, ".0f", 1000), num(f.slowing_after_s, ".0f", 1000),
             "-" if f.mode == "position" else num(f.steady_speed, "+.3f"),
             "-" if f.mode == "position" else num(f.steady_ripple, ".1%")] for f, _ in loaded]
    st.out.table(None, ["run", "step", "switch", "settled", "dead", "peak", "peak at", "slows at", "steady",
                        "ripple"], rows, right=tuple(range(2, 10)))
    st.out.line("switch, dead: ms from the command; peak, steady: rad/s; peak at, slows at: ms from the motion's "
                "start; ripple: standard deviation / mean of the steady speed")
    if written:
        st.out.line(f"png: {output}")


def _step_would_refuse(st: AppState, target: Axis, req: MoveRequest) -> list[str] | None:
    """What `--apply` would refuse (ops/dry_check.py), read from the drive; None when the drive
    cannot be read (the dry run then says it did not check)."""
    from sherpa_cli.ops.dry_check import would_refuse

    try:
        with st.session(buses=[target.ref.bus]) as session:
            return would_refuse(session, target, req)
    except SherpaError as exc:
        st.out.warn(f"not checked on the drive ({exc}): --apply checks calibration, limits and faults first")
        return None


def _step_dry_run(st: AppState, cfg: ArmConfig, target: Axis, mode: str, value: float, duration: float,
                  rate: float, *, mode_first: bool = False, hold: float = 0.0,
                  refused: list[str] | None = None, from_mode: str | None = None) -> None:
    """Without --apply: what the step would send; nothing is sent, no file is written."""
    from sherpa_cli.joints.units import rad_per_s_to_counts_per_s, rad_to_counts

    ref, cpr = target.ref, target.cpr
    assert cpr is not None  # step_request refused a target without a joint
    if mode == "position":
        plan = f"UM=5, PA=PX{rad_to_counts(value, cpr):+d}, BG; until settled, at most {duration:g} s"
    elif mode == "velocity":
        plan = (f"UM={cfg.motion.velocity_unit_mode}, JV={rad_per_s_to_counts_per_s(value, cpr)}, BG; until settled, "
                f"at most {duration:g} s")
    else:
        plan = f"UM=1, TC={value:g} for {duration:g} s"
    if hold and mode != "torque":
        plan = plan.replace("until settled,", f"until settled and {hold:g} s more,")
    if mode_first:
        plan = "before t = 0 the drive in the step's mode, motor on, its settle window waited; then " + plan
    if from_mode is not None:
        plan = (f"before t = 0 the drive in {from_mode} mode, motor on, its settle window waited; then MO=0, "
                "the step's UM, MO=1 (a settle window after each); then " + plan)
    if st.json_mode:
        st.out.json({"joint": target.name, "drive": ref.name, "address": ref.address, "mode": mode, "value": value,
                     "applied": False, "plan": plan, "rate": rate, "checked": refused is not None,
                     "would_be_refused": refused or []})
        return
    if refused:
        st.out.line(f"dry run: would be refused: {'; '.join(refused)}")
        st.out.line(f"  (the plan: record {target.name} ({ref.name}, {ref.address}) at {rate:g} Hz and step it: "
                    f"{plan})")
        st.out.line("nothing sent; --apply would refuse it too")
        return
    st.out.line(f"dry run: would record {target.name} ({ref.name}, {ref.address}) at {rate:g} Hz and step it: "
                f"{plan}, then stop and switch off")
    st.out.line("nothing sent; add --apply to move")


@app.command("section9")
def section9(
    ctx: typer.Context,
    folder: Path = typer.Argument(..., metavar="DIR", help="The out directory of recipes/seed-section9.yaml."),
    bands: Path | None = typer.Option(None, "--bands", metavar="FILE.yaml",
                                      help="Check every figure against these bands (docs/section9/bands.yaml): "
                                      "exit 1 when one is outside."),
) -> None:
    """The seed's Section 9 in numbers: summarise the runs of recipes/seed-section9.yaml (switch
    delays, speeds and their ripple, the 1 A supply's drop, the pair's coupling) into DIR/summary.json
    and DIR/summary.md, each number beside its band from the seed's text (docs/section9.md).

    \b
    Example:
      sherpa log section9 section9-out --bands docs/section9/bands.yaml
    """
    import json

    from sherpa_cli.log.section9 import check, load_bands, summarize

    st = state(ctx)
    numbers = summarize(folder)
    checked = check(numbers, load_bands(bands)) if bands is not None else []
    banded = {b.key for b, _, _ in checked}
    doc = {"numbers": {k: (None if v is None else round(v, 6)) for k, v in numbers.items()},
           "bands": [{"key": b.key, "figure": b.figure, "value": None if v is None else round(v, 6), "min": b.low,
                      "max": b.high, "unit": b.unit, "holds": ok, "quote": b.quote} for b, v, ok in checked]}
    (folder / "summary.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    rows = [[b.figure, b.key, "-" if v is None else f"{v:.4g}", f"{b.low:g} .. {b.high:g} {b.unit}",
             "ok" if ok else "OUTSIDE"] for b, v, ok in checked]
    rows += [["", k, "-" if v is None else f"{v:.4g}", "", ""] for k, v in numbers.items() if k not in banded]
    md = ["# Section 9 on this arm", "", "| figure | number | value | band (seed's text) | |", "|---|---|---|---|---|",
          *(f"| {' | '.join(r)} |" for r in rows), ""]
    (folder / "summary.md").write_text("\n".join(md), encoding="utf-8")
    failed = [b.key for b, _, ok in checked if not ok]
    if st.json_mode:
        st.out.json({**doc, "files": [str(folder / "summary.json"), str(folder / "summary.md")], "ok": not failed})
    else:
        st.out.table(None, ["figure", "number", "value", "band (seed's text)", "check"], rows, right=(2,))
        st.out.line(f"summary: {folder / 'summary.json'}, {folder / 'summary.md'}")
        if failed:
            st.out.line(f"{len(failed)} of {plural(len(checked), 'figure')} outside the seed's band: {', '.join(failed)}")
    if failed:
        raise typer.Exit(1)
