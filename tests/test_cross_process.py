"""The simulated arm in its own process, served over python-can-remote on 127.0.0.1, and `sherpa`
commands in other processes: real frames over real sockets, as a second terminal would do it."""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest
from arm_harness import free_base_port
from conftest import ROOT

pytestmark = pytest.mark.crossprocess


def _env(tmp_path) -> dict[str, str]:
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"), NO_COLOR="1", COLUMNS="100")
    env.pop("SHERPA_BUS_MAP", None)
    return env


def _start_sim(tmp_path, *extra: str):
    try:
        port = free_base_port(3)
    except RuntimeError:
        pytest.skip("no three consecutive free ports on 127.0.0.1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "sherpa_cli", "sim", "--serve", f"127.0.0.1:{port}", "--duration", "60", *extra],
        cwd=ROOT, env=_env(tmp_path), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    # A thread drains the pipe: select() on it while readline() buffers ahead loses lines.
    lines: queue.Queue[str | None] = queue.Queue()
    seen: list[str] = []

    def drain() -> None:
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=drain, daemon=True).start()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.5)
        except queue.Empty:
            continue
        if line is None:
            break
        seen.append(line)
        if "export SHERPA_BUS_MAP=" in line:
            return proc, line.split("=", 1)[1].strip(), ""
    _stop(proc)
    return None, None, "".join(seen)


def _stop(proc) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture
def served_sim(tmp_path):
    """`sherpa sim --serve` in a subprocess; yields (process, bus map); always stopped afterwards."""
    proc, bus_map, output = None, None, ""
    for _ in range(3):  # a port taken between probing and binding: try another
        proc, bus_map, output = _start_sim(tmp_path)
        if proc is not None:
            break
    assert proc is not None, f"sim did not start:\n{output}"
    try:
        yield proc, bus_map
    finally:
        _stop(proc)


def _sherpa(tmp_path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sherpa_cli", *args], cwd=ROOT, env=_env(tmp_path),
                          capture_output=True, text=True, timeout=60)


def test_cmd_in_another_process_talks_to_the_served_sim(served_sim, tmp_path):
    proc, bus_map = served_sim
    assert bus_map.startswith("can0=remote:127.0.0.1:")
    first = _sherpa(tmp_path, "--bus-map", bus_map, "cmd", "shoulder_1a", "AC=150000", "AC", "--apply")
    assert first.returncode == 0, first.stderr
    assert "150000" in first.stdout
    # the served arm keeps running between commands: the RAM value is still there
    second = _sherpa(tmp_path, "--bus-map", bus_map, "--json", "cmd", "shoulder_1a", "AC")
    assert second.returncode == 0, second.stderr
    assert json.loads(second.stdout)["results"][0]["value"] == 150000
    # a drive on another bus, through the environment variable a technician would export
    env_run = subprocess.run([sys.executable, "-m", "sherpa_cli", "--json", "cmd", "wrist_3b", "UM"], cwd=ROOT,
                             env={**_env(tmp_path), "SHERPA_BUS_MAP": bus_map}, capture_output=True, text=True,
                             timeout=60)
    assert env_run.returncode == 0, env_run.stderr
    assert json.loads(env_run.stdout)["results"][0]["value"] == 5
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=10) == 0


def test_sigterm_stops_the_served_sim_and_keeps_what_sv_saved(served_sim, tmp_path):
    # A service manager stops `sherpa sim` with SIGTERM: the saved flash must survive that too.
    proc, bus_map = served_sim
    saved = _sherpa(tmp_path, "--bus-map", bus_map, "cmd", "shoulder_1a", "AC=123456", "SV", "--apply",
                    "--raw-save")
    assert saved.returncode == 0, saved.stderr
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 0
    after = _sherpa(tmp_path, "--sim", "--json", "cmd", "shoulder_1a", "AC")  # same state directory
    assert json.loads(after.stdout)["results"][0]["value"] == 123456


def test_serving_beyond_loopback_is_refused(cli):
    result = cli("sim", "--serve", "0.0.0.0:54799")
    assert result.exit_code == 2
    assert "refusing to serve" in result.stderr and "--allow-remote" in result.stderr


def test_sim_needs_somewhere_to_run(cli):
    result = cli("sim")
    assert result.exit_code == 2 and "--serve" in result.stderr


def test_reset_state(cli):
    cli("--sim", "cmd", "shoulder_1a", "AC=150000", "SV", "--apply", "--raw-save")
    assert json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)["results"][0]["value"] == 150000
    result = cli("sim", "--reset-state")
    assert result.exit_code == 0 and "factory flash" in result.stdout
    assert json.loads(cli("--sim", "--json", "cmd", "shoulder_1a", "AC").stdout)["results"][0]["value"] == 100000


CLIENT = """
import sys, can
bus = can.Bus(interface="remote", channel=sys.argv[1])
for node in (10, 11):  # heartbeats every 5 ms (0x1017): the server keeps sending to this client
    bus.send(can.Message(arbitration_id=0x600 + node, data=[0x2B, 0x17, 0x10, 0, 5, 0, 0, 0],
                         is_extended_id=False))
print("connected", flush=True)
while True:
    bus.recv(0.1)
"""


def _lines(stream, into: queue.Queue) -> None:
    for line in stream:
        into.put(line)
    into.put(None)


def _wait_for(lines: queue.Queue, marker: str, timeout: float) -> str | None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.5)
        except queue.Empty:
            continue
        if line is None:
            return None
        if marker in line:
            return line
    return None


def test_a_client_killed_mid_traffic_and_ctrl_c_leave_no_traceback(tmp_path):
    # python-can-remote printed tracebacks (BrokenPipeError, ConnectionResetError, ENOTCONN) for a
    # client that vanished while frames flowed to it, and python-can warned at exit that its bus was
    # not shut down
    try:
        port = free_base_port(3)
    except RuntimeError:
        pytest.skip("no three consecutive free ports on 127.0.0.1")
    server = subprocess.Popen(
        [sys.executable, "-m", "sherpa_cli", "sim", "--serve", f"127.0.0.1:{port}", "--duration", "120"],
        cwd=ROOT, env=_env(tmp_path), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    out: queue.Queue[str | None] = queue.Queue()
    err: list[str] = []
    threading.Thread(target=_lines, args=(server.stdout, out), daemon=True).start()
    err_thread = threading.Thread(target=lambda: err.extend(server.stderr), daemon=True)
    err_thread.start()
    client = None
    try:
        line = _wait_for(out, "export SHERPA_BUS_MAP=", 30)
        if line is None:
            pytest.skip("the served sim did not start (a port taken meanwhile?)")
        channel = line.split("can0=remote:", 1)[1].split(",", 1)[0].strip()
        client = subprocess.Popen([sys.executable, "-c", CLIENT, channel], cwd=ROOT, env=_env(tmp_path),
                                  stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                  text=True)
        client_out: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=_lines, args=(client.stdout, client_out), daemon=True).start()
        assert _wait_for(client_out, "connected", 30) is not None, "the client did not connect"
        time.sleep(0.3)  # heartbeats flowing to the client
        client.send_signal(signal.SIGKILL)
        client.wait(timeout=10)
        time.sleep(1.0)  # the server's next sends find the client gone
        server.send_signal(signal.SIGINT)
        assert server.wait(timeout=30) == 0
    finally:
        if client is not None and client.poll() is None:
            client.kill()
            client.wait(timeout=10)
        _stop(server)
    err_thread.join(timeout=10)
    stderr = "".join(err)
    assert "stopping the simulated arm" in stderr
    assert "Traceback" not in stderr, stderr
    assert "not properly shut down" not in stderr, stderr
