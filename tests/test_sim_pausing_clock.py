"""The in-process simulator's time stands still while its process does not run (sim/clock.py
PausingClock): a loaded machine that deschedules a `--sim` command stalls the simulated drives and
the tool's heartbeat together, and the drives' consumers no longer stop a command that sent every
beat ("EMCY 0x8130: heartbeat event" in a CI run on a loaded machine)."""

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
from sherpa_cli.sim.clock import PausingClock

ARM = Path(__file__).resolve().parent / "data" / "home-arm.yaml"


class Wall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_gaps_up_to_max_gap_are_wall_time_and_a_longer_one_counts_as_max_gap():
    wall = Wall()
    clock = PausingClock(0.1, wall=wall)
    assert clock.now() == 100.0
    wall.t = 100.1
    assert clock.now() == pytest.approx(100.1)  # a gap of max_gap: wall time
    wall.t = 101.1  # nobody read it for 1 s: the process did not run
    assert clock.now() == pytest.approx(100.2)
    assert clock.paused == pytest.approx(0.9)
    wall.t = 101.15
    assert clock.now() == pytest.approx(100.25)  # after the stall it runs at wall speed again


@given(steps=st.lists(st.floats(min_value=0, max_value=5, allow_nan=False), max_size=50),
       max_gap=st.floats(min_value=0.001, max_value=1))
def test_the_clock_never_goes_back_and_advances_at_most_max_gap_per_reading(steps, max_gap):
    wall = Wall()
    clock = PausingClock(max_gap, wall=wall)
    last = clock.now()
    for dt in steps:
        wall.t += dt
        got = clock.now()
        assert last <= got <= last + min(dt, max_gap) + 1e-9
        assert got == pytest.approx(wall.t - clock.paused)
        last = got


def test_a_max_gap_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match="max_gap must be positive"):
        PausingClock(0)


def test_the_in_process_arm_keeps_its_clock_read_while_it_runs_and_stops_the_reader_with_it():
    cfg = load_config(ARM)
    arm = SimArm.in_process(cfg)
    assert isinstance(arm.clock, PausingClock)
    arm.start()
    try:
        assert any(t.name == "sim-clock" and t.is_alive() for t in threading.enumerate())
    finally:
        arm.stop()
    assert not any(t.name == "sim-clock" and t.is_alive() for t in threading.enumerate())


CHILD = textwrap.dedent("""
    import dataclasses, sys, threading, time
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
                        settings=dataclasses.replace(MotionSettings.from_config(cfg), stall_time=0.0))
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
        # than the consumer's 500 ms (the child's stall watch is off: its wall-time view sees no
        # progress meanwhile, however long a loaded machine takes to deliver the SIGCONT)
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
