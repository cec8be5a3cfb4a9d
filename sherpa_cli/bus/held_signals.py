"""SIGINT, SIGTERM and SIGHUP held back while buses (and the in-process simulator) close.

A signal's exception raised half-way through a close leaves a bus open: its receive thread still
running, python-can's "VirtualBus was not properly shut down" on stderr at exit, a socket left to
the interpreter. Blocking the signal in the main thread is not enough (the kernel hands it to
another thread and CPython still runs the handler on the main one), so the handlers themselves
only note the signal here; it is delivered to the handler from before once everything is closed.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

HELD = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Run the block to its end; a signal that came meanwhile is delivered after it (main thread
    only: elsewhere handlers cannot be set, and Python runs them on the main thread anyway)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []

    def note(signum: int, frame: FrameType | None) -> None:
        came.append(signum)

    previous: dict[int, Callable[[int, FrameType | None], Any] | int] = {}
    for signum in HELD:
        handler = signal.getsignal(signum)
        if handler is None or handler == signal.SIG_IGN:
            continue  # ignored stays ignored; None: not set from Python, left alone
        previous[signum] = handler
        signal.signal(signum, note)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if came:
            signal.raise_signal(came[0])  # the first one, to the handler from before
