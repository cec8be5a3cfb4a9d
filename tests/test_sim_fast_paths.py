"""What the simulator's speed work must not change: idle drives skip model steps, not events;
the interpreter's per-command cache still applies each drive's own input count.
"""

from __future__ import annotations

from sherpa_cli.elmo.codec import decode_reply, encode_query, encode_set
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive

NODE = 3


def started(clock: ManualClock, **settings) -> SimDrive:
    drive = SimDrive(NODE, clock=clock, settings=SimSettings(**settings), serial=1)
    drive.receive(0x000, bytes([0x01, NODE]))
    drive.pop_frames()
    return drive


def ask(drive: SimDrive, frame: bytes):
    drive.receive(0x300 + NODE, frame)
    (can_id, data), = drive.pop_frames()
    assert can_id == 0x280 + NODE
    return decode_reply(data)


def test_a_drive_with_its_motor_off_is_not_stepped_every_millisecond():
    clock = ManualClock()
    drive = started(clock)
    steps: list[float] = []
    drive.on_step = lambda d: steps.append(clock.now())
    clock.advance(1.0)
    drive.tick()
    assert steps == [1.0], "one step to the present: nothing can move with the motor off"


def test_a_drive_with_its_motor_on_still_steps_every_model_step():
    clock = ManualClock()
    drive = started(clock, mo_settle_s=0.0)
    assert ask(drive, encode_set("MO", 0, 1)).ok
    steps: list[float] = []
    drive.on_step = lambda d: steps.append(clock.now())
    clock.advance(0.1)
    drive.tick()
    assert len(steps) == round(0.1 / drive.settings.model_step_s)


def test_events_of_an_idle_drive_still_happen_on_time():
    clock = ManualClock()
    drive = started(clock, heartbeat_ms=100)
    clock.advance(1.0)
    drive.tick()  # one call across ten heartbeat periods
    beats = [can_id for can_id, _ in drive.pop_frames() if can_id == 0x700 + NODE]
    assert len(beats) == 10


def test_the_input_count_is_checked_per_drive_after_another_drive_answered():
    clock = ManualClock()
    wide = started(clock, inputs=10)
    narrow = started(clock, inputs=6)
    assert ask(wide, encode_query("IL", 8)).ok  # IL[8] resolved and remembered
    refused = ask(narrow, encode_query("IL", 8))
    assert refused.error_code == 3  # EC 3 bad index: this drive has 6 inputs
    assert ask(narrow, encode_query("IL", 6)).ok
