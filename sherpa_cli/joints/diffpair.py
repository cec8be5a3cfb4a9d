"""Differential pair kinematics in counts (seed Appendix C.3 and D.1.3).

Two motors a and b (a = lower node id) move two joints together:

    Σ = m_a + m_b        Δ = m_a - m_b
    m_a = (Σ + Δ) / 2    m_b = (Σ - Δ) / 2

Σ and Δ always have the same parity (their difference is 2*m_b), so a joint pair with
mixed parity has no integer motor position; :func:`to_motors` refuses it and
:func:`nearest_reachable` offers the closest pair that exists.

Motor box: a rectangle of allowed joint positions ``Σ ∈ [Σmin, Σmax]``, ``Δ ∈ [Δmin, Δmax]``
is a diamond in motor space. Its axis-aligned bounding box is

    m_a ∈ [(Σmin + Δmin)/2, (Σmax + Δmax)/2]
    m_b ∈ [(Σmin - Δmax)/2, (Σmax - Δmin)/2]

and on integer counts the bounds are rounded inward (ceil the minimum, floor the maximum).
That box contains every integer motor position whose (Σ, Δ) lies in the rectangle, and
every bound is reached by one of them, so it is the tightest per-motor limit a drive can
hold (VL[3]/VH[3], LL[3]/HL[3]). It is *necessary, not sufficient*: the box corners lie
outside the rectangle (e.g. both motors at their maximum give Σ = Σmax + Δmax), so the
tool must still check :func:`inside_joint_limits` in joint space before any motion.
The seed's rule ``(max_Σ + max_Δ)/2`` is this box for symmetric ranges.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral

from sherpa_cli.errors import UsageError

Range = tuple[int, int]


def _int(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise UsageError(f"{what} must be an integer number of counts, got {value!r}")
    return int(value)


def _range(r: Range, what: str) -> Range:
    try:
        lo, hi = r
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be a (min, max) pair, got {r!r}") from None
    lo, hi = _int(lo, f"{what} min"), _int(hi, f"{what} max")
    if lo > hi:
        raise UsageError(f"{what} is empty: min {lo} > max {hi}")
    return lo, hi


def _ceil_half(n: int) -> int:
    return -((-n) // 2)


def _floor_half(n: int) -> int:
    return n // 2


def to_joints(m_a: int, m_b: int) -> tuple[int, int]:
    """Motor counts -> (Σ, Δ)."""
    a, b = _int(m_a, "motor a position"), _int(m_b, "motor b position")
    return a + b, a - b


def to_motors(sigma: int, delta: int) -> tuple[int, int]:
    """(Σ, Δ) -> (m_a, m_b); UsageError when Σ and Δ differ in parity (no such motor position)."""
    s, d = _int(sigma, "Σ position"), _int(delta, "Δ position")
    if (s - d) % 2:
        raise UsageError(
            f"Σ={s} and Δ={d} cannot be reached: m_a=(Σ+Δ)/2 and m_b=(Σ-Δ)/2 are whole counts only "
            f"when Σ and Δ are both even or both odd",
            hint="change Σ or Δ by 1 count")
    return (s + d) // 2, (s - d) // 2


def is_reachable(sigma: int, delta: int) -> bool:
    return (_int(sigma, "Σ position") - _int(delta, "Δ position")) % 2 == 0


def nearest_reachable(sigma: int, delta: int, sigma_range: Range | None = None,
                      delta_range: Range | None = None) -> tuple[int, int]:
    """The reachable (Σ, Δ) nearest to the request (same pair when it is reachable).

    A mixed-parity request is exactly one count away from four reachable pairs; the choice
    is deterministic: keep Σ and move Δ toward zero, then Δ away from zero, then Σ toward
    zero, then Σ away from zero (from 0, -1 comes before +1). Σ is kept first because the
    Σ joint is the one calibrated from its switches (seed Table C.2 ``cal_pos``). When ranges
    are given the first candidate inside them wins; none inside raises UsageError.
    """
    s, d = _int(sigma, "Σ position"), _int(delta, "Δ position")
    sr = _range(sigma_range, "Σ range") if sigma_range is not None else None
    dr = _range(delta_range, "Δ range") if delta_range is not None else None

    def inside(cs: int, cd: int) -> bool:
        return (sr is None or sr[0] <= cs <= sr[1]) and (dr is None or dr[0] <= cd <= dr[1])

    if (s - d) % 2 == 0:
        if inside(s, d):
            return s, d
        raise UsageError(f"Σ={s}, Δ={d} is outside the joint limits Σ {sr}, Δ {dr}")

    def steps(v: int) -> list[int]:
        return sorted((v - 1, v + 1), key=lambda x: (abs(x), x))

    candidates = [(s, cd) for cd in steps(d)] + [(cs, d) for cs in steps(s)]
    for cs, cd in candidates:
        if inside(cs, cd):
            return cs, cd
    raise UsageError(f"no reachable position next to Σ={s}, Δ={d} lies inside Σ {sr}, Δ {dr}")


@dataclass(frozen=True)
class MotorBox:
    """Per-motor integer ranges (inclusive) that bound a Σ/Δ rectangle; see the module docstring."""

    a: Range
    b: Range

    def contains(self, m_a: int, m_b: int) -> bool:
        return self.a[0] <= m_a <= self.a[1] and self.b[0] <= m_b <= self.b[1]


def motor_box(sigma_range: Range, delta_range: Range) -> MotorBox:
    """Integer bounding box in motor space of the Σ/Δ rectangle, rounded inward.

    UsageError when the rectangle holds no reachable integer point (a single Σ and a single
    Δ of different parity): the box would be empty.
    """
    s_lo, s_hi = _range(sigma_range, "Σ range")
    d_lo, d_hi = _range(delta_range, "Δ range")
    a = (_ceil_half(s_lo + d_lo), _floor_half(s_hi + d_hi))
    b = (_ceil_half(s_lo - d_hi), _floor_half(s_hi - d_lo))
    if a[0] > a[1] or b[0] > b[1]:
        raise UsageError(f"Σ range {s_lo}..{s_hi} and Δ range {d_lo}..{d_hi} contain no reachable "
                         f"motor position (Σ and Δ must have the same parity)")
    return MotorBox(a=a, b=b)


def inside_joint_limits(m_a: int, m_b: int, sigma_range: Range, delta_range: Range) -> bool:
    """True when the motors' Σ and Δ both lie inside their (inclusive) ranges: the real check."""
    s, d = to_joints(m_a, m_b)
    s_lo, s_hi = _range(sigma_range, "Σ range")
    d_lo, d_hi = _range(delta_range, "Δ range")
    return s_lo <= s <= s_hi and d_lo <= d <= d_hi


# --------------------------------------------------------------------------- moving one joint of a pair

def motor_velocities(sigma_rate: int, delta_rate: int) -> tuple[int, int]:
    """Joint speeds (counts/s of Σ and Δ) -> motor speeds: the inverse transform per second,
    ``v_a = (vΣ + vΔ)/2``, ``v_b = (vΣ - vΔ)/2``, each rounded half away from zero.

    A Σ jog (vΔ = 0) runs both motors at vΣ/2; a Δ jog runs them at +vΔ/2 and -vΔ/2. With an
    odd joint speed both halves round away from zero, so the held joint still reads 0 and the
    moving joint runs one count/s faster than asked (reported as such).
    """
    s, d = _int(sigma_rate, "Σ speed"), _int(delta_rate, "Δ speed")
    return _half_away(s + d), _half_away(s - d)


def _half_away(n: int) -> int:
    return (n + 1) // 2 if n >= 0 else -((-n + 1) // 2)


def motor_currents(sigma_current: float, delta_current: float) -> tuple[float, float]:
    """Joint torques (as motor current, A) -> motor currents: ``I_a = IΣ + IΔ``, ``I_b = IΣ - IΔ``.

    This is the transpose of the position map (virtual work: the power of the two motors
    ``I_a·v_a + I_b·v_b`` equals ``IΣ·vΣ + IΔ·vΔ`` when ``IΣ = (I_a + I_b)/2``, ``IΔ = (I_a - I_b)/2``).
    A Σ torque of I drives both motors with I (both accelerate alike, Δ stays); a Δ torque of I
    drives motor a with +I and motor b with -I (Σ stays).
    """
    return sigma_current + delta_current, sigma_current - delta_current


def joint_currents(current_a: float, current_b: float) -> tuple[float, float]:
    """Motor currents (A) -> the joints' torques as current: ``IΣ = (I_a + I_b)/2``,
    ``IΔ = (I_a - I_b)/2``, the inverse of :func:`motor_currents`."""
    return (current_a + current_b) / 2, (current_a - current_b) / 2


def hold_other(sigma: int, delta: int, moving: str, held_range: Range | None = None) -> tuple[int, int]:
    """(Σ, Δ) for a move of one joint while the other holds: the moving joint's value is kept
    exactly; when the pair has no whole motor position (mixed parity) the held joint gives way
    by one count, inside ``held_range`` when given, else toward zero.
    """
    s, d = _int(sigma, "Σ position"), _int(delta, "Δ position")
    if moving not in ("sigma", "delta"):
        raise ValueError(f"moving must be 'sigma' or 'delta', got {moving!r}")
    if (s - d) % 2 == 0:
        return s, d
    held = d if moving == "sigma" else s
    candidates = sorted((held - 1, held + 1), key=lambda v: (abs(v), v))
    if held_range is not None:
        lo, hi = _range(held_range, "held joint range")
        candidates.sort(key=lambda v: not lo <= v <= hi)  # stable: toward zero among the inside ones
    return (s, candidates[0]) if moving == "sigma" else (candidates[0], d)
