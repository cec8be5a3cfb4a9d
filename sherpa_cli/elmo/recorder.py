"""The drive's own recorder (real-arm.md section 2): configure, arm, poll, upload, scale.

What the sources say (MAN-SIMCR, MAN-SIMSW 7.4, MAN-CAN301IG): ``RV[N]=x`` maps signal id x to
logical signal N; ``RC`` is the mask of logical signals (at most 8); ``RG`` the gap (``RG=1``
samples every sample time); ``RL`` the length; ``RP[3]`` the trigger (0 immediate, 1 BG);
``RR`` arms (0 kill, 1 start at the next BG, 2 start now) and reads the state (-1 no data,
0 data ready, 1..3 waiting or recording); SR bits 16-17 hold the state too (0 inactive,
1 waiting, 2 data ready, 3 recording). Over CAN each recorded signal is uploaded by segmented
SDO from object 0x2030, one sub-index per signal.

What only one source says -- cob_driver's ElmoRecorder.cpp, for a Harmonica, not a Whistle --
is a :class:`RecorderSettings` field with that source's value as default, and the simulator
(sim/recorder.py) plays either way: the signal ids, the 0x2030 header layout (type nibble,
sample count, float scale factor, then 4-byte little-endian samples) and the sample time
(90 us x 4 on that drive).

Everything here is RAM: :meth:`DriveRecorder.snapshot` reads what it will change and
:meth:`DriveRecorder.restore` writes it back (ops/drive_record.py does so on every exit path).
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from sherpa_cli.errors import ProtocolError, UsageError

if TYPE_CHECKING:
    from sherpa_cli.elmo.client import DriveClient

RECORDER_OBJECT = 0x2030  # "bring recorded data" (MAN-CAN301IG p. 13-5)
MAX_SIGNALS = 8  # RC: at most 8 signals at once
MAX_GAP = 4096  # RG: 1..4096
SR_RECORDER_SHIFT = 16  # SR bits 16-17
SR_STATES = {0: "inactive", 1: "waiting for the trigger", 2: "data ready", 3: "recording"}
RR_KILL, RR_AT_BG, RR_NOW = 0, 1, 2
TRIGGER_NOW, TRIGGER_BG = 0, 1  # RP[3]
TYPE_HALF, TYPE_LONG, TYPE_FLOAT = 1, 4, 5  # byte 0 high nibble of an upload (cob_driver)
TYPE_NAMES = {TYPE_HALF: "half float", TYPE_LONG: "long", TYPE_FLOAT: "float"}

# What the tool records, in this order; the ids are a setting (RecorderSettings.signal_ids).
SIGNALS = ("pos", "vel", "cur", "pos_err", "vel_cmd")
SIGNAL_TEXT = {"pos": "position (counts)", "vel": "velocity (cnt/s)", "cur": "active current (A)",
               "pos_err": "position error (counts)", "vel_cmd": "speed command (cnt/s)"}
# cob_driver's RC=33283 sets bits 0, 1, 9, 15: speed 1, position 2, active current 10, speed
# command 16 (one source). No public source names the position error's id: 4 is a guess,
# UNCONFIRMED -- check it on the bench (Composer's recorder list) and set it in the config.
DEFAULT_SIGNAL_IDS: tuple[tuple[str, int], ...] = (("pos", 2), ("vel", 1), ("cur", 10), ("pos_err", 4),
                                                  ("vel_cmd", 16))


@dataclass(frozen=True)
class HeaderLayout:
    """Where the type nibble (high nibble of byte 0), the u16 sample count, the f32 scale factor
    and the first sample sit in one signal's 0x2030 upload."""

    name: str
    count_at: int
    scale_at: int
    data_at: int


# "cob": cob_driver's reading (bytes 1-2 count, 3-6 scale, data from 7); "aligned": an 8-byte
# header (count at 2, scale at 4, data at 8), the other plausible reading of the same fields.
LAYOUTS: Mapping[str, HeaderLayout] = {
    "cob": HeaderLayout("cob", 1, 3, 7),
    "aligned": HeaderLayout("aligned", 2, 4, 8),
}


@dataclass(frozen=True)
class RecorderSettings:
    """Recorder details that rest on one source (real-arm.md 2): the documented value as default."""

    sample_time_s: float = 360e-6  # RG=1 period: cob_driver's 90 us x 4 (Whistle: WS[29], UNCONFIRMED)
    capacity: int = 4096  # samples shared by the recorded signals (cob_driver: RL = 4096 / signals)
    header: str = "cob"  # a LAYOUTS key
    signal_ids: tuple[tuple[str, int], ...] = DEFAULT_SIGNAL_IDS
    sub_base: int = 1  # 0x2030 sub-index of logical signal N is N - 1 + sub_base (RC bit k -> sub k + sub_base)
    state_from: Literal["RR", "SR"] = "RR"  # which register the tool polls for "data ready"
    poll_interval_s: float = 0.02

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_time_s) and self.sample_time_s > 0):
            raise ValueError("RecorderSettings.sample_time_s must be a number > 0")
        if self.header not in LAYOUTS:
            raise ValueError(f"RecorderSettings.header must be one of {', '.join(LAYOUTS)}")
        if not 1 <= self.capacity <= 1 << 20:
            raise ValueError("RecorderSettings.capacity must be 1..1048576")
        if self.state_from not in ("RR", "SR"):
            raise ValueError("RecorderSettings.state_from must be RR or SR")

    def signal_id(self, name: str) -> int:
        for signal, sid in self.signal_ids:
            if signal == name:
                return sid
        raise ValueError(f"no signal id for {name!r}")


@dataclass(frozen=True)
class RecorderPlan:
    """One recording: which signals (logical ids 1..n in this order), gap, length, trigger."""

    signals: tuple[str, ...]
    gap: int
    length: int
    trigger: Literal["now", "bg"]

    @property
    def mask(self) -> int:
        return (1 << len(self.signals)) - 1

    def period(self, settings: RecorderSettings) -> float:
        return settings.sample_time_s * self.gap

    def writes(self, settings: RecorderSettings) -> list[tuple[str, int, int]]:
        """The sets that configure the recorder, in order (the recorder killed first)."""
        return [("RR", 0, RR_KILL),
                *[("RV", n, settings.signal_id(s)) for n, s in enumerate(self.signals, start=1)],
                ("RC", 0, self.mask), ("RG", 0, self.gap), ("RL", 0, self.length),
                ("RP", 3, TRIGGER_BG if self.trigger == "bg" else TRIGGER_NOW)]


def plan_recording(duration: float, settings: RecorderSettings, *, signals: Sequence[str] = SIGNALS,
                   trigger: Literal["now", "bg"] = "now") -> RecorderPlan:
    """The finest gap whose buffer holds ``duration`` seconds, and the length that covers it."""
    if not signals or len(signals) > MAX_SIGNALS:
        raise UsageError(f"the recorder takes 1..{MAX_SIGNALS} signals, not {len(signals)}")
    unknown = [s for s in signals if s not in SIGNALS]
    if unknown:
        raise UsageError(f"unknown recorder signal {unknown[0]!r}", hint=f"one of {', '.join(SIGNALS)}")
    if not (math.isfinite(duration) and duration > 0):
        raise UsageError(f"recording time {duration!r}: expected seconds > 0")
    per_signal = settings.capacity // len(signals)
    gap = max(1, math.ceil(duration / (per_signal * settings.sample_time_s) - 1e-9))
    if gap > MAX_GAP:
        longest = MAX_GAP * per_signal * settings.sample_time_s
        raise UsageError(f"--for {duration:g} s: the drive's recorder holds at most {longest:g} s "
                         f"of {len(signals)} signals")
    length = min(per_signal, max(2, math.ceil(duration / (gap * settings.sample_time_s) - 1e-9)))
    return RecorderPlan(tuple(signals), gap, length, trigger)


def encode_upload(layout: HeaderLayout, type_code: int, scale: float, raw: Sequence[int | float]) -> bytes:
    """One signal's 0x2030 data as the drive sends it (the simulator's side)."""
    head = bytearray(layout.data_at)
    head[0] = (type_code & 0xF) << 4
    struct.pack_into("<H", head, layout.count_at, len(raw))
    struct.pack_into("<f", head, layout.scale_at, scale)
    fmt = "<f" if type_code == TYPE_FLOAT else "<i"
    return bytes(head) + b"".join(struct.pack(fmt, v) for v in raw)


def decode_upload(data: bytes, layout: HeaderLayout, *, what: str) -> list[float]:
    """Samples (scaled) of one signal's 0x2030 data; ProtocolError naming ``what`` on anything off."""
    hint = ("the drive's upload does not match recorder.header / the drive's firmware; "
            "the recording was not written")
    if len(data) < layout.data_at:
        raise ProtocolError(f"{what}: {len(data)} byte(s), shorter than the {layout.data_at}-byte header "
                            f"({layout.name} layout)", hint=hint)
    type_code = data[0] >> 4
    if type_code not in (TYPE_LONG, TYPE_FLOAT):
        known = "half float: sample layout unknown, not read" if type_code == TYPE_HALF else "unknown"
        raise ProtocolError(f"{what}: data type nibble {type_code} ({known}); expected {TYPE_LONG} (long) "
                            f"or {TYPE_FLOAT} (float)", hint=hint)
    (count,) = struct.unpack_from("<H", data, layout.count_at)
    (scale,) = struct.unpack_from("<f", data, layout.scale_at)
    body = len(data) - layout.data_at
    if body != 4 * count:
        raise ProtocolError(f"{what}: header says {count} sample(s) ({4 * count} bytes), the upload carries "
                            f"{body} byte(s) after the header", hint=hint)
    if not math.isfinite(scale):
        raise ProtocolError(f"{what}: scale factor {scale!r} is not a finite number", hint=hint)
    fmt = f"<{count}{'f' if type_code == TYPE_FLOAT else 'i'}"
    return [v * scale for v in struct.unpack_from(fmt, data, layout.data_at)]


Upload = Callable[[int, int], bytes]  # (index, sub-index) -> data; raises SdoError (bus/sdo.py DriveSdo.upload)


class DriveRecorder:
    """One drive's recorder through its interpreter client and an SDO upload function."""

    def __init__(self, client: DriveClient, upload: Upload, settings: RecorderSettings | None = None, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.client = client
        self.upload = upload
        self.settings = settings or RecorderSettings()
        self._clock = clock
        self._sleep = sleep

    def snapshot(self, plan: RecorderPlan) -> list[tuple[str, int, int | float]]:
        """The values :meth:`configure` will change (RR aside), to put back with :meth:`restore`."""
        return [(letters, index, self.client.get(letters, index))
                for letters, index, _ in plan.writes(self.settings) if letters != "RR"]

    def configure(self, plan: RecorderPlan) -> None:
        for letters, index, value in plan.writes(self.settings):
            # RR reads the recorder's state, not what was written: after RR=0 (kill) it reads "no
            # data" (-1) or "data ready" (0), which a drive that does not echo sets confirms
            self.client.set(letters, index, value,
                            reads_back=(lambda state: int(state) in (-1, 0)) if letters == "RR" else None)

    def arm(self, plan: RecorderPlan) -> None:
        """RR=2 (start now) or RR=1 (start at the next BG, e.g. the pair's one group BG)."""
        value = RR_AT_BG if plan.trigger == "bg" else RR_NOW
        if self.client.settings.expect_set_echo:
            self.client.set("RR", 0, value)
        else:
            # no echo, and a read-back of RR is the state, not the value written: the polls confirm it
            self.client.send_only("RR", 0, value)

    def ready(self) -> bool:
        """Data ready: RR reads 0, or SR bits 16-17 read 2 (RecorderSettings.state_from)."""
        if self.settings.state_from == "SR":
            return (int(self.client.get("SR")) >> SR_RECORDER_SHIFT) & 3 == 2
        return int(self.client.get("RR")) == 0

    def wait_ready(self, timeout: float) -> None:
        deadline = self._clock() + timeout
        while not self.ready():
            if self._clock() >= deadline:
                state = (int(self.client.get("SR")) >> SR_RECORDER_SHIFT) & 3
                raise ProtocolError(f"{self.client.label}: the recorder has no data after {timeout:g} s "
                                    f"(SR says: {SR_STATES[state]})",
                                    hint="with --trigger bg it waits for a BG; else check RR and SR on the drive")
            self._sleep(self.settings.poll_interval_s)

    def read(self, plan: RecorderPlan) -> dict[str, list[float]]:
        """Upload every signal (all of them before anything is returned: no partial result)."""
        layout = LAYOUTS[self.settings.header]
        out: dict[str, list[float]] = {}
        for n, signal in enumerate(plan.signals):
            sub = n + self.settings.sub_base
            data = self.upload(RECORDER_OBJECT, sub)
            out[signal] = decode_upload(data, layout,
                                        what=f"{self.client.label}: recorder upload 0x{RECORDER_OBJECT:04X}:{sub} "
                                             f"({signal})")
        counts = {len(v) for v in out.values()}
        if len(counts) > 1:
            raise ProtocolError(f"{self.client.label}: the recorder's signals have different sample counts "
                                f"({', '.join(f'{k} {len(v)}' for k, v in out.items())})",
                                hint="the recording was not written")
        return out

    def kill(self) -> None:
        self.client.set("RR", 0, RR_KILL) if self.client.settings.expect_set_echo else \
            self.client.send_only("RR", 0, RR_KILL)

    def restore(self, saved: Sequence[tuple[str, int, int | float]]) -> None:
        """Stop the recorder and put the saved settings back."""
        self.kill()
        for letters, index, value in saved:
            self.client.set(letters, index, value)
