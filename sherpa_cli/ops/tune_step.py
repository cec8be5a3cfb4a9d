"""`sherpa tune step JOINT`: one step with the gains the drive holds and one with trial gains, the
metrics of both (docs/tune.md).

The trial gains are written to RAM only, just for the second step: what the drive held is read first,
journaled (`sherpa recover` puts it back after a killed command) and written back on every way out --
the end, an error, Ctrl-C. Nothing is saved; `tune set` writes gains to keep. Each step is
ops/step.py's `log step` (motion guard, joint-limit watch, the recording); a position step goes +X
with the drive's gains and back -X with the trial gains, so the joint ends where it started.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sherpa_cli.elmo.commands import parse_param_key
from sherpa_cli.errors import ProtocolError

if TYPE_CHECKING:
    from sherpa_cli.bus.session import ArmSession
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.ops.step import StepResult

JOURNAL_OWNER = "tune step"


@dataclass
class TuneStepResult:
    held: dict[str, float]  # the gains the drive held (and holds again)
    trial: dict[str, float]
    before: StepResult
    after: StepResult

    def as_json(self) -> dict[str, Any]:
        return {"held": self.held, "trial": self.trial, "before": self.before.as_json(),
                "after": self.after.as_json()}


def run_tune_step(session: ArmSession, target: Axis, mode: str, value: float, trial: Mapping[str, float],
                  step: Callable[[str, float], StepResult]) -> TuneStepResult:
    """``step(mode, value)`` runs one step (ops/step.py run_step with the command's settings)."""
    from sherpa_cli.bus import journal

    client = session.client(target.ref)
    client.nmt_start()
    held = {k: float(client.get(*parse_param_key(k))) for k in trial}
    before = step(mode, value)
    journal.note(target.ref, *(journal.interp(JOURNAL_OWNER, *parse_param_key(k), v) for k, v in held.items()))
    try:
        for key, v in trial.items():
            client.set(*parse_param_key(key), v)
        after = step(mode, -value if mode == "position" else value)
    finally:
        failed = []
        for key, v in held.items():
            try:
                client.set(*parse_param_key(key), v)
            except Exception:  # noqa: BLE001 - every key is tried; the journal keeps the rest for `recover`
                failed.append(key)
        if not failed:
            journal.forget(target.ref, JOURNAL_OWNER)
    if failed:
        raise ProtocolError(f"{target.ref.name}: the trial gains {', '.join(failed)} were not put back",
                            hint="`sherpa recover --apply` puts them back from the journal")
    return TuneStepResult(held, dict(trial), before, after)
