"""Digital inputs of a simulated drive: what IP shows and which directions stop switches block.

Input functions follow the [MBARI] IL table (elmo-protocol.md 2.4), value // 2 = function.
The polarity half (even = active low) is not modelled: an input is simply active or not.
"""

from __future__ import annotations

import builtins
from collections.abc import Callable

IP_PIN_SHIFT = 16
# IL value // 2 -> IP function bit; "both stop" shows as soft + hard stop.
_IL_FLAGS = {0: 1 << 12, 1: 1 << 9, 4: 1 << 11, 5: 1 << 10, 6: 1 << 13, 7: 1 << 8, 8: 1 << 6, 9: 1 << 7,
             10: (1 << 8) | (1 << 9), 11: 1 << 14}
_STOP_FUNCTIONS = {1, 7, 10}  # hard stop, soft stop, both stop
_RLS, _FLS = 4, 5


class Inputs:
    """``set`` is what the mechanics do to switch ``n`` (its wire); ``press`` is a technician holding
    it (``home --check-wiring``); ``swap``/``invert`` are wiring faults between switch and pin."""

    def __init__(self, count: int) -> None:
        self._state: dict[int, tuple[bool, int]] = {n: (False, 0) for n in range(1, count + 1)}
        self._pressed: dict[int, bool] = {}
        self._pin_of: dict[int, int] = {}
        self._inverted: set[int] = set()

    def wiring_faults(self, swap: tuple[tuple[int, int], ...] = (), invert: tuple[int, ...] = ()) -> None:
        for a, b in swap:
            self._pin_of[a], self._pin_of[b] = b, a
        self._inverted = set(invert)

    def press(self, n: int, pressed: bool | None) -> None:
        """A hand on switch ``n``: True pressed, False released, None: back to the mechanics."""
        if pressed is None:
            self._pressed.pop(n, None)
        else:
            self._pressed[n] = bool(pressed)

    def pin(self, n: int) -> bool:
        """The level the drive reads on input ``n`` (1-based)."""
        return any(p == n for p, _ in self._active())

    def set(self, n: int, active: bool, direction: int = 0) -> None:
        if n not in self._state:
            raise ValueError(f"input {n} does not exist (1..{len(self._state)})")
        if direction not in (-1, 0, 1):
            raise ValueError(f"direction must be -1, 0 or +1, got {direction!r}")
        self._state[n] = (bool(active), direction)

    def _active(self) -> list[tuple[int, int]]:
        if not (self._pressed or self._pin_of or self._inverted):
            return [(n, direction) for n, (active, direction) in self._state.items() if active]
        out = []
        for n, (active, direction) in self._state.items():
            active = self._pressed.get(n, active) != (n in self._inverted)
            if active:
                out.append((self._pin_of.get(n, n), direction))
        return out

    def ip(self, il: Callable[[int], int]) -> int:
        """IP: raw pins from bit 16, the per-input flags of inputs 1..6, and function flags."""
        value = 0
        for n, _ in self._active():
            value |= 1 << (IP_PIN_SHIFT + n - 1) | _IL_FLAGS.get(il(n) // 2, 0)
            if n <= 6:
                value |= 1 << (n - 1)
        return value

    def blocked(self, il: Callable[[int], int], stop_code: int) -> builtins.set[int]:  # here `set` is the method
        """Directions (+1, -1) in which active switches forbid motion.

        A stop switch blocks the side it lies on; without a side it blocks both, as a hard
        stop freezes the reference. FLS/RLS block their own side whatever ``direction`` says.
        """
        blocked: set[int] = set()
        for n, direction in self._active():
            function = il(n) // 2
            if function in _STOP_FUNCTIONS or function == stop_code // 2:
                blocked.update((direction,) if direction else (-1, 1))
            elif function == _FLS:
                blocked.add(1)
            elif function == _RLS:
                blocked.add(-1)
        return blocked
