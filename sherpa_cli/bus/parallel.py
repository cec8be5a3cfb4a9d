"""Run work on several buses (or drives) at once and collect every outcome."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Hashable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

K = TypeVar("K", bound=Hashable)


@dataclass
class Outcome(Generic[K]):
    key: K
    value: Any = None
    error: BaseException | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def run_concurrently(jobs: Mapping[K, Callable[[], Any]], *, max_workers: int | None = None,
                     on_interrupt: Callable[[], None] | None = None) -> dict[K, Outcome[K]]:
    """Run every job in its own thread; an exception in one job never stops the others.

    CAN work is I/O-bound (waiting for replies), so threads overlap it well even under the GIL.
    Results keep the order of ``jobs`` so output stays deterministic whatever finished first.
    ``on_interrupt``: while the jobs run, Ctrl-C calls it (the jobs' cue to stop at a safe
    point) instead of raising KeyboardInterrupt, so every job is still waited for and reported.
    """
    if not jobs:
        return {}
    if on_interrupt is not None and threading.current_thread() is threading.main_thread():
        # A handler, not `except KeyboardInterrupt`: the signal may land inside pool.submit,
        # where an exception would lose the future of a job that already started.
        previous = signal.signal(signal.SIGINT, lambda signum, frame: on_interrupt())
        try:
            return run_concurrently(jobs, max_workers=max_workers)
        finally:
            signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)
    outcomes: dict[K, Outcome[K]] = {}
    with ThreadPoolExecutor(max_workers=max_workers or len(jobs), thread_name_prefix="sherpa") as pool:
        futures = {key: pool.submit(job) for key, job in jobs.items()}
        for key, future in futures.items():
            # what the job raised is its outcome; what this thread's wait raised (a SIGTERM's
            # Terminated, a Ctrl-C) is not the job's: it propagates once every job has ended
            error = future.exception()
            outcomes[key] = Outcome(key, error=error) if error is not None else Outcome(key, value=future.result())
    return outcomes
