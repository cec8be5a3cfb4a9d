"""The guard's watch of its drives: what the drives and the other
nodes of the bus say while a command moves them.

- an EMCY of an error class from a drive whose motor the guard has on (warning-class codes, the
  ``motion.emcy_warning_codes`` setting, are counted and logged once, never acted on);
- an NMT command (stop, pre-operational, reset node, reset communication) that another node sends
  to a drive of the command, or to all nodes;
- the drive's own heartbeat (when it produces one, 0x1017): a state other than Operational, a
  boot-up, or silence for three of its periods.

Once the guard's exit begins (:meth:`DriveWatch.stop`) nothing trips any more, but resets are
still followed: an NMT reset another node sends, and the boot-up that ends it. A drive that
reboots during its own stop is in Pre-operational, deaf to the interpreter, and a real drive is
deaf for its whole boot: the exit waits for the boot-up (:meth:`DriveWatch.resetting`), starts the
drive again and does the step once more (:meth:`DriveWatch.boots`), instead of spending a reply
timeout on every step left. A boot-up ends the request the exit waits for at once.

The receive thread only notes the first reason and cuts short the request the command is waiting
for (``DriveClient.abort_pending``): a deaf drive (NMT Stopped) would otherwise keep the command
waiting a whole reply timeout per attempt while the other drives move on. The command's thread then
raises in :meth:`MotionGuard.check` / :meth:`MotionGuard.query` and the guard's exit stops every
drive at once. Nothing here sends a frame. Cheap per frame, so an EMCY flood never stalls a command.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.elmo.protocol import HEARTBEAT_BASE, NMT_ID, NMT_OPERATIONAL
from sherpa_cli.errors import CommunicationError, SafetyError, SherpaError

if TYPE_CHECKING:
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.elmo.faults import Emcy

log = logging.getLogger(__name__)

# CiA 301 EMCY codes that say "something to know", not "the motion is unsafe": the default of
# motion.emcy_warning_codes (docs/motion.md). 0x6300 is also how the drive refuses a command sent
# through RPDO2 -- the command that sent it gets that refusal itself (DriveClient.set)
DEFAULT_EMCY_WARNING_CODES = (0x6300, 0x8110, 0x8140, 0x8200, 0x8210)
EMCY_ERROR_RESET = 0x0000  # "error reset / no error": never an error

NMT_COMMANDS = {0x02: "NMT Stopped", 0x80: "NMT Pre-operational", 0x81: "NMT reset node",
                0x82: "NMT reset communication"}
NMT_RESETS = frozenset({0x81, 0x82})
NMT_BOOT_UP = 0x00
HB_STATES = {0x00: "boot-up (the drive restarted)", 0x04: "Stopped", 0x05: "Operational",
             0x7F: "Pre-operational"}
SILENT_PERIODS = 3  # heartbeats missed before the drive counts as silent


class DriveWatchError(SafetyError):
    """A drive of the command sent an error EMCY, left Operational, or its dead-man entry was
    changed by another node: the command was stopped (exit 1)."""


class DriveRestartedError(CommunicationError):
    """A drive of the command booted again (reset by another node, or power) while the guard's exit
    waited for its answer: the exit starts it again and repeats the step."""


class DriveSilentError(CommunicationError):
    """A drive of the command stopped sending its heartbeat (exit 3, like a drive that stops answering)."""


@dataclass
class _Watched:
    bus: str
    node: int
    label: str
    client: DriveClient
    moving: bool = False
    last_beat: float | None = None
    period: float | None = None
    warnings: int = 0
    boots: int = 0  # boot-ups heard since the watch began
    reset_at: float | None = None  # an NMT reset of it was seen and its boot-up not yet heard
    callbacks: list[tuple[Any, int, Callable[..., None]]] = field(default_factory=list)


class DriveWatch:
    """Watch the drives of one motion guard (see the module docstring)."""

    def __init__(self, networks: Callable[[str], Any], *, warning_codes: Iterable[int] = DEFAULT_EMCY_WARNING_CODES,
                 answered_codes: Iterable[int] = (), min_silence: float = 0.05,
                 now: Callable[[], float] = time.monotonic) -> None:
        self._networks = networks
        self.warning_codes = frozenset(int(c) for c in warning_codes) | {EMCY_ERROR_RESET}
        self.answered_codes = frozenset(int(c) for c in answered_codes)
        self.min_silence = min_silence
        self._now = now
        self._lock = threading.Lock()
        self._drives: dict[tuple[str, int], _Watched] = {}
        self._nmt_subs: dict[str, tuple[Any, Callable[..., None]]] = {}
        self._active = False
        self.error: SherpaError | None = None  # the first reason to stop, once found
        # the command learnt of it: a request it waited for raised it (a trip between two requests
        # is raised by the guard at the command's next request to one of its drives instead)
        self.told = False
        self.emcy_errors = 0  # error EMCYs seen after the first (a flood is counted, not acted on twice)

    # -- set-up -----------------------------------------------------------------------------------

    def add(self, bus: str, node: int, label: str, client: DriveClient) -> None:
        key = (bus, node)
        if key in self._drives:
            return
        w = _Watched(bus, node, label, client)
        network = self._networks(bus)

        def on_beat(can_id: int, data: bytearray, timestamp: float, w: _Watched = w) -> None:
            self._on_heartbeat(w, bytes(data))

        def on_emcy(emcy: Emcy, w: _Watched = w) -> None:
            self._on_emcy(w, emcy)

        network.subscribe(HEARTBEAT_BASE + node, on_beat)
        w.callbacks.append((network, HEARTBEAT_BASE + node, on_beat))
        client.on_emcy(on_emcy)
        w.callbacks.append((client, -1, on_emcy))
        if bus not in self._nmt_subs:
            def on_nmt(can_id: int, data: bytearray, timestamp: float, bus: str = bus) -> None:
                self._on_nmt(bus, bytes(data))

            network.subscribe(NMT_ID, on_nmt)
            self._nmt_subs[bus] = (network, on_nmt)
        with self._lock:
            self._drives[key] = w

    def remove(self, bus: str, node: int) -> None:
        with self._lock:
            w = self._drives.pop((bus, node), None)
        if w is not None:
            self._unsubscribe(w)
            w.client.clear_abort()

    def set_moving(self, bus: str, node: int, moving: bool) -> None:
        w = self._drives.get((bus, node))
        if w is not None:
            w.moving = moving

    def start(self) -> None:
        with self._lock:
            self._active = True

    def stop(self) -> None:
        """No more trips: the guard's exit begins, and its own requests wait for their answers again --
        except across a boot-up of their drive. Resets are followed until :meth:`close`."""
        with self._lock:
            self._active = False
            drives = list(self._drives.values())
        for w in drives:
            w.client.clear_abort()

    def boots(self, bus: str, node: int) -> int:
        """Boot-ups of the drive heard since it was added (0 for a drive not watched)."""
        w = self._drives.get((bus, node))
        return 0 if w is None else w.boots

    def resetting(self, bus: str, node: int) -> bool:
        """An NMT reset of the drive was seen and its boot-up not yet heard: it is deaf until then."""
        w = self._drives.get((bus, node))
        return w is not None and w.reset_at is not None

    def close(self) -> None:
        """Every subscription undone (the guard's exit is over)."""
        with self._lock:
            self._active = False
            drives = list(self._drives.values())
            self._drives.clear()
            subs = list(self._nmt_subs.values())
            self._nmt_subs.clear()
        for w in drives:
            self._unsubscribe(w)
            w.client.clear_abort()
        for network, cb in subs:
            try:
                network.unsubscribe(NMT_ID, cb)
            except Exception as exc:  # noqa: BLE001 - a closed network: nothing left to undo
                log.debug("drive watch: unsubscribe NMT: %s", exc)

    def _unsubscribe(self, w: _Watched) -> None:
        for target, can_id, cb in w.callbacks:
            try:
                if can_id < 0:
                    target.remove_emcy(cb)
                else:
                    target.unsubscribe(can_id, cb)
            except Exception as exc:  # noqa: BLE001 - a closed network: nothing left to undo
                log.debug("drive watch: unsubscribe %s: %s", w.label, exc)
        w.callbacks.clear()

    # -- the command's thread ---------------------------------------------------------------------

    def poll(self) -> SherpaError | None:
        """The reason to stop, if any: a trip noted by the receive thread, or a heartbeat that went
        silent (checked here, on the command's thread: silence sends no frame)."""
        if self.error is not None:
            return self.error
        now = self._now()
        for w in list(self._drives.values()):
            if w.last_beat is None or w.period is None:
                continue
            limit = max(SILENT_PERIODS * w.period, self.min_silence)
            if now - w.last_beat > limit:
                w.client.silent = True  # the exit skips it: its own consumer stops it
                self._trip(DriveSilentError(
                    f"{w.label}: its heartbeat went silent ({now - w.last_beat:.2f} s, every {w.period:.3f} s "
                    "before): stopping every drive of the command",
                    hint="check the drive's power and CAN cable; `sherpa monitor --once` shows it"))
                break
        return self.error

    # -- the receive thread -----------------------------------------------------------------------

    def _on_emcy(self, w: _Watched, emcy: Emcy) -> None:
        if emcy.code in self.answered_codes:
            return  # the command listens to these itself and says what they meant
        if emcy.code in self.warning_codes:
            w.warnings += 1
            if w.warnings == 1:
                log.warning("%s: %s (a warning: motion goes on; motion.emcy_warning_codes)", w.label, emcy.text)
            return
        if not w.moving:
            log.warning("%s: %s (motor off)", w.label, emcy.text)
            return
        if self.error is not None:
            self.emcy_errors += 1
            return
        self._trip(DriveWatchError(f"{w.label}: {emcy.text}: stopping every drive of the command",
                                   hint="find the cause first; `sherpa monitor --once` shows MF and the "
                                        "drive's error history"))

    def _on_nmt(self, bus: str, data: bytes) -> None:
        if len(data) < 2 or data[0] not in NMT_COMMANDS:
            return
        node = data[1]
        targets = [w for w in list(self._drives.values()) if w.bus == bus and (node == 0 or w.node == node)]
        if data[0] in NMT_RESETS:
            now = self._now()
            for w in targets:
                w.reset_at = now
        if targets:
            who = "every node" if node == 0 else targets[0].label
            self._trip(DriveWatchError(
                f"{targets[0].label}: another node sent {NMT_COMMANDS[data[0]]} to {who}: the drive left "
                "Operational; stopping every drive of the command",
                hint="find which tool or node sends NMT commands on this bus"))

    def _on_heartbeat(self, w: _Watched, data: bytes) -> None:
        if not data:
            return
        now = self._now()
        if w.last_beat is not None:
            gap = now - w.last_beat
            w.period = gap if w.period is None else min(max(w.period, gap), 10 * w.period)
        w.last_beat = now
        state = data[0] & 0x7F
        if state == NMT_BOOT_UP:
            with self._lock:
                w.boots += 1
                w.reset_at = None
                tripping = self._active and self.error is None
            if not tripping:  # a request to a drive that just booted gets no answer: end it now
                w.client.abort_pending(DriveRestartedError(f"{w.label}: booted again (boot-up heard): it is deaf until started"))
                return
        if state != NMT_OPERATIONAL:
            self._trip(DriveWatchError(
                f"{w.label}: left Operational: its heartbeat says {HB_STATES.get(state, f'state 0x{state:02X}')}; "
                "stopping every drive of the command",
                hint="another node sent an NMT command, or the drive's own consumer tripped"))

    def _trip(self, error: SherpaError) -> None:
        with self._lock:
            if not self._active or self.error is not None:
                return
            self.error = error
            for w in self._drives.values():  # the request the command waits for ends now, with this reason
                self.told = w.client.abort_pending(error) or self.told
        log.warning("drive watch: %s", error)
