"""The Elmo SimplIQ drive behind the drive seam (sherpa_cli/drive.py): each call in interpreter letters.

One call, the fewest requests: status reads MO, UM, SR, MF; a mode change switches the motor off
first (the drive refuses UM with MO=1); stop is ST, with JV=0 + BG where the firmware refuses ST
in speed mode (motion.stop_method "auto"); a profile has ended when MS reads 0.

The motion guard keeps its own Elmo path for what must be journaled or configured -- UM changes
(put back by `recover` after a kill), the stop by motion.stop_method with TC=0 first in torque mode
-- and asks this class only for the rest (positions, profiles, targets, a profile's end). A caller
outside the guard that uses :meth:`enable` or :meth:`stop` gets neither the journal nor the setting.
"""

from __future__ import annotations

import logging

from sherpa_cli.drive import DriveStatus, Mode, Ramp
from sherpa_cli.elmo.client import DriveClient
from sherpa_cli.elmo.faults import fault_reason
from sherpa_cli.elmo.protocol import UM_POSITION, UM_SPEED, UM_TORQUE
from sherpa_cli.errors import DriveRefusedError

log = logging.getLogger(__name__)

UNIT_MODES = {Mode.POSITION: UM_POSITION, Mode.VELOCITY: UM_SPEED, Mode.TORQUE: UM_TORQUE}
_MODE_OF = {um: mode for mode, um in UNIT_MODES.items()}


def mode_of(unit_mode: int) -> Mode:
    return _MODE_OF.get(unit_mode, Mode.OTHER)


class ElmoDrive:
    """:class:`sherpa_cli.drive.Drive` for an Elmo SimplIQ drive, over its interpreter client."""

    kind = "elmo"

    def __init__(self, client: DriveClient) -> None:
        self.client = client

    @property
    def label(self) -> str:
        return self.client.label

    def status(self) -> DriveStatus:
        c = self.client
        mo, um, sr, mf = int(c.get("MO")), int(c.get("UM")), int(c.get("SR")), int(c.get("MF"))
        return DriveStatus(enabled=bool(mo), mode=mode_of(um), fault=fault_reason(mf, sr))

    def position(self) -> int:
        return int(self.client.get("PX"))

    def velocity(self) -> int:
        return int(self.client.get("VX"))

    def enable(self, mode: Mode) -> None:
        if mode not in UNIT_MODES:
            raise ValueError(f"{self.label}: no unit mode for {mode.value}")
        c, um = self.client, UNIT_MODES[mode]
        on = bool(int(c.get("MO")))
        if int(c.get("UM")) != um:
            if on:
                c.motor_off()
                on = False
            c.set("UM", 0, um)
        if not on:
            if um == UM_TORQUE and c.get("TC") != 0:
                c.set("TC", 0, 0.0)  # MO=1 in UM=1 applies TC at once: never an old torque command
            c.motor_on()

    def disable(self) -> None:
        self.client.motor_off()

    def ramp(self) -> Ramp:
        c = self.client
        return Ramp(int(c.get("SP")), int(c.get("AC")), int(c.get("DC")))

    def set_ramp(self, ramp: Ramp) -> None:
        c = self.client
        c.set("SP", 0, ramp.speed)
        c.set("AC", 0, ramp.accel)
        c.set("DC", 0, ramp.decel)

    def move_to(self, target: int) -> None:
        self.client.set("PA", 0, target)

    def jog(self, velocity: int) -> None:
        self.client.set("JV", 0, velocity)

    def begin(self) -> None:
        self.client.execute("BG")

    def stop(self) -> str:
        c = self.client
        try:
            c.execute("ST")
            return "ST"
        except DriveRefusedError as exc:
            log.info("%s: ST refused (%s); stopping with JV=0 + BG", c.label, exc)
        c.set("JV", 0, 0)
        c.execute("BG")
        return "JV=0 + BG"

    def profile_done(self) -> bool:
        return int(self.client.get("MS")) == 0
