"""One drive of the differential pair dies in the middle of a command, across
processes: the simulated arm served over python-can-remote by `sherpa sim --serve` with
``sim: drives: shoulder_2b: {die_moving_after: S}`` (the drive goes silent S s after its first BG, so in
the middle of the move whatever the host's start-up time), the command in a process of its own, and
the test as another node on can0 seeing when the partner gets its stop.

Before: during `diffdrive move` the partner kept moving 4.6 s, until its own heartbeat consumer
tripped, and the command then hung for good on an SDO download to the dead drive.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import can
import pytest
from conftest import ROOT
from test_cross_process import _env, _start_sim, _stop
from test_motion_crossprocess import Arm

from sherpa_cli.bus.busmap import parse_bus_map
from sherpa_cli.elmo.codec import decode_request

# serial: the bundled 0.1 s reply timeout across processes, timed (REQUEST_BOUND): beside other workers on a
# loaded machine a healthy partner's reply came late (2026-11-29, "no answer to DC within 0.1 s")
pytestmark = [pytest.mark.crossprocess, pytest.mark.serial]

DEAD, PARTNER = "shoulder_2b", "shoulder_2a"
PARTNER_NODE, GROUP_ID = 20, 125
DIE_AFTER = 0.5  # s after the dead drive's first BG
REQUEST_BOUND = 0.1 * (1 + 1)  # the bundled config's reply_timeout x (1 + retries)
# two request timeouts, plus what a loaded 2-core machine adds between the sim's process, the
# command's and this test's receive (the behaviour this catches took 4.6 s)
PARTNER_STOP_S = 2 * REQUEST_BOUND + 0.6
EXIT_S = 5.0
START_TIMEOUT = 120.0


@pytest.fixture
def arm(tmp_path, monkeypatch):
    config = tmp_path / "arm.yaml"
    config.write_text((ROOT / "configs" / "sherpa-arm.yaml").read_text(encoding="utf-8")
                      + f"\nsim:\n  drives:\n    {DEAD}: {{die_moving_after: {DIE_AFTER}}}\n", encoding="utf-8")
    monkeypatch.setenv("SHERPA_CONFIG", str(config))  # the served sim's config (_start_sim passes the environment)
    log = tmp_path / "events.jsonl"
    proc = bus_map = None
    output = ""
    for _ in range(3):
        proc, bus_map, output = _start_sim(tmp_path, "--event-log", str(log))
        if proc is not None:
            break
    assert proc is not None, f"sim did not start:\n{output}"
    try:
        yield Arm(str(config), bus_map, log)
    finally:
        _stop(proc)


def _stops_to_partner(frames: list[tuple[float, int, bytes]]) -> list[float]:
    """Times (this process's monotonic clock) of the ST requests that reached the partner: its own
    RPDO2 or the pair's group id."""
    out = []
    for t, can_id, data in frames:
        if can_id in (0x300 + PARTNER_NODE, 0x300 + GROUP_ID) and len(data) in (4, 8):
            try:
                if decode_request(data).letters == "ST":
                    out.append(t)
            except Exception:  # noqa: BLE001 - not an interpreter request: not a stop
                continue
    return out


@pytest.mark.parametrize("args", [
    ("diffdrive", "move", "shoulder_diff", "--sigma", "0.3", "--relative", "--uncalibrated", "--apply"),
    ("jog", "shoulder_pitch", "--velocity", "0.2", "--for", "5", "--apply"),
    ("home", "shoulder_diff", "--yes"),
], ids=["diffdrive-move", "pair-jog", "pair-home"])
def test_a_pair_drive_dying_stops_the_partner_at_once_and_ends_the_command_naming_it(arm, tmp_path, args):
    target = parse_bus_map([arm.bus_map])["can0"]
    bus = can.Bus(interface=target.interface, channel=target.channel)
    frames: list[tuple[float, int, bytes]] = []
    try:
        proc = subprocess.Popen([sys.executable, "-m", "sherpa_cli", "--config", arm.config, "--bus-map", arm.bus_map,
                                 *args], cwd=ROOT, env=_env(tmp_path), stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + START_TIMEOUT
        died: list[dict] = []
        exited_at = None
        while time.monotonic() < deadline:
            msg = bus.recv(timeout=0.02)
            if msg is not None and not msg.is_error_frame:
                frames.append((time.monotonic(), msg.arbitration_id, bytes(msg.data)))
            if not died:
                died = [e for e in arm.events(DEAD) if e["event"] == "motor off: the drive died"]
            if proc.poll() is not None:
                exited_at = time.monotonic()
                break
            if died and time.monotonic() > died[0]["t"] + EXIT_S + 5:
                break  # hung: fail below
        if proc.poll() is None:
            proc.kill()
        out, err = proc.communicate(timeout=60)
    finally:
        bus.shutdown()
    assert died, f"{DEAD} did not die during the command (it never started moving?):\n{out}\n{err}"
    t_dead = died[0]["t"]
    assert exited_at is not None and exited_at - t_dead <= EXIT_S, \
        f"the command ran on {'for good' if exited_at is None else f'{exited_at - t_dead:.1f} s'} after {DEAD} died:\n{err}"
    assert proc.returncode not in (0, None), f"{out}\n{err}"
    assert DEAD in err, f"the error does not name the dead drive:\n{err}"
    assert "Traceback" not in err
    stops = [t for t in _stops_to_partner(frames) if t >= t_dead]
    assert stops, f"{PARTNER} never got a stop after {DEAD} died:\n{err}"
    assert stops[0] - t_dead <= PARTNER_STOP_S, f"{PARTNER} got its stop {stops[0] - t_dead:.2f} s after {DEAD} died"
    partner_offs = [e for e in arm.events(PARTNER) if e["t"] >= t_dead and e["event"].startswith("motor off")]
    assert partner_offs and "heartbeat lost" not in partner_offs[0]["event"], arm.events(PARTNER)


def test_die_moving_after_is_a_known_sim_key(tmp_path):
    """The fault the tests above inject is part of the config's `sim:` section (validated like die_at)."""
    from sherpa_cli.config import load_config
    from sherpa_cli.errors import ConfigError

    p = Path(tmp_path) / "arm.yaml"
    base = (ROOT / "configs" / "sherpa-arm.yaml").read_text(encoding="utf-8")
    p.write_text(base + f"\nsim:\n  drives:\n    {DEAD}: {{die_moving_after: 0.25}}\n", encoding="utf-8")
    assert load_config(p).sim[DEAD].die_moving_after == 0.25
    p.write_text(base + f"\nsim:\n  drives:\n    {DEAD}: {{die_moving_after: -1}}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="die_moving_after"):
        load_config(p)
