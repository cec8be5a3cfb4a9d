"""The test transport itself (SHERPA_TEST_BUS): the arm fixtures behave the same on every bus.

Run on vcan with the CI stage (.ci/vcan-stage.sh) and over python-can-remote with
`SHERPA_TEST_BUS=remote python -m pytest -m realbus`; see docs/testing.md.
"""

from __future__ import annotations

import json

import pytest
from arm_harness import TestBus, parse_test_bus


@pytest.mark.golden
@pytest.mark.realbus
def test_console_script_in_its_own_process_gives_the_in_process_golden(arm_console, golden):
    # the same golden file as tests/test_cmd.py's in-process run of the same command
    result = arm_console("cmd", "shoulder_1a", "PX", "LL[3]", "MF", "SR", "IP", "IL[1]", "EC")
    assert "Traceback" not in result.stderr
    golden("cmd-sim-queries.txt", result.transcript())


def _ac(arm_cli) -> int:
    result = arm_cli("--json", "cmd", "shoulder_1a", "AC")
    assert result.exit_code == 0, result.transcript()
    return json.loads(result.stdout)["results"][0]["value"]


@pytest.mark.realbus
def test_every_command_meets_a_power_cycled_arm_and_flash_persists_within_a_test(arm_cli):
    assert _ac(arm_cli) == 100000  # factory flash, even if an earlier test saved
    assert arm_cli("cmd", "shoulder_1a", "AC=120000", "--apply").exit_code == 0
    assert _ac(arm_cli) == 100000, "RAM survived between two commands: the arm was not power-cycled"
    assert arm_cli("cmd", "shoulder_1a", "AC=150000", "SV", "--apply", "--raw-save").exit_code == 0
    assert _ac(arm_cli) == 150000, "what SV saved is gone after a power cycle"


@pytest.mark.realbus
def test_the_next_test_starts_with_factory_flash(arm_cli):
    # runs after the test above (file order), which saved AC=150000
    assert _ac(arm_cli) == 100000


@pytest.mark.parametrize("text,expected", [
    (None, TestBus("virtual")),
    ("virtual", TestBus("virtual")),
    (" remote ", TestBus("remote")),
    ("socketcan:vcan0,vcan1,vcan2", TestBus("socketcan", ("vcan0", "vcan1", "vcan2"))),
    ("socketcan:can0", TestBus("socketcan", ("can0",))),
])
def test_test_bus_values(text, expected):
    assert parse_test_bus(text) == expected


@pytest.mark.parametrize("text", ["vcan", "socketcan", "socketcan:", "socketcan:vcan0,,vcan2", "udp_multicast",
                                  "remote:127.0.0.1:5000"])
def test_test_bus_rejects_anything_else_by_name(text):
    with pytest.raises(ValueError, match=r"SHERPA_TEST_BUS=.*expected virtual, remote or socketcan:IF,IF,IF"):
        parse_test_bus(text)


@pytest.mark.parametrize("args", [("--config", "configs/appendix-c/example1.yaml", "cmd", "drive1", "PX"),
                                  ("--bus-map=can0=virtual:x", "cmd", "shoulder_1a", "PX"),
                                  ("--sim", "cmd", "shoulder_1a", "PX")])
def test_arm_cli_refuses_options_that_would_test_another_arm(arm_cli, args):
    with pytest.raises(pytest.fail.Exception, match="arm_cli's own"):
        arm_cli(*args)
