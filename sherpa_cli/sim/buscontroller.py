"""The host's CAN controller on one simulated bus: its state, error counters, kernel counters and the
Linux error frames (CAN_ERR_*) it reports, so `bus status`, `bus watch`, the preflight and `doctor`
meet a bus in trouble without hardware.

Set up from the config's ``sim: buses:`` (config/simbus.py), driven by tests through
:meth:`BusController.inject` and :meth:`BusController.set_state` (take ``SimArm.lock``), and read
through :class:`SimNetlink`, which answers like bus/netlink.py's ``Netlink`` seam (the same mapping).

The counter model follows ISO 11898-1 as far as a host sees it: an error while transmitting
(no ACK, bit error, TX timeout) adds 8 to TEC, one while receiving (stuff, form, CRC) adds 1 to REC;
no ACK does not raise TEC past 127 (a node alone on the bus stays error-passive, it does not go
bus-off); warning at 96, passive at 128, bus-off at TEC 256; after ``restart_ms`` (0: never) the
controller restarts with both counters at 0. Error frames follow the kernel: bus errors (protocol,
no ACK) only with berr-reporting on, state changes always, TEC/REC in bytes 6-7 (CAN_ERR_CNT).
The error-frame numbers are include/uapi/linux/can/error.h's (bus/errframes.py decodes them; its
tests decode what this module sends).
"""

from __future__ import annotations

import errno
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from sherpa_cli.config.simbus import SimBusConfig

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

# include/uapi/linux/can/error.h
ERR_TX_TIMEOUT, ERR_LOSTARB, ERR_CRTL, ERR_PROT, ERR_TRX = 0x001, 0x002, 0x004, 0x008, 0x010
ERR_ACK, ERR_BUSOFF, ERR_BUSERROR, ERR_RESTARTED, ERR_CNT = 0x020, 0x040, 0x080, 0x100, 0x200
CRTL_RX_OVERFLOW, CRTL_TX_OVERFLOW, CRTL_RX_WARNING, CRTL_TX_WARNING = 0x01, 0x02, 0x04, 0x08
CRTL_RX_PASSIVE, CRTL_TX_PASSIVE, CRTL_ACTIVE = 0x10, 0x20, 0x40
PROT_BIT, PROT_FORM, PROT_STUFF, PROT_OVERLOAD, PROT_TX = 0x01, 0x02, 0x04, 0x20, 0x80
LOC_ID28_21, LOC_DATA, LOC_CRC_SEQ, LOC_ACK = 0x02, 0x0A, 0x08, 0x19
TRX_CANH_NO_WIRE = 0x04

ACTIVE, WARNING, PASSIVE, BUS_OFF, STOPPED = "ERROR-ACTIVE", "ERROR-WARNING", "ERROR-PASSIVE", "BUS-OFF", "STOPPED"
WARNING_LEVEL, PASSIVE_LEVEL, BUS_OFF_LEVEL = 96, 128, 256
TX_ERRORS = {"no-ack", "bit", "tx-timeout"}
RX_ERRORS = {"stuff", "form", "crc", "protocol"}
# what a kind's error frame carries: class bits, data[1] (controller), data[2] (type), data[3] (location)
FRAME = {
    "tx-timeout": (ERR_TX_TIMEOUT, 0, 0, 0), "lost-arbitration": (ERR_LOSTARB, 0, 0, 0),
    "rx-overflow": (ERR_CRTL, CRTL_RX_OVERFLOW, 0, 0), "tx-overflow": (ERR_CRTL, CRTL_TX_OVERFLOW, 0, 0),
    "bit": (ERR_PROT | ERR_BUSERROR, 0, PROT_BIT | PROT_TX, LOC_ID28_21),
    "form": (ERR_PROT | ERR_BUSERROR, 0, PROT_FORM, LOC_DATA),
    "stuff": (ERR_PROT | ERR_BUSERROR, 0, PROT_STUFF, LOC_DATA),
    "crc": (ERR_PROT | ERR_BUSERROR, 0, 0, LOC_CRC_SEQ),
    "protocol": (ERR_PROT | ERR_BUSERROR, 0, 0, 0),
    "overload": (ERR_PROT, 0, PROT_OVERLOAD, 0),
    "transceiver": (ERR_TRX, 0, 0, 0),
    "no-ack": (ERR_ACK | ERR_BUSERROR, 0, 0, 0),
    "bus-error": (ERR_BUSERROR, 0, 0, 0),
}
BUS_ERRORS = {"bit", "form", "stuff", "crc", "protocol", "overload", "no-ack", "bus-error"}  # need berr-reporting
LEVEL_OF = {"error-active": (0, 0), "error-warning": (WARNING_LEVEL, 0), "error-passive": (PASSIVE_LEVEL + 8, 0),
            "bus-off": (BUS_OFF_LEVEL, 0), "stopped": (0, 0)}

Frame = tuple[int, bytes, bool]  # (can_id or error class bits, data, is an error frame)


class BusController:
    """The host adapter's controller on one simulated bus (module docstring)."""

    def __init__(self, name: str, cfg: SimBusConfig, configured_bitrate: int | None, now: float) -> None:
        self.name = name
        self.cfg = cfg
        self.present = cfg.present
        self.up = cfg.up
        self.bitrate = cfg.bitrate if cfg.bitrate is not None else configured_bitrate
        self.sample_point = cfg.sample_point
        self.restart_ms = cfg.restart_ms
        self.berr_reporting = cfg.berr_reporting
        tec, rec = LEVEL_OF[cfg.state]
        self.tec = cfg.tec if cfg.tec is not None else tec
        self.rec = cfg.rec if cfg.rec is not None else rec
        self.state = STOPPED if cfg.state == "stopped" else self._level_state()
        if cfg.state == "bus-off":
            self.state = BUS_OFF
        self.device_stats = dict.fromkeys(("bus_error", "error_warning", "error_passive", "bus_off",
                                           "arbitration_lost", "restarts"), 0)
        self.stats = dict.fromkeys(("rx_packets", "tx_packets", "rx_bytes", "tx_bytes", "rx_errors", "tx_errors",
                                    "rx_dropped", "tx_dropped"), 0)
        self.errors_sent: list[tuple[float, str]] = []  # (time, kind) of every error injected
        self._outbox: list[Frame] = []
        self._t0 = now
        self._now = now
        self._bus_off_since: float | None = now if self.state == BUS_OFF else None
        self._bus_off_due = None if cfg.bus_off_at is None else now + cfg.bus_off_at
        self._next_errors = now if cfg.errors else None
        self._next_beat = now if cfg.foreign_heartbeats else None

    # -- what the host sees -------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        """Frames pass: the interface exists, is up, and the controller is neither bus-off nor stopped."""
        return self.present and self.up and self.state not in (BUS_OFF, STOPPED)

    def link(self) -> dict[str, Any] | None:
        """The mapping of bus/netlink.py's ``Netlink.link`` (a real CAN controller's figures)."""
        if not self.present:
            return None
        return {"kind": "can", "up": self.up, "operstate": "UP" if self.up else "DOWN",
                "can_state": self.state if self.up else STOPPED, "tec": self.tec, "rec": self.rec,
                "bitrate": self.bitrate, "sample_point": round(self.sample_point * 1000), "clock": 80_000_000,
                "restart_ms": self.restart_ms,
                "ctrlmode": {"berr_reporting": self.berr_reporting, "listen_only": False, "one_shot": False,
                             "loopback": False},
                "device_stats": dict(self.device_stats), "stats": dict(self.stats)}

    def set_link(self, *, up: bool | None = None, bitrate: int | None = None, restart_ms: int | None = None,
                 berr_reporting: bool | None = None) -> None:
        """As the kernel: CAN settings only while the link is down (EBUSY), up restarts the controller."""
        if not self.present:
            raise FileNotFoundError(errno.ENODEV, f"no interface {self.name}")
        if (bitrate, restart_ms, berr_reporting) != (None, None, None) and self.up and up is not False:
            raise OSError(errno.EBUSY, "Device or resource busy (CAN settings need the link down)")
        if bitrate is not None:
            self.bitrate = int(bitrate)
        if restart_ms is not None:
            self.restart_ms = int(restart_ms)
        if berr_reporting is not None:
            self.berr_reporting = bool(berr_reporting)
        if up is True and not self.up:
            self.up = True
            self.tec = self.rec = 0
            self.state = ACTIVE
            self._bus_off_since = None
        elif up is False:
            self.up = False

    # -- test controls --------------------------------------------------------------------------------

    def set_state(self, state: str, *, tec: int | None = None, rec: int | None = None) -> None:
        """Put the controller in ``state`` (ERROR-ACTIVE ... BUS-OFF, STOPPED or the config's lower-case
        names) with these counters (default: the state's threshold), and report the change."""
        name = state.lower()
        if name.upper() in (ACTIVE, WARNING, PASSIVE, BUS_OFF, STOPPED):
            name = name.lower()
        if name not in LEVEL_OF:
            raise ValueError(f"unknown controller state {state!r}")
        t, r = LEVEL_OF[name]
        before = self.state
        self.tec = t if tec is None else tec
        self.rec = r if rec is None else rec
        self.state = STOPPED if name == "stopped" else BUS_OFF if name == "bus-off" else self._level_state()
        self._report_change(before)

    def inject(self, kind: str) -> None:
        """One error of this kind on the bus: counters, state, kernel counters and the error frame."""
        before = self.state
        if before in (BUS_OFF, STOPPED) or not (self.present and self.up):
            return
        self.errors_sent.append((self._now, kind))
        if kind == "warning":
            self.tec = max(self.tec, WARNING_LEVEL)
        elif kind == "passive":
            self.tec = max(self.tec, PASSIVE_LEVEL)
        elif kind == "bus-off":
            self.tec = BUS_OFF_LEVEL
        elif kind == "active":
            self.tec = self.rec = 0
        elif kind == "restarted":
            self._restart()
            return
        elif kind in TX_ERRORS:
            if not (kind == "no-ack" and self.tec >= PASSIVE_LEVEL):
                self.tec += 8
            self.stats["tx_errors"] += 1
        elif kind in RX_ERRORS:
            self.rec = min(self.rec + 1, PASSIVE_LEVEL + 7)
            self.stats["rx_errors"] += 1
        elif kind == "lost-arbitration":
            self.device_stats["arbitration_lost"] += 1
        elif kind == "rx-overflow":
            self.stats["rx_dropped"] += 1
        elif kind == "tx-overflow":
            self.stats["tx_dropped"] += 1
        if kind in BUS_ERRORS:
            self.device_stats["bus_error"] += 1
        if kind in FRAME and (kind not in BUS_ERRORS or self.berr_reporting):
            cls, ctrl, prot, loc = FRAME[kind]
            d = bytearray(8)
            d[1], d[2], d[3] = ctrl, prot, loc
            if kind == "transceiver":
                d[4] = TRX_CANH_NO_WIRE
            self._error_frame(cls, d)
        self.state = BUS_OFF if self.tec >= BUS_OFF_LEVEL else self._level_state()
        self._report_change(before)

    def pop_frames(self) -> list[Frame]:
        frames, self._outbox = self._outbox, []
        return frames

    # -- time -----------------------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Advance to ``now``: the configured bus-off, the restart after restart_ms, the repeating errors
        and another master's heartbeats."""
        self._now = now
        if self._bus_off_due is not None and now >= self._bus_off_due:
            self._bus_off_due = None
            self.inject("bus-off")
        if (self.state == BUS_OFF and self._bus_off_since is not None and self.restart_ms > 0
                and now >= self._bus_off_since + self.restart_ms / 1000):
            self._restart()
        if self._next_errors is not None and now >= self._next_errors:
            for kind in self.cfg.errors:
                self.inject(kind)
            self._next_errors = now + self.cfg.error_period
        if self._next_beat is not None and now >= self._next_beat:
            if self.running:
                for node in self.cfg.foreign_heartbeats:
                    self._outbox.append((0x700 + node, b"\x05", False))
            self._next_beat = now + self.cfg.heartbeat_period

    def count(self, *, host_sent: int = 0, host_received: int = 0, sent_bytes: int = 0, received_bytes: int = 0) -> None:
        """Frames through the host's interface (its tx: what the host sent; rx: what reached it)."""
        self.stats["tx_packets"] += host_sent
        self.stats["tx_bytes"] += sent_bytes
        self.stats["rx_packets"] += host_received
        self.stats["rx_bytes"] += received_bytes

    # -- inside ---------------------------------------------------------------------------------------

    def _level_state(self) -> str:
        level = max(self.tec, self.rec)
        return PASSIVE if level >= PASSIVE_LEVEL else WARNING if level >= WARNING_LEVEL else ACTIVE

    def _error_frame(self, cls: int, data: bytearray) -> None:
        data[6], data[7] = min(self.tec, 255), min(self.rec, 255)
        self._outbox.append((cls | ERR_CNT, bytes(data), True))

    def _report_change(self, before: str) -> None:
        after = self.state
        if after == before:
            return
        tx = self.tec >= self.rec
        d = bytearray(8)
        if after == BUS_OFF:
            self.device_stats["bus_off"] += 1
            self._bus_off_since = self._now
            self._error_frame(ERR_BUSOFF, d)
        elif after == PASSIVE:
            self.device_stats["error_passive"] += 1
            d[1] = CRTL_TX_PASSIVE if tx else CRTL_RX_PASSIVE
            self._error_frame(ERR_CRTL, d)
        elif after == WARNING and before == ACTIVE:
            self.device_stats["error_warning"] += 1
            d[1] = CRTL_TX_WARNING if tx else CRTL_RX_WARNING
            self._error_frame(ERR_CRTL, d)
        elif after == ACTIVE:
            d[1] = CRTL_ACTIVE
            self._error_frame(ERR_CRTL, d)

    def _restart(self) -> None:
        self.tec = self.rec = 0
        self.state = ACTIVE
        self._bus_off_since = None
        self.device_stats["restarts"] += 1
        self._error_frame(ERR_RESTARTED, bytearray(8))


class SimNetlink:
    """bus/netlink.py's ``Netlink`` for the simulated buses, by bus name (under the arm's lock)."""

    def __init__(self, controllers: Mapping[str, BusController], lock: AbstractContextManager[object]) -> None:
        self.controllers = controllers
        self.lock = lock

    def link(self, name: str) -> dict[str, Any] | None:
        ctrl = self.controllers.get(name)
        if ctrl is None:
            return None
        with self.lock:
            return ctrl.link()

    def set_link(self, name: str, *, up: bool | None = None, bitrate: int | None = None,
                 restart_ms: int | None = None, berr_reporting: bool | None = None) -> None:
        ctrl = self.controllers.get(name)
        if ctrl is None:
            raise FileNotFoundError(errno.ENODEV, f"no interface {name}")
        with self.lock:
            ctrl.set_link(up=up, bitrate=bitrate, restart_ms=restart_ms, berr_reporting=berr_reporting)
