"""The compiled front doors (sherpa_cli/elmo/_codec_c.c) answer exactly as the pure codec does.

Every case is asked of both implementations with the caches in the same state, cold and then
warm, and the outcomes (bytes, Reply fields and their types, CodecError texts) must be equal.
The module must be built: CI and the README's install compile it. SHERPA_PURE_CODEC=1 is the
explicit way to test the pure codec alone (a machine without a C compiler).
"""

from __future__ import annotations

import gc
import os
import pickle
import struct
import subprocess
import sys
import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sherpa_cli.elmo import codec
from sherpa_cli.errors import CodecError

from test_codec_fast_paths import FRAMES, INDEX, LETTERS, VALUE

if os.environ.get("SHERPA_PURE_CODEC", "") not in ("", "0"):
    pytest.skip("SHERPA_PURE_CODEC is set: the compiled codec is off on purpose", allow_module_level=True)


def test_the_compiled_codec_is_built_and_in_use():
    assert codec.IMPLEMENTATION == "compiled", (
        "sherpa_cli/elmo/_codec_c.c was not built: install with a C compiler (pip install -e .), "
        "or set SHERPA_PURE_CODEC=1 to test the pure codec alone")
    assert codec.encode_set is not codec.pure_encode_set
    assert type(codec.decode_reply).__name__ == "builtin_function_or_method"


def detailed(fn, *args):
    """The outcome with the types a plain == would gloss over (1 == 1.0 == True)."""
    try:
        result = fn(*args)
    except CodecError as exc:
        return ("error", exc.message, exc.hint)
    if isinstance(result, tuple):
        return ("ok", type(result), tuple((field, type(field)) for field in result))
    return ("ok", type(result), result)


def both_ways(pure, compiled, args, *warmers):
    answers = []
    for fn in (pure, compiled):
        codec._clear_caches()
        cold = detailed(fn, *args)
        for warm_args in warmers:
            detailed(fn, *warm_args)
        answers.append((cold, detailed(fn, *args), detailed(fn, *args)))
    return answers


@settings(max_examples=500)
@given(LETTERS, INDEX, VALUE)
def test_encode_set_equals_the_pure_one(letters, index, value):
    neighbour = index if type(index) is int else 0
    pure, compiled = both_ways(codec.pure_encode_set, codec.encode_set, (letters, index, value),
                               (letters, neighbour, 1), (letters, neighbour, 1.5))
    assert compiled == pure


@settings(max_examples=500)
@given(FRAMES, st.sampled_from([bytes, bytearray, memoryview]))
def test_decode_reply_equals_the_pure_one(frame, kind):
    pure, compiled = both_ways(codec.pure_decode_reply, codec.decode_reply, (kind(frame),),
                               (frame[:4] + bytes(4),))
    assert compiled == pure


@settings(max_examples=300)
@given(st.sampled_from(sorted(codec.COMMANDS)), st.integers(0, 0x3FFF),
       st.one_of(st.integers(-(2**31), 2**31 - 1), st.floats(width=32, allow_nan=False, allow_infinity=False)))
def test_every_reply_value_survives_the_compiled_decoder(letters, index, value):
    is_float = isinstance(value, float)
    frame = codec.encode_reply(letters, index, value, is_float)
    codec.decode_reply(frame)  # first call fills the header cache
    reply = codec.decode_reply(frame)
    assert reply == codec.Reply(letters, index, value, is_float)
    assert type(reply.value) is type(value) and (reply.ok, reply.error_text) == (True, None)


def test_compiled_replies_are_real_reply_tuples():
    frame = bytes.fromhex("43 4C 01 80 00 00 C0 3F")
    codec.decode_reply(frame)
    reply = codec.decode_reply(frame)
    assert type(reply) is codec.Reply
    assert reply == ("CL", 1, 1.5, True, None) and hash(reply) == hash(("CL", 1, 1.5, True, None))
    assert repr(reply) == "Reply(letters='CL', index=1, value=1.5, is_float=True, error_code=None)"
    assert reply._asdict()["value"] == 1.5 and reply._replace(value=2.0).value == 2.0
    assert pickle.loads(pickle.dumps(reply)) == reply
    assert gc.is_tracked(reply)


@pytest.mark.parametrize("pure, compiled, args, kwargs", [
    ("pure_encode_set", "encode_set", (), {"letters": "AC", "index": 0, "value": 150000}),
    ("pure_encode_set", "encode_set", ("AC", 0), {}),
    ("pure_encode_set", "encode_set", ("AC", 0, 1, 2), {}),
    ("pure_decode_reply", "decode_reply", (), {"data": bytes.fromhex("41 43 00 00 F0 49 02 00")}),
    ("pure_decode_reply", "decode_reply", (), {}),
    ("pure_decode_reply", "decode_reply", (bytes(8), 1), {}),
])
def test_keywords_and_bad_arity_answer_as_the_pure_function(pure, compiled, args, kwargs):
    def run(fn):
        try:
            return ("ok", fn(*args, **kwargs))
        except (TypeError, CodecError) as exc:
            return (type(exc).__name__, str(exc))

    assert run(getattr(codec, compiled)) == run(getattr(codec, pure))


class _RaisingEq(str):
    """A cache key that cannot be compared once armed: the pure path then checks instead of failing."""

    armed = False
    __hash__ = str.__hash__

    def __eq__(self, other):
        if _RaisingEq.armed:
            raise TypeError("cannot compare")
        return str.__eq__(self, other)


@pytest.mark.parametrize("name", ["pure_encode_set", "encode_set"])
def test_a_cache_lookup_that_raises_falls_back_to_the_checked_path(name):
    fn = getattr(codec, name)
    codec._clear_caches()
    try:
        fn(_RaisingEq("AC"), 0, 1)  # caches the key ("AC" as the subclass, 0)
        _RaisingEq.armed = True
        assert fn("AC", 0, 5) == bytes.fromhex("41 43 00 00 05 00 00 00")
    finally:
        _RaisingEq.armed = False
        codec._clear_caches()


def test_a_rebind_by_a_finalizer_during_a_call_frees_nothing_the_call_reads():
    compiled = codec._compiled
    ran = []

    class Rebind:
        def __init__(self):
            self.cycle = self  # only the cycle collector frees it, at an allocation inside the call

        def __del__(self):
            ran.append(len(ran))
            compiled.bind({}, {}, {}, {}, codec.Reply, codec.pure_encode_set, codec.pure_decode_reply)
            # reuse the freed dicts' memory with a header that would show if it were read
            ran.append([{("AC", 0): b"XX\xff\xff"} for _ in range(50)])

    threshold = gc.get_threshold()
    try:
        compiled.bind({("AC", 0): b"AC\x00\x00"}, {}, {}, {}, codec.Reply, codec.pure_encode_set,
                      codec.pure_decode_reply)  # the only reference to these dicts is the module's
        gc.collect()
        gc.disable()
        gc.set_threshold(1)
        Rebind()
        pending = [(i, -i) for i in range(5000)]  # noqa: F841  # over the threshold: the next allocation collects
        gc.enable()
        frame = compiled.encode_set("AC", 0, 1)
    finally:
        gc.enable()
        gc.set_threshold(*threshold)
        compiled.bind(codec._INT_SETS, codec._FLOAT_SETS, codec._INT_REPLIES, codec._FLOAT_REPLIES, codec.Reply,
                      codec.pure_encode_set, codec.pure_decode_reply)
    if not ran:
        pytest.skip("the collector did not run inside the call on this interpreter")
    assert frame == bytes.fromhex("41 43 00 00 01 00 00 00")


def test_a_function_unpickled_in_a_fresh_process_binds_itself():
    blob = pickle.dumps((codec.decode_reply, codec.encode_set))
    script = ("import pickle, sys; decode, encode = pickle.loads(sys.stdin.buffer.read()); "
              "print(decode(bytes.fromhex('41 43 00 00 F0 49 02 00')).value, encode('AC', 0, 7).hex())")
    out = subprocess.run([sys.executable, "-c", script], input=blob, capture_output=True, check=True)
    assert out.stdout.decode().split() == ["150000", "41430000" "07000000"]


def test_bind_refuses_what_it_cannot_use():
    compiled = codec._compiled
    with pytest.raises(TypeError):
        compiled.bind({}, {}, {}, {}, dict, codec.pure_encode_set, codec.pure_decode_reply)  # not a tuple type
    with pytest.raises(TypeError):
        compiled.bind({}, {}, {}, {}, codec.Reply, None, codec.pure_decode_reply)
    with pytest.raises(TypeError):
        compiled.bind([], {}, {}, {}, codec.Reply, codec.pure_encode_set, codec.pure_decode_reply)
    assert codec.decode_reply(bytes.fromhex("41 43 00 00 F0 49 02 00")).value == 150000  # still bound as before


def _hot_loop(n: int) -> None:
    encode_set, decode_reply = codec.encode_set, codec.decode_reply
    replies = [codec.encode_reply("ET", 992, 150000, False), codec.encode_reply("CL", 1, 1.5, True)]
    for i in range(n):
        encode_set("AC", 0, i)
        encode_set("CL", 1, 0.25)
        decode_reply(replies[i & 1])


def test_the_hot_paths_leak_neither_references_nor_memory():
    codec._clear_caches()
    _hot_loop(1000)
    # ET[992]: an index above the small-int cache, so its count is the caches' and the replies' alone
    letters, index = codec._INT_REPLIES[struct.unpack("<I", b"ET\xe0\x03")[0]]
    header = codec._INT_SETS[("AC", 0)]
    before = (sys.getrefcount(letters), sys.getrefcount(index), sys.getrefcount(header))
    tracemalloc.start()
    try:
        _hot_loop(1000)
        gc.collect()
        start = tracemalloc.get_traced_memory()[0]
        _hot_loop(50_000)
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - start
    finally:
        tracemalloc.stop()
    assert (sys.getrefcount(letters), sys.getrefcount(index), sys.getrefcount(header)) == before
    assert grown < 64 * 1024, f"150,000 calls kept {grown} bytes"


def test_SHERPA_PURE_CODEC_selects_the_pure_functions():
    out = subprocess.run([sys.executable, "-c", "from sherpa_cli.elmo import codec; "
                          "print(codec.IMPLEMENTATION, codec.encode_set is codec.pure_encode_set)"],
                         env={**os.environ, "SHERPA_PURE_CODEC": "1"}, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["pure", "Python", "True"]


def test_a_subinterpreter_binds_its_own_module_state():
    interpreters = pytest.importorskip("_xxsubinterpreters", reason="CPython's private subinterpreter module")
    frame = bytes.fromhex("41 43 00 00 F0 49 02 00")
    codec.decode_reply(frame)
    sub = interpreters.create()
    try:
        interpreters.run_string(sub, "from sherpa_cli.elmo import codec\n"
                                     "codec.decode_reply(bytes.fromhex('41 43 00 00 01 00 00 00'))")
        assert type(codec.decode_reply(frame)) is codec.Reply  # not the subinterpreter's Reply
    finally:
        interpreters.destroy(sub)
    assert codec.decode_reply(frame) == codec.Reply("AC", 0, 150000, False)
    assert codec.encode_set("AC", 0, 7) == bytes.fromhex("41 43 00 00 07 00 00 00")
