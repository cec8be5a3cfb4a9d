"""What a recording adds for an MCAP or a live view (`log record`, `log step`, `Arm.record`): the
drives' status read before and after, the EMCYs heard meanwhile, and the newest sample for the
live feed. Nothing here imports mcap or foxglove-sdk at import time."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.bus.targets import DriveRef
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.elmo.faults import Emcy
    from sherpa_cli.log.foxglove_live import LiveView
    from sherpa_cli.log.mcap_out import TimedEmcy, TimedStatus
    from sherpa_cli.log.record import Poller, Recorder


class RecordExtras:
    """What `log record` / `log step` add for an MCAP or a live view: the drives' status (MO, UM, SR,
    MF) read before and after the recording, the EMCYs heard meanwhile, and the live feed. With
    neither an MCAP nor a live view it does nothing (the recording sends what it always sent)."""

    def __init__(self, session: ArmSession, refs: Sequence[DriveRef], *, mcap: bool, view: LiveView | None,
                 budget: Mapping[str, float] | None = None) -> None:
        self.session, self.refs, self.view = session, list(refs), view
        self.active = mcap or view is not None
        self.status: list[TimedStatus] = []
        self.emcy: list[TimedEmcy] = []
        self.budget = dict(budget or {})
        self._listening: list[tuple[DriveRef, Callable[[Emcy], None]]] = []

    def stop(self) -> None:
        """Stop listening for EMCY: a long-lived session's clients outlive this recording, and its
        result must not change after it is handed over."""
        for ref, heard in self._listening:
            self.session.client(ref).remove_emcy(heard)
        self._listening.clear()

    def read_status(self) -> None:
        if not self.active:
            return
        from sherpa_cli.log.mcap_out import TimedStatus, read_states

        ns = time.time_ns()
        states = read_states(self.session, self.refs)
        self.status.append(TimedStatus(ns, states))
        if self.view is not None:
            self.view.status(states, ns=ns)

    def start(self) -> None:
        """Status at the start, and listen for EMCY (and, live, count the bus's frames)."""
        if not self.active:
            return
        self.read_status()
        for ref in self.refs:
            heard = self._on_emcy(ref.name)
            self.session.client(ref).on_emcy(heard)
            self._listening.append((ref, heard))
        if self.view is not None:
            self.view.listen({r.bus: self.session.links[r.bus] for r in self.refs}, self.budget)

    def _on_emcy(self, drive: str) -> Callable[[Emcy], None]:
        from sherpa_cli.log.mcap_out import TimedEmcy

        def heard(emcy: Emcy) -> None:
            ns = time.time_ns()
            self.emcy.append(TimedEmcy(ns, drive, emcy))
            if self.view is not None:
                self.view.emcy(drive, emcy, ns=ns)
        return heard

    @contextmanager
    def feed(self, cfg: ArmConfig, sample: Callable[[], Mapping[str, tuple[int, int]] | None]) -> Iterator[None]:
        """Live: publish the newest sample while the recording runs."""
        if self.view is None:
            yield
            return
        from sherpa_cli.log.foxglove_live import RecorderFeed

        with RecorderFeed(self.view, cfg, sample):
            yield



def poller_sample(poller: Poller) -> Callable[[], dict[str, tuple[int, int]] | None]:
    """The newest PX, VX of each drive of a `--poll` recording."""
    def sample() -> dict[str, tuple[int, int]] | None:
        newest: dict[str, tuple[int, int]] = {}
        for _, name, px, vx, _iq in reversed(list(poller.rows[-4 * max(1, len(poller.refs)):])):
            newest.setdefault(name, (px, vx))
        return newest or None
    return sample


def recorder_sample(recorder: Recorder) -> Callable[[], dict[str, tuple[int, int]] | None]:
    def sample() -> dict[str, tuple[int, int]] | None:
        latest = recorder.latest()
        return None if latest is None else latest[1]
    return sample


