"""Binary-interpreter codec and command table: manual vectors, invalid input, round-trip properties."""

from __future__ import annotations

import contextlib
import math
import re
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.elmo import codec
from sherpa_cli.elmo.codec import (
    Reply,
    Request,
    decode_reply,
    decode_request,
    encode_error_reply,
    encode_execute,
    encode_query,
    encode_reply,
    encode_set,
    parse_expr,
)
from sherpa_cli.elmo.commands import COMMANDS, lookup, param_key, parse_param_key
from sherpa_cli.errors import CodecError


def hx(text: str) -> bytes:
    return bytes.fromhex(text)


# -- manual vectors ([IG] ch. 9, and the derived ones in elmo-protocol.md 1.2) -------------------

@pytest.mark.parametrize(("letters", "index", "value", "frame"), [
    ("CL", 1, 1.0, "43 4C 01 80 00 00 80 3F"),
    ("AC", 0, 150000, "41 43 00 00 F0 49 02 00"),
    ("CA", 18, 4096, "43 41 12 00 00 10 00 00"),
    ("MO", 0, 1, "4D 4F 00 00 01 00 00 00"),
    ("IL", 3, 5, "49 4C 03 00 05 00 00 00"),
    ("PL", 1, 2.5, "50 4C 01 80 00 00 20 40"),
])
def test_set_vectors(letters, index, value, frame):
    assert encode_set(letters, index, value) == hx(frame)


def test_query_vectors():
    assert encode_query("AC") == hx("41 43 00 00")
    assert encode_query("AC", long=True) == hx("41 43 00 40 00 00 00 00")
    assert encode_query("MO") == hx("4D 4F 00 00")
    assert encode_query("ET", 992, long=True) == hx("45 54 E0 43 00 00 00 00")
    # float parameters: the query bit and the float bit (byte 3 = 0x80 | 0x40)
    assert encode_query("CL", 1, long=True) == hx("43 4C 01 C0 00 00 00 00")
    assert encode_query("CL", 1) == hx("43 4C 01 00")


def test_execute_vectors():
    assert encode_execute("BG") == hx("42 47 00 00")
    assert encode_execute("SV") == hx("53 56 00 00")


def test_reply_vectors():
    assert decode_reply(hx("41 43 00 00 F0 49 02 00")) == Reply("AC", 0, 150000, False)
    assert decode_reply(hx("45 54 E0 03 79 7D 00 00")) == Reply("ET", 992, 0x7D79, False)
    bg = decode_reply(hx("42 47 00 00 00 00 00 00"))
    assert bg.ok and bg.value == 0 and bg.letters == "BG"


def test_error_reply_vectors():
    ca = decode_reply(hx("43 41 01 40 15 00 00 00"))
    assert (ca.letters, ca.index, ca.error_code, ca.value, ca.ok) == ("CA", 1, 21, None, False)
    assert ca.error_text == "operand out of range"
    bg = decode_reply(hx("42 47 00 40 3A 00 00 00"))
    assert (bg.error_code, bg.error_text) == (58, "motor must be on")


def test_float_reply():
    r = decode_reply(hx("43 4C 01 80 00 00 80 3F"))
    assert (r.value, r.is_float, r.index) == (1.0, True, 1)
    assert isinstance(r.value, float)


def test_simulator_side_vectors():
    assert encode_reply("AC", 0, 150000, False) == hx("41 43 00 00 F0 49 02 00")
    assert encode_reply("ET", 992, 0x7D79, False) == hx("45 54 E0 03 79 7D 00 00")
    assert encode_reply("BG", 0, None, False) == hx("42 47 00 00 00 00 00 00")
    assert encode_error_reply("CA", 1, 21) == hx("43 41 01 40 15 00 00 00")
    assert encode_error_reply("BG", 0, 58) == hx("42 47 00 40 3A 00 00 00")


def test_decode_request_kinds():
    assert decode_request(hx("41 43 00 00 F0 49 02 00")) == Request("set", "AC", 0, 150000, False)
    assert decode_request(hx("43 4C 01 80 00 00 80 3F")) == Request("set", "CL", 1, 1.0, True)
    assert decode_request(hx("41 43 00 00")) == Request("query", "AC", 0, None, False)
    assert decode_request(hx("41 43 00 40 00 00 00 00")) == Request("query", "AC", 0, None, False)
    assert decode_request(hx("45 54 E0 43 00 00 00 00")) == Request("query", "ET", 992, None, False)
    assert decode_request(hx("42 47 00 00")) == Request("execute", "BG", 0, None, False)
    assert decode_request(hx("42 47 00 00 00 00 00 00")).kind == "execute"


def test_decode_request_unknown_command_is_left_to_the_simulator():
    # The drive answers unknown commands with EC 2, so the frame itself must still decode.
    assert decode_request(hx("5A 5A 00 00")) == Request("query", "ZZ", 0, None, False)


# -- type handling -------------------------------------------------------------------------------

def test_per_index_types():
    assert encode_set("CL", 3, 100)[3] & 0x80 == 0  # CL[3] int cnt/s
    assert encode_set("CL", 2, 50)[3] & 0x80 == 0x80  # CL[2] float %
    assert encode_set("PL", 2, 3) == hx("50 4C 02 00 03 00 00 00")  # PL[2] int s


def test_int_for_float_command_is_converted():
    assert encode_set("CL", 1, 1) == encode_set("CL", 1, 1.0)


def test_integral_float_for_int_command_is_accepted():
    assert encode_set("AC", 0, 150000.0) == hx("41 43 00 00 F0 49 02 00")


def test_float_is_rounded_to_float32():
    frame = encode_set("CL", 1, 0.1)
    assert struct.unpack("<f", frame[4:])[0] == pytest.approx(0.1, rel=1e-7)


def test_int32_edges():
    assert encode_set("PA", 0, -(2**31))[4:] == hx("00 00 00 80")
    assert encode_set("PA", 0, 2**31 - 1)[4:] == hx("FF FF FF 7F")
    assert encode_set("LL", 3, -240)[4:] == hx("10 FF FF FF")


# -- invalid input: every class raises CodecError naming the problem -----------------------------

@pytest.mark.parametrize(("call", "match"), [
    (lambda: encode_set("ac", 0, 1), "upper case"),
    (lambda: encode_set("QQ", 0, 1), "unknown command QQ"),
    (lambda: encode_set("A", 0, 1), "two letters"),
    (lambda: encode_set("AÇ", 0, 1), "non-ASCII"),
    (lambda: encode_set("LL", 16384, 1), "0..16383"),
    (lambda: encode_set("LL", 4, 1), r"LL\[4\]: index outside 1..3"),
    (lambda: encode_set("LL", 0, 1), "outside 1..3"),
    (lambda: encode_set("AC", 1, 1), "not an array command"),
    (lambda: encode_set("VX", 0, 1), "read-only"),
    (lambda: encode_set("BG", 0, 1), "execute command"),
    (lambda: encode_set("AC", 0, 2**31), "outside int32"),
    (lambda: encode_set("AC", 0, -(2**31) - 1), "outside int32"),
    (lambda: encode_set("AC", 0, 1.5), "not a whole number"),
    (lambda: encode_set("CL", 1, math.nan), "not a finite number"),
    (lambda: encode_set("CL", 1, math.inf), "not a finite number"),
    (lambda: encode_set("AC", 0, math.inf), "not a finite number"),
    (lambda: encode_set("CL", 1, 1e39), "too large for float32"),
    (lambda: encode_set("CL", 1, "1.0"), "must be a number"),
    (lambda: encode_set("MO", 0, True), "must be a number"),
    (lambda: encode_set("CL", True, 1.5), "index must be an integer"),
    (lambda: encode_set("CL", 1.0, 1.5), "index must be an integer"),
    (lambda: encode_query("LL", True), "index must be an integer"),
    (lambda: encode_query("BG"), "cannot be queried"),
    (lambda: encode_query("IL", 11), "outside 1..10"),
    (lambda: encode_execute("AC"), "not an execute command"),
    (lambda: decode_reply(hx("41 43 00 00")), "must be 8 bytes, got 4"),
    (lambda: decode_reply(hx("41 43 00 00 00 00 00 00 00")), "must be 8 bytes, got 9"),
    (lambda: decode_reply("41430000"), "must be bytes"),
    (lambda: decode_reply(hx("61 63 00 00 00 00 00 00")), "upper case"),
    (lambda: decode_reply(hx("C1 43 00 00 00 00 00 00")), "not ASCII"),
    (lambda: decode_reply(hx("41 43 00 80 00 00 C0 7F")), "not a finite number"),
    (lambda: decode_request(hx("41 43 00")), "must be 4 or 8 bytes, got 3"),
    (lambda: decode_request(hx("41 43 00 00 00 00")), "must be 4 or 8 bytes, got 6"),
    (lambda: decode_request(b""), "got 0"),
    (lambda: encode_reply("AC", 16384, 0, False), "0..16383"),
    (lambda: encode_reply("AC", 0, 2**31, False), "outside int32"),
    (lambda: encode_error_reply("AC", 0, 256), "0..255"),
])
def test_invalid_input(call, match):
    with pytest.raises(CodecError, match=match):
        call()


def test_lower_case_has_hint():
    with pytest.raises(CodecError) as info:
        parse_expr("ac=5")
    assert info.value.hint == "write AC"


def test_unknown_command_suggests_closest():
    with pytest.raises(CodecError, match="did you mean") as info:
        lookup("MG")  # not a command; MO, MF, MS and MC are one letter away
    assert info.value.hint.removeprefix("did you mean ").rstrip("?") in COMMANDS


# -- technician text -----------------------------------------------------------------------------

@pytest.mark.parametrize(("text", "expected"), [
    ("PX", Request("query", "PX", 0, None, False)),
    ("LL[3]", Request("query", "LL", 3, None, False)),
    ("AC=150000", Request("set", "AC", 0, 150000, False)),
    ("BG", Request("execute", "BG", 0, None, False)),
    ("CL[1]=1.5", Request("set", "CL", 1, 1.5, True)),
    ("LL[3]=-240", Request("set", "LL", 3, -240, False)),
    ("  LL [ 3 ] =  -240 ", Request("set", "LL", 3, -240, False)),
    ("IL[2]=0x0B", Request("set", "IL", 2, 11, False)),
    ("PA=-0x10", Request("set", "PA", 0, -16, False)),
    ("AC=007", Request("set", "AC", 0, 7, False)),
    ("AC=1.5e5", Request("set", "AC", 0, 150000, False)),
    ("CL[1]=2", Request("set", "CL", 1, 2.0, True)),
    ("CL[3]=40", Request("set", "CL", 3, 40, False)),
    ("AC[0]", Request("query", "AC", 0, None, False)),
])
def test_parse_expr(text, expected):
    assert parse_expr(text) == expected


def test_parse_expr_then_encode_matches_direct_encoding():
    assert codec.encode_request(parse_expr("CL[1]=1.0")) == hx("43 4C 01 80 00 00 80 3F")
    assert codec.encode_request(parse_expr("ET[992]"), long=True) == hx("45 54 E0 43 00 00 00 00")
    assert codec.encode_request(parse_expr("BG")) == hx("42 47 00 00")


@pytest.mark.parametrize(("text", "match"), [
    ("px", "upper case"),
    ("Px=1", "upper case"),
    ("QQ", "unknown command QQ"),
    ("LL", "array command and needs an index"),
    ("LL[16384]", "0..16383"),
    ("LL[9]", "outside 1..3"),
    ("LL[-1]", "decimal number"),
    ("LL[3", "cannot parse"),
    ("AC[2]", "not an array command"),
    ("VX=5", "read-only"),
    ("BG=1", "takes no value"),
    ("AC=", "value is missing"),
    ("AC=abc", "not a number"),
    ("AC=1.5", "not a whole number"),
    ("AC=2147483648", "outside int32"),
    ("AC=0x80000000", "outside int32"),
    ("CL[1]=nan", "not a finite number"),
    ("CL[1]=inf", "not a finite number"),
    ("CL[1]=0x10", "not a number"),
    ("ÄC", "non-ASCII"),
    ("", "cannot parse"),
    ("=5", "cannot parse"),
])
def test_parse_expr_errors(text, match):
    with pytest.raises(CodecError, match=match):
        parse_expr(text)


# -- command table -------------------------------------------------------------------------------

REQUIRED = ["MO", "UM", "PM", "AC", "DC", "SD", "SP", "JV", "PA", "PR", "PX", "PY", "VX", "VY", "PE", "VE", "DV", "MS", "BG", "ST", "TC", "IQ", "ID", "XM", "YM", "TR", "LL", "HL", "VL", "VH", "ER", "CL", "PL", "MC", "LC", "IP", "IL", "IB", "SR", "MF", "EC", "SV", "LD", "HP", "CA", "SN", "WS", "HM", "RM"]


def test_table_covers_required_commands():
    missing = [c for c in REQUIRED if c not in COMMANDS]
    assert not missing


def test_table_is_consistent():
    for spec in COMMANDS.values():
        assert (spec.value_type is None) == (spec.access == "x"), spec.letters
        assert 0 <= spec.index_min <= spec.index_max <= 16383
        for index in spec.overrides:
            assert spec.index_min <= index <= spec.index_max, (spec.letters, index)


def test_per_index_overrides():
    cl = lookup("CL")
    assert (cl.at(1).value_type, cl.at(1).units) == ("float", "A")
    assert (cl.at(3).value_type, cl.at(3).units) == ("int", "cnt/s")
    assert (lookup("PL").at(2).value_type, lookup("PL").at(2).units) == ("int", "s")
    assert lookup("LL").at(3).units == "counts"


def test_motor_off_flags():
    for letters in ("UM", "PX", "XM", "CA", "IL", "LL", "HL", "VL", "VH"):
        assert lookup(letters).motor_off, letters
    for letters in ("AC", "JV", "PA", "MO"):
        assert not lookup(letters).motor_off, letters


def test_zero_disables():
    ll, hl, cl = lookup("LL"), lookup("HL"), lookup("CL")
    assert ll.at(3).zero_disables and hl.at(3).zero_disables
    assert ll.at(2).zero_disables and hl.at(2).zero_disables
    assert hl.disables_protection(3, 0) and not hl.disables_protection(3, 1000)
    assert cl.disables_protection(2, 0) and cl.disables_protection(2, 1.9)
    assert not cl.disables_protection(2, 2.0)
    assert not lookup("AC").disables_protection(0, 0)


def test_param_keys():
    assert param_key("AC") == "AC"
    assert param_key("LL", 3) == "LL[3]"
    assert parse_param_key("LL[3]") == ("LL", 3)
    assert parse_param_key("AC") == ("AC", 0)
    for bad, match in (("LL", "needs an index"), ("LL[4]", "outside 1..3"), ("ll[3]", "upper case"),
                       ("LL[x]", "decimal"), ("AC[2]", "not an array"), ("XQ", "unknown command")):
        with pytest.raises(CodecError, match=match):
            parse_param_key(bad)
    with pytest.raises(CodecError, match=re.escape("outside 1..10")):
        param_key("IL", 11)


# -- properties ----------------------------------------------------------------------------------

SETTABLE = [(spec.letters, index) for spec in COMMANDS.values() if spec.access == "rw"
            for index in ([0] if not spec.is_array else range(spec.index_min, min(spec.index_max, 40) + 1))]
LETTERS = st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ", min_size=2, max_size=2)
INDEX = st.integers(0, 16383)
INT32 = st.integers(-(2**31), 2**31 - 1)
FLOAT32_MAX = 3.4028234663852886e38


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


@given(st.sampled_from(SETTABLE), st.data())
def test_set_round_trip(key, data):
    letters, index = key
    spec = lookup(letters).at(index)
    if spec.value_type == "float":
        value = data.draw(st.floats(-FLOAT32_MAX, FLOAT32_MAX, allow_nan=False))
        expected = f32(value)
    else:
        value = data.draw(INT32)
        expected = value
    req = decode_request(encode_set(letters, index, value))
    assert (req.kind, req.letters, req.index, req.is_float) == ("set", letters, index, spec.value_type == "float")
    assert req.value == expected
    assert type(req.value) is type(expected)


@given(st.sampled_from(SETTABLE), st.booleans())
def test_query_round_trip(key, long):
    letters, index = key
    frame = encode_query(letters, index, long=long)
    assert len(frame) == (8 if long else 4)
    # a long query carries the parameter's type bit ([IG] 9-3); the short form has no room for it
    is_float = long and lookup(letters).at(index).value_type == "float"
    assert decode_request(frame) == Request("query", letters, index, None, is_float)


@given(LETTERS, INDEX, st.one_of(INT32.map(lambda v: (v, False)),
                                 st.floats(width=32, allow_nan=False, allow_infinity=False).map(lambda v: (v, True))))
def test_reply_round_trip(letters, index, typed):
    value, is_float = typed
    reply = decode_reply(encode_reply(letters, index, value, is_float))
    assert reply == Reply(letters, index, value, is_float)


@given(LETTERS, INDEX, st.integers(0, 255))
def test_error_reply_round_trip(letters, index, code):
    reply = decode_reply(encode_error_reply(letters, index, code))
    assert (reply.letters, reply.index, reply.error_code, reply.ok) == (letters, index, code, False)
    assert reply.error_text


@given(st.binary(min_size=8, max_size=8))
def test_random_replies_raise_only_codec_error(data):
    try:
        reply = decode_reply(data)
    except CodecError:
        return
    assert 0 <= reply.index <= 16383
    assert reply.ok == (data[3] & 0x40 == 0)


@given(st.binary(min_size=0, max_size=12))
def test_random_requests_raise_only_codec_error(data):
    try:
        req = decode_request(data)
    except CodecError:
        return
    assert len(data) in (4, 8) and req.letters == data[:2].decode()


@given(LETTERS, st.binary(min_size=2, max_size=2))
def test_short_frames_with_valid_letters_always_decode(letters, rest):
    req = decode_request(letters.encode() + rest)
    assert req.kind in ("query", "execute") and req.index == int.from_bytes(rest, "little") & 0x3FFF


@given(st.text(max_size=20))
def test_random_text_raises_only_codec_error(text):
    with contextlib.suppress(CodecError):
        parse_expr(text)


def test_an_index_of_hundreds_of_digits_is_refused_naming_the_command():
    """The refusal said only "bad index 9999999999... (400 digits)": on a command line of several
    expressions the technician could not tell which one."""
    from sherpa_cli.elmo.codec import CodecError, parse_expr

    with pytest.raises(CodecError, match=r"^LL: bad index 9999999999\.\.\. \(400 digits\): out of range 0\.\.16383$"):
        parse_expr("LL[" + "9" * 400 + "]=1")
