"""Step-response metrics of a sampled signal: a small pure function (no numpy, no scipy).

Definitions (as ``control.step_info``, with the command's time as t = 0):

- final value: mean of the samples in the last ``final_share`` of the record;
- dead time: from the command until the response first leaves ``band`` (2 %) of the step
  around the initial value (includes a mode switch's delay, seed Fig. 9.1);
- rise time: from the first 10 % crossing to the first 90 % crossing of the step;
- overshoot: peak beyond the final value in % of the step (0 when none);
- settling time: from the command until the response last enters ``band`` of the step around
  the final value and stays there;
- steady-state error: target - final value (when a target is given).

Crossing times are interpolated linearly between samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class StepMetrics:
    initial: float
    final: float
    target: float | None
    dead_time: float | None  # s
    rise_time: float | None  # s, 10-90 %
    overshoot: float | None  # % of the step (None: the step did not settle, log/settle.py)
    settling_time: float | None  # s to stay within band of the final value
    steady_state_error: float | None  # target - final, in the signal's unit
    settled: bool  # the record ends inside the band

    def as_json(self, digits: int = 6) -> dict:
        return {k: (round(v, digits) if isinstance(v, float) else v) for k, v in asdict(self).items()}


def _crossing(t: Sequence[float], y: Sequence[float], start: int, level: float, sign: float) -> float | None:
    """First time at or after sample ``start`` where sign*(y - level) >= 0, interpolated."""
    for i in range(start, len(y)):
        if sign * (y[i] - level) >= 0:
            if i == start or i == 0:
                return t[i]
            y0, y1 = y[i - 1], y[i]
            if y1 == y0:
                return t[i]
            return t[i - 1] + (level - y0) * (t[i] - t[i - 1]) / (y1 - y0)
    return None


# the least change (initial -> final) that counts as a step, per signal column (rad, rad/s, A): a few
# counts of a still joint's quantisation are not a step, and get no metrics
MIN_STEP = {"pos_rad": 0.005, "vel_rad_s": 0.01, "cur_a": 0.02}


def step_size(t: Sequence[float], y: Sequence[float], *, t_step: float = 0.0, final_share: float = 0.05) -> float:
    """final - initial as :func:`step_metrics` takes them (0.0 when there is nothing after the step)."""
    first = next((i for i, ti in enumerate(t) if ti >= t_step), None)
    if first is None or len(t) < 2 or len(t) != len(y):
        return 0.0
    y0 = y[max(first - 1, 0)]
    tail_from = t[-1] - final_share * (t[-1] - t[first])
    tail = [v for ti, v in zip(t, y, strict=True) if ti >= tail_from] or [y[-1]]
    return sum(tail) / len(tail) - y0


def stepped(t: Sequence[float], y: Sequence[float], *, threshold: float, t_step: float = 0.0) -> bool:
    """Whether the signal changed by at least ``threshold`` across the step (MIN_STEP per signal)."""
    return abs(step_size(t, y, t_step=t_step)) >= threshold


def step_metrics(t: Sequence[float], y: Sequence[float], *, t_step: float = 0.0, target: float | None = None,
                 initial: float | None = None, band: float = 0.02, final_share: float = 0.05) -> StepMetrics:
    """Metrics of the response ``y(t)`` to a step commanded at ``t_step`` (times in s, ascending)."""
    if len(t) != len(y) or len(t) < 2:
        raise ValueError("step_metrics needs at least two samples and as many times as values")
    if any(not math.isfinite(v) for v in (*t, *y)):
        raise ValueError("step_metrics: times and values must be finite numbers")
    first = next((i for i, ti in enumerate(t) if ti >= t_step), None)
    if first is None:
        raise ValueError(f"step_metrics: no sample at or after the step (t = {t_step})")
    y0 = initial if initial is not None else y[max(first - 1, 0)] if first > 0 else y[0]
    tail_from = t[-1] - final_share * (t[-1] - t[first])
    tail = [v for ti, v in zip(t, y, strict=True) if ti >= tail_from] or [y[-1]]
    yf = sum(tail) / len(tail)
    step = yf - y0
    sse = None if target is None else target - yf
    if step == 0:
        return StepMetrics(y0, yf, target, None, None, 0.0, None, sse, True)
    sign = 1.0 if step > 0 else -1.0
    tt, yy = t[first:], y[first:]

    def cross(fraction: float, start: int = 0) -> float | None:
        return _crossing(tt, yy, start, y0 + fraction * step, sign)

    moved = cross(band)
    t10, t90 = cross(0.10), cross(0.90)
    dead = None if moved is None else moved - t_step
    rise = None if t10 is None or t90 is None else t90 - t10
    peak = max(yy) if sign > 0 else min(yy)
    overshoot = max(0.0, sign * (peak - yf) / abs(step) * 100.0)
    limit = band * abs(step)
    last_out = None
    for i in range(len(yy) - 1, -1, -1):
        if abs(yy[i] - yf) > limit:
            last_out = i
            break
    settled = abs(yy[-1] - yf) <= limit
    if last_out is None:
        settling = tt[0] - t_step
    elif last_out == len(yy) - 1:
        settling = None
    else:
        a, b = yy[last_out], yy[last_out + 1]
        edge = yf + math.copysign(limit, a - yf)
        frac = (edge - a) / (b - a) if b != a else 1.0
        settling = tt[last_out] + frac * (tt[last_out + 1] - tt[last_out]) - t_step
    return StepMetrics(y0, yf, target, dead, rise, overshoot, settling, sse, settled)
