"""`sherpa recipe run|check` and `sherpa commission`: scripted commissioning with a report."""

from __future__ import annotations

import io
import sys
from collections.abc import Callable, Sequence
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli import context
from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import (
    ApplyCommission,
    ApplyRecipe,
    FromStep,
    Junit,
    Quiet,
    Report,
    SetVars,
    Verbose,
    YesRecipe,
)
from sherpa_cli.cli.step_check import check_step_commands
from sherpa_cli.errors import UsageError
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from rich.live import Live
    from rich.spinner import Spinner

    from sherpa_cli.cli.output import Output
    from sherpa_cli.recipes.model import Step
    from sherpa_cli.recipes.runner import Invoke, RecipeReport, StepResult

app = typer.Typer(no_args_is_help=True, help="Run commissioning recipes (YAML lists of sherpa steps; docs/recipes.md).")

RECIPES_DIR = Path(__file__).resolve().parent.parent.parent / "recipes"
COMMISSION_RECIPE = RECIPES_DIR / "commission-arm.yaml"
INDENT = "    "


def _parse_sets(values: Sequence[str] | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for text in values or []:
        key, sep, value = text.partition("=")
        if not sep or not key:
            raise UsageError(f"--set {text!r}: expected KEY=VALUE")
        out[key] = value
    return out


def _invoker(st: AppState, shown: Callable[[], bool] = lambda: True) -> Invoke:
    """Run one sherpa command line in this process with the runner's global options.

    Output is captured (the recipe shows it under the step) and stdin is empty, so a step
    never waits at a prompt nobody sees: questions belong in `confirm:` steps. ``shown()`` False:
    nobody sees or reads the step's stdout, so the command renders no results at all.
    """
    from sherpa_cli.cli.boundary import run
    from sherpa_cli.cli.output import DISCARD_RESULTS
    from sherpa_cli.recipes.runner import CommandRun

    base = ["--config", str(st.config_path), "--no-color"]
    if st.sim:
        base.append("--sim")
    if st.bus_map and not st.bus_map_from_env:
        base += ["--bus-map", ",".join(st.bus_map)]

    def invoke(argv: Sequence[str]) -> CommandRun:
        outer = context.CURRENT
        out, err = io.StringIO(), io.StringIO()
        stdin = sys.stdin
        sys.stdin = io.StringIO("")
        discard = DISCARD_RESULTS.set(not shown())
        try:
            with redirect_stdout(out), redirect_stderr(err):
                code = run([*base, *argv])
        finally:
            DISCARD_RESULTS.reset(discard)
            sys.stdin = stdin
            context.CURRENT = outer
        return CommandRun(code, out.getvalue(), err.getvalue())

    return invoke


def _shown_path(path: Path) -> Path:
    """The recipe's path as the operator would type it: relative to the working directory when inside it."""
    try:
        return path.resolve().relative_to(Path.cwd().resolve())
    except ValueError:
        return path


def _indent(text: str) -> list[str]:
    return [INDENT + line if line.strip() else "" for line in text.rstrip("\n").split("\n")] if text.strip() else []


def step_clock() -> Callable[[], float]:
    """The runner's clock: real time, or with $SHERPA_FAKE_STEP_SECONDS (tests, docs/testing.md) a fake
    one under which every step lasts exactly that long, so durations in golden files are stable."""
    import os
    import time

    fixed = os.environ.get("SHERPA_FAKE_STEP_SECONDS")
    if not fixed:
        return time.monotonic
    try:
        seconds = float(fixed)
    except ValueError:
        raise UsageError(f"$SHERPA_FAKE_STEP_SECONDS={fixed!r}: expected a number of seconds") from None
    import itertools

    readings = itertools.count()
    # the runner reads the clock once before and once after a step: every step lasts `seconds`
    return lambda: (next(readings) + 1) // 2 * seconds


def _duration(seconds: float) -> str:
    return f"{seconds:.1f} s" if seconds < 60 else f"{int(seconds // 60)} min {seconds % 60:02.0f} s"


class _Warnings:
    """Warnings the steps printed, each shown once with how often it came."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}

    def take(self, stderr: str) -> list[str]:
        """Record the step's warnings; the rest of its stderr (errors, hints, notes) is returned."""
        rest = []
        for line in stderr.splitlines():
            if line.startswith("warning: "):
                text = line[len("warning: "):]
                self.counts[text] = self.counts.get(text, 0) + 1
            elif line.strip():
                rest.append(line)
        return rest

    def show(self, out: Output) -> None:
        # "SUBJECT: MESSAGE" warnings with the same message are one line naming every subject
        groups: dict[str, list[tuple[str, int]]] = {}
        for text, n in self.counts.items():
            subject, sep, message = text.rpartition(": ")
            groups.setdefault(message if sep else text, []).append((subject if sep else "", n))
        for message, items in groups.items():
            counts = {n for _, n in items}
            times = sum(n for _, n in items)
            # the count goes last: "(5 times)" beside "9 drives" read as a count of drives
            count = "" if times == 1 else f" (said {counts.pop()} times each)" if len(counts) == 1 and len(items) > 1 \
                else f" (said {times} times)"
            subjects = [s for s, _ in items if s]
            out.warn(f"{message}: {'; '.join(subjects)}{count}" if subjects else f"{message}{count}")


def _progress(st: AppState) -> Live | None:
    """A spinner on stderr while a step runs: only on a terminal, never with --json."""
    if st.json_mode or not sys.stderr.isatty():
        return None
    from rich.live import Live
    from rich.spinner import Spinner

    return Live(Spinner("dots", text=""), console=st.out._console(stderr=True), transient=True,
                redirect_stdout=False, redirect_stderr=False, refresh_per_second=8)


def execute(st: AppState, recipe_path: Path, *, apply: bool, yes: bool, start: str | None,
            report: Path | None, junit: Path | None, sets: Sequence[str] | None, verbose: bool) -> RecipeReport:
    """Run a recipe in one session (config loaded and buses opened once); returns the RecipeReport.

    By default one line per step (name, outcome, duration); ``verbose`` also shows every step's
    command and output. The full output of every step is in the JSON report either way.
    """
    from sherpa_cli.recipes import load_recipe
    from sherpa_cli.recipes.report import check_report_paths, write_reports
    from sherpa_cli.recipes.runner import FAILED, PASSED, SKIPPED, run_recipe

    recipe = load_recipe(_shown_path(recipe_path), _parse_sets(sets))
    check_step_commands(recipe)  # a step the CLI cannot parse stops the recipe before step 1
    check_report_paths(report, junit)
    start_at = recipe.find_step(start) if start else None
    clock = step_clock()
    st.load_config()  # a bad config is reported once, before the first step
    out = st.out
    total = len(recipe.steps)
    width = max(len(s.name) for s in recipe.steps)
    numw = len(f"{total}/{total}")
    warnings = _Warnings()
    if not st.json_mode:
        mode = "applying writes" if apply else "dry run (writing steps show their plan; --apply to write)"
        out.line(f"recipe {recipe.name}: {total} steps from {recipe.path}; {mode}")
        if verbose and recipe.description:
            out.line(recipe.description.strip())
    live = _progress(st)

    # whether the step about to run has readers of its stdout: shown (--verbose), stored (--report,
    # --junit, the --json document) or checked (stdout_contains, json); otherwise it renders nothing
    needs_stdout = [True]

    def on_start(step: Step, dry: bool) -> None:
        needs_stdout[0] = bool(verbose or st.json_mode or report is not None or junit is not None
                               or step.expect.stdout_contains or step.expect.json)
        if st.json_mode:
            return
        what = f"confirm: {step.confirm}" if step.kind == "confirm" else step.command_text() if not dry \
            else "sherpa " + " ".join(step.dry_argv()) + "   (dry run)"
        if verbose:
            out.line("")
            out.line(f"[{step.number}/{total}] {step.name}: {what}")
        elif live is not None and step.kind == "run":
            live.update(_spinner(f"[{step.number}/{total}] {step.name}: {what}"))
            live.start()

    def on_end(result: StepResult) -> None:
        done.append(result)
        if live is not None:
            live.stop()
        if st.json_mode:
            return
        rest = warnings.take(result.stderr)
        if verbose:
            _verbose_end(result, rest)
            return
        n = f"{result.step.number}/{total}"
        if result.status == SKIPPED:
            outcome = f"skipped ({'; '.join(result.failures)})"
        elif result.step.kind == "confirm":
            outcome = f"{result.status} (answer: {result.answer})"
        elif result.status == PASSED:
            outcome = f"passed{' (dry run)' if result.dry_run else ''}"
        else:
            outcome = result.status.upper()
        dur = "" if result.step.kind == "confirm" or result.status == SKIPPED else _duration(result.duration_s)
        out.line(f"[{n:>{numw}}] {result.step.name:<{width}}  {outcome:<18} {dur}".rstrip())
        if not result.ok:
            if result.failures and result.status != SKIPPED:
                out.line(f"{INDENT}{'; '.join(result.failures)}")
            for line in rest[-10:]:
                out.line(INDENT + line)

    def _verbose_end(result: StepResult, rest: list[str]) -> None:
        if result.step.kind == "run":
            lines = _indent(result.stdout) if not _is_json(result.stdout) else \
                [f"{INDENT}(JSON output, {len(result.stdout.splitlines())} lines: in the --report file)"]
            for line in lines + [INDENT + r for r in rest]:
                out.line(line)
        if result.status == SKIPPED:
            out.line("")
            out.line(f"[{result.step.number}/{total}] {result.step.name}")
            out.line(f"{INDENT}-> skipped ({'; '.join(result.failures)})")
        elif result.step.kind == "confirm":
            out.line(f"{INDENT}-> {result.status} (answer: {result.answer})")
        elif result.status == PASSED:
            out.line(f"{INDENT}-> passed (exit {result.exit_code}{', dry run' if result.dry_run else ''}, "
                     f"{_duration(result.duration_s)})")
        else:
            out.line(f"{INDENT}-> {result.status.upper()}: {'; '.join(result.failures) or result.status}")

    done: list[StepResult] = []

    def confirm(question: str) -> bool:
        if yes:
            return True
        return st.out.confirm(_with_drives(question, done))

    with context.shared_session(st, stepped=recipe.sim_time == "stepped"):
        rep = run_recipe(recipe, _invoker(st, lambda: needs_stdout[0]), apply=apply, confirm=confirm, start_at=start_at,
                         on_start=on_start, on_end=on_end, clock=clock)
    write_reports(rep, report, junit)
    if st.json_mode:
        out.json(rep.as_json())
        return rep
    if verbose:
        out.line("")
    counts = ", ".join(f"{rep.count(s)} {s}" for s in ("passed", "failed", "declined", "skipped", "interrupted")
                       if rep.count(s))
    out.line(f"recipe {recipe.name}: {rep.outcome.upper()} ({counts}; {_duration(sum(r.duration_s for r in rep.results))})")
    if rep.outcome == FAILED:
        first = next(r for r in rep.results if not r.ok)
        out.line(f"  first failure: step {first.step.number} {first.step.name}: {'; '.join(first.failures)}")
        out.line(f"  resume with: --from {first.step.name}")
    warnings.show(out)
    for path, kind in ((report, "JSON"), (junit, "JUnit")):
        if path is not None:
            out.info(f"{kind} report written to {path}")
    return rep


def _with_drives(question: str, done: Sequence[StepResult]) -> str:
    """A save question names the drives it is about: those the last `program-limits --apply` step wrote
    or left unsaved (from its --json output)."""
    for result in reversed(done):
        doc = result.json
        if isinstance(doc, dict) and doc.get("command") == "program-limits" and doc.get("apply"):
            drives = [d["drive"] for d in doc.get("drives", [])
                      if d.get("save_due") or (d.get("outcome") or {}).get("written")]
            listed = ", ".join(drives) if drives else "none (no drive changed)"
            return f"{question} (would save: {listed})"
    return question


def _spinner(text: str) -> Spinner:
    from rich.spinner import Spinner

    return Spinner("dots", text=text)


def _is_json(text: str) -> bool:
    return text.lstrip().startswith(("{", "["))


@app.command("run")
def run_cmd(
    ctx: typer.Context,
    file: Path = typer.Argument(..., metavar="FILE", help="The recipe (YAML)."),
    apply: ApplyRecipe = False,
    yes: YesRecipe = False,
    start: FromStep = None,
    report: Report = None,
    junit: Junit = None,
    sets: SetVars = None,
    verbose: Verbose = False,
    quiet: Quiet = False,
) -> None:
    """Run a recipe's steps in order, stop at the first failure, and report.

    Each step is a sherpa command run with this invocation's --config/--sim/--bus-map, all in
    one session: the config is loaded and the buses are opened once. With --sim the steps
    share one simulated arm, as on a real arm: RAM survives between steps.
    Exit code: 0 every step passed, 1 a step failed or was declined, 2 bad recipe, 130 Ctrl-C.

    \b
    Examples:
      sherpa --sim recipe run recipes/commission-arm.yaml
      sherpa recipe run recipes/commission-arm.yaml --apply --junit commission.xml
      sherpa recipe run recipes/backup.yaml --set out=arm-2026-11-22.yaml
    """
    st = state(ctx)
    rep = execute(st, file, apply=apply, yes=yes, start=start, report=report, junit=junit, sets=sets,
                  verbose=verbose and not quiet)
    if rep.exit_code:
        raise typer.Exit(rep.exit_code)


@app.command("check")
def check_cmd(ctx: typer.Context, file: Path = typer.Argument(..., metavar="FILE"),
              sets: SetVars = None) -> None:
    """Validate a recipe and list its steps (nothing is run)."""
    from sherpa_cli.recipes import load_recipe

    st = state(ctx)
    recipe = load_recipe(file, _parse_sets(sets))
    check_step_commands(recipe)
    if st.json_mode:
        st.out.json({"recipe": recipe.name, "file": recipe.path, "vars": recipe.variables,
                     "steps": [{"number": s.number, "name": s.name, "kind": s.kind,
                                "command": ["sherpa", *s.argv] if s.argv else None, "question": s.confirm,
                                "writes": s.writes, "on_failure": s.on_failure, "expect": s.expect.as_dict()}
                               for s in recipe.steps]})
        return
    rows = [[s.number, s.name, s.confirm if s.kind == "confirm" else s.command_text(),
             "yes" if s.writes else "", s.on_failure] for s in recipe.steps]
    st.out.table(f"recipe {recipe.name} ({recipe.path})", ["#", "step", "does", "writes", "on failure"],
                 rows, right=(0,))


def commission(
    ctx: typer.Context,
    apply: ApplyCommission = False,
    yes: YesRecipe = False,
    start: FromStep = None,
    report: Report = None,
    junit: Junit = None,
    verbose: Verbose = False,
    quiet: Quiet = False,
    sets: SetVars = None,
) -> None:
    """Commission the arm: run recipes/commission-arm.yaml (scan, identify, plan, program, save, back up, diff).

    \b
    Examples:
      sherpa --sim commission --apply --yes      # the whole job on the simulated arm
      sherpa commission                          # dry run on the real arm: shows the plan
    """
    st = state(ctx)
    rep = execute(st, COMMISSION_RECIPE, apply=apply, yes=yes, start=start, report=report, junit=junit,
                  sets=sets, verbose=verbose and not quiet)
    if not st.json_mode:
        _commission_summary(st, rep)
    if rep.exit_code:
        raise typer.Exit(rep.exit_code)


def _commission_summary(st: AppState, rep: RecipeReport) -> None:
    """Per drive: what the save step left (programmed, verified, saved), or in a dry run what it would do."""
    save = rep.result_of("save")
    verify = rep.result_of("verify")
    if save is None or not isinstance(save.json, dict):
        st.out.line("the save step did not run: no per-drive result")
        return
    rows = []
    complete = True
    if not rep.apply:
        for d in save.json.get("drives", []):
            params = d.get("params", [])
            changes = sum(1 for p in params if p.get("changes"))
            problems = d.get("problems") or []
            complete &= not problems
            rows.append([d["drive"], f"{d['bus']}:{d['node']}", f"{changes} of {len(params)}",
                         "yes" if changes or d.get("save_due") else "no", "; ".join(problems) or "none"])
        st.out.table("commissioning plan (dry run)", ["drive", "bus:node", "would write", "would save", "problems"],
                     rows)
        if complete:
            st.out.line(f"dry run: nothing was written ({plural(len(rows), 'drive')}); add --apply to program and save")
        else:
            st.out.line("dry run: some drives have problems (see the table); nothing was written")
        return
    for d in save.json.get("drives", []):
        o = d.get("outcome") or {}
        status = o.get("status")
        targets = len(d.get("params", []))
        held = status in ("saved", "unchanged") and not o.get("mismatches")
        if status == "saved":
            saved = f"yes (SV #{o['save_count']})" if o.get("save_count") else "yes"
        elif status == "unchanged":
            saved = "held already, no SV needed"
        else:
            saved = "NO"
        complete &= held
        rows.append([d["drive"], f"{d['bus']}:{d['node']}", f"{targets}/{targets}" if held else status,
                     "yes" if held else "NO", saved])
    st.out.table("commissioning result", ["drive", "bus:node", "programmed", "verified", "saved"], rows)
    diff_ok = verify is not None and verify.status == "passed"
    if complete and diff_ok and save.status == "passed":
        st.out.line(f"every drive is programmed, verified and saved ({plural(len(rows), 'drive')}); "
                    "the live values match the config")
    else:
        st.out.line("commissioning is NOT complete: see the failed step above")
    backup = rep.result_of("backup")
    argv = list(backup.argv) if backup is not None and backup.argv else []
    if backup is not None and backup.status == "passed" and "-o" in argv[:-1]:
        st.out.line(f"backup from before this run: {argv[argv.index('-o') + 1]}")
        st.out.line("  (the next run replaces it; --set backup=FILE keeps another)")
    proof = rep.result_of("flash-proof")
    if proof is not None and proof.status == "passed":
        st.out.line("the flash proof reset every drive: positions and homing marks are cleared;")
        st.out.line("  home the arm next (`sherpa home --yes`)")
