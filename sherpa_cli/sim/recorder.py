"""The simulated drive's recorder (real-arm.md 2; the host side is elmo/recorder.py).

It samples at the drive's servo rate: every ``SimSettings.recorder_sample_s`` x RG of the
drive's own time, whatever the host's ticks, because the drive schedules the next sample as an
event (sim/drive.py ``_next_event``) and its model steps up to it. Semantics as documented:

- ``RR`` write: -1/0 kill (the data is gone: RR reads -1), 1 start at the next BG, 2 start now,
  3 as ``RP[3]`` says (0 now, 1 BG; slope/window/input triggers are not modelled: they wait);
- ``RR`` read: -1 no data, 0 data ready, else the arming value while waiting or recording;
- SR bits 16-17: 0 inactive, 1 waiting for the trigger, 3 recording, 2 data ready;
- ``RL`` samples per signal from the trigger on (the first at the trigger), then data is ready;
  nothing before the trigger is kept (RP[8]/[9], the part to upload, are not modelled);
- ``RC`` with more than 8 bits, ``RG`` outside 1..4096 or ``RL`` x signals above the capacity
  are refused with EC 21 when they are set or when the recorder is armed;
- upload: object 0x2030, sub-index ``N - 1 + sub_base`` for logical signal N, in the layout and
  type the settings say (elmo/recorder.py ``encode_upload``). Faults: ``recorder_upload_fault``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from sherpa_cli.elmo.recorder import LAYOUTS, MAX_GAP, MAX_SIGNALS, RECORDER_OBJECT, TYPE_FLOAT, encode_upload
from sherpa_cli.sim.interpreter import EC_OUT_OF_RANGE, Refused
from sherpa_cli.sim.od import ODError

if TYPE_CHECKING:
    from sherpa_cli.sim.settings import SimSettings

ABORT_NO_DATA = 0x08000024  # CiA 301: no data available
ABORT_LOCAL = 0x08000021  # CiA 301: data cannot be transferred because of local control
DOMAIN = 0x0F  # CiA 301 data type of a byte block (canopen.objectdictionary.DOMAIN)
# 0x2030 sub-indexes served (one per logical signal), for the SDO server's dictionary (sim/sdo.py)
SDO_ENTRIES = tuple((RECORDER_OBJECT, sub, f"Recorded signal {sub}", DOMAIN, "ro") for sub in range(1, 17))
# scale factor the simulated drive sends per signal with the long type (current in mA)
_LONG_SCALE = {"cur": 0.001}
EPS = 1e-9

Ram = Callable[[], Mapping[str, int | float]]


class SimRecorder:
    """``ram()`` gives the drive's RAM (RV/RC/RG/RL/RP live there); ``sources`` the live signal
    values by name (sim names: pos, vel, cur, pos_err, vel_cmd)."""

    def __init__(self, settings: SimSettings, *, ram: Ram, now: Callable[[], float],
                 sources: Mapping[str, Callable[[], float]]) -> None:
        self.settings = settings
        self._ram = ram
        self._now = now
        self._sources = dict(sources)
        self._ids = {sid: name for name, sid in settings.recorder_signals}
        self.reset()

    def reset(self) -> None:
        """Power-up, NMT reset: no data, inactive."""
        self.state = 0  # SR bits 16-17
        self.rr = -1
        self.next_due = math.inf
        self.samples_taken = 0  # every sample of the model, for tests
        self._trigger = "none"  # "now" / "bg" / "never" while armed
        self._data: dict[int, list[float]] = {}  # logical id -> values, oldest first
        self._length = 0
        self._period = 0.0

    # -- interpreter ------------------------------------------------------------------------------

    def check(self, key: str, value: int | float) -> None:
        """Refuse (EC 21) a recorder setting the drive would not take."""
        if key == "RC" and not (0 <= value < 1 << 16 and bin(int(value)).count("1") <= MAX_SIGNALS):
            raise Refused(EC_OUT_OF_RANGE)
        if key == "RG" and not 1 <= value <= MAX_GAP:
            raise Refused(EC_OUT_OF_RANGE)
        if key == "RL" and not 1 <= value <= self.settings.recorder_capacity:
            raise Refused(EC_OUT_OF_RANGE)
        if key == "RR" and value not in (-1, 0, 1, 2, 3):
            raise Refused(EC_OUT_OF_RANGE)

    def write_rr(self, value: int) -> None:
        if value in (-1, 0):
            self.reset()
            return
        ram = self._ram()
        mask, length, gap = int(ram["RC"]), int(ram["RL"]), int(ram["RG"])
        signals = [n for n in range(1, 17) if mask >> (n - 1) & 1]
        if not signals or length * len(signals) > self.settings.recorder_capacity:
            raise Refused(EC_OUT_OF_RANGE)
        self.reset()
        self.rr = value
        self._length, self._period = length, self.settings.recorder_sample_s * gap
        self._data = {n: [] for n in signals}
        trigger = {1: "bg", 2: "now"}.get(value) or {0: "now", 1: "bg"}.get(int(ram["RP[3]"]), "never")
        self._trigger = trigger
        if trigger == "now":
            self._start()
        else:
            self.state = 1  # waiting: nothing before the trigger is kept, so nothing is sampled

    def on_bg(self) -> None:
        """An accepted BG (own RPDO2, group id or SYNC): the trigger of RR=1 / RP[3]=1."""
        if self.state == 1 and self._trigger == "bg":
            self._start()

    def _start(self) -> None:
        self.state = 3
        for values in self._data.values():
            values.clear()
        self.next_due = self._now()  # the first sample is at the trigger

    # -- servo-rate sampling ----------------------------------------------------------------------

    def fire(self, t: float) -> None:
        """Take every sample due by drive time ``t`` (called from the drive's event loop)."""
        while self.state == 3 and self.next_due <= t + EPS:
            self._sample()
            self.samples_taken += 1
            if len(next(iter(self._data.values()))) >= self._length:
                self.state, self.rr, self.next_due = 2, 0, math.inf
                return
            self.next_due += self._period

    def _sample(self) -> None:
        ram = self._ram()
        for n, values in self._data.items():
            name = self._ids.get(int(ram[f"RV[{n}]"]))
            source = self._sources.get(name) if name is not None else None
            values.append(float(source()) if source is not None else 0.0)  # signals not modelled read 0

    # -- upload -----------------------------------------------------------------------------------

    def upload(self, sub: int) -> bytes:
        n = sub - self.settings.recorder_sub_base + 1
        if self.state != 2 or n not in self._data:
            raise ODError(f"0x{RECORDER_OBJECT:04X}:{sub}: no recorded data", ABORT_NO_DATA)
        fault = self.settings.recorder_upload_fault
        if fault == "abort":
            raise ODError(f"0x{RECORDER_OBJECT:04X}:{sub}: upload refused (injected)", ABORT_LOCAL)
        name = self._ids.get(int(self._ram()[f"RV[{n}]"]), "")
        type_code = self.settings.recorder_type
        values = self._data[n]
        if type_code == TYPE_FLOAT:
            scale, raw = 1.0, list(values)
        else:
            scale = _LONG_SCALE.get(name, 1.0)
            raw = [max(-(2**31), min(2**31 - 1, round(v / scale))) for v in values]
        data = encode_upload(LAYOUTS[self.settings.recorder_header], type_code, scale, raw)
        if fault == "short":
            data = data[:-2]
        elif fault == "bad_type":
            data = bytes([0xF0 | data[0] & 0xF]) + data[1:]
        return data
