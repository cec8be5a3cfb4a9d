"""End to end: DriveClients of an ArmSession talking to the simulated arm on python-can ``virtual`` buses.

Real threads and real time: the SimArm pumps each bus in its own thread, the session's canopen
Network receives in its notifier thread. A test whose assertions depend on how far the drives
move between two host requests runs them on a ManualClock instead (``sim_session(cfg, clock)``). Configs are small and use a short MO settle window and
SV blackout so every test stays well under 2 s; every wait is bounded by a deadline.

Each test has its own state directory (conftest.py), so the simulated flash of one test never
leaks into another; the session's networks poll their buses every 20 ms (bus/links.py), so closing
one costs milliseconds.
"""

from __future__ import annotations

import dataclasses
import json
import threading
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

import can
import canopen
import pytest

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config, load_config_text
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.errors import DriveRefusedError, DriveTimeoutError
from sherpa_cli.sim import state as sim_state
from sherpa_cli.sim.arm import SimArm
from sherpa_cli.sim.clock import ManualClock

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "configs" / "appendix-c"

# reply_timeout 0.5 s (the bundled 0.1 s): every request of these tests is on wall time, and a loaded
# machine that stalled the in-process simulator 0.2 s made two attempts of 0.1 s a DriveTimeoutError
FAST = "protocol: {mo_settle: 0.05, sv_blackout: 0.2, reply_timeout: 0.5}\n"
ONE_DRIVE = """\
name: e2e-one
buses:
  can0: {interface: socketcan, channel: can0}
drives:
  drive1: {bus: can0, node: 5, model: whistle-10/60}
"""
FACTORY_AC, FACTORY_DC = 100_000, 100_000
SR_LIMIT_STOP = 1 << 28


def write_config(tmp_path: Path, text: str, name: str = "arm.yaml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return load_config(path)


# The mechanics tests below read PX as the joint's position: the joint powers up where PX reads 0
# (without this the simulator puts a homeable joint away from its calibration switch; docs/home.md)
EX1_AT_ZERO = "sim:\n  power_up: {joint1: 0}\n"
EX3_AT_ZERO = "sim:\n  power_up: {joint_sigma: 0, joint_delta: 0}\n"


def example(name: str, extra: str = FAST):
    """An Appendix C example with extra top-level YAML (protocol, sim) appended."""
    path = EXAMPLES / name
    return load_config_text(path.read_text(encoding="utf-8") + "\n" + extra, str(path))


@contextmanager
def sim_session(cfg, clock: ManualClock | None = None):
    """The session's simulated arm; with ``clock`` its drives live in that clock's time, not real time."""
    # these tests time the protocol itself: the real-bus reply timeout, not --sim's patient one
    cfg = dataclasses.replace(cfg, sim_reply_timeout=cfg.protocol.reply_timeout)
    if clock is None:
        arm = SimArm.in_process(cfg)
    else:
        token = uuid.uuid4().hex[:8]  # virtual channels are process-wide
        arm = SimArm(cfg, {bus: {"interface": "virtual", "channel": f"e2e-{token}-{bus}"} for bus in cfg.buses},
                     clock=clock)
    with ArmSession.open(cfg, sim=arm) as session:
        yield session
        assert session.sim.errors == [], "a simulator pump thread died"


def client(session: ArmSession, name: str) -> DriveClient:
    return session.client(resolve_target(session.cfg, name))


def wait_until(predicate, timeout: float, what: str, interval: float = 0.005):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


def rpdo2_frames(session: ArmSession, name: str) -> list[bytes]:
    node = session.cfg.drives[name].node
    with session.sim.lock:
        return [data for _, can_id, data in session.sim.drives[name].received if can_id == 0x300 + node]


def is_set_frame(data: bytes) -> bool:
    """An RPDO2 set: 8 bytes without the query bit (byte 3 bit 6), and not an 8-byte execute."""
    return len(data) == 8 and not data[3] & 0x40


# -- (a) NMT -------------------------------------------------------------------------------------

def test_interpreter_is_deaf_before_nmt_start(tmp_path):
    cfg = write_config(tmp_path, ONE_DRIVE + FAST)
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        t0 = time.monotonic()
        with pytest.raises(DriveTimeoutError) as info:
            c.get("AC")
        assert time.monotonic() - t0 < 5.0  # 2 attempts x reply_timeout 0.5 s, not a hang
        assert "drive1 (node 5)" in str(info.value)
        assert "AC" in str(info.value)
        # the frames did reach the drive (1 + retries of them); it just does not answer in Pre-op
        assert rpdo2_frames(s, "drive1") == [b"AC\x00\x00"] * 2
        assert s.sim.drives["drive1"].nmt_state == 0x7F

        c.nmt_start()
        assert c.get("AC") == FACTORY_AC
        assert s.sim.drives["drive1"].nmt_state == 0x05


# -- (b) NMT reset loses RAM, keeps flash --------------------------------------------------------

def test_nmt_reset_node_loses_unsaved_values_and_keeps_saved_ones(tmp_path):
    cfg = write_config(tmp_path, ONE_DRIVE + FAST)
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        c.set("AC", 0, 150_000)
        c.save()
        c.set("DC", 0, 120_000)  # after the save: RAM only
        assert (c.get("AC"), c.get("DC")) == (150_000, 120_000)
        c.reset_node(10.0)  # waits for the boot-up, then NMT start
        assert c.get("AC") == 150_000  # saved
        assert c.get("DC") == FACTORY_DC  # not saved: gone
        assert s.sim.drives["drive1"].boots == 2
        assert s.sim.drives["drive1"].save_count == 1


@pytest.mark.parametrize("reboots", [False, True], ids=["cia301", "reset_comm_reboots"])
def test_nmt_reset_communication_reloads_the_communication_objects_and_keeps_the_application_ram(
        tmp_path, reboots):
    """CiA 301: reset communication puts 0x1000-0x1FFF back to their saved values (the
    heartbeat consumer a motion command armed is gone) and keeps the application's RAM; the sim
    setting `reset_comm_reboots: true` plays a drive that reboots instead."""
    extra = "sim:\n  drives:\n    drive1: {reset_comm_reboots: true}\n" if reboots else ""
    cfg = write_config(tmp_path, ONE_DRIVE + FAST + extra)
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        boot = threading.Event()
        s.links["can0"].network.subscribe(0x705, lambda can_id, data, ts: data == b"\x00" and boot.set())
        c.nmt_start()
        c.set("DC", 0, 120_000)  # RAM only
        s.sdo(resolve_target(cfg, "drive1")).download(0x1016, 1, (126 << 16 | 500).to_bytes(4, "little"))
        boot.clear()  # the power-up boot-up may or may not have reached the host
        c.nmt_reset_communication()
        assert boot.wait(10.0), "no boot-up frame after NMT reset communication"
        assert s.sim.drives["drive1"].nmt_state == 0x7F  # Pre-operational: the interpreter needs NMT start
        c.nmt_start()
        consumer = int.from_bytes(s.sdo(resolve_target(cfg, "drive1")).upload(0x1016, 1), "little")
        assert consumer == 0  # a communication object: back to its saved value either way
        assert c.get("DC") == (FACTORY_DC if reboots else 120_000)
        assert s.sim.drives["drive1"].boots == (2 if reboots else 1)


# -- (c) power cycle: flash persists between sessions -----------------------------------------

def test_power_cycle_keeps_flash_and_save_count(tmp_path):
    cfg = write_config(tmp_path, ONE_DRIVE + FAST)
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        assert c.get("AC") == FACTORY_AC  # fresh state directory: factory drive
        c.set("AC", 0, 150_000)
        c.save()
        c.set("DC", 0, 120_000)
        assert c.get("DC") == 120_000

    state_file = sim_state.state_path(cfg)
    assert state_file.is_relative_to(tmp_path / "state")
    saved = json.loads(state_file.read_text())["drives"]["drive1"]
    assert saved["flash"]["AC"] == 150_000
    assert saved["flash"]["DC"] == FACTORY_DC  # SV saved the RAM of that moment, before DC=120000
    assert saved["save_count"] == 1

    with sim_session(cfg) as s:  # still powered (--sim keeps RAM between sessions): DC is as set
        assert client(s, "drive1").get("DC") == 120_000
    assert sim_state.power_cycle(cfg)
    with sim_session(cfg) as s:  # power cycle: new RAM from the persisted flash
        c = client(s, "drive1")
        c.nmt_start()
        assert c.get("AC") == 150_000
        assert c.get("DC") == FACTORY_DC
        assert s.sim.drives["drive1"].save_count == 1
        c.save()
    assert json.loads(state_file.read_text())["drives"]["drive1"]["save_count"] == 2


# -- (d) dead node ---------------------------------------------------------------------------

def test_dead_node_times_out_quickly_naming_the_drive(tmp_path):
    cfg = example("example3.yaml", FAST + "sim:\n  drives:\n    drive2: {die_at: 0.0}\n")
    with sim_session(cfg) as s:
        alive, dead = client(s, "drive1"), client(s, "drive2")
        alive.nmt_start()
        dead.nmt_start()
        t0 = time.monotonic()
        with pytest.raises(DriveTimeoutError) as info:
            dead.get("AC")
        elapsed = time.monotonic() - t0
        assert elapsed < 5.0  # 2 attempts x reply_timeout 0.5 s, not a hang
        assert "drive2 (node 2)" in str(info.value)
        assert s.sim.drives["drive2"].dead
        assert alive.get("AC") == FACTORY_AC  # the other drive on the bus is unaffected


def test_die_at_counts_from_simulator_start(tmp_path):
    cfg = write_config(tmp_path, ONE_DRIVE + FAST + "sim:\n  drives:\n    drive1: {die_at: 5.0}\n")
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        assert c.get("AC") == FACTORY_AC  # 5 s have not passed yet


def test_dead_node_sends_nothing_at_all(tmp_path):
    cfg = write_config(tmp_path, ONE_DRIVE + "sim:\n  drives:\n    drive1: {die_at: 0.0}\n")
    channel = f"e2e-dead-{time.monotonic_ns()}"
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        with SimArm(cfg, {"can0": {"interface": "virtual", "channel": channel}}) as arm:
            wait_until(lambda: arm.drives["drive1"].dead, 10.0, "the drive to die")
            time.sleep(0.05)
        frames = []
        while (msg := listener.recv(0)) is not None:
            frames.append((hex(msg.arbitration_id), bytes(msg.data)))
        assert frames == []
    finally:
        listener.shutdown()


# -- (e) reply latency vs. reply timeout ---------------------------------------------------------

@pytest.mark.parametrize("reply_timeout, answers", [(0.02, False), (1.0, True)])
def test_reply_latency_against_reply_timeout(tmp_path, reply_timeout, answers):
    cfg = write_config(tmp_path, ONE_DRIVE + f"protocol: {{reply_timeout: {reply_timeout}, retries: 0}}\n"
                       "sim:\n  drives:\n    drive1: {reply_latency: 0.05}\n")
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        t0 = time.monotonic()
        if answers:
            assert c.get("AC") == FACTORY_AC
            assert time.monotonic() - t0 >= 0.045  # the latency really was there
        else:
            with pytest.raises(DriveTimeoutError) as info:
                c.get("AC")
            assert "drive1 (node 5)" in str(info.value)
            assert len(rpdo2_frames(s, "drive1")) == 1  # retries: 0


# -- (f) stop switch of a plain joint ------------------------------------------------------------

def test_stop_switch_stops_a_jog_toward_it_and_lets_it_jog_away(tmp_path):
    cfg = example("example1.yaml", FAST + EX1_AT_ZERO)  # stop switches: input 3 at -220, input 4 at +220
    assert cfg.il_codes.stop == 21
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        c.set("UM", 0, 2)
        c.set("IL", 3, cfg.il_codes.stop)
        c.set("IL", 4, cfg.il_codes.stop)
        c.motor_on()
        c.set("JV", 0, 2000)
        c.execute("BG")
        wait_until(lambda: c.get("PX") > 100 and c.get("VX") == 0, 10.0, "the jog to stop")
        px = c.get("PX")
        assert 220 <= px <= 230, px
        assert c.get("SR") & SR_LIMIT_STOP
        ip = c.get("IP")
        assert ip & (1 << 3) and ip & (1 << (16 + 3)), hex(ip)  # input 4: flag and raw pin
        assert not ip & (1 << 2), hex(ip)  # input 3 (the low switch) is not pressed
        assert c.get("MO") == 1 and c.get("MF") == 0  # stopped by the switch, not a fault trip
        time.sleep(0.05)
        assert c.get("PX") == px  # it stays stopped

        c.set("JV", 0, -2000)
        c.execute("BG")
        wait_until(lambda: c.get("PX") < px - 30, 1.0, "the jog away from the switch")
        assert not c.get("SR") & SR_LIMIT_STOP
        assert not c.get("IP") & (1 << 3)
        c.motor_off()


# -- (g) differential pair -------------------------------------------------------------------

def pair_positions(s: ArmSession) -> tuple[float, float]:
    with s.sim.lock:
        a, b = s.sim.drives["drive1"].position, s.sim.drives["drive2"].position
    return a + b, a - b


def tick_pair(s, clock: ManualClock, step_s: float) -> tuple[list, float]:
    """One step of the ManualClock, both drives of the pair ticked to it (the pumps tick them too, to
    the same instant: no double step); returns the drives and Δ then."""
    clock.advance(step_s)
    with s.sim.lock:
        drives = [s.sim.drives[n] for n in ("drive1", "drive2")]
        for drive in drives:
            drive.tick()
        return drives, pair_positions(s)[1]


def test_pair_jog_both_same_way_moves_sigma_not_delta(tmp_path):
    # On a ManualClock only this test moves (as in the next test): both BGs reach the drives at the
    # same simulated instant and the jog lasts 0.2 s of simulated time, however loaded the machine is
    # (in real time Σ depended on how long the stop requests took, Δ on the gap between the BGs).
    step_s = 0.002
    cfg = example("example3.yaml", "protocol: {mo_settle: 0, reply_timeout: 2.0}\n" + EX3_AT_ZERO)
    clock = ManualClock()
    with sim_session(cfg, clock) as s:
        a, b = client(s, "drive1"), client(s, "drive2")
        for c in (a, b):
            c.nmt_start()
            c.set("UM", 0, 2)
            c.motor_on()
            c.set("JV", 0, 300)

        def run(seconds: float, until=lambda: False) -> list[float]:
            deltas: list[float] = []
            for _ in range(round(seconds / step_s)):
                deltas.append(tick_pair(s, clock, step_s)[1])
                if until():
                    break
            return deltas

        a.execute("BG")
        b.execute("BG")
        deltas = run(0.2)
        for c in (a, b):
            c.set("JV", 0, 0)
            c.execute("BG")
        deltas += run(2.0, until=lambda: a.get("VX") == 0 and b.get("VX") == 0)
        assert a.get("VX") == 0 and b.get("VX") == 0, "both motors stop within 2 s of simulated time"
        sigma = a.get("PX") + b.get("PX")
        delta = a.get("PX") - b.get("PX")
        assert 80 <= sigma < 220, sigma  # ~2 x 300 cnt/s x 0.2 s, short of the Σ switch and end stop
        assert delta == 0, delta  # the same instant, the same profile
        assert max(abs(d) for d in deltas) == 0, deltas


@pytest.mark.parametrize("gain", [1.05, 1.0])
def test_pair_sigma_move_with_speed_mismatch_transiently_moves_delta(tmp_path, gain):
    # Seed Fig. 9.10: motor b runs 5 % fast; a Σ-only move (both PR by the same amount) makes Δ
    # drift while moving, and Δ comes back when both reach their targets. gain 1.0 is the control.
    # Σ goes -200 -> +200, inside the Σ end stops at ±240 (overshoot range).
    # Simulated time is a ManualClock only this test moves: both BGs reach the drives at the same
    # simulated instant and Δ is sampled every 2 ms of simulated time, however loaded the machine
    # is (in real time the gap between the two BGs made Δ depend on the scheduler). With time
    # standing still while the host talks, MO settles at once (mo_settle 0) and a reply may take
    # as long as the machine needs (reply_timeout 2 s; every reply comes, so no test waits that long).
    step_s = 0.002
    cfg = example("example3.yaml", "protocol: {mo_settle: 0, reply_timeout: 2.0}\n"
                  f"sim:\n  power_up: {{joint_sigma: 0, joint_delta: 0}}\n  drives:\n    drive2: {{speed_gain: {gain}}}\n")
    clock = ManualClock()
    with sim_session(cfg, clock) as s:
        a, b = client(s, "drive1"), client(s, "drive2")
        for c in (a, b):
            c.nmt_start()
            c.set("SP", 0, 800)
            c.set("AC", 0, 8000)
            c.set("DC", 0, 8000)
            c.motor_on()

        def move(pr: int) -> list[float]:
            for c in (a, b):
                c.set("PR", 0, pr)
            a.execute("BG")
            b.execute("BG")
            deltas: list[float] = []
            for _ in range(int(2.0 / step_s)):  # both targets are ~0.4 s of simulated time away
                drives, delta = tick_pair(s, clock, step_s)
                deltas.append(delta)
                if all(drive.motor.at_target for drive in drives):
                    return deltas
            raise AssertionError(f"both motors did not reach their targets in 2 s of simulated time: {deltas[-5:]}")

        move(-100)
        assert pair_positions(s) == (-200, 0)
        deltas = move(200)  # Σ -200 -> +200, Δ commanded to stay 0
        if gain == 1.0:
            assert max(abs(d) for d in deltas) == 0, deltas  # the same instant, the same profile
        else:
            assert min(deltas) <= -4, min(deltas)  # b (faster) ahead: Δ = a - b went negative (~ -7)
            assert max(abs(d) for d in deltas) < 30, deltas
        assert (a.get("PX"), b.get("PX")) == (100, 100)
        assert pair_positions(s) == (200, 0)  # Δ back to 0 at the end


# -- (h) SDO identity through canopen ------------------------------------------------------------

def test_sdo_identity_through_canopen(tmp_path):
    cfg = example("example3.yaml")
    with sim_session(cfg) as s:
        serials = {}
        for name in ("drive1", "drive2"):
            d = cfg.drives[name]
            node = canopen.RemoteNode(d.node, canopen.ObjectDictionary())
            s.links[d.bus].network.add_node(node)
            vendor = int.from_bytes(node.sdo.upload(0x1018, 1), "little")
            serial = int.from_bytes(node.sdo.upload(0x1018, 4), "little")
            device = node.sdo.upload(0x1008, 0).decode("ascii")
            assert vendor == 0x9A
            assert device == "Whistle 10/60"  # model whistle-10/60 of the config
            assert serial == s.sim.drives[name].serial == sim_state.default_serial(cfg, name)
            serials[name] = serial
        assert serials["drive1"] != serials["drive2"]


# -- (i) frames recorded by the simulator ---------------------------------------------------------

@pytest.mark.parametrize("query_long", [False, True])
def test_query_only_run_sends_no_set_frame(tmp_path, query_long):
    proto = f"protocol: {{query_long: {str(query_long).lower()}}}\n"
    cfg = write_config(tmp_path, ONE_DRIVE + proto)
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        for letters, index in (("AC", 0), ("DC", 0), ("LL", 3), ("HL", 3), ("IL", 4), ("PX", 0), ("SR", 0),
                               ("MO", 0)):
            c.get(letters, index)
        frames = rpdo2_frames(s, "drive1")
        assert len(frames) == 8  # every query reached the drive, once
        assert all(len(f) == (8 if query_long else 4) for f in frames), frames
        assert [f for f in frames if is_set_frame(f)] == []
        drive = s.sim.drives["drive1"]
        assert drive.od_writes == [] and drive.save_count == 0

        # The check does see a set when there is one.
        c.set("AC", 0, 150_000)
        sets = [f for f in rpdo2_frames(s, "drive1") if is_set_frame(f)]
        assert sets == [bytes.fromhex("41 43 00 00 F0 49 02 00")]


# -- (i) drives that do not echo sets ------------------------------------------------------------

def test_echo_off_refusal_is_reported_with_the_drive_error_on_a_threaded_bus(tmp_path):
    # protocol.set_echo false: the drive answers a good set with nothing and a bad one with an
    # error reply; the client must report the error code every time, whatever the thread timing.
    cfg = write_config(tmp_path, ONE_DRIVE + "protocol: {mo_settle: 0.02, sv_blackout: 0.2, set_echo: false}\n")
    with sim_session(cfg) as s:
        c = client(s, "drive1")
        c.nmt_start()
        c.set("AC", 0, 150_000)  # accepted: confirmed by read-back
        assert c.get("AC") == 150_000
        c.motor_on()
        for _ in range(20):
            with pytest.raises(DriveRefusedError) as info:
                c.set("LL", 3, -240)
            assert info.value.code == 57
        c.motor_off()
        c.set("LL", 3, -240)
        assert c.get("LL", 3) == -240
