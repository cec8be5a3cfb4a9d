"""The codec's caches change nothing: warm answers (bytes, values, CodecError messages) equal cold ones.

Each case is asked twice: with every cache empty (the checked path alone), and after the caches
were filled with the nearest valid neighbour (same letters, int index, a plain value), which is
where a cache could wrongly answer: True and 1.0 equal 1 as dict keys, a non-finite float has
the same header as a finite one.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sherpa_cli.elmo import codec
from sherpa_cli.elmo.commands import COMMANDS
from sherpa_cli.errors import CodecError

TABLE_LETTERS = sorted(COMMANDS)
LETTERS = st.one_of(st.sampled_from(TABLE_LETTERS), st.sampled_from(["ac", "A", "ABC", "ZZ", "É1", 5, None]))
INDEX = st.one_of(st.integers(0, 20), st.sampled_from([0x3FFF, 0x4000, -1, True, False, 1.0, 3.0, "1", None]))
VALUE = st.one_of(
    st.integers(-(2**31), 2**31 - 1),
    st.sampled_from([2**31, -(2**31) - 1, 2**40, True, False, None, "5", float("nan"), float("inf"),
                     -float("inf"), 1e39, -1e39, 3.4028234663852886e38, 1.5, -0.0, 2.0]),
    st.floats(-1e6, 1e6, allow_nan=False),
)


def outcome(fn, *args):
    try:
        return ("ok", fn(*args))
    except CodecError as exc:
        return ("error", exc.message, exc.hint)


def cold_and_warm(fn, args, *warmers):
    codec._clear_caches()
    cold = outcome(fn, *args)
    codec._clear_caches()
    for warm_args in warmers:
        outcome(fn, *warm_args)
    first = outcome(fn, *args)
    second = outcome(fn, *args)  # now answered from what the first call may have cached
    return cold, first, second


def _int_or_zero(index):
    return index if type(index) is int else int(index) if isinstance(index, (int, float)) else 0


@settings(max_examples=400)
@given(LETTERS, INDEX, VALUE)
def test_encode_set_warm_equals_cold(letters, index, value):
    neighbour = _int_or_zero(index)
    cold, first, second = cold_and_warm(codec.encode_set, (letters, index, value),
                                        (letters, neighbour, 1), (letters, neighbour, 1.5))
    assert cold == first == second


@settings(max_examples=300)
@given(LETTERS, INDEX, st.sampled_from([False, True, 0, 1, "yes", "", [1], []]))
def test_encode_query_warm_equals_cold(letters, index, long):
    neighbour = _int_or_zero(index)
    cold, first, second = cold_and_warm(codec.encode_query, (letters, index, long),
                                        (letters, neighbour, bool(long)))
    assert cold == first == second


@settings(max_examples=200)
@given(st.one_of(st.sampled_from(["BG", "ST", "SV", "PX"]), LETTERS), INDEX)
def test_encode_execute_warm_equals_cold(letters, index):
    cold, first, second = cold_and_warm(codec.encode_execute, (letters, index), (letters, _int_or_zero(index)))
    assert cold == first == second


@settings(max_examples=400)
@given(LETTERS, INDEX, VALUE, st.sampled_from([False, True, 0, 1, [1]]))
def test_encode_reply_warm_equals_cold(letters, index, value, is_float):
    neighbour = _int_or_zero(index)
    cold, first, second = cold_and_warm(codec.encode_reply, (letters, index, value, is_float),
                                        (letters, neighbour, 1, False), (letters, neighbour, 1.5, True))
    assert cold == first == second


FRAME8 = st.builds(lambda head, body: head + body,
                   st.sampled_from([b"AC\x00\x00", b"CL\x01\x80", b"ET\xe0\x03", b"BG\x00\x40", b"ac\x00\x00",
                                    b"\xc1C\x00\x00", b"ZZ\xff\xbf", b"PX\x00\x80"]),
                   st.one_of(st.binary(min_size=4, max_size=4),
                             st.sampled_from([struct.pack("<f", float("nan")), struct.pack("<f", float("inf")),
                                              bytes(4)])))
FRAMES = st.one_of(FRAME8, st.binary(min_size=0, max_size=12))


@settings(max_examples=400)
@given(FRAMES, st.sampled_from([bytes, bytearray, memoryview, str]))
def test_decode_reply_warm_equals_cold(frame, kind):
    data = frame.hex() if kind is str else kind(frame)
    # the warmer: the same header with zero data (finite, so a float header gets cached)
    cold, first, second = cold_and_warm(codec.decode_reply, (data,), (frame[:4] + bytes(4),))
    assert cold == first == second


@settings(max_examples=300)
@given(st.one_of(st.builds(lambda f: f[:4], FRAME8), FRAMES), st.sampled_from([bytes, bytearray]))
def test_decode_request_warm_equals_cold(frame, kind):
    cold, first, second = cold_and_warm(codec.decode_request, (kind(frame),), (bytes(frame),))
    assert cold == first == second


def test_a_bool_or_float_index_is_refused_after_index_1_was_cached():
    codec._clear_caches()
    assert codec.encode_set("CL", 1, 1.5) == bytes.fromhex("43 4C 01 80 00 00 C0 3F")
    assert codec.encode_query("LL", 1) == bytes.fromhex("4C 4C 01 00")
    for bad in (True, 1.0):
        with pytest.raises(CodecError, match="index must be an integer"):
            codec.encode_set("CL", bad, 1.5)
        with pytest.raises(CodecError, match="index must be an integer"):
            codec.encode_query("LL", bad)


def test_out_of_range_values_still_fail_after_the_header_was_cached():
    codec._clear_caches()
    codec.encode_set("AC", 0, 1)
    codec.encode_set("CL", 1, 1.0)
    with pytest.raises(CodecError, match="outside int32"):
        codec.encode_set("AC", 0, 2**31)
    with pytest.raises(CodecError, match="too large for float32"):
        codec.encode_set("CL", 1, 1e39)
    with pytest.raises(CodecError, match="not a finite number"):
        codec.encode_set("CL", 1, float("nan"))
    with pytest.raises(CodecError, match="must be a number"):
        codec.encode_set("AC", 0, True)


def test_a_non_finite_float_reply_still_fails_after_its_header_was_cached():
    codec._clear_caches()
    ok = codec.encode_reply("CL", 1, 1.5, True)
    assert codec.decode_reply(ok).value == 1.5
    with pytest.raises(CodecError, match="not a finite number"):
        codec.decode_reply(ok[:4] + struct.pack("<f", float("inf")))


def test_caches_stop_growing_at_their_limit_and_answers_stay_right():
    codec._clear_caches()
    frames = [codec.encode_reply("ET", index, index, False) for index in range(codec._CACHE_LIMIT + 500)]
    for index, frame in enumerate(frames):
        assert codec.decode_reply(frame) == codec.Reply("ET", index, index, False)
    assert len(codec._INT_REPLIES) == codec._CACHE_LIMIT
    assert codec.decode_reply(frames[-1]) == codec.Reply("ET", len(frames) - 1, len(frames) - 1, False)
