"""The Linux CAN error-frame decoder (bus/errframes.py): exact decodes per class, the hints, the
simulated controller's frames, and that no input makes it raise."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.bus.errframes import (
    CAN_ERR_FLAG,
    HINTS,
    KINDS,
    decode_error_frame,
    encode_error_frame,
)
from sherpa_cli.config.simbus import SIM_ERROR_KINDS, SimBusConfig
from sherpa_cli.sim.buscontroller import BusController


def test_no_ack_with_counters():
    # what a node alone on the bus reports: CAN_ERR_ACK | CAN_ERR_BUSERROR | CAN_ERR_CNT, TEC 8
    f = decode_error_frame(0x2A0, bytes([0, 0, 0, 0, 0, 0, 8, 0]))
    assert f.kinds == ("no-ack",)
    assert f.details == ("no ACK on transmission",)
    assert (f.tec, f.rec) == (8, 0)
    assert f.hints == ("no ACK: is another node powered, is the bus terminated?",)
    assert f.summary == "no ACK on transmission (TEC 8, REC 0)"


def test_the_error_flag_in_the_id_is_ignored():
    assert decode_error_frame(CAN_ERR_FLAG | 0x020, bytes(8)).kinds == ("no-ack",)


@pytest.mark.parametrize(("prot", "loc", "kinds", "detail"), [
    (0x04, 0x0A, ("stuff",), "stuff error at data field"),
    (0x02, 0x19, ("form",), "form error at ACK slot"),
    (0x01 | 0x80, 0x02, ("bit",), "bit error at ID bits 28-21 (SFF 10-3) on transmit"),
    (0x08, 0x0E, ("bit",), "dominant bit not sent at ID bits 4-0"),
    (0x10, 0x0B, ("bit",), "recessive bit not sent at data length code"),
    (0x00, 0x08, ("crc",), "CRC error at CRC sequence"),
    (0x00, 0x18, ("crc",), "CRC error at CRC delimiter"),
    (0x00, 0x00, ("protocol",), "protocol violation (unspecified)"),
    (0x20, 0x12, ("overload",), "overload at intermission"),
    (0x06, 0x03, ("form", "stuff"), "form error at start of frame"),
])
def test_protocol_violations_with_their_location(prot, loc, kinds, detail):
    f = decode_error_frame(0x088, bytes([0, 0, prot, loc, 0, 0, 0, 0]))
    assert f.kinds == kinds
    assert f.details[0] == detail
    assert f.tec is None  # no CAN_ERR_CNT: bytes 6-7 are not counters


def test_stuff_and_form_share_the_bit_rate_hint():
    f = decode_error_frame(0x008, bytes([0, 0, 0x06, 0x0A, 0, 0, 0, 0]))
    assert f.hints == ("stuff/form errors: bit rate mismatch or wiring",)


@pytest.mark.parametrize(("ctrl", "kinds", "detail"), [
    (0x04, ("warning",), "controller: error-warning (RX)"),
    (0x08, ("warning",), "controller: error-warning (TX)"),
    (0x0C, ("warning",), "controller: error-warning (TX/RX)"),
    (0x10, ("passive",), "controller: error-passive (RX)"),
    (0x20, ("passive",), "controller: error-passive (TX)"),
    (0x40, ("active",), "controller: back to error-active"),
    (0x01, ("rx-overflow",), "controller: RX buffer overflow"),
    (0x02, ("tx-overflow",), "controller: TX buffer overflow"),
])
def test_controller_status(ctrl, kinds, detail):
    f = decode_error_frame(0x204, bytes([0, ctrl, 0, 0, 0, 0, 100, 3]))
    assert f.kinds == kinds
    assert f.details == (detail,)
    assert (f.tec, f.rec) == (100, 3)


def test_bus_off_restarted_lost_arbitration_transceiver_timeout():
    assert decode_error_frame(0x040, bytes(8)).details == ("bus-off",)
    assert decode_error_frame(0x100, bytes(8)).details == ("controller restarted",)
    assert decode_error_frame(0x002, bytes([7, 0, 0, 0, 0, 0, 0, 0])).details == ("lost arbitration at bit 7",)
    assert decode_error_frame(0x010, bytes([0, 0, 0, 0, 0x70, 0, 0, 0])).details == ("transceiver: CANL short to GND",)
    assert decode_error_frame(0x001, bytes(8)).details == ("TX timeout",)
    assert decode_error_frame(0x040, bytes(8)).hints[0].startswith("bus-off: the controller stopped sending")


def test_bus_error_alone_asks_for_berr_reporting_beside_a_class_it_is_dropped():
    assert decode_error_frame(0x080, bytes(8)).kinds == ("bus-error",)
    assert decode_error_frame(0x088, bytes([0, 0, 0x04, 0x0A, 0, 0, 0, 0])).kinds == ("stuff",)


def test_several_classes_in_one_frame_keep_a_fixed_order():
    f = decode_error_frame(0x004 | 0x008 | 0x020 | 0x200, bytes([0, 0x20, 0x04, 0x0A, 0, 0, 136, 0]))
    assert f.kinds == ("passive", "stuff", "no-ack")
    assert f.summary == ("controller: error-passive (TX); stuff error at data field; no ACK on transmission "
                         "(TEC 136, REC 0)")
    assert len(f.hints) == 3


def test_short_data_reads_as_zeros():
    assert decode_error_frame(0x204, b"\x00\x10").rec == 0


@pytest.mark.parametrize("kind", [k for k in KINDS if k != "bus-error"])
def test_encode_then_decode_names_the_kind(kind):
    cls, data = encode_error_frame([kind], tec=9, rec=1)
    f = decode_error_frame(cls, data)
    assert kind in f.kinds
    assert (f.tec, f.rec) == (9, 1)


def test_every_kind_has_a_hint_and_the_simulator_knows_the_same_kinds():
    assert set(HINTS) == set(KINDS)
    assert SIM_ERROR_KINDS == KINDS
    with pytest.raises(ValueError, match="unknown error kind"):
        encode_error_frame(["no-such"])


@given(st.integers(min_value=0, max_value=0x3FFFFFFF), st.binary(max_size=12))
def test_no_input_makes_the_decoder_raise(can_id, data):
    f = decode_error_frame(can_id, data)
    assert len(f.kinds) == len(f.details)
    assert all(k in KINDS for k in f.kinds)


@pytest.mark.parametrize(("kind", "expected"), [
    ("no-ack", ("no-ack",)), ("stuff", ("stuff",)), ("form", ("form",)), ("crc", ("crc",)), ("bit", ("bit",)),
    ("lost-arbitration", ("lost-arbitration",)), ("transceiver", ("transceiver",)),
    ("rx-overflow", ("rx-overflow",)), ("tx-timeout", ("tx-timeout",)),
])
def test_the_simulated_controller_sends_frames_the_decoder_names(kind, expected):
    ctrl = BusController("can0", SimBusConfig(), 1_000_000, now=0.0)
    ctrl.inject(kind)
    frames = ctrl.pop_frames()
    assert len(frames) == 1
    cls, data, is_error = frames[0]
    assert is_error
    assert decode_error_frame(cls, data).kinds == expected


def test_the_simulated_counters_walk_through_warning_passive_and_bus_off_then_restart():
    ctrl = BusController("can0", SimBusConfig(restart_ms=100), 1_000_000, now=0.0)
    seen = []
    for _ in range(40):
        ctrl.inject("bit")  # a TX error: TEC += 8
        seen += [decode_error_frame(c, d) for c, d, _e in ctrl.pop_frames()]
    states = [f.kinds[0] for f in seen if f.kinds[0] in ("warning", "passive", "bus-off")]
    assert states == ["warning", "passive", "bus-off"]
    assert ctrl.state == "BUS-OFF" and not ctrl.running
    assert ctrl.device_stats["bus_off"] == 1 and ctrl.device_stats["error_passive"] == 1
    ctrl.tick(0.05)
    assert ctrl.state == "BUS-OFF"
    ctrl.tick(0.1)
    assert ctrl.state == "ERROR-ACTIVE" and (ctrl.tec, ctrl.rec) == (0, 0)
    assert [decode_error_frame(c, d).kinds for c, d, _e in ctrl.pop_frames()] == [("restarted",)]
    assert ctrl.device_stats["restarts"] == 1


def test_no_ack_alone_stops_at_error_passive():
    ctrl = BusController("can0", SimBusConfig(), 1_000_000, now=0.0)
    for _ in range(100):
        ctrl.inject("no-ack")
    assert (ctrl.state, ctrl.tec) == ("ERROR-PASSIVE", 128)


def test_without_berr_reporting_bus_errors_send_no_frame_but_state_changes_do():
    ctrl = BusController("can0", SimBusConfig(berr_reporting=False), 1_000_000, now=0.0)
    for _ in range(12):
        ctrl.inject("no-ack")
    kinds = [decode_error_frame(c, d).kinds for c, d, _e in ctrl.pop_frames()]
    assert kinds == [("warning",)]
    assert ctrl.tec == 96
