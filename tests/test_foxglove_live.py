"""`monitor --foxglove`: a WebSocket client subscribes to /joint_states of the
live view on the simulated arm and sees the positions follow the joint; the server binds to the
loopback address unless told otherwise. The monitor's polls are stepped by the test (its `sleep`
hook), so what each message holds does not depend on the machine's speed."""

from __future__ import annotations

import json
import queue
import socket
import struct
import threading

import pytest
from websockets.sync.client import connect

import sherpa_cli.cli.monitor_cmd as monitor_cmd
from sherpa_cli.joints.units import counts_to_rad
from sherpa_cli.sim.arm import SimArm

SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk's WebSocket protocol (the older foxglove.websocket.v1 too)
MESSAGE_DATA = 0x01  # binary opcode: subscription id (u32), log time (u64), payload
WAIT_S = 10.0  # bound of every wait (never reached on a working run)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SteppedMonitor:
    """Runs `monitor --foxglove` in a thread; the monitor waits in its sleep hook until released."""

    def __init__(self, cli, monkeypatch, *args: str) -> None:
        self.parked: queue.Queue[None] = queue.Queue()
        self.go: queue.Queue[None] = queue.Queue()
        self.free = threading.Event()
        self.arms: list[SimArm] = []
        self.result = None
        self.error: BaseException | None = None
        built = SimArm.in_process

        def keep(cfg, *a, **kw):
            arm = built(cfg, *a, **kw)
            self.arms.append(arm)
            return arm

        def sleep(seconds: float) -> None:
            if self.free.is_set():
                return
            self.parked.put(None)
            self.go.get(timeout=WAIT_S)

        monkeypatch.setattr(SimArm, "in_process", staticmethod(keep))
        monkeypatch.setattr(monitor_cmd, "sleep", sleep)

        def run() -> None:
            try:
                self.result = cli("--sim", "monitor", *args)
            except BaseException as exc:  # noqa: BLE001 - handed to the test thread by finish()
                self.error = exc

        self.thread = threading.Thread(target=run, name="test-monitor")
        self.thread.start()

    def wait_parked(self) -> None:
        """Until the monitor has polled and published, and waits for the next poll."""
        self.parked.get(timeout=WAIT_S)

    def release(self) -> None:
        self.go.put(None)

    def finish(self):
        self.free.set()
        self.go.put(None)
        self.thread.join(timeout=60)
        assert not self.thread.is_alive()
        if self.error is not None:
            raise self.error
        return self.result


def _channels(ws) -> dict[str, dict]:
    """serverInfo, then the advertised channels by topic."""
    channels: dict[str, dict] = {}
    while "/joint_states" not in channels or "/diagnostics" not in channels:
        msg = json.loads(ws.recv(timeout=WAIT_S))
        if msg["op"] == "advertise":
            channels.update({c["topic"]: c for c in msg["channels"]})
    return channels


def _next_data(ws, wanted: int, timeout: float = WAIT_S) -> tuple[int, dict]:
    """The next message of subscription ``wanted`` (other subscriptions' and text frames skipped)."""
    while True:
        frame = ws.recv(timeout=timeout)
        if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            if sub == wanted:
                return log_time, json.loads(frame[13:])


def test_monitor_foxglove_joint_states_follow_the_joint(cli, monkeypatch):
    port = _free_port()
    run = SteppedMonitor(cli, monkeypatch, "elbow_pitch", "--interval", "0.01", "--for", "2",
                         "--foxglove", "--foxglove-at", f"127.0.0.1:{port}")
    try:
        run.wait_parked()  # polled once: the server is up
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=WAIT_S) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            channels = _channels(ws)
            joint_channel = channels["/joint_states"]
            assert joint_channel["schemaName"] == "sensor_msgs/msg/JointState"
            assert joint_channel["encoding"] == "json"
            assert channels["/diagnostics"]["schemaName"] == "diagnostic_msgs/msg/DiagnosticArray"
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": joint_channel["id"]}, {"id": 2, "channelId": channels["/diagnostics"]["id"]}]}))
            # polls until the subscription is in place (the server takes it on its own thread)
            first = None
            for _ in range(20):
                run.release()
                run.wait_parked()
                try:
                    first = _next_data(ws, 1, timeout=0.5)[1]
                    break
                except TimeoutError:
                    continue
            assert first is not None, "no joint state reached the subscriber"
            assert first["name"] == ["elbow_pitch"] and first["position"] == [0.0]
            _, status = _next_data(ws, 2)
            assert [s["name"] for s in status["status"]] == ["elbow_1a"]
            values = {kv["key"]: kv["value"] for kv in status["status"][0]["values"]}
            assert values["MO"] == "0" and values["MF"] == "0x00000000"
            # jog the simulated joint while the monitor waits; each next poll publishes where it is now
            arm = run.arms[0]
            motor = arm.drives["elbow_1a"].motor
            seen = []
            for counts in (300, 600, -450):
                with arm.lock:
                    motor.counts, motor.frac, motor.v = counts, 0.0, 0.0
                run.release()
                run.wait_parked()
                # a message of a poll released before the move may still be on its way: take them in
                # order until the new position shows (at most one stale one)
                for _ in range(2):
                    position = _next_data(ws, 1)[1]["position"][0]
                    if position == pytest.approx(counts_to_rad(counts, 3600)):
                        break
                seen.append(position)
            assert seen == pytest.approx([counts_to_rad(c, 3600) for c in (300, 600, -450)])
    finally:
        result = run.finish()
    assert result.exit_code == 0, result.transcript()
    assert f"foxglove: ws://127.0.0.1:{port}" in result.stderr


def test_the_live_view_binds_loopback_by_default(cli, monkeypatch):
    """Without --foxglove-at the server is asked for 127.0.0.1:8765 (here moved to a free port: a
    test must not take the real one), and a client reaches it there."""
    import foxglove

    asked = []
    start = foxglove.start_server
    port = _free_port()

    def spy(**kwargs):
        asked.append((kwargs["host"], kwargs["port"]))
        return start(**{**kwargs, "port": port})

    monkeypatch.setattr(foxglove, "start_server", spy)
    run = SteppedMonitor(cli, monkeypatch, "elbow_pitch", "--interval", "0.01", "--for", "0.02", "--foxglove")
    try:
        run.wait_parked()
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=WAIT_S) as ws:
            assert "/joint_states" in _channels(ws)
    finally:
        result = run.finish()
    assert result.exit_code == 0, result.transcript()
    assert asked == [("127.0.0.1", 8765)]


@pytest.mark.parametrize(("args", "message"), [
    (("--foxglove", "--foxglove-at", "0.0.0.0:8765"), "refusing to show the arm beyond this machine"),
    (("--foxglove", "--foxglove-at", "192.168.1.5:8765"), "refusing to show the arm beyond this machine"),
    (("--foxglove", "--foxglove-at", "localhost"), "is not HOST:PORT"),
    (("--foxglove", "--once"), "--foxglove is for the live view, not --once"),
    (("--for", "0"), "--for 0.0: expected seconds"),
    (("--allow-remote",), "need --foxglove"),
])
def test_monitor_foxglove_bad_inputs(cli, args, message):
    result = cli("--sim", "monitor", "elbow_pitch", *args)
    assert result.exit_code == 2 and message in result.stderr, result.transcript()
    assert "Traceback" not in result.stderr


def test_a_taken_port_is_one_clear_message(cli):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = cli("--sim", "monitor", "elbow_pitch", "--for", "0.5", "--foxglove", "--foxglove-at",
                     f"127.0.0.1:{port}")
    assert result.exit_code == 2 and "cannot listen there" in result.stderr, result.transcript()
    assert "Traceback" not in result.stderr


def test_allow_remote_binds_another_address(cli, monkeypatch):
    """--allow-remote lets a non-loopback address through to the server (asked for, not opened here)."""
    import foxglove

    asked = []

    def refuse(**kwargs):
        asked.append(kwargs["host"])
        raise RuntimeError("not in a test")

    monkeypatch.setattr(foxglove, "start_server", refuse)
    result = cli("--sim", "monitor", "elbow_pitch", "--for", "0.5", "--foxglove", "--foxglove-at", "0.0.0.0:8765",
                 "--allow-remote")
    assert asked == ["0.0.0.0"] and result.exit_code == 2 and "cannot listen there" in result.stderr
