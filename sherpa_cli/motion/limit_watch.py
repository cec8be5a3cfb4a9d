"""Joint-limit watch (seed section 6.1): the tool's own guard on joint positions during motion.

While a command moves a joint the tool samples the motor positions. When a joint leaves its
FULL range the command stops at once, nothing queued is sent, and the joint is moved back
(position mode) to the nearest edge of its NORMAL range. For a differential pair the check and
the way back are in joint space (Σ = m_a + m_b, Δ = m_a - m_b), since the drives' own limits
only see one motor each (the motor box is necessary, not sufficient: joints/diffpair.py).

In torque mode the drive's position and speed limits do not act (seed C.1.1, C.1.2), so this
watch is the only protection there; torque commands therefore also carry a time limit.

This module holds the pure decision logic on samples (:func:`check`, :func:`recovery_targets`)
and a small polling loop (:func:`watch`) whose I/O, time and stop conditions are injected.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from sherpa_cli.joints.diffpair import Range, is_reachable, to_motors
from sherpa_cli.motion.axis import Axis, Motors
from sherpa_cli.motion.blocked import StallWatch

TIME_EPSILON_S = 1e-9


def _clamp(x: int, r: Range | None) -> int:
    return x if r is None else min(max(x, r[0]), r[1])


@dataclass(frozen=True)
class Breach:
    """A joint found outside its full range, and where the recovery takes it."""

    joint: str
    position: int
    full: Range
    normal: Range

    @property
    def side(self) -> str:
        return "low" if self.position < self.full[0] else "high"

    @property
    def back_to(self) -> int:
        """The nearest edge of the normal range."""
        return _clamp(self.position, self.normal)

    def describe(self) -> str:
        return (f"joint {self.joint} at {self.position} counts left its full range "
                f"[{self.full[0]}, {self.full[1]}] on the {self.side} side")

    def as_dict(self) -> dict[str, object]:
        return {"joint": self.joint, "position": self.position, "full_range": list(self.full),
                "side": self.side, "back_to": self.back_to}


def check(joints: Sequence[Axis], motors: Motors) -> list[Breach]:
    """The joints outside their full range (inclusive bounds are inside)."""
    out = []
    for j in joints:
        p = j.position(motors)
        if j.full is not None and not j.full[0] <= p <= j.full[1]:
            out.append(Breach(j.name, p, j.full, j.normal or j.full))
    return out


def recovery_targets(joints: Sequence[Axis], motors: Motors, breaches: Sequence[Breach],
                     hold: Mapping[str, int] | None = None) -> dict[str, int]:
    """Motor targets (counts) that bring every breached joint to the nearest edge of its normal range.

    A plain joint is its motor. For a pair both joints are clamped into their normal ranges
    (a joint already inside stays where it is) and mapped back through the inverse transform;
    when Σ and Δ differ in parity (no whole motor position) the joint that did not breach gives
    way by one count, toward the inside of its normal range. ``hold`` gives a pair joint that did
    not breach the value to keep instead of where it stands (a jog's held joint: its value before
    the jog, which start and stop skew between the two motors may have shifted by a few counts).
    Only drives that must move are returned.
    """
    hold = hold or {}
    breached = {b.joint for b in breaches}
    targets: dict[str, int] = {}
    pairs: dict[tuple[str, str], dict[int, Axis]] = {}
    for j in joints:
        if j.drive_b is None:
            if j.name in breached:
                targets[j.drive_a] = _clamp(j.position(motors), j.normal)
        else:
            pairs.setdefault((j.drive_a, j.drive_b), {})[j.sign] = j
    for (a, b), members in pairs.items():
        if not breached & {m.name for m in members.values()}:
            continue
        m_a, m_b = motors[a], motors[b]
        s, d = m_a + m_b, m_a - m_b
        sig, dlt = members.get(1), members.get(-1)
        if sig is not None and sig.name not in breached and sig.name in hold:
            s = hold[sig.name]
        if dlt is not None and dlt.name not in breached and dlt.name in hold:
            d = hold[dlt.name]
        s2 = _clamp(s, sig.normal) if sig is not None else s
        d2 = _clamp(d, dlt.normal) if dlt is not None else d
        if not is_reachable(s2, d2):
            s2, d2 = _give_way(s2, d2, sig, dlt, breached)
        targets[a], targets[b] = to_motors(s2, d2)
    return targets


def _give_way(s: int, d: int, sig: Axis | None, dlt: Axis | None,
              breached: set[str]) -> tuple[int, int]:
    """Move one joint by one count so Σ and Δ share parity: the joint that did not breach gives
    way (Δ when only Σ breached, else Σ), to the side inside its normal range, toward its middle."""
    move_delta = sig is not None and sig.name in breached and not (dlt is not None and dlt.name in breached)
    moving, value = (dlt, d) if move_delta else (sig, s)
    candidates = [value - 1, value + 1]
    if moving is not None and moving.normal is not None:
        lo, hi = moving.normal
        candidates.sort(key=lambda v: (not lo <= v <= hi, abs(2 * v - lo - hi)))
    return (s, candidates[0]) if move_delta else (candidates[0], d)


@dataclass(frozen=True)
class WatchResult:
    """How a watched motion ended.

    ``outcome``: ``finished`` (the motion's own end), ``elapsed`` (its time, --for, is over),
    ``breach`` (a joint left its full range: the caller must stop and recover), ``stalled`` (no
    progress for the stall time: blocked by a switch, a hard stop or a load; motion/blocked.py).
    """

    outcome: str
    motors: Mapping[str, int]  # the last sample
    breaches: tuple[Breach, ...] = ()
    samples: int = 0
    elapsed: float = 0.0
    joints: Mapping[str, int] = field(default_factory=dict)  # joint positions at the last sample


def watch(joints: Sequence[Axis], sample: Callable[[], Motors], *,
          clock: Callable[[], float], sleep: Callable[[float], None], interval: float,
          finished: Callable[[Motors], bool] | None = None, duration: float | None = None,
          check_drives: Callable[[], None] | None = None, stall: StallWatch | None = None) -> WatchResult:
    """Sample the motors every ``interval`` s until the motion finishes, ``duration`` s pass, or a
    joint leaves its full range (checked first on every sample, so a breach always wins).

    ``check_drives`` (the motion guard's fault check) runs after every sample and may raise;
    ``stall`` ends the watch when the motors stop progressing.
    ``finished`` or ``duration`` must be given: the loop never runs open-ended.
    """
    if finished is None and duration is None:
        raise ValueError("watch needs finished or duration: a watch must end")
    start = clock()
    n = 0
    while True:
        motors = dict(sample())
        n += 1
        elapsed = clock() - start
        positions = {j.name: j.position(motors) for j in joints}
        breaches = check(joints, motors)
        if breaches:
            return WatchResult("breach", motors, tuple(breaches), n, elapsed, positions)
        if check_drives is not None:
            check_drives()
        if finished is not None and finished(motors):
            return WatchResult("finished", motors, (), n, elapsed, positions)
        # a remainder below TIME_EPSILON_S is float error of the clock's sums: sleeping it would not
        # move a stepped clock, and the watch would never end
        if duration is not None and elapsed >= duration - TIME_EPSILON_S:
            return WatchResult("elapsed", motors, (), n, elapsed, positions)
        if stall is not None and stall.feed(motors, clock()):
            return WatchResult("stalled", motors, (), n, elapsed, positions)
        wait = interval if duration is None else min(interval, max(duration - elapsed, 0.0))
        sleep(wait if wait > 0 else interval)


class BreachOutcome:
    """What a move's result says of its limit watch (the result dataclasses of the movers inherit
    it): ``ok`` unless a joint left its full range, then ``outcome`` "limit"."""

    breaches: list[Breach]

    @property
    def ok(self) -> bool:
        return not self.breaches

    @property
    def outcome(self) -> str:
        return "limit" if self.breaches else "done"
