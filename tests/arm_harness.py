"""The simulated arm under test in its own process, over the transport SHERPA_TEST_BUS selects.

    virtual (default)              no process here: arm_cli runs `sherpa --sim ...` in-process
    remote                         `sherpa sim --serve 127.0.0.1:PORT` (python-can-remote, loopback)
    socketcan:vcan0,vcan1,vcan2    `sherpa --bus-map can0=socketcan:vcan0,... sim` (kernel vcan)

The harness keeps one control connection per bus open for the whole session. Through it,
it power-cycles the arm before every command (NMT reset, then every boot-up), as `--sim`
does by building a fresh arm per command, and it watches the bus for SV: a test that wrote
flash gets a new simulator process (factory flash) before the next test, as `--sim` gets a
fresh state directory per test. So one golden file holds on every transport.
"""

from __future__ import annotations

import dataclasses
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

NMT_ID = 0x000
NMT_RESET_NODE = 0x81
BOOT_UP = b"\x00"
INTERPRETER_RX = range(0x301, 0x380)  # RPDO2 of nodes 1..127: the binary interpreter's requests

# The QEMU guest runs Python 15-20x slower than the host: the first start imports everything.
START_TIMEOUT_S = 300.0
BOOT_TIMEOUT_S = 120.0
STOP_TIMEOUT_S = 30.0


@dataclasses.dataclass(frozen=True)
class TestBus:
    """What SHERPA_TEST_BUS asked for."""

    __test__ = False  # not a test class, whatever its name
    kind: str  # virtual | remote | socketcan
    channels: tuple[str, ...] = ()

    @property
    def separate_process(self) -> bool:
        return self.kind != "virtual"

    def describe(self) -> str:
        return f"{self.kind}:{','.join(self.channels)}" if self.channels else self.kind


def parse_test_bus(text: str | None) -> TestBus:
    """``virtual`` | ``remote`` | ``socketcan:IF[,IF...]`` (one interface per configured bus)."""
    value = (text or "virtual").strip()
    if value in ("virtual", "remote"):
        return TestBus(value)
    kind, sep, rest = value.partition(":")
    channels = tuple(c.strip() for c in rest.split(",")) if sep else ()
    if kind == "socketcan" and channels and all(channels):
        return TestBus("socketcan", channels)
    raise ValueError(f"SHERPA_TEST_BUS={text!r}: expected virtual, remote or socketcan:IF,IF,IF "
                     "(e.g. socketcan:vcan0,vcan1,vcan2)")


class _BusWatch:
    """Listener on the control connection: boot-ups since the last reset, and any SV request."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.booted: set[tuple[int, int]] = set()
        self.saw_save = False

    def listener(self, index: int):
        import can

        watch = self

        class Listener(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                if msg.is_extended_id or msg.is_error_frame:
                    return
                can_id, data = msg.arbitration_id, bytes(msg.data)
                if 0x701 <= can_id <= 0x77F and data == BOOT_UP:
                    with watch.cond:
                        watch.booted.add((index, can_id))
                        watch.cond.notify_all()
                elif can_id in INTERPRETER_RX and data[:2] == b"SV":
                    watch.saw_save = True

        return Listener()


class ArmProcess:
    """`sherpa sim` in a child process, its bus map, and a control connection to its buses."""

    def __init__(self, test_bus: TestBus, root: Path, config: str, work_dir: Path) -> None:
        self.test_bus = test_bus
        self.root = root
        self.config = config
        self.work_dir = work_dir
        self.starts = 0
        self.fresh = False  # True: no command has run since the last start or power cycle
        self.proc: subprocess.Popen | None = None
        self.bus_map = ""
        self.event_log: Path | None = None
        self.output: list[str] = []
        self._buses: list[Any] = []
        self._notifier: Any = None
        self._watch = _BusWatch()
        from sherpa_cli.config import load_config

        self.drives = len(load_config(config).drives)

    # -- the child process ---------------------------------------------------------------------

    def start(self, attempts: int = 3) -> None:
        """A new simulator process with factory flash (a state directory of its own)."""
        for attempt in range(attempts):
            try:
                return self._start_once()
            except RuntimeError:
                # python-can-remote: a port taken between probing and listening; try others
                if self.test_bus.kind != "remote" or attempt == attempts - 1:
                    raise

    def _start_once(self) -> None:
        self.starts += 1
        self.fresh = False
        env = dict(os.environ, XDG_STATE_HOME=str(self.work_dir / f"state-{self.starts}"), NO_COLOR="1")
        env.pop("SHERPA_BUS_MAP", None)
        env.pop("SHERPA_CONFIG", None)
        if self.test_bus.kind == "remote":
            args, marker = ["sim", "--serve", f"127.0.0.1:{free_base_port(3)}"], "export SHERPA_BUS_MAP="
        else:
            bus_map = ",".join(f"can{i}=socketcan:{ch}" for i, ch in enumerate(self.test_bus.channels))
            args, marker = ["--bus-map", bus_map, "sim"], "drives answering on"
        self.output = []
        # the simulator's record of motor on/off and heartbeat-loss events (tests/test_motion_crossprocess.py)
        self.event_log = self.work_dir / f"events-{self.starts}.jsonl"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "sherpa_cli", "--config", self.config, *args, "--duration", "7200",
             "--event-log", str(self.event_log)],
            cwd=self.root, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        # A thread drains the pipe: selecting on it while readline() buffers ahead loses lines,
        # and a full pipe would block the simulator.
        lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._drain, args=(self.proc, lines), daemon=True).start()
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            try:
                line = lines.get(timeout=1)
            except queue.Empty:
                continue
            if line is None:
                break
            if marker in line:
                self.bus_map = line.split("=", 1)[1].strip() if self.test_bus.kind == "remote" else bus_map
                self._connect()
                self.fresh = True
                return
        self.stop()
        raise RuntimeError(f"the simulated arm ({self.test_bus.describe()}) did not start:\n{self.log()}")

    def _drain(self, proc: subprocess.Popen, lines: queue.Queue) -> None:
        for line in proc.stdout:
            self.output.append(line)
            lines.put(line)
        lines.put(None)

    def log(self) -> str:
        status = "running" if self.proc is not None and self.proc.poll() is None else \
            f"exited {self.proc.returncode if self.proc is not None else '-'}"
        return f"[sherpa sim: {status}]\n" + "".join(self.output)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> None:
        self._disconnect()
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=STOP_TIMEOUT_S)

    def kill(self) -> float:
        """SIGKILL the simulator (a bus that goes away mid-command); returns when (time.monotonic()).
        The control connection is closed first, so only the command under test sees the loss."""
        self._disconnect()
        assert self.proc is not None
        self.proc.kill()
        killed = time.monotonic()
        self.proc.wait(timeout=STOP_TIMEOUT_S)
        return killed

    # -- the control connection ----------------------------------------------------------------

    def bus_kwargs(self) -> list[dict[str, str]]:
        from sherpa_cli.bus.busmap import parse_bus_map

        return [{"interface": t.interface, "channel": t.channel} for t in parse_bus_map([self.bus_map]).values()]

    def _connect(self) -> None:
        import can

        self._watch = _BusWatch()
        self._buses = [can.Bus(**kw) for kw in self.bus_kwargs()]
        self._notifier = can.Notifier(self._buses, [], timeout=0.5)
        for i in range(len(self._buses)):
            self._notifier.add_listener(self._watch.listener(i))

    def _disconnect(self) -> None:
        if self._notifier is not None:
            self._notifier.stop(timeout=5)
            self._notifier = None
        for bus in self._buses:
            bus.shutdown()
        self._buses = []

    def power_cycle(self, timeout: float = BOOT_TIMEOUT_S) -> None:
        """NMT reset-node to every drive, then wait for every boot-up: RAM as after power-on."""
        import can

        if not self.alive():
            raise RuntimeError(f"the simulated arm is not running:\n{self.log()}")
        with self._watch.cond:
            self._watch.booted.clear()
        for bus in self._buses:
            bus.send(can.Message(arbitration_id=NMT_ID, data=[NMT_RESET_NODE, 0], is_extended_id=False))
        with self._watch.cond:
            if not self._watch.cond.wait_for(lambda: len(self._watch.booted) >= self.drives, timeout):
                raise RuntimeError(f"only {len(self._watch.booted)} of {self.drives} simulated drives booted "
                                   f"within {timeout:.0f} s after an NMT reset:\n{self.log()}")
        self.fresh = True

    def new_test(self) -> None:
        """Factory flash and fresh RAM, as `--sim` has at the start of a test.

        The power cycle comes first: its boot-ups follow on each bus every frame sent before
        it, so after it any SV request of the previous test has been seen.
        """
        self.power_cycle()
        if self._watch.saw_save:
            self.stop()
            self.start()

    def before_command(self) -> None:
        """RAM as after power-on, as `--sim` builds a new arm for every command."""
        if not self.fresh:
            self.power_cycle()
        self.fresh = False


def free_base_port(count: int) -> int:
    """A port on 127.0.0.1 with ``count`` free ports from it on."""
    import socket

    for _ in range(50):
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        if base + count > 65536:
            continue
        sockets = []
        try:
            for port in range(base, base + count):
                s = socket.socket()
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind(("127.0.0.1", port))
                sockets.append(s)
            return base
        except OSError:
            continue
        finally:
            for s in sockets:
                s.close()
    raise RuntimeError("no free consecutive ports on 127.0.0.1")
