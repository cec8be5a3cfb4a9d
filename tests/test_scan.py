"""`sherpa scan`: golden outputs on the simulated arm, injected faults, and how it probes."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest
import yaml

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.ops.scan import NODE_IDS, BusProber, ScanSettings, decode_device_type, scan
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "configs" / "sherpa-arm.yaml"

# Meaningful on a real bus: run through arm_cli, so also over python-can-remote and vcan.
ARM_CASES = [
    ("scan-sim", ["scan"]),
    ("scan-sim-json", ["--json", "scan"]),
    ("scan-sim-reset-one-bus", ["scan", "--bus", "can1", "--reset", "--apply"]),
    ("scan-sim-reset-dry-run", ["scan", "--bus", "can1", "--reset"]),
]


@pytest.mark.golden
@pytest.mark.realbus
@pytest.mark.parametrize("name,args", ARM_CASES, ids=[c[0] for c in ARM_CASES])
def test_scan_on_the_arm_golden(arm_golden, name, args):
    arm_golden(name, args)


def test_healthy_arm_exits_0_and_finds_every_drive(arm_cli):
    result = arm_cli("--json", "scan")
    assert result.exit_code == 0, result.transcript()
    report = json.loads(result.stdout)
    found = {n["drive"] for b in report["buses"] for n in b["nodes"] if n["verdict"] == "expected"}
    assert found == set(load_config(ARM).drives)
    assert report["missing"] == [] and report["unexpected"] == []
    for bus in report["buses"]:
        nodes = [n["node"] for n in bus["nodes"]]
        assert nodes == sorted(nodes), "rows sorted by node id"
    assert sum(len(b["nodes"]) for b in report["buses"]) == 14


# -- injected faults (config `sim:` section) --------------------------------------------------------

def _faulty_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sim: dict) -> None:
    """The arm config plus a `sim:` section, selected through $SHERPA_CONFIG (keeps transcripts stable)."""
    data = yaml.safe_load(ARM.read_text())
    data["sim"] = sim
    path = tmp_path / "arm-faults.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    monkeypatch.setenv("SHERPA_CONFIG", str(path))


FAULT_CASES = [
    # elbow_1b's CPU is dead from power-up: it never answers
    ("scan-missing", {"drives": {"elbow_1b": {"die_at": 0.0}}}, ["--sim", "scan", "--bus", "can1"], 1),
    # a device the config does not name, from another vendor
    ("scan-unexpected", {"extra_nodes": [{"bus": "can1", "node": 99, "vendor_id": 0x123, "device_name": "Foreign"}]},
     ["--sim", "scan", "--bus", "can1"], 1),
    # a second drive numbered like wrist_3a
    ("scan-duplicate", {"extra_nodes": [{"bus": "can2", "node": 70}]}, ["--sim", "scan", "--bus", "can2"], 1),
    # wrist_2a answers SDO 200 ms late: still there, but flagged
    ("scan-slow", {"drives": {"wrist_2a": {"sdo_latency": 0.2}}}, ["--sim", "scan", "--bus", "can2"], 0),
    ("scan-missing-json", {"drives": {"elbow_1b": {"die_at": 0.0}},
                           "extra_nodes": [{"bus": "can1", "node": 99}]}, ["--sim", "--json", "scan", "--bus", "can1"], 1),
]


@pytest.mark.golden
@pytest.mark.parametrize("name,sim,args,code", FAULT_CASES, ids=[c[0] for c in FAULT_CASES])
def test_scan_with_injected_faults_golden(cli, golden, tmp_path, monkeypatch, name, sim, args, code):
    _faulty_config(tmp_path, monkeypatch, sim)
    result = cli(*args)
    assert "Traceback" not in result.stderr
    assert result.exit_code == code, result.transcript()
    golden(f"{name}.txt", result.transcript())


def test_missing_drive_is_named(cli, tmp_path, monkeypatch):
    _faulty_config(tmp_path, monkeypatch, {"drives": {"elbow_1b": {"die_at": 0.0}}})
    report = json.loads(cli("--sim", "--json", "scan").stdout)
    assert report["missing"] == ["elbow_1b"]
    (row,) = [n for b in report["buses"] for n in b["nodes"] if n["drive"] == "elbow_1b"]
    assert (row["node"], row["verdict"], row["device_type"]) == (41, "missing", None)


def test_unexpected_node_makes_exit_1_and_is_listed(cli, tmp_path, monkeypatch):
    _faulty_config(tmp_path, monkeypatch, {"extra_nodes": [{"bus": "can0", "node": 5, "vendor_id": 0x123,
                                                             "device_name": "Foreign"}]})
    result = cli("--sim", "--json", "scan", "--bus", "can0")
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    assert report["unexpected"] == ["can0:5"]
    first = report["buses"][0]["nodes"][0]
    assert (first["node"], first["vendor_id"], first["vendor"], first["device_name"], first["drive"]) == (
        5, 0x123, "0x00000123", "Foreign", None)


def test_unknown_bus_is_a_usage_error(cli):
    result = cli("--sim", "scan", "--bus", "can7")
    assert result.exit_code == 2
    assert "no bus 'can7' in the config" in result.stderr and "Traceback" not in result.stderr


def test_extra_node_on_unknown_bus_is_a_config_error(cli, tmp_path, monkeypatch):
    _faulty_config(tmp_path, monkeypatch, {"extra_nodes": [{"bus": "can9", "node": 5}]})
    result = cli("--sim", "scan")
    assert result.exit_code == 2
    assert "extra node on unknown bus 'can9'" in result.stderr


# -- what goes on the bus -----------------------------------------------------------------------------

def test_scan_writes_nothing_and_reads_only_identity(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    cfg = load_config(ARM)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        report = scan(session)
        drives = session.sim.drives.values()
        frames = [(can_id, data) for d in drives for _, can_id, data in d.received]
        writes = [w for d in drives for w in d.od_writes]
    assert not report.problems
    assert writes == []
    assert all(0x600 < can_id <= 0x67F for can_id, _ in frames), "no NMT, no interpreter frame without --reset"
    uploads = {(data[0] & 0xE0, int.from_bytes(data[1:3], "little"), data[3]) for _, data in frames}
    assert {(i, s) for cmd, i, s in uploads if cmd == 0x40} == {(0x1000, 0), (0x1018, 1), (0x1008, 0)}


class _FakeNetwork:
    """canopen.Network's subscribe/unsubscribe/send_message; configured nodes answer inside send."""

    def __init__(self, answering: set[int], barrier: threading.Barrier | None = None) -> None:
        self.answering = answering
        self.barrier = barrier
        self.subscribers: dict[int, list] = {}
        self.sent: list[int] = []
        self.sleeps_before_last_send = 0
        self.sleeps = 0

    def subscribe(self, can_id, callback):
        self.subscribers.setdefault(can_id, []).append(callback)

    def unsubscribe(self, can_id, callback):
        self.subscribers[can_id].remove(callback)

    def send_message(self, can_id, data, remote=False):
        if self.barrier is not None and not self.sent:
            self.barrier.wait()  # every bus must be probing at the same time to get past this
        self.sent.append(can_id)
        node = can_id - 0x600
        if node in self.answering:
            answer = bytes([0x43, 0x00, 0x10, 0x00]) + (0x00020192).to_bytes(4, "little")
            for cb in list(self.subscribers.get(0x580 + node, ())):
                cb(0x580 + node, answer, 0.0)

    def sleep(self, s):
        self.sleeps += 1
        if len(self.sent) < len(NODE_IDS):
            self.sleeps_before_last_send += 1


def test_every_id_is_asked_before_any_wait():
    net = _FakeNetwork({10, 11})
    t = [0.0]

    def sleep(s):
        net.sleep(s)
        t[0] += s

    prober = BusProber(net, [10, 11], ScanSettings(), clock=lambda: t[0], sleep=sleep)
    heard = prober.run()
    assert net.sent == [0x600 + n for n in NODE_IDS]
    assert net.sleeps_before_last_send == 0
    assert {n for n, h in heard.items() if h.answers} == {10, 11}
    assert all(not cbs for cbs in net.subscribers.values()), "every subscription is removed again"


def test_a_missing_node_is_waited_for_one_sdo_timeout_only():
    net = _FakeNetwork({10})
    t = [0.0]

    def sleep(s):
        t[0] += s

    BusProber(net, [10, 11], ScanSettings(sdo_timeout=0.3), clock=lambda: t[0], sleep=sleep).run()
    assert 0.3 <= t[0] < 0.3 + 2 * ScanSettings().poll_s


def test_buses_are_scanned_at_the_same_time():
    """Each fake bus blocks its first frame until all three buses send: one after another would hang."""
    barrier = threading.Barrier(3, timeout=10)
    cfg = load_config(ARM)

    class Link:
        def __init__(self, bus):
            self.network = _FakeNetwork(set(), barrier)
            self.config = cfg.buses[bus]

    class Session:
        pass

    session = Session()
    session.cfg = cfg
    session.links = {bus: Link(bus) for bus in cfg.buses}
    report = scan(session, settings=ScanSettings(sdo_timeout=0.05, quiet_s=0.01))
    assert not barrier.broken
    assert sorted(report.missing) == sorted(cfg.drives)


@pytest.mark.parametrize(("frame", "value", "why"), [
    (bytes.fromhex("4300100092010200"), 0x00020192, None),
    (bytes.fromhex("4F00100005000000"), 5, None),
    (bytes.fromhex("8000100000000206"), None, "0x1000 aborted with 0x06020000"),
    (bytes.fromhex("4100100004000000"), None, "0x1000 answered as a segmented transfer"),
])
def test_decode_device_type(frame, value, why):
    assert decode_device_type(frame) == (value, why)


def test_sdo_timeout_comes_from_the_config(tmp_path):
    # protocol.sdo_timeout reaches both the scan's listening time and every SDO read of the session
    import dataclasses

    from sherpa_cli.bus.sdo import DriveSdo, sdo_upload
    from sherpa_cli.bus.session import ArmSession, resolve_target
    from sherpa_cli.config import load_config
    from sherpa_cli.errors import SdoError

    cfg = load_config("configs/appendix-c/example1.yaml")
    # (with the in-process simulator a session's SDO waits the longer of this and `sim: reply_timeout`)
    cfg = dataclasses.replace(cfg, protocol=dataclasses.replace(cfg.protocol, sdo_timeout=0.05), sim_reply_timeout=0.01)
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg)) as session:
        network = next(iter(session.links.values())).network
        assert network.sdo_timeout == 0.05
        # the clients' own response timeout (canopen's default is 0.3 s), not a measured time: that
        # would depend on the machine's load
        client = DriveSdo(network, 99)
        try:
            assert client.timeout == 0.05
        finally:
            client.close()
        assert session.sdo(resolve_target(cfg, next(iter(cfg.drives)))).timeout == 0.05
        with pytest.raises(SdoError):
            sdo_upload(network, 99, 0x1000, 0)  # nobody at node 99


def test_a_device_on_the_host_heartbeat_id_is_warned_about(cli, tmp_path, monkeypatch):
    # motion.host_node_id (126) is the tool's heartbeat COB-ID 0x77E: a device there defeats the dead-man
    _faulty_config(tmp_path, monkeypatch, {"extra_nodes": [{"bus": "can2", "node": 126}]})
    result = cli("--sim", "scan", "--bus", "can2")
    assert result.exit_code == 1
    assert "warning: bus can2: a device answers on node 126, a heartbeat id of the tool" in result.stderr
    clean = cli("--sim", "scan", "--bus", "can1")
    assert "heartbeat id" not in clean.stderr


def test_one_late_answer_of_a_loaded_host_does_not_make_a_drive_slow(cli, monkeypatch):
    """A loaded host held one probe answer up for a second (its receive thread waited for the CPU):
    scan called two healthy drives "answering slowly" in a CI run. A drive is as quick as its quicker
    answer; one that is slow every time (scan-slow's injected latency) is still flagged."""
    run = BusProber.run

    def held_up(self, *args, **kwargs):
        heard = run(self, *args, **kwargs)
        for node in (20, 21):
            if node in heard and heard[node].sent_at is not None:
                heard[node].sent_at -= 1.0  # its answer came a second after the request
        return heard

    monkeypatch.setattr(BusProber, "run", held_up)
    report = json.loads(cli("--sim", "--json", "scan", "--bus", "can0").stdout)
    assert report.get("slow", []) == [] and not [n for b in report["buses"] for n in b["nodes"]
                                                 if n["verdict"] == "answering slowly"], report
