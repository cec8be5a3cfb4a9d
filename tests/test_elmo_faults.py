"""SR / MF / EC / EMCY / IP / IL decoding against the tables in elmo-protocol.md 2.4, 2.5 and 3.6."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.elmo.faults import (
    EC_CODES,
    EMCY_CODES,
    PVT_CODES,
    decode_emcy,
    decode_il,
    decode_ip,
    decode_mf,
    decode_sr,
    describe_il,
    describe_ip,
    describe_mf,
    describe_sr,
    ec_text,
)
from sherpa_cli.errors import CodecError


def emcy(code: int, register: int = 0x81, elmo: int = 0, f1: int = 0, f2: int = 0) -> bytes:
    return struct.pack("<HBBHH", code, register, elmo, f1, f2)


# -- EC ------------------------------------------------------------------------------------------

CONFIRMED_EC = (2, 3, 7, 9, 10, 11, 13, 16, 19, 21, 23, 26, 28, 33, 34, 47, 48, 51, 54, 57, 58, 60, 61, 67,
                68, 71, 72, 82, 83, 122, 166, 168, 172, 178, 179)
BLISS_ONLY_EC = (12, 14, 15, 22, 25, 43, 90, 92)


def test_every_documented_ec_is_known():
    assert set(EC_CODES) == set(CONFIRMED_EC) | set(BLISS_ONLY_EC)
    assert {c for c, e in EC_CODES.items() if e.bliss_only} == set(BLISS_ONLY_EC)


@pytest.mark.parametrize(("code", "text"), [
    (21, "operand out of range"), (57, "motor must be off"), (58, "motor must be on"),
    (72, "modulo range must be even"), (179, "consumer heartbeat event"), (22, "zero division"),
])
def test_ec_text(code, text):
    assert ec_text(code) == text


def test_unknown_ec():
    assert ec_text(200) == "unknown error code 200"


# -- SR ------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("low", "text"), [(3, "under-voltage"), (5, "over-voltage"), (11, "short circuit"),
                                           (13, "over-temperature")])
def test_sr_servo_status_as_bliss_reads_it(low, text):
    sr = decode_sr(low)
    assert sr.problem and sr.servo_text == text
    assert describe_sr(low)[0] == f"drive problem: {text}"


def test_sr_fields():
    # MO on, UM=5, MS=2, recorder waiting, Hall A+C, stopped by limit, current limit.
    value = (1 << 4) | (5 << 7) | (1 << 13) | (2 << 14) | (1 << 16) | (0b101 << 24) | (1 << 28)
    sr = decode_sr(value)
    assert (sr.motor_on, sr.unit_mode, sr.motion_status, sr.recorder, sr.halls) == (True, 5, 2, 1, 0b101)
    assert sr.stopped_by_limit and sr.current_limit and not sr.problem and not sr.motor_failure
    lines = describe_sr(value)
    assert "motor on" in lines
    assert "unit mode 5 (single-feedback position)" in lines
    assert "motion status 2 (profiler active)" in lines
    assert "recorder: waiting for trigger" in lines
    assert "Halls A/B/C: 101" in lines
    assert "current limit active (LC)" in lines
    assert any("VL[3]/VH[3]" in line for line in lines)


def test_sr_negative_int32_is_bit_31():
    assert decode_sr(-1).raw == 0xFFFFFFFF
    assert any("unknown SR bits" in line for line in describe_sr(-(2**31)))


def test_sr_idle():
    assert describe_sr(0)[:2] == ["motor off", "unit mode 0 (unknown)"]


@pytest.mark.parametrize("bad", [2**32, -(2**31) - 1, 1.5, "5", None, True])
def test_register_value_errors(bad):
    for decode in (decode_sr, decode_mf, decode_ip):
        with pytest.raises(CodecError):
            decode(bad)


# -- MF ------------------------------------------------------------------------------------------

def test_mf_zero_is_no_fault():
    assert decode_mf(0).ok and describe_mf(0) == []


@pytest.mark.parametrize(("value", "text"), [(0x3000, "under-voltage"), (0x5000, "over-voltage"),
                                             (0xB000, "short circuit"), (0xD000, "over-temperature")])
def test_mf_servo_fault_detail(value, text):
    (fault,) = decode_mf(value).faults
    assert fault.text == f"servo drive fault: {text}" and fault.known


def test_mf_servo_detail_without_bit_12():
    (fault,) = decode_mf(0x2000).faults
    assert not fault.known and "without bit 12" in fault.text


@pytest.mark.parametrize(("value", "text", "check"), [
    (0x400000, "position limit exceeded", "LL[3]/HL[3]"),
    (0x20000, "speed limit exceeded", "LL[2]/HL[2]"),
    (0x800, "heartbeat failure", "0x1016"),
    (0x200000, "motor stuck", "CL[2]/CL[3]"),
    (0x80, "speed tracking error", "ER[2]"),
    (0x100, "position tracking error", "ER[3]"),
])
def test_mf_bits_with_hints(value, text, check):
    (fault,) = decode_mf(value).faults
    assert fault.text.startswith(text) and check in fault.check


def test_mf_several_bits_and_unknown():
    lines = describe_mf(0x400000 | 0x8 | 0x80000000)
    assert len(lines) == 3
    assert lines[0].startswith("peak current exceeded")
    assert lines[1].startswith("position limit exceeded")
    assert lines[2] == "unknown MF bit 31 (0x80000000)"


# -- EMCY ----------------------------------------------------------------------------------------

DOC_EMCY = (0x8110, 0x8200, 0x8210, 0x8130, 0x6180, 0x6200, 0xFF01, 0x6300, 0xFF02,
            0x2340, 0x3120, 0x3310, 0x4310, 0x5280, 0x5441, 0x7121, 0x7300, 0x7381, 0x8311, 0x8480,
            0x8481, 0x8611, 0x8680, 0xFF10,
            0x3130, 0x5281, 0x5400, 0x6181, 0x6320, 0x7380, 0x7382, 0x8140, 0x8380, 0x8381, 0x5442,
            0xFF20, 0xFF40)
DOC_PVT = (0x56, 0x5B, 0x5C, 0x34, 0x07, 0x08, 0x09, 0xA6)


def test_every_documented_emcy_code_is_known():
    assert set(DOC_EMCY) <= set(EMCY_CODES)
    assert set(DOC_PVT) == set(PVT_CODES)
    for code in DOC_EMCY:
        e = decode_emcy(emcy(code))
        assert e.known and "unknown" not in e.text, hex(code)


def test_emcy_layout():
    e = decode_emcy(bytes.fromhex("80 86 81 00 34 12 78 56"))
    assert (e.code, e.error_register, e.elmo_code, e.field1, e.field2) == (0x8680, 0x81, 0, 0x1234, 0x5678)
    assert e.text.startswith("EMCY 0x8680: position limit exceeded")
    assert "LL[3]/HL[3]" in e.check


@pytest.mark.parametrize(("code", "check"), [(0x8481, "LL[2]/HL[2]"), (0x8130, "0x1016"),
                                             (0x8611, "ER[3]"), (0x8480, "ER[2]")])
def test_emcy_hints(code, check):
    assert check in decode_emcy(emcy(code)).text


def test_emcy_elmo_code_text():
    e = decode_emcy(emcy(0x6300, 0x01, 21, 0x2012, 0x0001))
    assert "error 21: operand out of range" in e.text
    assert "object 0x2012" in e.text


def test_emcy_can_message_lost_field2():
    assert "hardware buffer overrun" in decode_emcy(emcy(0x8110, 0x11, 9, 0, 0xFFFF)).text
    assert "lost COB-ID 0x301" in decode_emcy(emcy(0x8110, 0x11, 9, 0, 0x301)).text


@pytest.mark.parametrize(("sub", "text"), [(0x56, "queue low"), (0x34, "queue full"), (0xA6, "out of modulo"),
                                           (0x5C, "not mapped")])
def test_emcy_pvt_variants(sub, text):
    e = decode_emcy(emcy(0xFF00, 0x81, sub))
    assert text in e.text and e.known
    assert e.elmo_text is None  # byte 3 is a PVT sub-code here, not an EC number


def test_emcy_unknown_codes_do_not_raise():
    e = decode_emcy(emcy(0x1234))
    assert not e.known and "unknown code 0x1234" in e.text
    assert "unknown sub-code 0x77" in decode_emcy(emcy(0xFF00, 0x81, 0x77)).text


@pytest.mark.parametrize("data", [b"", bytes(7), bytes(9), "80860000"])
def test_emcy_bad_frames(data):
    with pytest.raises(CodecError):
        decode_emcy(data)


@given(st.binary(min_size=8, max_size=8))
def test_any_emcy_frame_decodes(data):
    e = decode_emcy(data)
    assert e.text.startswith(f"EMCY 0x{e.code:04X}: ")


@given(st.integers(-(2**31), 2**32 - 1))
def test_any_register_value_decodes(value):
    assert describe_sr(value)
    assert isinstance(describe_mf(value), list)
    assert describe_ip(value)
    assert (decode_mf(value).raw == 0) == (value == 0)


# -- IP / IL -------------------------------------------------------------------------------------

def test_ip_flags_and_pins():
    ip = decode_ip((1 << 10) | (1 << 11) | (1 << 6) | (1 << 16) | (1 << 25))
    assert ip.flags == ("main home switch", "forward limit switch (FLS)", "reverse limit switch (RLS)")
    assert ip.pins == (1, 10)
    assert ip.unknown_bits == 0


def test_ip_other_flags_and_unknown_bits():
    ip = decode_ip((1 << 12) | (1 << 14) | (1 << 0) | (1 << 15) | (1 << 26))
    assert ip.flags == ("input 1 function flag", "inhibit", "abort")
    assert ip.unknown_bits == (1 << 15) | (1 << 26)
    assert describe_ip(0) == ["no input function active", "no input pin active"]


@pytest.mark.parametrize(("value", "text"), [
    (0, "inhibit, active low"), (5, "ignore, active high"), (8, "reverse limit switch (RLS), active low"),
    (11, "forward limit switch (FLS), active high"), (16, "main home, active low"),
    (19, "auxiliary home, active high"), (23, "abort, active high"), (24, "unknown input function 24"),
    (-1, "unknown input function -1"),
])
def test_describe_il(value, text):
    assert describe_il(value) == text


def test_il_polarity():
    assert not decode_il(10).active_high and decode_il(21).active_high
