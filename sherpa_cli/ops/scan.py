"""`sherpa scan`: which node ids answer on each bus, and whether that is what the config says.

canopen's ``network.scanner.search()`` is not used: it gives no completion signal and counts
any frame with a node's function code as a node (measurements.md). Instead every bus gets
all 127 SDO uploads of 0x1000 at once (paced by the bus's Network) and its answers are
collected until the SDO timeout after the last request, or earlier once every configured
node has answered and the bus has gone quiet. Boot-up and heartbeat frames heard meanwhile
count as evidence too. Then 0x1018:1 and 0x1008 are read from every node that answered.

Nothing here prints; the CLI renders :class:`ScanReport`.
"""

from __future__ import annotations

import contextlib
import statistics
import struct
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, cast

from sherpa_cli.bus.canopen_names import VENDORS, decode_text, nmt_text
from sherpa_cli.bus.parallel import run_concurrently
from sherpa_cli.bus.sdo import DriveSdo
from sherpa_cli.config.model import ArmConfig
from sherpa_cli.elmo.protocol import HEARTBEAT_BASE, NMT_ID, NMT_RESET_COMM, SDO_RX_BASE, SDO_TX_BASE
from sherpa_cli.errors import SdoError, SherpaError

if TYPE_CHECKING:
    import canopen

    from sherpa_cli.bus.links import BusLink
    from sherpa_cli.bus.session import ArmSession

NODE_IDS = range(1, 128)
SDO_TX, SDO_RX, HEARTBEAT = SDO_TX_BASE, SDO_RX_BASE, HEARTBEAT_BASE
NMT_COB_ID, NMT_RESET_COMMUNICATION = NMT_ID, NMT_RESET_COMM
UPLOAD_DEVICE_TYPE = bytes([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0])
SDO_ABORT = 0x80

EXPECTED = "expected"
MISSING = "missing"
UNEXPECTED = "unexpected"
DUPLICATE = "duplicate id"
SLOW = "answering slowly"
NO_SDO = "no SDO answer"
SHERPA_HOST = "sherpa host"  # only a heartbeat on a motion.host_id_pool id: a sherpa command of this machine moving drives
# only a heartbeat on a pool id that no sherpa command of this machine holds: another host or tool, whose
# heartbeat would keep this machine's commands' drives on if they took the id
FOREIGN_HOST = "foreign host"
# Verdicts that make `sherpa scan` exit 1: the bus is not wired or numbered as configured.
PROBLEM_VERDICTS = frozenset({MISSING, UNEXPECTED, DUPLICATE, NO_SDO, FOREIGN_HOST})


@dataclass(frozen=True)
class ScanSettings:
    """The scan's timing choices; the defaults suit a 1 Mbit/s bus and the in-process simulator."""

    # canopen's SdoClient.RESPONSE_TIMEOUT: the longest any tool here waits for one SDO answer,
    # so a node slower than this is absent for every other command too.
    sdo_timeout: float = 0.3
    # Silence that ends listening early once every configured node has answered. 127 requests
    # take ~17 ms of bus time at 1 Mbit/s; an unconfigured node answers within that too.
    quiet_s: float = 0.03
    # A node answers slowly when its answer took longer than slow_factor x the bus's median
    # answer time, but never below slow_floor x sdo_timeout: on a loaded host a healthy node's
    # answer can wait several ms for the GIL, which must not read as a slow drive.
    slow_factor: float = 3.0
    slow_floor: float = 0.5
    # --reset: how long to wait for boot-ups. Elmo gives no boot time after reset communication
    # (UNCONFIRMED); a quiet period ends the wait once every configured node has booted.
    boot_timeout: float = 2.0
    poll_s: float = 0.002

    @property
    def slow_floor_s(self) -> float:
        return self.slow_floor * self.sdo_timeout


@dataclass(frozen=True)
class NodeFinding:
    """One node id of one bus that answered, or that the config expects."""

    node: int
    verdict: str
    drive: str | None = None
    joint: str | None = None  # the plain joint, or the pair a pair motor belongs to
    device_type: int | None = None
    vendor_id: int | None = None
    device_name: str | None = None
    answer_s: float | None = None  # request to first answer; never rendered into stable output
    nmt_state: str | None = None  # from the last boot-up or heartbeat heard while scanning
    notes: tuple[str, ...] = ()

    @property
    def vendor(self) -> str | None:
        if self.vendor_id is None:
            return None
        return VENDORS.get(self.vendor_id, f"0x{self.vendor_id:08X}")

    def as_json(self) -> dict[str, Any]:
        return {"node": self.node, "device_type": self.device_type, "vendor_id": self.vendor_id,
                "vendor": self.vendor, "device_name": self.device_name, "drive": self.drive,
                "joint": self.joint, "verdict": self.verdict, "nmt_state": self.nmt_state,
                "notes": list(self.notes)}


@dataclass
class BusScan:
    bus: str
    nodes: list[NodeFinding] = field(default_factory=list)
    error: SherpaError | BaseException | None = None
    median_answer_s: float | None = None
    slow_threshold_s: float | None = None

    def with_verdict(self, *verdicts: str) -> list[NodeFinding]:
        return [n for n in self.nodes if n.verdict in verdicts]


@dataclass
class ScanReport:
    buses: list[BusScan]
    settings: ScanSettings
    reset: bool = False

    @property
    def missing(self) -> list[str]:
        """Configured drives that gave no SDO answer (silent, or heard only on 0x700)."""
        return [n.drive for b in self.buses for n in b.with_verdict(MISSING, NO_SDO) if n.drive]

    @property
    def unexpected(self) -> list[str]:
        """``BUS:NODE`` of nodes the config does not name."""
        return [f"{b.bus}:{n.node}" for b in self.buses for n in b.with_verdict(UNEXPECTED)]

    @property
    def duplicates(self) -> list[str]:
        """``BUS:NODE`` of ids that more than one node answers on."""
        return [f"{b.bus}:{n.node}" for b in self.buses for n in b.with_verdict(DUPLICATE)]

    @property
    def slow(self) -> list[str]:
        """Nodes answering slowly: the drive name, or ``BUS:NODE`` when the config does not name it."""
        return [n.drive or f"{b.bus}:{n.node}" for b in self.buses for n in b.with_verdict(SLOW)]

    @property
    def problems(self) -> bool:
        return any(n.verdict in PROBLEM_VERDICTS for b in self.buses for n in b.nodes)

    @property
    def bus_errors(self) -> list[BusScan]:
        return [b for b in self.buses if b.error is not None]

    def as_json(self) -> dict[str, Any]:
        return {"buses": [{"bus": b.bus, "nodes": [n.as_json() for n in b.nodes],
                           **({"error": str(b.error)} if b.error is not None else {})} for b in self.buses],
                "missing": self.missing, "unexpected": self.unexpected}


# -- listening ------------------------------------------------------------------------------------

@dataclass
class _Heard:
    """Everything one bus said about one node id while we listened."""

    sent_at: float | None = None
    answers: list[tuple[float, bytes]] = field(default_factory=list)  # (monotonic time, SDO frame)
    nmt: list[int] = field(default_factory=list)  # boot-up / heartbeat state bytes, in order


FrameCallback = Callable[[int, bytearray, float], None]  # canopen.Network's: (can_id, data, timestamp)


class Network(Protocol):
    """What a scan needs of a bus: canopen.Network's ``subscribe``, ``unsubscribe`` and
    ``send_message`` (tests use a fake)."""

    def subscribe(self, can_id: int, callback: FrameCallback) -> None: ...

    def unsubscribe(self, can_id: int, callback: FrameCallback | None = None) -> None: ...

    def send_message(self, can_id: int, data: bytes) -> None: ...


class BusProber:
    """SDO upload of 0x1000 to every node id of one bus without waiting between requests.

    Works on anything with canopen.Network's ``subscribe``, ``unsubscribe`` and
    ``send_message`` (tests use a fake); callbacks may arrive on a receive thread or inside
    ``send_message``.
    """

    def __init__(self, network: Network, configured: Iterable[int], settings: ScanSettings = ScanSettings(), *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 progress: Callable[[str, int, int], None] | None = None) -> None:
        self.network = network
        self.configured = frozenset(configured)
        self.settings = settings
        self.clock = clock
        self.sleep = sleep
        self.progress = progress or (lambda phase, done, total: None)
        self.heard: dict[int, _Heard] = {n: _Heard() for n in NODE_IDS}
        self._lock = threading.Lock()
        self._last_frame = float("-inf")
        # Wall-clock time listening began: frames stamped earlier were on the bus before this
        # scan (a boot-up of the power-up) and say nothing about what answers now.
        self._since = time.time()

    def run(self, *, reset: bool = False) -> dict[int, _Heard]:
        self._since = time.time()
        subscriptions = [(SDO_TX + n, self._on_sdo) for n in NODE_IDS] + [(HEARTBEAT + n, self._on_nmt)
                                                                            for n in NODE_IDS]
        for can_id, callback in subscriptions:
            self.network.subscribe(can_id, callback)
        try:
            if reset:
                self._reset()
            self._probe()
        finally:
            for can_id, callback in subscriptions:
                with contextlib.suppress(KeyError, ValueError):  # the bus went away; nothing left to unhook
                    self.network.unsubscribe(can_id, callback)
        return self.heard

    def _reset(self) -> None:
        s = self.settings
        self.network.send_message(NMT_COB_ID, bytes([NMT_RESET_COMMUNICATION, 0]))
        sent = self.clock()
        self.progress("waiting for boot-ups", 0, len(self.configured))
        self._wait(sent + s.boot_timeout, sent, lambda: self._booted(), "waiting for boot-ups")

    def _booted(self) -> set[int]:
        with self._lock:
            return {n for n in self.configured if 0x00 in self.heard[n].nmt}

    def _answered(self) -> set[int]:
        with self._lock:
            return {n for n in self.configured if self.heard[n].answers}

    def _probe(self) -> None:
        total = len(NODE_IDS)
        for i, node in enumerate(NODE_IDS, start=1):
            # stamped before sending: the answer may arrive inside send_message (a fast node, a
            # synchronous test network), and a pacing wait only makes the node look slower
            with self._lock:
                self.heard[node].sent_at = self.clock()
            self.network.send_message(SDO_RX + node, UPLOAD_DEVICE_TYPE)
            if i % 8 == 0 or i == total:
                self.progress("probing", i, total)
        last_send = self.clock()
        self._wait(last_send + self.settings.sdo_timeout, last_send, self._answered, "listening")

    def _wait(self, deadline: float, last_send: float, done: Callable[[], set[int]], phase: str) -> None:
        """Until ``deadline``, or until ``done()`` covers every configured node and the bus is quiet."""
        quiet = self.settings.quiet_s
        while True:
            now = self.clock()
            if now >= deadline:
                return
            have = done()
            self.progress(phase, len(have), len(self.configured))
            with self._lock:
                last = max(self._last_frame, last_send)
            if have >= self.configured and now - last >= quiet:
                return
            self.sleep(self.settings.poll_s)

    def _on_sdo(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        data = bytes(data)
        # Only answers to our request (0x1000:00) or aborts of it; anything else is another
        # tool's transfer and proves nothing about this scan.
        if len(data) < 8 or data[1:4] != UPLOAD_DEVICE_TYPE[1:4]:
            return
        now = self.clock()
        with self._lock:
            self.heard[can_id - SDO_TX].answers.append((now, data))
            self._last_frame = now

    def _on_nmt(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        if len(data) < 1 or (timestamp and timestamp > 1e9 and timestamp < self._since):
            return
        with self._lock:
            self.heard[can_id - HEARTBEAT].nmt.append(data[0])
            self._last_frame = self.clock()


def decode_device_type(frame: bytes) -> tuple[int | None, str | None]:
    """(0x1000 value, None) from an upload answer, or (None, why not)."""
    cmd = frame[0]
    if cmd == SDO_ABORT:
        code = struct.unpack_from("<I", frame, 4)[0]
        return None, f"0x1000 aborted with 0x{code:08X}"
    if cmd & 0xE0 != 0x40:
        return None, f"0x1000: unexpected SDO answer {frame.hex(' ').upper()}"
    if not cmd & 0x02:
        return None, "0x1000 answered as a segmented transfer"
    size = 4 - (cmd >> 2 & 3) if cmd & 0x01 else 4
    return int.from_bytes(frame[4:4 + size], "little"), None


# -- identity -------------------------------------------------------------------------------------

def _read_identity(network: Network, node: int,
                   clock: Callable[[], float] = time.monotonic) -> tuple[int | None, str | None, list[str], float | None]:
    """Vendor id, device name, what could not be read, and how long the first read took to be
    answered (None: not answered)."""
    vendor_id = name = None
    answered: float | None = None
    notes: list[str] = []
    # canopen's SdoClient needs the whole Network (its notifier and subscriptions), not only the
    # three calls the probe makes: in a session it is one; a test's fake network never gets here
    # with answers to read, since identity is read only of nodes that answered the probe
    sdo = DriveSdo(cast("canopen.Network", network), node)
    try:
        try:
            began = clock()
            vendor_id = int.from_bytes(sdo.upload(0x1018, 1)[:4], "little")
            answered = clock() - began
        except SdoError as exc:
            notes.append(exc.detail)
        try:
            name = decode_text(sdo.upload(0x1008, 0))
        except SdoError as exc:
            notes.append(exc.detail)
    finally:
        sdo.close()
    return vendor_id, name, notes, answered


# -- putting it together --------------------------------------------------------------------------

def _joint_label(cfg: ArmConfig, drive: str) -> str | None:
    if drive in cfg.devices:  # a device: the joint whose absolute encoder it is
        dev = cfg.devices[drive]
        return next((j.name for j in cfg.joints.values()
                     if j.abs_encoder is not None and cfg.device_by_source(j.abs_encoder.source) is dev), None)
    joint = cfg.joint_of_drive(drive)
    if joint is not None:
        return joint.name
    pair = cfg.pair_of_drive(drive)
    return pair.name if pair is not None else None


def _nmt_text(states: list[int]) -> str | None:
    return nmt_text(states[-1]) if states else None


def scan_bus(cfg: ArmConfig, bus: str, network: Network, settings: ScanSettings = ScanSettings(), *,
             reset: bool = False, progress: Callable[[str, int, int], None] | None = None,
             host_holder: Callable[[int], int | None] = lambda host_id: None) -> BusScan:
    """Probe one bus, then read the identity of every node that answered; verdicts per node id.
    ``host_holder``: the pid of the sherpa command of this machine holding a pool id on this bus
    (motion/lock.py MachineLock.holder), None when none does."""
    configured = {d.node: d.name for d in cfg.drives.values() if d.bus == bus}
    configured.update({d.node: d.name for d in cfg.devices.values() if d.bus == bus and d.canopen})  # encoders, ...
    prober = BusProber(network, configured, settings, progress=progress)
    heard = prober.run(reset=reset)

    answer_times = {n: max(0.0, h.answers[0][0] - h.sent_at) for n, h in heard.items()
                    if h.answers and h.sent_at is not None}

    present = sorted(n for n, h in heard.items() if h.answers or h.nmt)
    # Two answers to one request mean two nodes share the id. (Two boot-ups do not: a node that
    # powered up just before a --reset boots twice.)
    shared = {n for n in present if len(heard[n].answers) > 1}
    identity: dict[int, tuple[int | None, str | None, list[str]]] = {}
    readable = [n for n in present if heard[n].answers and n not in shared]
    for i, node in enumerate(readable):
        if progress:
            progress("reading identity", i, len(readable))
        vendor_read, name_read, notes_read, answered = _read_identity(network, node)
        identity[node] = (vendor_read, name_read, notes_read)
        if answered is not None and node in answer_times:
            # a node is as quick as its quicker answer: a slow drive is slow every time, while a
            # loaded host delays one answer now and then (its thread waited for the CPU)
            answer_times[node] = min(answer_times[node], answered)
    median = statistics.median(answer_times.values()) if answer_times else None
    threshold = max(settings.slow_factor * median, settings.slow_floor_s) if median is not None else None

    findings = []
    for node in sorted(set(present) | set(configured)):
        h = heard[node]
        drive = configured.get(node)
        joint = _joint_label(cfg, drive) if drive else None
        notes: list[str] = []
        device_type = None
        distinct = sorted({data for _, data in h.answers})
        for data in distinct:
            value, why = decode_device_type(data)
            if why:
                notes.append(why)
            elif device_type is None:
                device_type = value
        vendor_id, name, id_notes = identity.get(node, (None, None, []))
        notes.extend(id_notes)
        answer = answer_times.get(node)
        if not h.answers and not h.nmt:
            verdict = MISSING
        elif node in shared:
            verdict = DUPLICATE
            notes.append(f"{len(h.answers)} nodes answer on id {node}; "
                         "identity not read (the answers would mix)")
        elif drive is None and not h.answers and node in cfg.motion.host_ids:
            pid = host_holder(node)
            if pid is not None:
                verdict = SHERPA_HOST
                notes.append("the dead-man heartbeat of a running sherpa motion command"
                             + (f" (pid {pid})" if pid else "") + " on this machine (motion.host_id_pool)")
            else:
                verdict = FOREIGN_HOST
                notes.append("a heartbeat on a dead-man id of motion.host_id_pool that no sherpa command of this "
                             "machine holds: another host or tool; give it ids outside the pool "
                             "(docs/motion.md \"Heartbeat ids\")")
        elif drive is None:
            verdict = UNEXPECTED
        elif not h.answers:
            verdict = NO_SDO
            notes.append("heard on 0x700 (boot-up/heartbeat) but no answer to the SDO upload of 0x1000")
        elif threshold is not None and answer is not None and answer > threshold:
            verdict = SLOW
        else:
            verdict = EXPECTED
        findings.append(NodeFinding(node, verdict, drive, joint, device_type, vendor_id, name, answer,
                                    _nmt_text(h.nmt), tuple(notes)))
    if progress:
        progress("done", 1, 1)
    return BusScan(bus, findings, None, median, threshold)


def _host_holder(link: BusLink) -> Callable[[int], int | None]:
    from sherpa_cli.bus.machine_lock import MachineLock, wire_key

    key = wire_key(link.config.interface, link.config.channel)
    return lambda host_id: MachineLock(key, f"host{host_id}").holder()


def _lock_for_reset(session: ArmSession, buses: Iterable[str]) -> list[Any]:
    """A reset communication puts back every drive's heartbeat consumer and PDOs: on a drive another
    command moves, it would drop that command's dead-man. So it takes each configured drive's motion
    lock first (motion/lock.py DriveLock), and refuses (exit 5, nothing sent) while one is held."""
    from sherpa_cli.bus.machine_lock import wire_key
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.motion.lock import DriveLock

    wanted = set(buses)
    held: list[DriveLock] = []
    try:
        for d in session.cfg.drives.values():
            if d.bus in wanted:
                link = session.links[d.bus].config
                lock = DriveLock(DriveRef(d.name, d.bus, d.node, d), purpose="resetting",
                                 key=wire_key(link.interface, link.channel))
                lock.acquire()
                held.append(lock)
    except BaseException:
        for lock in held:
            lock.release()
        raise
    return held


def scan(session: ArmSession, buses: Iterable[str] | None = None, settings: ScanSettings | None = None, *,
         reset: bool = False, progress: Callable[[str, str, int, int], None] | None = None) -> ScanReport:
    """Scan the named buses of an open session (default: all it has open), all at once."""
    cfg: ArmConfig = session.cfg
    if settings is None:
        settings = ScanSettings(sdo_timeout=cfg.protocol.sdo_timeout)
    names = list(buses) if buses is not None else list(session.links)
    links: Mapping[str, BusLink] = session.links

    def job(bus: str) -> Callable[[], BusScan]:
        report = (lambda phase, done, total: progress(bus, phase, done, total)) if progress else None
        holder = _host_holder(links[bus])
        return lambda: scan_bus(cfg, bus, links[bus].network, settings, reset=reset, progress=report,
                                host_holder=holder)

    held = _lock_for_reset(session, names) if reset else []
    try:
        outcomes = run_concurrently({bus: job(bus) for bus in names})
    finally:
        for lock in held:
            lock.release()
    result = []
    for bus, outcome in outcomes.items():
        if outcome.ok:
            result.append(outcome.value)
        else:
            assert outcome.error is not None
            if not isinstance(outcome.error, Exception):
                raise outcome.error  # KeyboardInterrupt and friends end the command
            result.append(BusScan(bus, error=outcome.error))
    return ScanReport(result, settings, reset)
