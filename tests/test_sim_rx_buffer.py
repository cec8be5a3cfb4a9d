"""The simulated drive's one receive buffer (SimSettings.rx_buffer_s): a frame to
the drive before it took (answered, or held for rx_buffer_s) the previous one is an overrun, lost
and counted, so a tool that paces too fast is caught. Time moves only through a ManualClock."""

from __future__ import annotations

import pytest

from sherpa_cli.elmo.codec import encode_query, encode_set
from sherpa_cli.sim import ManualClock, SimSettings
from sherpa_cli.sim.drive import SimDrive

NODE = 10
RPDO2, TPDO2, SDO_RX = 0x300 + NODE, 0x280 + NODE, 0x600 + NODE


def _drive(clock: ManualClock, **settings) -> SimDrive:
    drive = SimDrive(NODE, clock=clock, settings=SimSettings(**settings), serial=1)
    drive.receive(0x000, bytes([0x01, NODE]))  # NMT start
    drive.pop_frames()
    return drive


def test_an_answered_frame_frees_the_buffer_at_once():
    clock = ManualClock()
    drive = _drive(clock, rx_buffer_s=0.0005)
    for _ in range(3):
        assert drive.receive(RPDO2, encode_query("PX"))
        assert [can_id for can_id, _ in drive.pop_frames()] == [TPDO2]
    assert drive.overruns == []


def test_an_unanswered_frame_holds_the_buffer_and_the_next_one_overruns():
    clock = ManualClock()
    drive = _drive(clock, rx_buffer_s=0.0005, echo_sets=False)  # a set is not answered
    assert drive.receive(RPDO2, encode_set("AC", 0, 150000))
    assert not drive.receive(RPDO2, encode_query("AC"))  # too soon: lost
    assert drive.overruns == [(0.0, RPDO2, encode_query("AC"))] and drive.pop_frames() == []
    clock.advance(0.0005)
    assert drive.receive(RPDO2, encode_query("AC"))  # the buffer is free again
    assert drive.pop_frames() == [(TPDO2, bytes.fromhex("41 43 00 00 F0 49 02 00"))]


def test_a_late_reply_holds_the_buffer_until_it_leaves():
    clock = ManualClock()
    drive = _drive(clock, rx_buffer_s=0.001, reply_latency_s=0.0003)
    assert drive.receive(RPDO2, encode_query("PX"))
    clock.advance(0.0002)
    assert not drive.receive(SDO_RX, bytes.fromhex("40 00 10 00 00 00 00 00"))  # another frame to it: overrun
    clock.advance(0.0001)
    drive.tick()
    assert [can_id for can_id, _ in drive.pop_frames()] == [TPDO2]
    assert drive.receive(RPDO2, encode_query("PX"))  # answered: free
    assert len(drive.overruns) == 1


def test_off_by_default_and_frames_to_other_nodes_do_not_count():
    clock = ManualClock()
    drive = _drive(clock, echo_sets=False)
    assert drive.receive(RPDO2, encode_set("AC", 0, 150000)) and drive.receive(RPDO2, encode_query("AC"))
    paced = _drive(ManualClock(), rx_buffer_s=0.01, echo_sets=False)
    assert paced.receive(RPDO2, encode_set("AC", 0, 150000))
    assert not paced.receive(RPDO2 + 1, encode_query("AC"))  # not addressed to it: ignored, not an overrun
    assert paced.overruns == [] and drive.overruns == []


def test_the_config_sets_a_simulated_drives_receive_buffer(tmp_path):
    from pathlib import Path

    from sherpa_cli.config import load_config
    from sherpa_cli.errors import SherpaError
    from sherpa_cli.sim.arm import SimArm

    text = Path("configs/appendix-c/example1.yaml").read_text(encoding="utf-8")
    cfg_path = tmp_path / "a.yaml"
    drive = next(iter(load_config("configs/appendix-c/example1.yaml").drives))
    cfg_path.write_text(text + f"\nsim: {{drives: {{{drive}: {{rx_buffer: 0.0005}}}}}}\n", encoding="utf-8")
    cfg = load_config(cfg_path)
    assert cfg.sim[drive].rx_buffer == 0.0005
    assert SimArm.in_process(cfg).drives[drive].settings.rx_buffer_s == 0.0005
    cfg_path.write_text(text + f"\nsim: {{drives: {{{drive}: {{rx_buffer: -1}}}}}}\n", encoding="utf-8")
    with pytest.raises(SherpaError, match="rx_buffer"):
        load_config(cfg_path)
