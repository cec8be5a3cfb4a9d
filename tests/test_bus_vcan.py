"""`sherpa bus` on kernel vcan, in the QEMU guest of .ci/vcan-stage.sh (marker `vcan`).

They use a spare interface of their own (SHERPA_VCAN_SPARE, vcan3 in the stage), never vcan0..2: the
simulated arm of the realbus tests is bound to those, and `bus down` would pull the link from under
it. Elsewhere they are skipped: the normal suite runs on python-can virtual buses, and this
machine's kernel has no SocketCAN.

- pyroute2 reads vcan's link: up, frame counters; vcan has no CAN controller, and the status says so;
- `bus down` / `bus up` as root set what vcan takes (the link) and say what it cannot (the bit rate);
- error frames injected on vcan (can-utils `cansend` where installed, else python-can sending an error
  frame) are decoded by `bus watch`;
- `log capture` keeps the kernel's receive timestamps.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

ARM = Path(__file__).resolve().parent.parent / "configs" / "sherpa-arm.yaml"
pytestmark = pytest.mark.vcan


@pytest.fixture
def spare(test_bus) -> str:
    name = os.environ.get("SHERPA_VCAN_SPARE")
    if test_bus.kind != "socketcan" or not name:
        pytest.skip("needs kernel vcan with a spare interface (SHERPA_VCAN_SPARE; .ci/vcan-stage.sh sets it)")
    return name


def bus_map(spare: str) -> tuple[str, str]:
    return ("--bus-map", f"can0=socketcan:{spare}")


def test_pyroute2_reads_vcan_and_the_status_says_what_vcan_cannot_report(cli, spare):
    from sherpa_cli.bus.netlink import Pyroute2Netlink

    nl = Pyroute2Netlink()
    try:
        figures = nl.link(spare)
    finally:
        nl.close()
    assert figures is not None and figures["kind"] == "vcan" and figures["up"] is True
    assert figures.get("can_state") is None and "rx_packets" in figures["stats"]

    result = cli(*bus_map(spare), "--json", "bus", "status", "can0", "--window", "0.2")
    assert result.exit_code == 0, result.transcript()
    row = json.loads(result.stdout)["buses"][0]
    assert (row["channel"], row["kind"], row["state"], row["controller_state"]) == (spare, "vcan", "up", None)
    for figure in ("state", "counters", "bitrate", "sample_point", "restart_ms", "berr_reporting"):
        assert row["not_reported"][figure] == "not reported by vcan"
    assert row["load"] is not None and row["problems"] == []
    plain = cli(*bus_map(spare), "bus", "status", "can0", "--window", "0")
    assert "not reported by vcan" in plain.stdout and "Traceback" not in plain.stderr


def test_bus_up_as_root_sets_what_vcan_takes_and_names_what_it_cannot(cli, spare):
    assert os.geteuid() == 0, "the guest runs the tests as root"
    down = cli(*bus_map(spare), "bus", "down", "can0")
    assert down.exit_code == 0, down.transcript()
    status = json.loads(cli(*bus_map(spare), "--json", "bus", "status", "can0", "--window", "0").stdout)
    assert status["buses"][0]["state"] == "down"

    up = cli(*bus_map(spare), "--json", "bus", "up", "can0")
    assert up.exit_code == 0, up.transcript()
    change = json.loads(up.stdout)["buses"][0]
    assert change["kind"] == "vcan" and change["done"] == ["link up"]
    assert change["not_taken"] == ["bit rate (1000000 in the config): vcan has no CAN controller",
                                   "restart-ms: vcan has no CAN controller",
                                   "berr-reporting: vcan has no CAN controller"]
    status = json.loads(cli(*bus_map(spare), "--json", "bus", "status", "can0", "--window", "0").stdout)
    assert status["buses"][0]["state"] == "up"


# (class bits, data): no ACK with TEC 8; a stuff error in the data field with REC 1; error-passive (TX)
FRAMES = [(0x220, bytes([0, 0, 0, 0, 0, 0, 8, 0])), (0x288, bytes([0, 0, 0x04, 0x0A, 0, 0, 8, 1])),
          (0x204, bytes([0, 0x20, 0, 0, 0, 0, 136, 1])), (0x240, bytes([0, 0, 0, 0, 0, 0, 255, 1]))]


def _sender(spare: str, stop: threading.Event, cansend: str | None) -> None:
    """Send the error frames again and again until the watch is over (the guest is slow to start it)."""
    bus = None
    if cansend is None:
        import can

        bus = can.Bus(interface="socketcan", channel=spare)
    try:
        while not stop.wait(0.2):
            for cls, data in FRAMES:
                if cansend is not None:
                    subprocess.run([cansend, spare, f"{0x20000000 | cls:08X}#{data.hex().upper()}"], check=True,
                                   timeout=30)
                else:
                    import can

                    assert bus is not None
                    bus.send(can.Message(arbitration_id=cls, data=data, is_extended_id=False, is_error_frame=True))
    finally:
        if bus is not None:
            bus.shutdown()


@pytest.mark.parametrize("tool", ["cansend", "python-can"])
def test_error_frames_injected_on_vcan_are_decoded_by_bus_watch(cli, spare, tool):
    cansend = shutil.which("cansend") if tool == "cansend" else None
    if tool == "cansend" and cansend is None:
        pytest.skip("can-utils is not installed here (apt-get install can-utils); python-can sends them instead")
    stop = threading.Event()
    sender = threading.Thread(target=_sender, args=(spare, stop, cansend), name="vcan-error-frames", daemon=True)
    sender.start()
    try:
        result = cli(*bus_map(spare), "bus", "watch", "can0", "--for", "4", "--interval", "0.5")
    finally:
        stop.set()
        sender.join(timeout=60)
    assert result.exit_code == 0, result.transcript()
    out = result.stdout
    assert "can0: no ACK on transmission (TEC 8, REC 0)" in out
    assert "hint: no ACK: is another node powered, is the bus terminated?" in out
    assert "can0: stuff error at data field (TEC 8, REC 1)" in out
    assert "hint: stuff/form errors: bit rate mismatch or wiring" in out
    assert "can0: controller: error-passive (TX) (TEC 136, REC 1)" in out
    assert "can0: bus-off (TEC 255, REC 1)" in out
    assert "error frames seen" in out


def _bursts(spare: str, stop: threading.Event, sent: list[tuple[float, float, int]], ready: Path,
            bursts: int = 5, per_burst: int = 20) -> None:
    """Bursts of frames on the spare interface with a pause between them, each frame bracketed by
    time.time() before and after its send: a kernel receive stamp falls inside that bracket."""
    import time

    import can

    bus = can.Bus(interface="socketcan", channel=spare)
    try:
        # the capture's sockets are open once its file is (capture() opens the buses, then the writer)
        deadline = time.monotonic() + 60
        while not ready.exists() and time.monotonic() < deadline and not stop.wait(0.05):
            pass
        n = 0
        for _ in range(bursts):
            if stop.is_set():
                break
            for _ in range(per_burst):
                before = time.time()
                bus.send(can.Message(arbitration_id=0x5A0, data=n.to_bytes(4, "little"), is_extended_id=False))
                sent.append((before, time.time(), n))
                n += 1
            stop.wait(0.3)
    finally:
        bus.shutdown()


def test_log_capture_on_vcan_keeps_the_kernels_receive_timestamps(cli, spare, tmp_path):
    """`log capture` on a socketcan bus writes the kernel's receive time of each frame (SO_TIMESTAMP
    through python-can), not when the capture got round to it: every frame's stamp lies between the
    sender's clock readings just before and just after its send, even when the capture reads a burst
    late. A stamp taken in user space on the capture's side would come after the bracket."""
    from sherpa_cli.log.capture import read_frames

    stop = threading.Event()
    sent: list[tuple[float, float, int]] = []
    out = tmp_path / "burst.log"
    sender = threading.Thread(target=_bursts, args=(spare, stop, sent, out), name="vcan-bursts", daemon=True)
    sender.start()
    try:
        result = cli(*bus_map(spare), "log", "capture", "--bus", "can0", "-o", str(out), "--for", "10")
    finally:
        stop.set()
        sender.join(timeout=60)
    assert result.exit_code == 0, result.transcript()
    frames = [f for f in read_frames(out, ["can0"]) if f.can_id == 0x5A0]
    assert len(frames) == len(sent) == 100, (len(frames), len(sent))
    slack = 0.001  # the capture file keeps microseconds
    for frame, (before, after, n) in zip(frames, sent, strict=True):
        assert int.from_bytes(frame.data, "little") == n and frame.bus == "can0"
        assert before - slack <= frame.timestamp <= after + slack, (n, before, frame.timestamp, after)
    stamps = [f.timestamp for f in frames]
    assert stamps == sorted(stamps)


def test_the_simulator_serves_again_after_its_vcan_link_went_down_and_up(spare, tmp_path):
    """`ip link set vcanN down` under `sherpa sim`, then up: the simulator's pump reopens the bus and
    answers SDO again (a stock canopen master on the kernel bus), and SIGTERM ends it without a
    traceback. Before, the pump thread died with the link and SIGTERM printed a traceback. Nothing
    here is timed: the test waits for the simulator's own "link down" line and counts SDO attempts
    (each bounded by canopen's response timeout); the waits' bounds only keep a hang from blocking."""
    import signal
    import sys

    import canopen

    root = ARM.parent.parent
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"))
    sim = subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", str(ARM), "--bus-map",
                            f"can0=socketcan:{spare}", "sim"], cwd=root, env=env, stdin=subprocess.DEVNULL,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    down = threading.Event()

    def read_stderr() -> None:
        for line in sim.stderr:
            lines.append(line)
            if "link down" in line:
                down.set()

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()

    def answers(node: canopen.RemoteNode, attempts: int = 30) -> bool:
        for _ in range(attempts):
            try:
                node.sdo.upload(0x1000, 0)
                return True
            except (canopen.SdoCommunicationError, canopen.SdoAbortedError, OSError):
                continue
        return False

    def master() -> tuple[canopen.Network, canopen.RemoteNode]:
        network = canopen.Network()
        network.connect(interface="socketcan", channel=spare)
        node = network.add_node(10, canopen.ObjectDictionary())  # shoulder_1a on can0
        node.sdo.RESPONSE_TIMEOUT = 2.0
        return network, node

    network, node = master()
    try:
        assert answers(node), "the simulator never answered on the kernel bus"
        network.disconnect()
        subprocess.run(["ip", "link", "set", spare, "down"], check=True, timeout=30)
        assert down.wait(120), "the simulator never met the link going down: " + "".join(lines)
        subprocess.run(["ip", "link", "set", spare, "up"], check=True, timeout=30)
        network, node = master()
        assert answers(node), "the simulator did not serve again after the link came back"
    finally:
        network.disconnect()
        subprocess.run(["ip", "link", "set", spare, "up"], timeout=30)
        sim.send_signal(signal.SIGTERM)
        sim.wait(timeout=120)
        reader.join(timeout=30)
    err = "".join(lines)
    assert "Traceback" not in err, err
