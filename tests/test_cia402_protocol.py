"""CiA 402's codec and power state machine (sherpa_cli/cia402/protocol.py): exact and hypothesis."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.cia402 import protocol as p
from sherpa_cli.cia402.protocol import Command, State


@pytest.mark.parametrize(("statusword", "state"), [
    (0x0000, State.NOT_READY_TO_SWITCH_ON), (0x0040, State.SWITCH_ON_DISABLED), (0x0250, State.SWITCH_ON_DISABLED),
    (0x0021, State.READY_TO_SWITCH_ON), (0x0031, State.READY_TO_SWITCH_ON), (0x0023, State.SWITCHED_ON),
    (0x0027, State.OPERATION_ENABLED), (0x1637, State.OPERATION_ENABLED), (0x0007, State.QUICK_STOP_ACTIVE),
    (0x000F, State.FAULT_REACTION_ACTIVE), (0x0008, State.FAULT), (0x0228, State.FAULT),
    (0x0001, None), (0x0061, None), (0x0048, None),
])
def test_statusword_to_state_exact(statusword, state):
    assert p.state_of(statusword) is state


@pytest.mark.parametrize(("controlword", "command"), [
    (0x06, "shutdown"), (0x0E, "shutdown"), (0x07, "switch on"), (0x0F, "enable operation"), (0x1F, "enable operation"),
    (0x010F, "enable operation"), (0x00, "disable voltage"), (0x0D, "disable voltage"), (0x02, "quick stop"),
    (0x0B, "quick stop"), (0x80, "fault reset"), (0x8F, "fault reset"),
])
def test_controlword_commands_exact(controlword, command):
    assert p.command_of(controlword) == command


@pytest.mark.parametrize(("state", "controlword", "after"), [
    (State.SWITCH_ON_DISABLED, 0x06, State.READY_TO_SWITCH_ON),  # 2
    (State.READY_TO_SWITCH_ON, 0x07, State.SWITCHED_ON),  # 3
    (State.SWITCHED_ON, 0x0F, State.OPERATION_ENABLED),  # 4
    (State.OPERATION_ENABLED, 0x07, State.SWITCHED_ON),  # 5
    (State.SWITCHED_ON, 0x06, State.READY_TO_SWITCH_ON),  # 6
    (State.READY_TO_SWITCH_ON, 0x00, State.SWITCH_ON_DISABLED),  # 7
    (State.READY_TO_SWITCH_ON, 0x02, State.SWITCH_ON_DISABLED),  # 7
    (State.OPERATION_ENABLED, 0x06, State.READY_TO_SWITCH_ON),  # 8
    (State.OPERATION_ENABLED, 0x00, State.SWITCH_ON_DISABLED),  # 9
    (State.SWITCHED_ON, 0x00, State.SWITCH_ON_DISABLED),  # 10
    (State.OPERATION_ENABLED, 0x02, State.QUICK_STOP_ACTIVE),  # 11
    (State.QUICK_STOP_ACTIVE, 0x00, State.SWITCH_ON_DISABLED),  # 12
    (State.QUICK_STOP_ACTIVE, 0x0F, State.QUICK_STOP_ACTIVE),  # 16 is optional: not taken
    (State.FAULT, 0x80, State.SWITCH_ON_DISABLED),  # 15
    (State.FAULT, 0x0F, State.FAULT),
    (State.SWITCH_ON_DISABLED, 0x0F, State.SWITCH_ON_DISABLED),
])
def test_transitions_exact(state, controlword, after):
    assert p.transition(state, controlword) is after


def test_fault_reset_needs_the_rising_edge():
    assert p.transition(State.FAULT, 0x80, fault_reset_edge=False) is State.FAULT


def test_next_command_exact():
    oe, rtso = State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON
    assert p.next_command(State.SWITCH_ON_DISABLED, oe) is Command.SHUTDOWN
    assert p.next_command(rtso, oe) is Command.SWITCH_ON
    assert p.next_command(State.SWITCHED_ON, oe) is Command.ENABLE_OPERATION
    assert p.next_command(oe, oe) is None
    assert p.next_command(State.FAULT, oe) is Command.FAULT_RESET
    assert p.next_command(State.QUICK_STOP_ACTIVE, oe) is Command.DISABLE_VOLTAGE
    assert p.next_command(oe, rtso) is Command.SHUTDOWN
    assert p.next_command(State.NOT_READY_TO_SWITCH_ON, oe) is None
    with pytest.raises(ValueError, match="no path to Fault"):
        p.next_command(oe, State.FAULT)


@given(st.sampled_from(list(State)), st.sampled_from([State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON]))
def test_every_state_reaches_the_goal_in_four_commands(start, goal):
    state, commands = start, 0
    while True:
        state = p.settle(state)
        command = p.next_command(state, goal)
        if command is None:
            break
        state = p.transition(state, int(command))
        commands += 1
        assert commands <= 4, f"{start} -> {goal}: no arrival in 4 commands"
    assert state is goal


@given(st.sampled_from(list(State)), st.integers(0, 0xFFFF))
def test_statusword_round_trip(state, noise):
    word = p.statusword_of(state)
    assert p.state_of(word) is state
    mask, _ = p.STATE_BITS[state]
    assert p.state_of(word & mask | noise & ~mask & 0xFFFF) is state  # the bits outside the mask do not matter


@given(st.integers(0, 0xFFFF))
def test_at_most_one_state_per_statusword(word):
    matching = [s for s, (mask, value) in p.STATE_BITS.items() if word & mask == value]
    assert len(matching) <= 1
    assert p.state_of(word) is (matching[0] if matching else None)


@given(st.sampled_from(sorted(p.FORMATS)), st.data())
def test_object_codec_round_trip(index, data):
    fmt = p.FORMATS[index]
    bits = {"b": 8, "h": 16, "i": 32, "B": 8, "H": 16, "I": 32}[fmt[1]]
    lo, hi = (-(1 << bits - 1), (1 << bits - 1) - 1) if fmt[1].islower() else (0, (1 << bits) - 1)
    value = data.draw(st.integers(lo, hi))
    raw = p.encode(index, value)
    assert len(raw) == bits // 8
    assert p.decode(index, raw) == value


def test_codec_exact():
    assert p.encode(p.CONTROLWORD, 0x1F) == b"\x1f\x00"
    assert p.encode(p.TARGET_POSITION, -2) == b"\xfe\xff\xff\xff"
    assert p.encode(p.MODES_OF_OPERATION, 3) == b"\x03"
    assert p.decode(p.STATUSWORD, b"\x37\x16") == 0x1637
    with pytest.raises(ValueError, match=r"0x6041 \(statusword\): 1 bytes, expected 2"):
        p.decode(p.STATUSWORD, b"\x37")


@pytest.mark.parametrize(("code", "text"), [
    (0x8130, "0x8130 life guard error or heartbeat error"), (0x2310, "0x2310 continuous over-current"),
    (0x3211, "0x3211 voltage error"), (0xFF12, "0xFF12 device specific (see the drive's manual)"),
    (0xB000, "0xB000 unknown error"), (0x0000, "0x0000 no error"),
])
def test_error_codes(code, text):
    assert str(p.decode_error(code)) == text


@given(st.integers(0, 0xFFFF))
def test_every_error_code_decodes(code):
    decoded = p.decode_error(code)
    assert decoded.code == code and decoded.text
