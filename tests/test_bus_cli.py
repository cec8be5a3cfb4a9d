"""`sherpa bus status|watch|up|down` in-process: the simulated controllers in each state, netlink faked at
the seam (bus/netlink.py's Netlink) for the privilege and vcan paths, and this machine's real netlink
(no SocketCAN here: every configured interface is missing)."""

from __future__ import annotations

import errno
import json
import re
from pathlib import Path
from typing import Any

import pytest

from sherpa_cli.bus import linkstate
from sherpa_cli.bus.errwatch import BusWatch
from sherpa_cli.bus.linkstate import from_netlink
from sherpa_cli.bus.netlink import decode_link, parse_device_stats
from sherpa_cli.config.model import BusConfig

ARM = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"


def faulty(tmp_path: Path, sim: str) -> str:
    """The bundled arm with a `sim:` section appended."""
    path = tmp_path / "arm.yaml"
    path.write_text(ARM.read_text() + "\nsim:\n" + sim)
    return str(path)


# -- status -------------------------------------------------------------------------------------

@pytest.mark.golden
def test_status_of_the_healthy_simulated_arm(cli, golden):
    result = cli("--sim", "bus", "status", "--window", "0.1")
    assert result.exit_code == 0, result.transcript()
    golden("bus-status-sim.txt", result.transcript())


@pytest.mark.parametrize(("sim", "bus", "state", "text"), [
    ("  buses:\n    can1: {state: bus-off, restart_ms: 0}\n", "can1", "BUS-OFF", "the controller is BUS-OFF"),
    ("  buses:\n    can1: {state: error-passive}\n", "can1", "ERROR-PASSIVE", "the controller is ERROR-PASSIVE (TEC 136, REC 0)"),
    ("  buses:\n    can1: {state: error-warning}\n", "can1", "ERROR-WARNING", None),
    ("  buses:\n    can2: {bitrate: 500000}\n", "can2", "ERROR-ACTIVE", "bit rate 500000 differs from the config's 1000000"),
    ("  buses:\n    can2: {up: false}\n", "can2", "down", "the link is down"),
    ("  buses:\n    can2: {present: false}\n", "can2", "missing", "no interface can2"),
    ("  buses:\n    can0: {state: stopped}\n", "can0", "STOPPED", "the controller is STOPPED"),
])
def test_status_names_each_state(cli, tmp_path, sim, bus, state, text):
    result = cli("--sim", "--config", faulty(tmp_path, sim), "--json", "bus", "status", "--window", "0")
    doc = json.loads(result.stdout)
    row = next(b for b in doc["buses"] if b["bus"] == bus)
    assert row["state"] == state
    if text is None:
        assert result.exit_code == 0 and row["problems"] == []
    else:
        assert result.exit_code == 1
        assert any(text in p["text"] for p in row["problems"]), row["problems"]
        assert all(p["hint"] for p in row["problems"])
    plain = cli("--sim", "--config", faulty(tmp_path, sim), "bus", "status", "--window", "0")
    assert state in plain.stdout
    if text is not None:
        assert f"{bus}: {text}" in plain.stdout and "  fix: " in plain.stdout


def test_status_counts_the_errors_the_bus_had(cli, tmp_path):
    config = faulty(tmp_path, "  buses:\n    can1: {errors: [stuff], error_period: 0.01}\n")
    doc = json.loads(cli("--sim", "--config", config, "--json", "bus", "status", "--window", "0.1").stdout)
    row = next(b for b in doc["buses"] if b["bus"] == "can1")
    assert row["device_stats"]["bus_error"] >= 1
    assert row["rec"] >= 1 and row["stats"]["rx_errors"] == row["device_stats"]["bus_error"]


def test_status_without_socketcan_says_the_interface_is_missing(cli):
    # this machine's kernel has no CAN: pyroute2 finds no can0..can2 (a real netlink read, no privilege)
    result = cli("bus", "status", "--window", "0")
    assert result.exit_code == 1, result.transcript()
    assert result.stdout.count("missing") >= 3
    assert "can0: no interface can0" in result.stdout and "ip link show can0" in result.stdout
    assert "Traceback" not in result.stderr


def test_a_vcan_link_says_what_it_cannot_report():
    cfg = BusConfig("can0", "socketcan", "vcan0", 1_000_000)
    s = from_netlink(cfg, {"kind": "vcan", "up": True, "operstate": "UNKNOWN",
                           "stats": {"rx_packets": 1, "tx_packets": 2, "rx_bytes": 8, "tx_bytes": 16}})
    assert s.state == "up" and s.can_state is None and s.bitrate is None and not s.bitrate_mismatch
    assert s.not_reported["state"] == "not reported by vcan"
    assert s.not_reported["bitrate"] == "not reported by vcan"
    assert s.not_reported["berr_reporting"] == "not reported by vcan"
    assert "stats" not in s.not_reported


def test_python_can_state_only_where_the_backend_has_one():
    import can

    cfg = BusConfig("can0", "virtual", "x")
    with can.Bus(interface="virtual", channel="sherpa-test-state") as bus:
        s = linkstate.from_python_can(cfg, bus)
    assert s.can_state is None and s.not_reported["state"] == "not reported by virtual"

    class WithState(can.BusABC):
        def __init__(self) -> None:
            pass

        @property
        def state(self):
            return can.BusState.PASSIVE

        def send(self, msg, timeout=None):
            pass

        def _recv_internal(self, timeout):
            return None, False

    s = linkstate.from_python_can(cfg, WithState())
    assert s.can_state == "ERROR-PASSIVE" and "state" not in s.not_reported


def test_load_from_two_snapshots():
    before = {"rx_packets": 0, "tx_packets": 0, "rx_bytes": 0, "tx_bytes": 0}
    after = {"rx_packets": 1000, "tx_packets": 0, "rx_bytes": 8000, "tx_bytes": 0}
    # 1000 frames x (47 + 64) bits over 1 s at 1 Mbit/s
    assert linkstate.bus_load(before, after, 1.0, 1_000_000) == pytest.approx(0.111)
    assert linkstate.bus_load(before, None, 1.0, 1_000_000) is None
    assert linkstate.bus_load(before, after, 1.0, None) is None


def test_device_stats_and_a_pyroute2_shaped_message():
    raw = b"".join(n.to_bytes(4, "little") for n in (5, 1, 1, 1, 3, 1))
    assert parse_device_stats(raw.hex(":")) == {"bus_error": 5, "error_warning": 1, "error_passive": 1,
                                                "bus_off": 1, "arbitration_lost": 3, "restarts": 1}
    assert parse_device_stats("00:01") is None

    class Nla(dict):
        def get_attr(self, name: str) -> Any:
            return self.get(name)

    data = Nla(IFLA_CAN_STATE="ERROR_PASSIVE", IFLA_CAN_BERR_COUNTER={"txerr": 130, "rxerr": 2},
               IFLA_CAN_BITTIMING={"bitrate": 500000, "sample_point": 875}, IFLA_CAN_RESTART_MS=100,
               IFLA_CAN_CLOCK=80_000_000, IFLA_CAN_CTRLMODE=Nla(berr_reporting="on", one_shot="off"))
    info = Nla(IFLA_INFO_KIND="can", IFLA_INFO_DATA=data, IFLA_INFO_XSTATS=raw.hex(":"))
    msg = Nla(flags=0x1, IFLA_OPERSTATE="UP", IFLA_LINKINFO=info,
              IFLA_STATS64={"rx_packets": 10, "tx_packets": 4, "rx_bytes": 80, "tx_bytes": 32})
    figures = decode_link(msg)
    assert figures["can_state"] == "ERROR-PASSIVE" and (figures["tec"], figures["rec"]) == (130, 2)
    assert figures["bitrate"] == 500000 and figures["ctrlmode"]["berr_reporting"] is True
    s = from_netlink(BusConfig("can0", "socketcan", "can0", 1_000_000), figures)
    assert s.bitrate_mismatch and s.sample_point == 0.875 and s.device_stats["arbitration_lost"] == 3


def test_bad_inputs_of_bus_commands(cli):
    for args, code, text in [
        (("bus", "status", "can9"), 2, "unknown bus 'can9'"),
        (("bus", "status", "--window", "-1"), 2, "--window -1"),
        (("bus", "status", "--window", "nan"), 2, "--window nan"),
        (("bus", "watch", "--for", "0"), 2, "--for 0"),
        (("--json", "bus", "watch"), 2, "--json needs --for"),
        (("bus", "up", "--bitrate", "0"), 2, "--bitrate 0"),
        (("bus", "up", "--restart-ms", "-5"), 2, "--restart-ms -5"),
        (("bus", "up", "cn0"), 2, "did you mean 'can0'"),
    ]:
        result = cli("--sim", *args)
        assert result.exit_code == code, result.transcript()
        assert text in result.stderr and "Traceback" not in result.stderr


# -- up / down ------------------------------------------------------------------------------------

class FakeNetlink:
    """bus/netlink.py's Netlink seam: links by name; ``privileged`` False refuses changes like the kernel."""

    def __init__(self, links: dict[str, dict[str, Any]], *, privileged: bool = True) -> None:
        self.links = links
        self.privileged = privileged
        self.calls: list[tuple[str, dict[str, Any]]] = []

    def link(self, name: str) -> dict[str, Any] | None:
        return self.links.get(name)

    def set_link(self, name: str, **changes: Any) -> None:
        if not self.privileged:
            raise PermissionError(errno.EPERM, "Operation not permitted")
        if self.links[name].get("kind") != "can" and any(
                changes.get(k) is not None for k in ("bitrate", "restart_ms", "berr_reporting")):
            raise OSError(errno.EOPNOTSUPP, "Operation not supported")
        self.calls.append((name, {k: v for k, v in changes.items() if v is not None}))
        if changes.get("up") is not None:
            self.links[name]["up"] = changes["up"]


@pytest.fixture
def fake_netlink(monkeypatch):
    def install(links: dict[str, dict[str, Any]], **kw: Any) -> FakeNetlink:
        nl = FakeNetlink(links, **kw)
        monkeypatch.setattr(linkstate, "shared_netlink", lambda: nl)
        monkeypatch.setattr(linkstate, "unavailable_reason", lambda: None)
        return nl
    return install


CAN_LINKS = {f"can{i}": {"kind": "can", "up": False} for i in range(3)}


def test_up_without_cap_net_admin_names_the_capability_and_the_commands(cli, fake_netlink):
    nl = fake_netlink({k: dict(v) for k, v in CAN_LINKS.items()}, privileged=False)
    result = cli("bus", "up")
    assert result.exit_code == 6, result.transcript()
    assert "CAP_NET_ADMIN" in result.stderr and "nothing was changed" in result.stderr
    for i in range(3):
        assert f"ip link set can{i} type can bitrate 1000000 restart-ms 100 berr-reporting on" in result.stderr
        assert f"ip link set can{i} up" in result.stderr
    assert result.stderr.count("error:") == 1 and "Traceback" not in result.stderr
    assert nl.calls == []
    down = cli("bus", "down", "can1")
    assert down.exit_code == 6 and "ip link set can1 down" in down.stderr


def test_up_sets_bit_rate_restart_ms_and_berr_reporting_then_the_link(cli, fake_netlink):
    nl = fake_netlink({"can0": {"kind": "can", "up": True}, "can1": {"kind": "can", "up": False},
                       "can2": {"kind": "can", "up": False}})
    result = cli("bus", "up", "can0", "--bitrate", "500000", "--restart-ms", "50")
    assert result.exit_code == 0, result.transcript()
    assert nl.calls == [("can0", {"up": False}),
                        ("can0", {"bitrate": 500000, "restart_ms": 50, "berr_reporting": True}),
                        ("can0", {"up": True})]
    assert "can0 (can0): link down; bit rate 500000, restart-ms 50, berr-reporting on; link up" in result.stdout


def test_up_on_vcan_says_what_vcan_cannot_take(cli, fake_netlink):
    nl = fake_netlink({"vcan0": {"kind": "vcan", "up": False}})
    result = cli("--bus-map", "can0=socketcan:vcan0", "--json", "bus", "up", "can0")
    assert result.exit_code == 0, result.transcript()
    doc = json.loads(result.stdout)["buses"][0]
    assert doc["done"] == ["link up"]
    assert doc["not_taken"][0] == "bit rate (1000000 in the config): vcan has no CAN controller"
    assert nl.calls == [("vcan0", {"up": True})]


def test_up_of_a_missing_interface_and_of_a_non_socketcan_bus(cli, fake_netlink):
    fake_netlink({})
    result = cli("bus", "up", "can2")
    assert result.exit_code == 3 and "no interface can2" in result.stderr
    result = cli("--bus-map", "can2=remote:127.0.0.1:1", "bus", "up", "can2")
    assert result.exit_code == 2 and "set SocketCAN links only" in result.stderr


def test_up_and_down_on_the_simulated_controllers(cli, tmp_path):
    config = faulty(tmp_path, "  buses:\n    can1: {up: false, bitrate: 250000}\n")
    result = cli("--sim", "--config", config, "bus", "up", "can1")
    assert result.exit_code == 0, result.transcript()
    assert "bit rate 1000000" in result.stdout
    assert cli("--sim", "bus", "down", "can1").stdout == "can1 (can1): link down\n"


# -- watch ----------------------------------------------------------------------------------------

class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def test_watch_decodes_fed_frames_on_an_injected_clock():
    from sherpa_cli.bus.errframes import encode_error_frame
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config import load_config
    from sherpa_cli.ops.buswatch import watch
    from sherpa_cli.sim.arm import SimArm

    cfg = load_config(ARM)
    clock = FakeClock()
    feed = BusWatch()
    updates = []
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can1"]) as session:
        def step(s: float) -> None:
            if clock.t == 0.0:
                for kind in ("no-ack", "stuff", "passive", "bus-off", "restarted"):
                    cls, data = encode_error_frame([kind], tec=136, rec=0)
                    feed.feed("can1", cls, data, is_error=True)
            clock.sleep(s)

        result = watch(session, ["can1"], duration=1.0, interval=0.25, clock=clock, sleep=step,
                       bus_watch=feed, on_update=lambda w: updates.append([e.frame.kinds for e in w.new]))
    assert updates == [[], [("no-ack",), ("stuff",), ("passive",), ("bus-off",), ("restarted",)], [], [], []]
    assert result.elapsed == 1.0
    assert dict(result.counts["can1"]) == {"no-ack": 1, "stuff": 1, "passive": 1, "bus-off": 1, "restarted": 1}
    assert result.hints("can1")[0] == "no ACK: is another node powered, is the bus terminated?"
    assert result.links["can1"].state == "ERROR-ACTIVE"


def test_watch_in_process_sees_the_simulated_controllers_error_frames():
    import time

    from sherpa_cli.bus.errwatch import watching
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.config import load_config
    from sherpa_cli.ops.buswatch import watch
    from sherpa_cli.sim.arm import SimArm

    cfg = load_config(ARM)
    arm = SimArm.in_process(cfg)
    with ArmSession.open(cfg, sim=arm) as session, watching(session, ["can0", "can2"]) as w:
        with arm.lock:
            arm.bus_controller("can2").set_state("bus-off")
            arm.bus_controller("can0").inject("crc")
        deadline = time.monotonic() + 5
        seen: list = []
        while len(seen) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
            seen += w.drain()
        result = watch(session, ["can0", "can2"], duration=0.0, bus_watch=w)
    assert sorted((e.bus, e.frame.kinds) for e in seen) == [("can0", ("crc",)), ("can2", ("bus-off",))]
    assert result.links["can2"].state == "BUS-OFF"


def test_watch_cli_prints_each_error_frame_and_its_hint_once(cli, tmp_path):
    config = faulty(tmp_path, "  buses:\n    can2: {errors: [no-ack, stuff], error_period: 0.02}\n")
    result = cli("--sim", "--config", config, "bus", "watch", "can2", "--for", "0.3", "--interval", "0.1")
    assert result.exit_code == 0, result.transcript()
    out = result.stdout
    # the first round went out before the command's bus was open: what is seen starts later
    assert re.search(r"^can2: no ACK on transmission \(TEC \d+, REC \d+\)$", out, re.M), out
    assert re.search(r"^can2: stuff error at data field \(TEC \d+, REC \d+\)$", out, re.M), out
    assert out.count("hint: no ACK: is another node powered, is the bus terminated?") == 1
    assert out.count("hint: stuff/form errors: bit rate mismatch or wiring") == 1
    assert "error frames seen" in out
    doc = json.loads(cli("--sim", "--config", config, "--json", "bus", "watch", "can2", "--for", "0.2").stdout)
    assert doc["buses"][0]["error_frames"]["no-ack"] >= 1
    assert doc["errors"][0]["kinds"] == ["no-ack"]
