"""`sherpa recipe run|check` and `sherpa commission`: scripted commissioning with a report."""

from __future__ import annotations

import io
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Optional, Sequence

import typer

from sherpa_cli.cli import context
from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import (ApplyCommission, ApplyRecipe, FromStep, Junit, Quiet, Report, SetVars,
                                    YesRecipe)
from sherpa_cli.errors import UsageError

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


def _invoker(st: AppState):
    """Run one sherpa command line in this process with the runner's global options.

    Output is captured (the recipe shows it under the step) and stdin is empty, so a step
    never waits at a prompt nobody sees: questions belong in `confirm:` steps.
    """
    from sherpa_cli.cli.app import run
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
        try:
            with redirect_stdout(out), redirect_stderr(err):
                code = run([*base, *argv])
        finally:
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


def execute(st: AppState, recipe_path: Path, *, apply: bool, yes: bool, start: Optional[str],
            report: Optional[Path], junit: Optional[Path], sets: Sequence[str] | None, quiet: bool):
    """Run a recipe with live step output; returns the RecipeReport (its exit_code ends the command)."""
    from sherpa_cli.recipes import load_recipe
    from sherpa_cli.recipes.report import check_report_paths, write_reports
    from sherpa_cli.recipes.runner import FAILED, PASSED, SKIPPED, run_recipe

    recipe = load_recipe(_shown_path(recipe_path), _parse_sets(sets))
    check_report_paths(report, junit)
    start_at = recipe.find_step(start) if start else None
    st.load_config()  # a bad config is reported once, before the first step
    out = st.out
    total = len(recipe.steps)
    if not st.json_mode:
        mode = "applying writes" if apply else "dry run (writing steps show their plan; --apply to write)"
        out.line(f"recipe {recipe.name}: {total} steps from {recipe.path}; {mode}")
        if recipe.description:
            out.line(recipe.description.strip())

    def on_start(step, dry: bool) -> None:
        if st.json_mode:
            return
        what = f"confirm: {step.confirm}" if step.kind == "confirm" else step.command_text() if not dry \
            else "sherpa " + " ".join(step.dry_argv()) + "   (dry run)"
        out.line("")
        out.line(f"[{step.number}/{total}] {step.name}: {what}")

    def on_end(result) -> None:
        if st.json_mode:
            return
        if result.step.kind == "run" and (not quiet or result.status != PASSED):
            for line in _indent(result.stdout) + _indent(result.stderr):
                out.line(line)
        if result.step.kind == "confirm":
            out.line(f"{INDENT}-> {result.status} (answer: {result.answer})")
        elif result.status == PASSED:
            out.line(f"{INDENT}-> passed (exit {result.exit_code}{', dry run' if result.dry_run else ''})")
        else:
            out.line(f"{INDENT}-> {result.status.upper()}: {'; '.join(result.failures) or result.status}")

    def confirm(question: str) -> bool:
        if yes:
            return True
        return st.out.confirm(question)

    rep = run_recipe(recipe, _invoker(st), apply=apply, confirm=confirm, start_at=start_at,
                     on_start=on_start, on_end=on_end)
    write_reports(rep, report, junit)
    if st.json_mode:
        out.json(rep.as_json())
        return rep
    out.line("")
    counts = ", ".join(f"{rep.count(s)} {s}" for s in ("passed", "failed", "declined", "skipped", "interrupted")
                       if rep.count(s))
    out.line(f"recipe {recipe.name}: {rep.outcome.upper()} ({counts})")
    for r in rep.results:
        if r.status == SKIPPED and start_at is None:
            out.line(f"  not run: step {r.step.number} {r.step.name} ({'; '.join(r.failures)})")
    if rep.outcome == FAILED:
        first = next(r for r in rep.results if not r.ok)
        out.line(f"  first failure: step {first.step.number} {first.step.name}: {'; '.join(first.failures)}")
        out.line(f"  resume with: --from {first.step.name}")
    for path, kind in ((report, "JSON"), (junit, "JUnit")):
        if path is not None:
            out.info(f"{kind} report written to {path}")
    return rep


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
    quiet: Quiet = False,
) -> None:
    """Run a recipe's steps in order, stop at the first failure, and report.

    Each step is a sherpa command run with this invocation's --config/--sim/--bus-map. With
    --sim each step meets a freshly powered-up simulated arm: only what SV saved survives.
    Exit code: 0 every step passed, 1 a step failed or was declined, 2 bad recipe, 130 Ctrl-C.

    \b
    Examples:
      sherpa --sim recipe run recipes/commission-arm.yaml
      sherpa recipe run recipes/commission-arm.yaml --apply --junit commission.xml
      sherpa recipe run recipes/backup.yaml --set out=arm-2026-11-22.yaml
    """
    st = state(ctx)
    rep = execute(st, file, apply=apply, yes=yes, start=start, report=report, junit=junit, sets=sets, quiet=quiet)
    if rep.exit_code:
        raise typer.Exit(rep.exit_code)


@app.command("check")
def check_cmd(ctx: typer.Context, file: Path = typer.Argument(..., metavar="FILE"),
              sets: SetVars = None) -> None:
    """Validate a recipe and list its steps (nothing is run)."""
    from sherpa_cli.recipes import load_recipe

    st = state(ctx)
    recipe = load_recipe(file, _parse_sets(sets))
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
                  sets=sets, quiet=quiet)
    if not st.json_mode:
        _commission_summary(st, rep)
    if rep.exit_code:
        raise typer.Exit(rep.exit_code)


def _commission_summary(st: AppState, rep) -> None:
    """Per drive: did the save step leave it programmed, verified and saved (from its --json output)."""
    save = rep.result_of("save")
    verify = rep.result_of("verify")
    if save is None or not isinstance(save.json, dict) or not rep.apply:
        st.out.line("no drive was written: this was a dry run (add --apply)" if not rep.apply
                    else "the save step did not run: no per-drive result")
        return
    rows = []
    complete = True
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
        st.out.line(f"every drive is programmed, verified and saved ({len(rows)} drives); "
                    "the live values match the config")
    else:
        st.out.line("commissioning is NOT complete: see the failed step above")
