"""`motion.pair_start: sync_rpdo` is atomic: both BG frames go out before one SYNC, whatever other
SYNC source of the tool runs meanwhile (bus/syncgate.py).

The other source is the recorder's own SYNC thread (log/record.py ThreadSync) at 500 Hz. The
network keeps a 5 ms floor between any two frames it sends (``protocol.pacing_floor_us``, what a
slow adapter or a loaded host does to the gap between the two BG frames), so without the gate a
recorder SYNC falls between them nearly every time. Twenty starts run while another thread and
another process keep the cores busy; each simulated drive records the SYNC at which its buffered
BG ran (SimDrive.sync_runs), and both must be the same SYNC every time."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import can

from sherpa_cli.bus import syncgate
from sherpa_cli.bus.session import ArmSession
from sherpa_cli.config import load_config
from sherpa_cli.log.record import ThreadSync
from sherpa_cli.motion import pair_start
from sherpa_cli.ops import diffdrive
from sherpa_cli.sim.arm import SimArm

FAST = Path(__file__).parent / "data" / "jog-fast-arm.yaml"
RUNS = 20
LOAD_LIMIT_S = 60.0  # the load stops by itself after this long, even if the test is killed


def _busy_thread(stop: threading.Event) -> threading.Thread:
    def spin() -> None:
        end = time.monotonic() + LOAD_LIMIT_S
        x = 0
        while not stop.is_set() and time.monotonic() < end:
            x = (x * 31 + 7) % 1_000_003  # holds the interpreter between switches, as a busy tool thread does
    t = threading.Thread(target=spin, name="busy", daemon=True)
    t.start()
    return t


def _busy_process() -> subprocess.Popen[bytes]:
    code = f"import time\nend = time.monotonic() + {LOAD_LIMIT_S}\nwhile time.monotonic() < end: pass\n"
    return subprocess.Popen([sys.executable, "-c", code])


def _starts_at(runs: int, *, sync_after_first_bg: bool = False) -> list[tuple[int, int]]:
    """(SYNC of the left BG, SYNC of the right BG) counted from before each start, per run.
    ``sync_after_first_bg``: another SYNC goes out right after the first BG frame, as a recorder's
    SYNC thread can send it when nothing holds it back (deterministic, not left to the scheduler)."""
    cfg = load_config(FAST)
    arm = SimArm(cfg, {"can0": {"interface": "virtual", "channel": f"atomic-{uuid.uuid4().hex[:8]}"}})
    out: list[tuple[int, int]] = []
    stop = threading.Event()
    busy = _busy_thread(stop)
    other = _busy_process()
    try:
        with ArmSession.open(cfg, sim=arm) as s:
            refs = diffdrive._refs(cfg, ("left", "right"))
            clients = {r.name: s.client(r) for r in refs}
            for c in clients.values():
                c.nmt_start()
                c.set("UM", 0, 5)
                c.set("PA", 0, 0)
                c.motor_on()
            link = s.links["can0"]
            link.network.floor = 0.005  # 5 ms between any two frames the tool sends (a slow adapter)
            if sync_after_first_bg:
                send = link.network.send_message
                sent_bg: list[int] = []

                def send_then_sync(can_id: int, data: bytes, remote: bool = False) -> None:
                    send(can_id, data, remote)
                    if 0x300 < can_id < 0x380 and bytes(data[:2]) == b"BG":
                        sent_bg.append(can_id)
                        if len(sent_bg) % 2 == 1:
                            link.bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))

                link.network.send_message = send_then_sync  # type: ignore[method-assign]
            recorder_sync = ThreadSync(link.bus, 0.002)
            try:
                for k in range(runs):
                    with s.sim.lock:
                        before = {r.name: s.sim.drives[r.name].syncs for r in refs}
                    for c in clients.values():
                        c.set("PA", 0, 10 * (k + 1))
                    with pair_start.CommonStart(s, refs, clients, "sync_rpdo", 125) as start:
                        start.begin()
                    with s.sim.lock:
                        runs_at = [s.sim.drives[r.name].sync_runs[-1][0] - before[r.name] for r in refs]
                    out.append((runs_at[0], runs_at[1]))
            finally:
                recorder_sync.stop()
                for c in clients.values():
                    c.motor_off()
    finally:
        stop.set()
        other.kill()
        other.wait()
        busy.join()
    return out


def test_sync_rpdo_starts_both_motors_at_one_sync_in_twenty_of_twenty_runs_under_load():
    starts = _starts_at(RUNS)
    assert len(starts) == RUNS
    apart = [(k, a, b) for k, (a, b) in enumerate(starts) if a != b]
    assert not apart, f"started one SYNC apart in {len(apart)} of {RUNS} runs: {apart}"


def test_without_the_gate_a_recorder_sync_falls_between_the_two_bgs(monkeypatch):
    """The check above can fail: with the critical section taken out (what the tool did before the
    gate), a SYNC between the two BG frames splits the start."""
    monkeypatch.setattr(syncgate.SyncGate, "exclusive", lambda self: contextlib.nullcontext())
    starts = _starts_at(2, sync_after_first_bg=True)
    assert all(a != b for a, b in starts), starts


def test_the_gate_holds_a_thread_sync_and_pauses_a_kernel_task_for_the_critical_section():
    """A SYNC sent through the gate waits for the critical section; a registered kernel task is
    paused for it and restarted after it, also when the section raises."""
    from sherpa_cli.log.record import PeriodicSync

    class Task:
        def __init__(self):
            self.calls = []

        def stop(self):
            self.calls.append("stop")

        def start(self):
            self.calls.append("start")

    class Bus:
        def __init__(self):
            self.task = Task()

        def send_periodic(self, msg, period):
            return self.task

    bus = Bus()
    kernel = PeriodicSync(bus, 0.01)  # type: ignore[arg-type]
    gate = syncgate.gate(bus)
    sent: list[str] = []
    with gate.exclusive():
        t = threading.Thread(target=gate.send, args=(lambda: sent.append("recorder SYNC"),))
        t.start()
        t.join(0.05)
        assert t.is_alive() and sent == []  # waits for the section
        sent.append("BG, BG, SYNC")
        assert bus.task.calls == ["stop"]
    t.join()
    assert sent == ["BG, BG, SYNC", "recorder SYNC"] and bus.task.calls == ["stop", "start"]
    try:
        with gate.exclusive():
            raise RuntimeError("a start that failed")
    except RuntimeError:
        pass
    assert bus.task.calls == ["stop", "start", "stop", "start"]
    kernel.stop()  # unregistered: the next section leaves the (stopped) task alone
    with gate.exclusive():
        pass
    assert bus.task.calls == ["stop", "start", "stop", "start", "stop"]
