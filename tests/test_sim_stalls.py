"""The in-process simulator's heartbeat consumers leave out the time their process did not run
(sim/clock.py StallMeter): a loaded machine that deschedules a `--sim` command stalls the simulated
drives and the tool's heartbeat thread together, and the consumers no longer stop a command that
sent every beat ("EMCY 0x8130: heartbeat event" in a CI run on a loaded machine). The motors keep
wall time: the tool sees the progress a real drive makes while it is held up."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock, StallMeter
from sherpa_cli.sim.drive import SimDrive

ARM = Path(__file__).resolve().parent / "data" / "home-arm.yaml"


class Wall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_gaps_up_to_max_gap_are_no_stall_and_a_longer_one_counts_beyond_max_gap():
    wall = Wall()
    meter = StallMeter(0.1, wall=wall)
    assert meter.read() == 0.0
    wall.t = 100.1
    assert meter.read() == 0.0  # a gap of max_gap: the process ran
    wall.t = 101.1  # nobody read it for 1 s: the process did not run
    assert meter.read() == pytest.approx(0.9)
    wall.t = 101.15
    assert meter.read() == pytest.approx(0.9)


@given(steps=st.lists(st.floats(min_value=0, max_value=5, allow_nan=False), max_size=50),
       max_gap=st.floats(min_value=0.001, max_value=1))
def test_the_stalled_time_never_decreases_and_grows_by_a_gap_beyond_max_gap(steps, max_gap):
    wall = Wall()
    meter = StallMeter(max_gap, wall=wall)
    last = meter.read()
    for dt in steps:
        wall.t += dt
        got = meter.read()
        assert got == pytest.approx(last + max(0.0, dt - max_gap))
        last = got


def test_stalled_at_leaves_out_what_was_counted_after_the_instant():
    wall = Wall()
    meter = StallMeter(0.1, wall=wall)
    meter.read()
    wall.t = 101.0  # a stretch of 1 s, 0.9 s counted: taken as its last 0.9 s (100.1 .. 101.0)
    assert meter.read() == pytest.approx(0.9)
    assert meter.stalled_at(100.05) == pytest.approx(0.0)  # before it: none of it
    assert meter.stalled_at(100.6) == pytest.approx(0.5)  # inside it: the part before
    assert meter.stalled_at(101.0) == pytest.approx(0.9)
    wall.t = 101.05
    assert meter.stalled_at(99.0) == pytest.approx(0.0)


@given(steps=st.lists(st.floats(min_value=0, max_value=2, allow_nan=False), max_size=30),
       when=st.floats(min_value=99, max_value=140, allow_nan=False))
def test_stalled_at_never_exceeds_the_reading_nor_goes_below_zero(steps, when):
    wall = Wall()
    meter = StallMeter(0.1, wall=wall)
    meter.read()
    for dt in steps:
        wall.t += dt
        meter.read()
    at = meter.stalled_at(when)
    assert -1e-9 <= at <= meter.read() + 1e-9


def test_a_heartbeat_handled_after_a_stall_is_not_charged_the_stall():
    # The pump of a starved process hands a heartbeat late, stamped with its arrival: paired with the
    # meter read when it was handled, its window lost the stall and the consumer tripped (a pair move
    # on a busy machine; a SIGSTOPped jog). It counts from the arrival with the stall left out.
    wall = Wall()
    meter = StallMeter(0.1, wall=wall)
    clock = ManualClock()
    clock.advance(100.0)
    drive = SimDrive(5, clock=clock, stalled=meter.read, stalled_at=meter.stalled_at)
    drive.od_write(0x1016, 1, 126 << 16 | 500)  # host 126, 500 ms
    meter.read()
    drive.receive(0x77E, bytes([5]))  # armed at 100.0

    def run(seconds: float) -> bool:  # the process runs: the meter read every 50 ms; whether it tripped
        for _ in range(round(seconds / 0.05)):
            wall.t = clock.advance(0.05)
            meter.read()
            drive.tick()
        return any("heartbeat lost" in text for _, text in drive.events)

    assert not run(0.4)  # a beat arrives at 100.4 ...
    arrived = clock.now()
    wall.t = clock.advance(0.8)  # ... and the process stops for 0.8 s before its pump gets to it
    drive.receive(0x77E, bytes([5]), at=arrived)
    drive.tick()
    assert not any("heartbeat lost" in text for _, text in drive.events), drive.events
    assert not run(0.25)  # the host's silence since the beat: 0.1 s before the stall, 0.25 after: 0.35 of 0.5
    assert run(0.15)  # then its silence is the consumer's time


def test_a_max_gap_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match="max_gap must be positive"):
        StallMeter(0)


def consumer_drive(stalled):
    clock = ManualClock()
    drive = SimDrive(5, clock=clock, stalled=stalled)
    drive.od_write(0x1016, 1, 126 << 16 | 500)  # host 126, 500 ms
    drive.receive(0x77E, bytes([5]))  # the host's first heartbeat arms the consumer
    return drive, clock


def test_the_consumer_leaves_out_the_stalled_time_and_still_acts_on_a_silent_host():
    stalled = [0.0]
    drive, clock = consumer_drive(lambda: stalled[0])
    clock.advance(0.45)
    stalled[0] = 0.3  # the process did not run for 0.3 s of that
    drive.tick()
    clock.advance(0.3)  # 0.75 s since the heartbeat, 0.45 s of it the host's
    drive.tick()
    assert not any("heartbeat lost" in text for _, text in drive.events)
    clock.advance(0.1)  # 0.55 s of the host's own silence
    drive.tick()
    assert any("heartbeat lost" in text for _, text in drive.events)


def test_without_a_meter_the_consumer_counts_wall_time():
    drive, clock = consumer_drive(None)
    clock.advance(0.55)
    drive.tick()
    assert any("heartbeat lost" in text for _, text in drive.events)


def test_the_in_process_arm_reads_its_meter_while_it_runs_and_stops_the_reader_with_it():
    cfg = load_config(ARM)
    arm = SimArm.in_process(cfg)
    assert isinstance(arm.stalls, StallMeter)
    arm.start()
    try:
        assert any(t.name == "sim-stalls" and t.is_alive() for t in threading.enumerate())
    finally:
        arm.stop()
    assert not any(t.name == "sim-stalls" and t.is_alive() for t in threading.enumerate())


CHILD = textwrap.dedent("""
    import sys, threading, time
    from pathlib import Path
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config import load_config
    from sherpa_cli.errors import SherpaError
    from sherpa_cli.motion.axis import resolve_axis
    from sherpa_cli.motion.request import parse_request
    from sherpa_cli.motion.settings import MotionSettings
    from sherpa_cli.ops.jog import run_jog
    from sherpa_cli.sim.arm import SimArm

    cfg = load_config(Path(sys.argv[1]))
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        axis = resolve_axis(cfg, "yaw")

        def tell_when_moving():
            while True:
                with s.sim.lock:
                    if s.sim.drives["yaw_drive"].motor_on:
                        break
                time.sleep(0.002)
            print("moving", flush=True)

        threading.Thread(target=tell_when_moving, daemon=True).start()
        try:
            r = run_jog(s, axis, parse_request(axis, mode="velocity", velocity=0.2, duration=2.0),
                        settings=MotionSettings.from_config(cfg))
        except SherpaError as exc:
            print(f"error: {exc}", flush=True)
            sys.exit(3)
        print(f"ended: {r.ended_by}", flush=True)
""")


@pytest.mark.crossprocess
@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="stops a process with SIGSTOP")
def test_a_jog_whose_whole_process_is_stopped_for_longer_than_the_consumer_time_ends_normally(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD, encoding="utf-8")
    env = {**os.environ, "XDG_STATE_HOME": str(tmp_path / "state")}
    proc = subprocess.Popen([sys.executable, str(script), str(ARM)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)  # a hang guard: it starts in about 1 s
        assert ready, "the child never started moving"
        assert proc.stdout.readline().strip() == "moving"
        # the whole process, simulated drives and heartbeat thread, does not run for 0.8 s: more
        # than the consumer's 500 ms
        proc.send_signal(signal.SIGSTOP)
        threading.Event().wait(0.8)
        proc.send_signal(signal.SIGCONT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, out
    assert out.strip() == "ended: time up", out
