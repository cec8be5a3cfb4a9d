"""`sherpa diffdrive move --source drive`: both motors of the pair recorded by the drives' own recorders
(ops/drive_record.py), armed for the move's one group BG; the coupling figures come from those recordings.

On the simulated mismatched pair (tests/data/diffdrive-arm.yaml) the drives' recorders sample at the
simulated drives' own servo instants, from the common BG on. The moves run on the simulator's stepped
time (sim/stepped.py; the CLI's through a recipe with `sim_time: stepped`, the others through
motion_helpers.stepped_session): the simulated drives move only while the command waits, so where they
end and what they record does not depend on how loaded the host is. Every recording lasts the move's
time bound (motion/axis.py) of simulated time.
"""

from __future__ import annotations

import itertools
import json
import re
import threading
from pathlib import Path

import pytest
from motion_helpers import stepped_session

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.elmo.recorder import RecorderSettings
from sherpa_cli.errors import UsageError
from sherpa_cli.ops import diffdrive
from sherpa_cli.ops.diffdrive import PairTarget
from sherpa_cli.sim.arm import SimArm

DATA = Path(__file__).resolve().parent / "data"
MISMATCHED = DATA / "diffdrive-arm.yaml"
MIS = ["--config", "tests/data/diffdrive-arm.yaml", "--sim"]
RECORDER_RAM = ("RC", "RG", "RL", "RP[3]", "RV[1]")
SOURCE = re.compile(r"^recording: drive recorders at (\d+) Hz \(sample time 360 us, RG=(\d+)\), (\d+) samples$", re.M)


@pytest.fixture
def cfg():
    return load_config(MISMATCHED)


def _ram(session):
    with session.sim.lock:
        return {n: ({k: d.ram[k] for k in RECORDER_RAM}, d.recorder.rr, d.recorder.state)
                for n, d in session.sim.drives.items()}


# the three moves as one recipe on stepped time (the shared simulated arm moves only while a step waits);
# each step's stdout is in the recipe's report
MOVES = """sim_time: stepped
vars:
  out: moves-out
steps:
  - name: drive
    run: diffdrive move diff --sigma 0.3 --source drive --report {out}/drive.json --apply
  - name: back
    run: diffdrive move diff --sigma 0 --apply
  - name: can
    run: diffdrive move diff --sigma 0.3 --report {out}/can.json --apply
"""


def test_a_drive_recorded_move_reports_the_coupling_of_a_can_recorded_one(cli, tmp_path):
    recipe, report = tmp_path / "moves.yaml", tmp_path / "recipe.json"
    recipe.write_text(MOVES)
    result = cli(*MIS, "recipe", "run", str(recipe), "--apply", "--set", f"out={tmp_path}", "--report", str(report))
    assert report.exists(), result.transcript()
    steps = {s["name"]: s for s in json.loads(report.read_text())["steps"]}
    assert result.exit_code == 0, result.transcript() + json.dumps(steps, indent=1)[:4000]
    assert all(s["exit_code"] == 0 for s in steps.values()), steps
    by_drive, by_can = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("drive", "can"))
    m = SOURCE.search(steps["drive"]["stdout"])
    assert m, steps["drive"]["stdout"]
    hz, gap, samples = (int(x) for x in m.groups())
    assert hz == round(1 / (gap * 360e-6)) and by_drive["recording"]["samples"] == samples
    assert by_drive["recording"]["source"].startswith("drive recorders at ")
    # the whole move is in the drives' recording: at least one sample per period over its duration
    assert samples >= 0.9 * by_drive["duration_s"] * hz
    assert abs(by_drive["sigma"]["error"]) <= 1 and by_drive["coupling"]["held"] == "roll"

    assert "recording: TPDO on SYNC at 500 Hz" in steps["can"]["stdout"]
    assert by_can["motors_start"] == by_drive["motors_start"] and by_can["motors_end"] == by_drive["motors_end"]
    # the same request on the same pair: the same coupling within a few counts (the TPDO recording
    # samples every 2 ms, the drives' every RG x 360 us)
    d, c = by_drive["coupling"], by_can["coupling"]
    assert d["held_excursion"]["counts"] >= 5  # the mismatched pair's held joint does move
    for key in ("held_excursion", "delta_off_path", "sigma_off_path"):
        assert abs(d[key]["counts"] - c[key]["counts"]) <= 3, (key, d, c)


def test_the_recorder_settings_are_put_back_and_the_motors_stop_before_the_uploads(cfg):
    with stepped_session(cfg) as (s, stepped):
        before = _ram(s)
        r = diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(delta="-60counts", source="drive"), timebase=stepped)
        after = _ram(s)
        with s.sim.lock:
            drives = list(s.sim.drives.values())
            assert all(not d.motor_on and d.group_id_written == 0 and d.save_count == 0 for d in drives)
            for d in drives:
                st = [t for t, i, f in d.received if i == 0x300 + d.node and f[:2] == b"ST"]
                uploads = [t for t, i, f in d.received if i == 0x600 + d.node and f[1:3] == b"\x30\x20"]
                assert st and uploads and max(st) < min(uploads)  # stopped before any recorded data was read
    assert after == before  # RAM only, put back
    assert r.trace_source.startswith("drive recorders at ") and abs(r.end[1] + 60) <= 1
    assert r.coupling.held == "pitch" and len(r.samples) > 10
    times = [t for t, _, _ in r.samples]
    assert times[0] == 0.0 and all(b > a for a, b in itertools.pairwise(times))


def test_an_error_during_the_move_still_puts_the_recorder_settings_back(cfg):
    class Boom(Exception):
        pass

    with stepped_session(cfg) as (s, stepped):
        before = _ram(s)
        step, failed = stepped.sleep, []

        def sleep(seconds):  # every wait of the move (the clients' too): the stepped clock's
            step(seconds)
            with s.sim.lock:
                running = s.sim.drives["left"].motor.v != 0
            if running and not failed and threading.current_thread() is threading.main_thread():
                # the motors run: fail inside the move's loop, once (the stop waits too)
                failed.append(seconds)
                raise Boom()

        stepped.sleep = sleep
        with pytest.raises(Boom):
            diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="0.5", source="drive"), timebase=stepped)
        assert _ram(s) == before
        with s.sim.lock:
            assert all(not d.motor_on and d.group_id_written == 0 for d in s.sim.drives.values())


def test_source_drive_with_poll_is_a_usage_error(cli):
    result = cli(*MIS, "diffdrive", "move", "diff", "--sigma", "0.3", "--source", "drive", "--poll", "--apply")
    assert result.exit_code == 2 and result.stdout == ""
    assert result.stderr.strip() == ("error: --source drive records in the drives, not over the bus: "
                                     "--poll does not apply"), result.stderr
    result = cli(*MIS, "diffdrive", "move", "diff", "--sigma", "0.3", "--source", "usb")
    assert result.exit_code == 2 and "--source usb: expected can or drive" in result.stderr


def test_a_move_longer_than_the_recorder_holds_is_refused_before_anything_moves(cfg):
    small = RecorderSettings(capacity=16)  # 4096 x 16 x 360 us: 23.6 s at most
    slow = PairTarget(sigma="300counts", velocity="10counts/s", source="drive")  # 30 s, its bound 65 s
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        before = _ram(s)
        with pytest.raises(UsageError, match=r"--source drive: the move may take up to .* s \(its time bound\); "
                                             r"the drive's recorder holds at most 23\.6 s"):
            diffdrive.run_move(s, cfg.pairs["diff"], slow, drive_recorder=small)
        assert _ram(s) == before
        with s.sim.lock:
            for d in s.sim.drives.values():
                assert not d.motor_on and d.motor.v == 0
                assert not [f for _, i, f in d.received if f[:2] in (b"BG", b"MO", b"PA", b"RR")]
                assert not [f for _, i, f in d.received if i == 0x300 + 125]  # no group BG either


def test_the_dry_run_names_the_drive_recorders_and_what_apply_would_refuse(cli):
    dry = cli(*MIS, "diffdrive", "move", "diff", "--sigma", "0.3", "--source", "drive")
    assert dry.exit_code == 0, dry.transcript()
    assert "records both motors: the drives' own recorders at the servo rate" in dry.stdout
    js = json.loads(cli(*MIS, "--json", "diffdrive", "move", "diff", "--sigma", "0.3", "--source", "drive").stdout)
    assert js["recording"] == "drive" and js["would_be_refused"] == []


def test_a_drive_recorded_move_refused_at_the_lock_sends_nothing_to_the_recorders(cfg):
    """The recorders are armed inside the motion guard: a pair another command holds is refused at
    the lock before anything reaches its drives (review: they were armed before the guard's lock)."""
    from sherpa_cli.bus.targets import drive_ref
    from sherpa_cli.motion.lock import DriveLock, MotionLockedError

    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as s:
        held = DriveLock(drive_ref(cfg, "left"), "another command")
        held.acquire()
        try:
            with s.sim.lock:
                before = {n: len(d.received) for n, d in s.sim.drives.items()}
            with pytest.raises(MotionLockedError):
                diffdrive.run_move(s, cfg.pairs["diff"], PairTarget(sigma="0.5", source="drive", uncalibrated=True))
            with s.sim.lock:
                sent = {n: {bytes(f[:2]) for _, _, f in d.received[before[n]:]} for n, d in s.sim.drives.items()}
        finally:
            held.release()
    recorder = {letters.encode() for letters in ("RC", "RG", "RL", "RP", "RV", "RR")}
    assert all(not (frames & recorder) for frames in sent.values()), sent
