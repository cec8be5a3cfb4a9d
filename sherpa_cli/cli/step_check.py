"""Check every `run:` step of a recipe against the CLI before anything runs.

A recipe is checked by the same parser that will run its steps: the command must exist and
its options and arguments must parse (names of drives and joints are the config's business
and are checked when the step runs). So `sherpa recipe check` fails on a step kind or option
that does not exist, and `recipe run` / `commission` refuse such a recipe before step 1
instead of writing to drives up to the bad step.
"""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout
from typing import TYPE_CHECKING, Any

from sherpa_cli.errors import ConfigError, Location, UsageError

if TYPE_CHECKING:
    from sherpa_cli.recipes.model import Recipe


# What a recipe with `sim_time: stepped` may run: the commands that wait on the shared simulated arm's
# stepped clock (or open no session). Any other command would wait on the wall while the stepped arm
# stands still, and time out.
STEPPED_COMMANDS = frozenset({("cmd",), ("log", "step"), ("diffdrive", "move"), ("log", "section9")})


def _root() -> Any:
    # a click Command of whichever click the installed typer uses (typer >= 0.29 vendors its own;
    # cli/boundary.py returns it as object): no one importable class names it for every typer
    from sherpa_cli.cli.boundary import root_command

    return root_command()


def _non_ascii_number(argv: list[str]) -> UsageError | None:
    """What the boundary refuses before parsing (a number in other scripts' digits): the UsageError or None."""
    from sherpa_cli.cli.boundary import refuse_non_ascii_numbers

    try:
        refuse_non_ascii_numbers(argv)
    except UsageError as exc:
        return exc
    return None


def check_step_commands(recipe: Recipe) -> None:
    """Raise ConfigError (file, line, step) for the first run step the CLI would refuse to parse."""
    import typer
    from typer.core import TyperGroup

    for step in recipe.steps:
        if step.kind != "run":
            continue
        where = Location(recipe.path, step.line, f"steps[{step.number - 1}].run")

        def refuse(problem: str) -> ConfigError:
            # raised within this iteration only: step and where are the current step's
            return ConfigError(f"step {step.number} '{step.name}': {problem}", where,  # noqa: B023
                               hint="run the command with --help to see what it takes")

        digits = _non_ascii_number(list(step.argv))
        if digits is not None:
            raise ConfigError(f"step {step.number} '{step.name}': {digits.message}", where, hint=digits.hint)
        cmd, args, words = _root(), list(step.argv), ["sherpa"]
        # contexts chained from the root's, with its settings: the tree is the one `run` uses (built
        # once per process), and click keeps the first help option it builds for a command, so a
        # context without the root's help_option_names (-h) would change every later --help
        ctx = typer.Context(cmd, info_name="sherpa", **getattr(cmd, "context_settings", {}))
        while isinstance(cmd, TyperGroup):
            if not args or args[0].startswith("-"):
                raise refuse(f"missing command after '{' '.join(words)}'")
            sub = cmd.get_command(ctx, args[0])
            if sub is None:
                known = ", ".join(sorted(cmd.list_commands(ctx)))
                raise refuse(f"no such command '{' '.join([*words, args[0]])}' (commands: {known})")
            words.append(args.pop(0))
            cmd = sub
            if isinstance(cmd, TyperGroup):
                ctx = typer.Context(cmd, parent=ctx, info_name=words[-1], **getattr(cmd, "context_settings", {}))
        if recipe.sim_time == "stepped" and tuple(words[1:]) not in STEPPED_COMMANDS:
            raise ConfigError(f"step {step.number} '{step.name}': '{' '.join(words)}' does not run on the simulator's "
                              "stepped time (sim_time: stepped)", where,
                              hint="stepped time takes: " + ", ".join(sorted(" ".join(c) for c in STEPPED_COMMANDS))
                              + "; or leave sim_time out (wall time)")
        try:
            with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
                cmd.make_context(words[-1], args, parent=ctx)  # parses, never runs
        except typer.Exit:
            continue  # --help: harmless, it prints and ends the step
        except typer.TyperException as exc:
            raise refuse(exc.format_message()) from None
