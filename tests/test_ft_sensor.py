"""The ATI Net F/T CAN codec (sherpa_cli/devices/ft_sensor.py): byte-exact frame transcripts, the
two-frame reply in N and N·m, status word, and the reader's bounded wait on an injected clock."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.devices import ft_sensor as ft
from sherpa_cli.errors import CommunicationError, DriveTimeoutError, ProtocolError

BASE = 0x1B0
CAL = ft.Calibration(counts_per_force=64.0, counts_per_torque=1000.0)
int16 = st.integers(min_value=-0x8000, max_value=0x7FFF)
word = st.integers(min_value=0, max_value=0xFFFF)
raw_samples = st.builds(ft.RawSample, int16, int16, int16, int16, int16, int16, word, word)


# -- transcripts -----------------------------------------------------------------------------------

def test_request_and_bias_are_one_byte_frames_to_the_base_id():
    assert str(ft.request_frame(BASE)) == "1B0#02"
    assert str(ft.bias_frame(BASE)) == "1B0#04"
    assert ft.sensor_ids(BASE) == (0x1B0, 0x1B5, 0x1B6)


def test_two_frame_reply_transcript_decodes_to_newtons():
    # Fx=100, Tx=-2000, Fy=-1, Ty=500 | Fz=-640, Tz=32767, status 0, sample 0x1234
    forces = ft.Frame(0x1B5, bytes.fromhex("6400 30F8 FFFF F401".replace(" ", "")))
    status = ft.Frame(0x1B6, bytes.fromhex("80FD FF7F 0000 3412".replace(" ", "")))
    raw = ft.decode_reply(BASE, forces, status)
    assert raw == ft.RawSample(fx=100, tx=-2000, fy=-1, ty=500, fz=-640, tz=32767, status=0, sample=0x1234)
    w = ft.to_wrench(raw, CAL, frame="wrist_ft")
    assert (w.fx, w.fy, w.fz) == (100 / 64, -1 / 64, -10.0)
    assert (w.tx, w.ty, w.tz) == (-2.0, 0.5, 32.767)
    assert w.status.ok and str(w.status) == "ok" and w.sample == 0x1234 and w.frame == "wrist_ft"
    assert ft.encode_reply(BASE, raw) == (forces, status)
    assert [str(f) for f in ft.encode_reply(BASE, raw)] == ["1B5#640030F8FFFFF401", "1B6#80FDFF7F00003412"]


def test_error_status_transcript():
    status = ft.Frame(0x1B6, bytes.fromhex("0000000001800700"))
    raw = ft.decode_reply(BASE, ft.Frame(0x1B5, bytes(8)), status)
    assert raw.status == 0x8001 and raw.sample == 7
    word = ft.StatusWord(raw.status)
    assert not word.ok and word.bits == (0, 15) and str(word) == "0x8001 (bits 0,15)"


@pytest.mark.parametrize(("forces", "status", "names"), [
    (ft.Frame(0x1B5, bytes(7)), ft.Frame(0x1B6, bytes(8)), "Fx/Tx/Fy/Ty frame 0x1B5 (base+5) has 7 data bytes"),
    (ft.Frame(0x1B5, bytes(8)), ft.Frame(0x1B6, bytes(2)), "Fz/Tz/status frame 0x1B6 (base+6) has 2 data bytes"),
    (ft.Frame(0x1B6, bytes(8)), ft.Frame(0x1B6, bytes(8)), "Fx/Tx/Fy/Ty frame (base+5) expected on id 0x1B5, got id 0x1B6"),
])
def test_bad_frames_raise_one_error_naming_the_frame(forces, status, names):
    with pytest.raises(ProtocolError) as err:
        ft.decode_reply(BASE, forces, status)
    assert names in str(err.value)


@pytest.mark.parametrize("base", [-1, 0x7FA])
def test_a_base_id_whose_replies_leave_11_bits_is_refused(base):
    with pytest.raises(ValueError, match="base id"):
        ft.request_frame(base)


# -- properties ------------------------------------------------------------------------------------

@given(raw_samples, st.integers(min_value=0, max_value=ft.MAX_BASE_ID))
def test_encode_decode_round_trip(raw, base):
    forces, status = ft.encode_reply(base, raw)
    assert (forces.can_id, status.can_id) == (base + 5, base + 6)
    assert len(forces.data) == len(status.data) == 8
    assert ft.decode_reply(base, forces, status) == raw


@given(raw_samples)
def test_signs_survive_the_conversion_to_si_and_back(raw):
    w = ft.to_wrench(raw, CAL)
    for counts, value in ((raw.fx, w.fx), (raw.fy, w.fy), (raw.fz, w.fz), (raw.tx, w.tx), (raw.ty, w.ty),
                          (raw.tz, w.tz)):
        assert math.copysign(1, value) == math.copysign(1, counts) or counts == 0
    assert ft.to_raw(w, CAL) == raw


@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False))
def test_si_beyond_int16_saturates(value):
    raw = ft.to_raw(ft.Wrench(value, 0, 0, value, 0, 0), CAL)
    assert -0x8000 <= raw.fx <= 0x7FFF and -0x8000 <= raw.tx <= 0x7FFF
    assert raw.fx == max(-0x8000, min(0x7FFF, round(value * 64)))


@given(st.binary(max_size=12), st.binary(max_size=12))
def test_any_wrong_length_is_a_protocol_error_never_a_struct_error(a, b):
    forces, status = ft.Frame(BASE + 5, a), ft.Frame(BASE + 6, b)
    if len(a) == len(b) == 8:
        ft.decode_reply(BASE, forces, status)
    else:
        with pytest.raises(ProtocolError, match="data bytes, expected 8"):
            ft.decode_reply(BASE, forces, status)


def test_norms():
    w = ft.Wrench(3, 4, 0, 0, 0, -2)
    assert w.force == 5 and w.torque == 2


def test_calibration_must_be_positive():
    with pytest.raises(ValueError):
        ft.Calibration(0, 1)


# -- the reader -----------------------------------------------------------------------------------

class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class ScriptedPort:
    """Answers each request with the scripted frames; every receive takes ``step`` s of fake time."""

    def __init__(self, clock: FakeClock, replies: list[list[ft.Frame]], step: float = 0.01) -> None:
        self.clock, self.replies, self.step = clock, replies, step
        self.sent: list[ft.Frame] = []
        self.queue: list[ft.Frame] = []

    def send(self, frame: ft.Frame) -> None:
        self.sent.append(frame)
        if frame.data == bytes([ft.REQUEST_SHORT]) and self.replies:
            self.queue = list(self.replies.pop(0))

    def receive(self, ids: frozenset[int], timeout: float) -> ft.Frame | None:
        while self.queue:
            frame = self.queue.pop(0)
            if frame.can_id in ids:
                self.clock.t += self.step
                return frame
        self.clock.t += min(timeout, self.step)
        return None


def test_reader_requests_and_decodes_one_sample():
    clock = FakeClock()
    raw = ft.RawSample(64, 0, 0, 0, -128, 1000, 0, 3)
    port = ScriptedPort(clock, [list(ft.encode_reply(BASE, raw))])
    w = ft.FtReader(port, BASE, CAL, frame="wrist", clock=clock).read()
    assert [str(f) for f in port.sent] == ["1B0#02"]
    assert (w.fx, w.fz, w.tz, w.sample, w.frame) == (1.0, -2.0, 1.0, 3, "wrist")


def test_reader_drops_a_status_frame_without_its_force_frame():
    clock = FakeClock()
    old = ft.encode_reply(BASE, ft.RawSample(1, 1, 1, 1, 1, 1, 0, 1))
    new = ft.encode_reply(BASE, ft.RawSample(64, 0, 0, 0, 0, 0, 0, 2))
    port = ScriptedPort(clock, [[old[1], ft.Frame(0x181, bytes(8)), *new]])
    assert ft.FtReader(port, BASE, CAL, clock=clock).read().sample == 2


@pytest.mark.parametrize(("reply", "said"), [([], "no reply"), ([0], "only the base+5 frame")])
def test_a_silent_sensor_times_out_after_the_bound(reply, said):
    clock = FakeClock()
    frames = ft.encode_reply(BASE, ft.RawSample(0, 0, 0, 0, 0, 0, 0, 0))
    port = ScriptedPort(clock, [[frames[i] for i in reply]])
    with pytest.raises(DriveTimeoutError, match=re.escape(f"{said} within 50 ms")) as err:
        ft.FtReader(port, BASE, CAL, wait_s=0.05, clock=clock).read()
    assert 0.05 <= clock.t <= 0.05 + 0.01 + 1e-9
    assert isinstance(err.value, CommunicationError)


def test_reader_bias_sends_the_bias_frame():
    port = ScriptedPort(FakeClock(), [])
    ft.FtReader(port, BASE, CAL).bias()
    assert [str(f) for f in port.sent] == ["1B0#04"]
