"""The recipe file format (docs/recipes.md): parsed with a line and key path on every error."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sherpa_cli.config.yamlnodes import (
    NAME_RE,
    Section,
    YNode,
    as_int,
    as_map,
    as_seq,
    as_str,
    describe,
    parse_yaml,
    plain,
    read_input,
)
from sherpa_cli.errors import ConfigError, Location

ON_FAILURE = ("stop", "continue")
# What a step does in a recipe dry run (no --apply): `run` it (a writing step as its own dry run)
# or `skip` it (a check of what the writes left, which cannot hold when nothing was written).
# Confirm steps default to skip: a dry run writes nothing, so there is nothing to confirm.
DRY_RUN = ("run", "skip")
SIM_TIMES = ("wall", "stepped")
# Flags that make a step write to drives: without `recipe run --apply` they are removed, so the
# step runs as the command's own dry run (design.md: every write is a dry run unless --apply).
# `scan --reset`, `--verify-flash` (NMT reset node) and `monitor --heartbeat MS` (0x1017 := MS) change
# the drives' state too: not in a dry run either (the commands themselves also need --apply for them).
WRITE_FLAGS = ("--apply", "--save", "--motor-off", "--yes", "-y", "--reset", "--verify-flash", "--raw-save")
# Write options that take a value (the value goes with them): `--heartbeat MS` or `--heartbeat=MS`.
WRITE_OPTIONS = ("--heartbeat",)
# Global options are the recipe runner's business (it passes its own --config/--sim/--bus-map);
# a step that set them would run against another arm than the one the operator chose.
GLOBAL_OPTIONS = ("--config", "-c", "--sim", "--bus-map", "--json", "--debug", "--no-color", "--version")
VAR_RE = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")


@dataclass(frozen=True)
class Expect:
    """What a step's result must look like for the step to pass."""

    exit: tuple[int, ...] = (0,)
    stdout_contains: tuple[str, ...] = ()
    json: tuple[tuple[str, Any], ...] = ()  # (dotted path, expected value); the step then runs with --json

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"exit": list(self.exit)}
        if self.stdout_contains:
            d["stdout_contains"] = list(self.stdout_contains)
        if self.json:
            d["json"] = {path: value for path, value in self.json}
        return d


@dataclass(frozen=True)
class Step:
    number: int  # 1-based position in the recipe
    name: str
    argv: tuple[str, ...] = ()  # a sherpa command line without the program name; empty for confirm
    confirm: str | None = None
    expect: Expect = Expect()
    on_failure: str = "stop"
    line: int | None = None
    dry_run: str | None = None  # run | skip; None: skip for confirm steps, run for the others

    @property
    def kind(self) -> str:
        return "confirm" if self.confirm is not None else "run"

    @property
    def skip_in_dry_run(self) -> bool:
        return (self.dry_run or ("skip" if self.kind == "confirm" else "run")) == "skip"

    @property
    def writes(self) -> bool:
        return any(a in WRITE_FLAGS or a.split("=", 1)[0] in WRITE_OPTIONS for a in self.argv)

    def dry_argv(self) -> tuple[str, ...]:
        out: list[str] = []
        skip_value = False
        for a in self.argv:
            if skip_value:
                skip_value = False
                continue
            if a in WRITE_OPTIONS:
                skip_value = True  # the option's value goes with it
                continue
            if a in WRITE_FLAGS or a.split("=", 1)[0] in WRITE_OPTIONS:
                continue
            out.append(a)
        return tuple(out)

    def command_text(self) -> str:
        return "sherpa " + shlex.join(self.argv) if self.argv else ""


@dataclass(frozen=True)
class Recipe:
    name: str
    path: str
    description: str = ""
    steps: tuple[Step, ...] = ()
    variables: dict[str, str] = field(default_factory=dict)
    # `sim_time: stepped`: with --sim the recipe's shared simulated arm runs on stepped time
    # (sim/stepped.py), for recipes whose steps measure time (the seed's figures); default "wall"
    sim_time: str = "wall"

    def find_step(self, text: str) -> Step:
        """A step by its name or 1-based number (``--from``)."""
        for step in self.steps:
            if step.name == text or (text.isascii() and text.isdigit() and int(text) == step.number):
                return step
        from sherpa_cli.errors import UsageError

        names = ", ".join(s.name for s in self.steps)
        raise UsageError(f"--from {text}: no such step in {self.path}", hint=f"steps: {names}")


def load_recipe(path: Path, overrides: dict[str, str] | None = None) -> Recipe:
    """Read and check a recipe; ``overrides`` (``--set KEY=VALUE``) replace its ``vars``."""
    try:
        text = read_input(path)
    except FileNotFoundError:
        raise ConfigError("recipe file not found", Location(str(path))) from None
    except IsADirectoryError:
        raise ConfigError("is a directory, expected a recipe file", Location(str(path))) from None
    except OSError as exc:
        raise ConfigError(f"cannot read recipe: {exc.strerror or exc}", Location(str(path))) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"cannot read recipe: not UTF-8 text ({exc.reason} at byte {exc.start})",
                          Location(str(path))) from None
    root = parse_yaml(text, str(path))
    top = Section(root, ["name", "description", "vars", "on_failure", "sim_time", "steps"], what="a recipe mapping")
    name = top.str("name", Path(path).stem)
    description = top.str("description", "")
    sim_time = "wall"
    if (tnode := top.get("sim_time")) is not None:
        sim_time = as_str(tnode)
        if sim_time not in SIM_TIMES:
            raise tnode.error(f"sim_time must be one of {', '.join(SIM_TIMES)}, got {sim_time!r}")
    default_failure = _on_failure(top.get("on_failure"), "stop")
    variables = _variables(top.get("vars"), overrides or {}, str(path))
    # {recipe_dir}: the recipe file's own directory, so a file the recipe brings (a bands table) is
    # found from any working directory; outputs stay where the user runs it
    recipe_dir = str(Path(path).resolve().parent)
    variables = {k: v.replace("{recipe_dir}", recipe_dir) for k, v in variables.items()}
    in_steps = {"recipe_dir": recipe_dir, **variables}
    steps_node = top.req("steps")
    items = as_seq(steps_node, "a list of steps")
    if not items:
        raise steps_node.error("a recipe needs at least one step")
    steps: list[Step] = []
    seen: dict[str, int] = {}
    for i, item in enumerate(items, start=1):
        step = _step(item, i, default_failure, in_steps)
        if step.name in seen:
            raise item.error(f"step name '{step.name}' is used twice (also step {seen[step.name]})",
                             hint="step names must be unique: --from and the report refer to them")
        seen[step.name] = i
        steps.append(step)
    return Recipe(name, str(path), description, tuple(steps), variables, sim_time)


def _variables(node: YNode | None, overrides: dict[str, str], file: str) -> dict[str, str]:
    values: dict[str, str] = {}
    if node is not None:
        for key, child in as_map(node, "a mapping of variable names to values").items():
            if not NAME_RE.match(key):
                raise ConfigError(f"invalid variable name {key!r}", Location(file, child.key_line, child.path))
            if child.kind != "scalar" or child.value is None or isinstance(child.value, bool):
                raise child.error(f"expected a string or number, got {describe(child)}")
            values[key] = str(child.value)
    for key in overrides:
        if key not in values:
            known = ", ".join(values) or "none"
            raise ConfigError(f"--set {key}=...: the recipe has no variable '{key}'",
                              Location(file, node.line if node is not None else None, "vars"),
                              hint=f"variables of this recipe: {known}")
    values.update(overrides)
    return values


def _on_failure(node: YNode | None, default: str) -> str:
    if node is None:
        return default
    value = as_str(node)
    if value not in ON_FAILURE:
        raise node.error(f"on_failure must be one of {', '.join(ON_FAILURE)}, got {value!r}")
    return value


def _substitute(text: str, variables: dict[str, str], node: YNode) -> str:
    def repl(m: re.Match) -> str:
        key = m.group(1)
        if key not in variables:
            raise node.error(f"unknown variable {{{key}}}",
                             hint=f"define it under vars: (known: {', '.join(variables) or 'none'})")
        return variables[key]

    return VAR_RE.sub(repl, text)


def _argv(node: YNode, variables: dict[str, str]) -> tuple[str, ...]:
    if node.kind == "seq":
        parts = [_substitute(str(as_str(p) if p.kind == "scalar" and isinstance(p.value, str) else plain(p)),
                             variables, p) for p in node.value]
    else:
        text = _substitute(as_str(node), variables, node)
        try:
            parts = shlex.split(text)
        except ValueError as exc:
            raise node.error(f"cannot split the command line: {exc}") from None
    if parts and parts[0] == "sherpa":
        parts = parts[1:]
    if not parts:
        raise node.error("empty command")
    for p in parts:
        opt = p.split("=", 1)[0]
        if opt in GLOBAL_OPTIONS:
            raise node.error(f"'{opt}' is a global option: give it to `sherpa recipe run`, not to a step",
                             hint="the runner passes its own --config, --sim and --bus-map to every step")
    if parts[0] in ("recipe", "commission"):
        raise node.error(f"a step cannot run `sherpa {parts[0]}` (recipes do not nest)")
    return tuple(parts)


def _expect(node: YNode | None) -> Expect:
    if node is None:
        return Expect()
    sec = Section(node, ["exit", "stdout_contains", "json"], what="a mapping of expectations")
    exit_codes: tuple[int, ...] = (0,)
    if (e := sec.get("exit")) is not None:
        codes = [as_int(x) for x in as_seq(e)] if e.kind == "seq" else [as_int(e)]
        for code, src in zip(codes, e.value if e.kind == "seq" else [e], strict=True):
            if not 0 <= code <= 255:
                raise src.error(f"exit code {code} is outside 0..255")
        exit_codes = tuple(codes)
    contains: tuple[str, ...] = ()
    if (c := sec.get("stdout_contains")) is not None:
        contains = tuple(as_str(x) for x in as_seq(c)) if c.kind == "seq" else (as_str(c),)
    checks: tuple[tuple[str, Any], ...] = ()
    if (j := sec.get("json")) is not None:
        checks = tuple((key, plain(value)) for key, value in as_map(j, "a mapping of JSON paths to values").items())
    return Expect(exit_codes, contains, checks)


def _step(node: YNode, number: int, default_failure: str, variables: dict[str, str]) -> Step:
    sec = Section(node, ["name", "run", "confirm", "expect", "on_failure", "dry_run"], what="a step mapping")
    run, confirm = sec.get("run"), sec.get("confirm")
    if (run is None) == (confirm is None):
        raise node.error("a step needs exactly one of 'run' (a sherpa command) or 'confirm' (a question)")
    name_node = sec.get("name")
    if name_node is not None:
        name = as_str(name_node)
        if not NAME_RE.match(name) or name.isdigit():
            raise name_node.error(f"invalid step name {name!r}; use letters, digits, '_', '-' or '.', "
                                  "starting with a letter")
    else:
        name = f"step-{number}"
    on_failure = _on_failure(sec.get("on_failure"), default_failure)
    dry_run: str | None = None
    if (dnode := sec.get("dry_run")) is not None:
        dry_run = as_str(dnode)
        if dry_run not in DRY_RUN:
            raise dnode.error(f"dry_run must be one of {', '.join(DRY_RUN)}, got {dry_run!r}")
    if confirm is not None:
        if (expect := sec.get("expect")) is not None:
            raise expect.error("a confirm step has no result to expect things of")
        return Step(number, name, confirm=_substitute(as_str(confirm), variables, confirm),
                    on_failure=on_failure, line=node.line, dry_run=dry_run)
    assert run is not None  # exactly one of run and confirm (checked above)
    return Step(number, name, argv=_argv(run, variables), expect=_expect(sec.get("expect")),
                on_failure=on_failure, line=node.line, dry_run=dry_run)
