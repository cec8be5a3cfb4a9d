"""`sherpa ft show` and `sherpa ft bias`: F/T sensor readings and its bias, without printing.

A sample is one request and its two reply frames within the sensor's ``reply_ms``
(devices/ft_sensor.py); the pace between samples and the clock are injected.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sherpa_cli.config.model import DeviceConfig
from sherpa_cli.devices.ft_sensor import BIAS, Wrench, open_reader

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession


MAX_RATE_HZ = 200.0  # a sample is a request and two frames, a few ms on a busy bus


def stream(session: ArmSession, dev: DeviceConfig, *, count: int | None, period: float,
           sleep: Callable[[float], None] = time.sleep,
           clock: Callable[[], float] = time.monotonic) -> Iterator[Wrench]:
    """``count`` samples (None: until the caller stops), one every ``period`` s."""
    with open_reader(session, dev, clock=clock) as reader:
        done = 0
        while count is None or done < count:
            if done:
                sleep(period)
            yield reader.read()
            done += 1


@dataclass(frozen=True)
class BiasResult:
    device: str
    applied: bool
    before: Wrench
    after: Wrench | None  # None: a dry run
    frame: str  # the bias frame, as sent or as it would be sent

    def as_json(self) -> dict[str, object]:
        def w(x: Wrench | None) -> dict[str, float] | None:
            return None if x is None else {k: round(v, 4) for k, v in x.axes().items()}
        return {"device": self.device, "applied": self.applied, "frame": self.frame, "before": w(self.before),
                "after": w(self.after)}


def bias(session: ArmSession, dev: DeviceConfig, *, apply: bool,
         clock: Callable[[], float] = time.monotonic) -> BiasResult:
    """A reading, then (``apply``) the bias command and a reading after it."""
    assert dev.ft is not None
    frame = f"{dev.ft.base_id:03X}#{BIAS:02X}"
    with open_reader(session, dev, clock=clock) as reader:
        before = reader.read()
        if not apply:
            return BiasResult(dev.name, False, before, None, frame)
        reader.bias()
        return BiasResult(dev.name, True, before, reader.read(), frame)


@dataclass(frozen=True)
class SensorReading:
    """One sample of a sensor for a status view (monitor, identify): the wrench, or why there is none."""

    device: str
    bus: str
    base_id: int
    wrench: Wrench | None
    problem: str | None = None

    def as_json(self) -> dict[str, object]:
        w = self.wrench
        return {"device": self.device, "bus": self.bus, "base_id": self.base_id,
                "wrench": None if w is None else {k: round(v, 4) for k, v in w.axes().items()},
                "status": None if w is None else w.status.raw, "sample": None if w is None else w.sample,
                "problem": self.problem}


def read_sensors(session: ArmSession, devs: list[DeviceConfig]) -> list[SensorReading]:
    """One sample of each sensor; a sensor that does not answer is a reading with its problem."""
    from sherpa_cli.errors import CommunicationError

    out = []
    for dev in devs:
        assert dev.ft is not None
        try:
            with open_reader(session, dev) as reader:
                out.append(SensorReading(dev.name, dev.bus, dev.ft.base_id, reader.read()))
        except CommunicationError as exc:
            out.append(SensorReading(dev.name, dev.bus, dev.ft.base_id, None, exc.message))
    return out
