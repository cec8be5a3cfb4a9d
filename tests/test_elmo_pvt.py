"""elmo/pvt.py: the PVT record frame, the set-up as data and the PVT emergencies, byte for byte."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.elmo.faults import decode_emcy
from sherpa_cli.elmo.pvt import (
    InterpSet,
    PvtEventKind,
    PvtRecord,
    PvtSettings,
    SdoSet,
    decode_record,
    encode_record,
    interpreter_setup,
    pdo_restore,
    pdo_setup,
    pvt_event,
    start_steps,
)
from sherpa_cli.errors import CodecError

INT32 = st.integers(-(2**31), 2**31 - 1)


def test_a_record_is_int32_position_then_int32_velocity_little_endian():
    assert encode_record(0x01020304, -2) == bytes.fromhex("04 03 02 01 fe ff ff ff")
    assert encode_record(-(2**31), 2**31 - 1) == bytes.fromhex("00 00 00 80 ff ff ff 7f")
    assert decode_record(bytes.fromhex("e8 03 00 00 18 fc ff ff")) == PvtRecord(1000, -1000)


@given(INT32, INT32)
def test_records_round_trip(position, velocity):
    data = encode_record(position, velocity)
    assert len(data) == 8
    assert decode_record(data) == PvtRecord(position, velocity)


@pytest.mark.parametrize(("position", "velocity"), [(2**31, 0), (0, -(2**31) - 1), (1.0, 0), (True, 0), (0, None)])
def test_a_value_that_is_no_int32_is_refused(position, velocity):
    with pytest.raises(CodecError):
        encode_record(position, velocity)


def test_a_record_of_another_length_is_refused():
    with pytest.raises(CodecError, match="8 bytes"):
        decode_record(b"\x00" * 7)


def test_the_default_setup_as_data():
    s = PvtSettings()
    assert interpreter_setup(s) == (
        InterpSet("UM", 0, 5), InterpSet("MP", 1, 1), InterpSet("MP", 2, 64), InterpSet("MP", 3, 1),
        InterpSet("MP", 4, 16), InterpSet("MP", 6, 1), InterpSet("QT", 1, 10))
    assert [step.name for step in interpreter_setup(s)] == ["UM", "MP[1]", "MP[2]", "MP[3]", "MP[4]", "MP[6]", "QT[1]"]
    assert pdo_setup(s, node=5) == (
        SdoSet(0x1402, 1, 4, 0x80000405), SdoSet(0x1602, 0, 1, 0), SdoSet(0x1602, 1, 4, 0x20010040),
        SdoSet(0x1602, 0, 1, 1), SdoSet(0x1402, 2, 1, 255), SdoSet(0x1402, 1, 4, 0x405))
    assert start_steps(s) == (InterpSet("PV", 0, 1),)


def test_other_settings_change_the_steps():
    s = PvtSettings(rpdo=4, data_object=0x2002, data_sub=1, first_row=9, queue_size=32, low_threshold=4,
                    period_ms=8, period_command=("MP", 5), start_command=("PT", 0))
    assert pdo_setup(s, node=0x7F)[2] == SdoSet(0x1603, 1, 4, 0x20020140)
    assert pdo_setup(s, node=0x7F)[-1] == SdoSet(0x1403, 1, 4, 0x57F)
    assert InterpSet("MP", 2, 40) in interpreter_setup(s)
    assert interpreter_setup(s)[-1] == InterpSet("MP", 5, 8)
    assert start_steps(s) == (InterpSet("PT", 0, 9),)
    assert s.period_s == 0.008


def test_restore_puts_the_old_mapping_back_in_a_safe_order():
    s = PvtSettings()
    old = {(0x1402, 1): 0x405, (0x1402, 2): 254, (0x1602, 0): 0, (0x1602, 1): 0}
    assert pdo_restore(s, old) == (
        SdoSet(0x1402, 1, 4, 0x80000405), SdoSet(0x1602, 0, 1, 0), SdoSet(0x1602, 1, 4, 0),
        SdoSet(0x1602, 0, 1, 0), SdoSet(0x1402, 2, 1, 254), SdoSet(0x1402, 1, 4, 0x405))


@pytest.mark.parametrize("kwargs", [dict(rpdo=2), dict(rpdo=5), dict(queue_size=65), dict(first_row=40),
                                    dict(low_threshold=64), dict(period_ms=0), dict(cyclic=2),
                                    dict(queue_size=True)])
def test_settings_no_drive_can_take_are_refused(kwargs):
    with pytest.raises(ValueError, match="PvtSettings"):
        PvtSettings(**kwargs)


@pytest.mark.parametrize(("frame", "kind", "ends", "underflow"), [
    ("00 ff 81 56 05 00 03 00", PvtEventKind.QUEUE_LOW, False, False),
    ("00 ff 81 34 07 00 00 00", PvtEventKind.QUEUE_FULL, True, False),
    ("00 ff 81 5b 41 00 00 00", PvtEventKind.BAD_HEAD_POINTER, True, False),
    ("00 ff 81 08 09 00 03 00", PvtEventKind.MOTION_TERMINATED, True, True),
    ("00 ff 81 08 09 00 01 00", PvtEventKind.MOTION_TERMINATED, True, False),
    ("00 ff 81 09 00 00 00 00", PvtEventKind.MESSAGE_LOST, True, False),
    ("00 ff 81 8a 00 00 00 00", PvtEventKind.UNDERFLOW, True, True),
])
def test_pvt_emergencies_are_named_events(frame, kind, ends, underflow):
    event = pvt_event(decode_emcy(bytes.fromhex(frame)))
    assert event is not None
    assert (event.kind, event.ends_stream, event.underflow) == (kind, ends, underflow)
    assert event.text


def test_queue_low_carries_the_pointers():
    event = pvt_event(decode_emcy(bytes.fromhex("00 ff 81 56 05 00 03 00")))
    assert event is not None and (event.field1, event.field2) == (5, 3)
    assert event.text == "PVT queue low (write pointer 5, read pointer 3)"


@pytest.mark.parametrize("frame", ["30 81 11 00 00 00 00 00", "00 ff 81 77 00 00 00 00", "02 ff 21 56 00 00 00 00"])
def test_other_emergencies_are_no_pvt_event(frame):
    assert pvt_event(decode_emcy(bytes.fromhex(frame))) is None
