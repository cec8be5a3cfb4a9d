"""Run a recipe: each step through an injected ``invoke``, confirmations through ``confirm``.

The runner never prints. It reports through ``on_start`` / ``on_end`` callbacks and returns a
:class:`RecipeReport`; the CLI renders it and writes the JSON / JUnit reports.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from sherpa_cli.errors import ExitCode, SherpaError
from sherpa_cli.recipes.model import Expect, Recipe, Step


class StepStatus(StrEnum):
    """What became of one recipe step (a str: the JSON and JUnit reports show the word)."""

    PASSED = "passed"
    FAILED = "failed"
    SKIPPED = "skipped"
    DECLINED = "declined"
    INTERRUPTED = "interrupted"


PASSED, FAILED, SKIPPED = StepStatus.PASSED, StepStatus.FAILED, StepStatus.SKIPPED
DECLINED, INTERRUPTED = StepStatus.DECLINED, StepStatus.INTERRUPTED


@dataclass(frozen=True)
class CommandRun:
    """What running one sherpa command line gave back."""

    exit_code: int
    stdout: str
    stderr: str


Invoke = Callable[[Sequence[str]], CommandRun]


@dataclass
class StepResult:
    step: Step
    status: StepStatus
    argv: tuple[str, ...] = ()  # what actually ran (global options excluded)
    dry_run: bool = False
    exit_code: int | None = None
    stdout: str = ""
    stderr: str = ""
    failures: list[str] = field(default_factory=list)
    answer: str | None = None  # confirm steps: how the question was answered
    duration_s: float = 0.0
    json: object = None  # the step's --json output, parsed

    @property
    def ok(self) -> bool:
        return self.status in (PASSED, SKIPPED)

    def as_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"number": self.step.number, "name": self.step.name, "kind": self.step.kind,
                             "status": self.status}
        if self.step.kind == "confirm":
            d.update(question=self.step.confirm, answer=self.answer)
        else:
            d.update(command=["sherpa", *self.argv] if self.argv else ["sherpa", *self.step.argv],
                     dry_run=self.dry_run, exit_code=self.exit_code, expect=self.step.expect.as_dict(),
                     stdout=self.stdout, stderr=self.stderr)
        d["failures"] = list(self.failures)
        d["duration_s"] = round(self.duration_s, 3)
        return d


@dataclass
class RecipeReport:
    recipe: Recipe
    apply: bool
    start_at: str | None
    results: list[StepResult]

    @property
    def outcome(self) -> StepStatus:
        if any(r.status == INTERRUPTED for r in self.results):
            return INTERRUPTED
        return PASSED if all(r.ok for r in self.results) else FAILED

    @property
    def exit_code(self) -> int:
        return {PASSED: ExitCode.OK, FAILED: ExitCode.PROBLEM, INTERRUPTED: ExitCode.INTERRUPTED}[self.outcome]

    def count(self, status: str) -> int:
        return sum(1 for r in self.results if r.status == status)

    def result_of(self, name: str) -> StepResult | None:
        return next((r for r in self.results if r.step.name == name), None)

    def as_json(self) -> dict[str, Any]:
        return {"recipe": self.recipe.name, "file": self.recipe.path, "apply": self.apply,
                "from": self.start_at, "outcome": self.outcome,
                "counts": {s: self.count(s) for s in (PASSED, FAILED, DECLINED, SKIPPED, INTERRUPTED)},
                "steps": [r.as_json() for r in self.results]}


def run_recipe(recipe: Recipe, invoke: Invoke, *, apply: bool, confirm: Callable[[str], bool],
               start_at: Step | None = None, on_start: Callable[[Step, bool], None] | None = None,
               on_end: Callable[[StepResult], None] | None = None,
               clock: Callable[[], float] = time.monotonic) -> RecipeReport:
    """Run the steps in order from ``start_at``; a failed step with ``on_failure: stop`` ends the run."""
    results: list[StepResult] = []
    stopped: str | None = None
    for step in recipe.steps:
        if start_at is not None and step.number < start_at.number:
            results.append(StepResult(step, SKIPPED, failures=[f"before --from {start_at.name}"]))
            if on_end:
                on_end(results[-1])
            continue
        if stopped is not None:
            results.append(StepResult(step, SKIPPED, failures=[stopped]))
            if on_end:
                on_end(results[-1])
            continue
        if not apply and step.skip_in_dry_run:
            reason = "dry run: nothing to confirm" if step.kind == "confirm" else "dry run: nothing was written"
            results.append(StepResult(step, SKIPPED, dry_run=True, failures=[reason]))
            if on_end:
                on_end(results[-1])
            continue
        dry = step.writes and not apply
        if on_start:
            on_start(step, dry)
        began = clock()
        result = _confirm(step, confirm) if step.kind == "confirm" else _run(step, invoke, dry)
        result.duration_s = clock() - began
        results.append(result)
        if on_end:
            on_end(result)
        if result.status == INTERRUPTED:
            stopped = f"interrupted at step {step.number} ({step.name})"
        elif not result.ok and step.on_failure == "stop":
            stopped = f"step {step.number} ({step.name}) {result.status}"
    return RecipeReport(recipe, apply, start_at.name if start_at else None, results)


def _confirm(step: Step, confirm: Callable[[str], bool]) -> StepResult:
    assert step.confirm is not None
    try:
        yes = confirm(step.confirm)
    except KeyboardInterrupt:
        return StepResult(step, INTERRUPTED, answer="interrupted")
    except SherpaError as exc:  # nobody at a terminal to answer
        return StepResult(step, DECLINED, answer="no answer", failures=[str(exc)])
    if yes:
        return StepResult(step, PASSED, answer="yes")
    return StepResult(step, DECLINED, answer="no", failures=["the operator answered no"])


def _run(step: Step, invoke: Invoke, dry: bool) -> StepResult:
    argv = step.dry_argv() if dry else step.argv
    # a step with JSON expectations runs with --json in a dry run too: its plan is then machine-read
    wants_json = bool(step.expect.json)
    ran = invoke((["--json"] if wants_json else []) + list(argv))
    result = StepResult(step, PASSED, tuple(argv), dry, ran.exit_code, ran.stdout, ran.stderr)
    if ran.exit_code == ExitCode.INTERRUPTED:
        result.status = INTERRUPTED
        return result
    result.failures = _check(step.expect, ran, dry, result)
    if result.failures:
        result.status = FAILED
    return result


def _check(expect: Expect, ran: CommandRun, dry: bool, result: StepResult) -> list[str]:
    failures: list[str] = []
    if ran.exit_code not in expect.exit:
        wanted = " or ".join(str(c) for c in expect.exit)
        failures.append(f"exit code {ran.exit_code}, expected {wanted}")
    if dry:
        # A dry run of a writing step shows the plan; what the step expects of the writes cannot hold yet.
        if expect.json:
            with contextlib.suppress(ValueError):
                result.json = json.loads(ran.stdout)
        return failures
    for text in expect.stdout_contains:
        if text not in ran.stdout:
            failures.append(f"stdout does not contain {text!r}")
    if expect.json:
        try:
            result.json = json.loads(ran.stdout)
        except ValueError:
            failures.append("stdout is not JSON")
            return failures
        for path, wanted in expect.json:
            failures.extend(check_json_path(result.json, path, wanted))
    return failures


_MISSING = object()


def check_json_path(doc: object, path: str, wanted: object) -> list[str]:
    """Failures of ``path`` (dotted; ``*`` = every element; digits index lists) against ``wanted``."""
    values = _resolve(doc, path.split("."), path)
    if isinstance(values, str):
        return [values]
    if not values:
        return [f"{path}: matches nothing in the output"]
    return [f"{where}: {json.dumps(got)}, expected {json.dumps(wanted)}" for where, got in values if got != wanted]


def _resolve(node: object, parts: list[str], path: str, prefix: str = "") -> list[tuple[str, object]] | str:
    if not parts:
        return [(prefix or path, node)]
    head, rest = parts[0], parts[1:]
    here = f"{prefix}.{head}" if prefix else head
    if head == "*":
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else None
        if items is None:
            return f"{prefix or path}: not a list or mapping"
        out: list[tuple[str, object]] = []
        for key, child in items:
            got = _resolve(child, rest, path, f"{prefix}.{key}" if prefix else str(key))
            if isinstance(got, str):
                return got
            out.extend(got)
        return out
    if isinstance(node, dict):
        if head not in node:
            return f"{here}: no such key in the output"
        return _resolve(node[head], rest, path, here)
    if isinstance(node, list) and head.isascii() and head.isdigit():
        if int(head) >= len(node):
            return f"{here}: the list has only {len(node)} item(s)"
        return _resolve(node[int(head)], rest, path, here)
    return f"{here}: cannot look up '{head}' in {type(node).__name__}"
