"""When a step experiment has settled, and what may be reported when it has not.

A step is *settled* when its signal has stayed within ``BAND`` (2 %) of the step around the
target for ``hold`` seconds at the end of what was recorded. Only a settled step has an
overshoot, a settling time and a steady-state error: a record cut off while the joint still
moves would report a "final value" the trace then crosses (the seed's Fig. 9.1 with ``--for``
too short). :func:`judged` blanks those figures of a step that did not settle.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from sherpa_cli.log.step_metrics import StepMetrics

BAND = 0.02  # share of the step the signal must stay within around the target
HOLD_S = 0.2  # s it must stay there to count as settled


def settled_at_end(times: Sequence[float], values: Sequence[float], target: float, *,
                   hold: float = HOLD_S, band: float = BAND) -> bool:
    """Whether the last ``hold`` s of the record (t = 0: the command) lie within ``band`` of the
    step around ``target``; the step's size is measured from the last sample before t = 0."""
    before = [v for t, v in zip(times, values, strict=True) if t < 0]
    if not before or not times:
        return False
    limit = band * max(abs(target - before[-1]), 1e-9)
    end = times[-1]
    tail = [v for t, v in zip(times, values, strict=True) if t >= end - hold]
    return len(tail) > 2 and end > hold and all(abs(v - target) <= limit for v in tail)


def judged(metrics: StepMetrics, settled: bool) -> StepMetrics:
    """``metrics`` as reported: a step that did not settle keeps its dead time and rise time (both
    are over once the signal passed 90 %) but has no overshoot, settling time or steady-state error."""
    if settled:
        return dataclasses.replace(metrics, settled=True)
    return dataclasses.replace(metrics, overshoot=None, settling_time=None, steady_state_error=None, settled=False)
