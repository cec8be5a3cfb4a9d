"""Ports are range-checked where they are parsed: `sim --serve HOST:PORT` serves
bus i on PORT + i, so PORT plus the number of buses must fit in 1..65535; a remote bus of
--bus-map names a port 1..65535. One message naming the option and the bound, exit 2."""

from __future__ import annotations

import pytest

from sherpa_cli.bus.busmap import parse_bus_map
from sherpa_cli.errors import UsageError
from sherpa_cli.sim.serve import parse_host_port


@pytest.mark.parametrize("text, buses, expected", [
    ("127.0.0.1:65535", 1, ("127.0.0.1", 65535)),
    ("127.0.0.1:65533", 3, ("127.0.0.1", 65533)),
    ("127.0.0.1:1", 3, ("127.0.0.1", 1)),
    ("[::1]:54701", 3, ("::1", 54701)),
])
def test_ports_that_fit(text, buses, expected):
    assert parse_host_port(text, buses) == expected


@pytest.mark.parametrize("text, buses, bound", [
    ("127.0.0.1:65535", 3, "1..65533"),
    ("127.0.0.1:65534", 3, "1..65533"),
    ("127.0.0.1:65536", 1, "1..65535"),
    ("127.0.0.1:0", 1, "1..65535"),
    ("127.0.0.1:0", 3, "1..65533"),
    ("127.0.0.1:" + "9" * 40, 2, "1..65534"),
])
def test_ports_past_the_range_are_refused_naming_the_bound(text, buses, bound):
    with pytest.raises(UsageError) as info:
        parse_host_port(text, buses)
    assert str(info.value).startswith("--serve") and bound in str(info.value)


@pytest.mark.parametrize("text", ["127.0.0.1:\uff15\uff14\uff17\uff10\uff11", "127.0.0.1:-1", "127.0.0.1:+80", "127.0.0.1: 80"])
def test_ports_are_ascii_digits(text):
    with pytest.raises(UsageError, match="is not HOST:PORT"):
        parse_host_port(text, 1)


@pytest.mark.parametrize("port, bound", [("65535", "1..65533"), ("65534", "1..65533"), ("70000", "1..65533"),
                                         ("0", "1..65533")])
def test_sim_serve_past_the_last_port_is_one_message_and_exit_2(cli, port, bound):
    result = cli("sim", "--serve", f"127.0.0.1:{port}", "--duration", "0.1")  # the bundled arm: 3 buses
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr and "OverflowError" not in result.stderr
    first = result.stderr.splitlines()[0]
    assert first.startswith(f"error: --serve 127.0.0.1:{port}") and bound in first, result.transcript()
    assert "3 buses" in first


@pytest.mark.parametrize("spec", ["can0=remote:127.0.0.1:65536", "can0=remote:127.0.0.1:0",
                                  "can0=remote:127.0.0.1:\uff15\uff14\uff17\uff10\uff11", "can0=remote:ws://h:99999/x"])
def test_bus_map_remote_ports_are_checked(spec):
    with pytest.raises(UsageError, match=r"--bus-map: .*1\.\.65535"):
        parse_bus_map([spec])


@pytest.mark.parametrize("spec", ["can0=remote:127.0.0.1:54701", "can0=remote:ws://h:80/path", "can0=remote:h",
                                  "can0=socketcan:vcan0"])
def test_bus_map_good_targets_pass(spec):
    assert "can0" in parse_bus_map([spec])


def test_bus_map_bad_port_through_the_cli(cli):
    result = cli("--bus-map", "can0=remote:127.0.0.1:99999", "scan")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert result.stderr.startswith("error: --bus-map: 'can0=remote:127.0.0.1:99999'"), result.transcript()


def test_sim_in_process_puts_the_sigterm_handler_back(cli):
    """`sherpa sim` stops on SIGTERM while it serves; run in-process (tests, recipes) it must not leave
    its handler behind, or a later motion guard finds a stranger's handler instead of the process's."""
    import signal
    import uuid

    before = signal.getsignal(signal.SIGTERM)
    result = cli("--bus-map", f"can0=virtual:sigterm-{uuid.uuid4().hex[:8]}", "sim", "--duration", "0.05")
    assert result.exit_code == 0, result.transcript()
    assert signal.getsignal(signal.SIGTERM) is before
