"""Generated bad inputs: 0 tracebacks and 0 hangs.

A seeded generator builds over 1,500 bad inputs -- configs (native and rosparam; wrong types in
every section; unsafe dead-man settings), recipes (and recipe steps with bad arguments), parameter
dumps, command lines of every command (Unicode digits and impossible numbers in every numeric
option, bad bus maps), recordings and captures truncated or garbled for `log plot`/`log decode`,
and hostile CAN frames for both ends of the bus (the simulated drive and the tool's drive client) -- and feeds them through the same doors
a user's input takes: ``load_config_text`` / ``load_recipe`` / ``dump_from_text``, the CLI's
``run(argv)`` in this process (as the ``cli`` fixture does), ``SimDrive.receive`` with its SDO
server, and ``DriveClient`` over a transport that answers at once.

What counts as a failure:

- a traceback: an exception that is not a SherpaError (or, for the simulated drive, any
  exception at all), or "Traceback" on stderr;
- a hang: one case taking longer than HANG_S;
- exit 0 (or no error) for input that is clearly bad (a must-fail case), or a refusal with an
  exit code docs/exit-codes.md does not list, or one that does not name the bad option;
- "no answer" for a drive that did answer (a malformed reply must be a ProtocolError);
- a config that `config check` passes but the derivation or the codec later refuses.

The test prints its count; the budget for the whole file is well under a minute.
"""

from __future__ import annotations

import io
import math
import random
import shlex
import struct
import threading
import time
import traceback
from collections.abc import Callable
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from conftest import ROOT

SEED = 11
HANG_S = 20.0
MIN_CASES = 1500


@dataclass
class Tally:
    count: int = 0
    by_kind: dict[str, int] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)

    def case(self, kind: str) -> None:
        self.count += 1
        self.by_kind[kind] = self.by_kind.get(kind, 0) + 1

    def fail(self, kind: str, what: str, problem: str) -> None:
        self.failures.append(f"[{kind}] {what[:300]}: {problem[:1500]}")


def bounded(fn: Callable[[], Any]) -> tuple[Any, BaseException | None, bool]:
    """Run fn in a thread: (result, exception, hung)."""
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["result"] = fn()
        except BaseException as exc:  # noqa: BLE001 -- the point is to see everything
            box["error"] = exc
            box["tb"] = traceback.format_exc()

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(HANG_S)
    if t.is_alive():
        return None, None, True
    exc = box.get("error")
    if exc is not None:
        exc.__dict__["_tb_text"] = box["tb"]
    return box.get("result"), exc, False


def judge(tally: Tally, kind: str, what: str, load: Callable[[], Any], *, must_fail: bool = False,
          after: Callable[[Any], None] | None = None) -> None:
    """Count one input: ``load`` may refuse it with a SherpaError; anything else escaping is a
    traceback. ``after(result)`` checks what was accepted; ``must_fail`` inputs must be refused."""
    from sherpa_cli.errors import SherpaError

    def attempt() -> str:
        try:
            result = load()
        except SherpaError:
            return "refused"
        if after is not None:
            after(result)
        return "accepted"

    tally.case(kind)
    outcome, exc, hung = bounded(attempt)
    if hung:
        tally.fail(kind, what, "hang")
    elif exc is not None:
        tally.fail(kind, what, exc.__dict__.get("_tb_text", repr(exc)))
    elif must_fail and outcome != "refused":
        tally.fail(kind, what, "clearly bad input was accepted")


# ---------------------------------------------------------------------------------------------
# hostile values

NAN_TEXT = [".nan", ".NaN", ".inf", "-.inf", ".Inf"]
HOSTILE_SCALARS = [
    ".nan", ".inf", "-.inf", "2147483648", "-2147483649", "4294967296", "1e40", "-1e40", "1e308",
    "9" * 60, "-" + "9" * 60, "9" * 5000, "0", "-1", "1.5", "-0.0", "0x7FFFFFFF", "0o777", "0b1",
    "''", "'x'", "null", "true", "[]", "{}", "[1, 2]", "{a: 1}", "'" + "x" * 3000 + "'",
    "'\u00e9\u0394\u03a3'", "'\\t'", "1_000", "+12", "1e-400", "65536", "127", "128",
]


def numeric_leaves(data: Any, path: tuple = ()) -> list[tuple]:
    out = []
    if isinstance(data, dict):
        for k, v in data.items():
            out += numeric_leaves(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += numeric_leaves(v, (*path, i))
    elif isinstance(data, (int, float)) and not isinstance(data, bool):
        out.append(path)
    return out


def all_leaves(data: Any, path: tuple = ()) -> list[tuple]:
    out = [path] if path else []
    if isinstance(data, dict):
        for k, v in data.items():
            out += all_leaves(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += all_leaves(v, (*path, i))
    return out


def with_value(data: Any, path: tuple, raw: str) -> str:
    """YAML text of ``data`` with the value at ``path`` replaced by the YAML text ``raw``."""
    marker = "@@HOSTILE@@"
    copy = yaml.safe_load(yaml.safe_dump(data))
    node = copy
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = marker
    return yaml.safe_dump(copy, sort_keys=False, width=10_000).replace(f"'{marker}'", raw).replace(marker, raw)


def text_mutation(rng: random.Random, text: str) -> str:
    lines = text.splitlines(True)
    kind = rng.randrange(10)
    if kind == 0:
        return text[: rng.randrange(len(text))]  # truncated
    if kind == 1 and lines:
        i = rng.randrange(len(lines))
        return "".join(lines[:i] + lines[i + 1:])  # a line deleted
    if kind == 2 and lines:
        i = rng.randrange(len(lines))
        return "".join([*lines[:i + 1], lines[i], *lines[i + 1:]])  # a line twice
    if kind == 3:
        i = rng.randrange(len(text) + 1)
        return text[:i] + rng.choice(["\t", ":", "- ", "{", "]", "&a ", "*a", "!!python/object:os.system ", "\x00",
                                      "\ufeff", "'", '"', "%YAML 1.1\n", "---\n", "? ", "|", ">"]) + text[i:]
    if kind == 4 and lines:
        i = rng.randrange(len(lines))
        return "".join([*lines[:i], "  " * rng.randrange(1, 6) + lines[i], *lines[i + 1:]])  # indentation
    if kind == 5:
        return text + "\nbomb: &b0 [x, x, x, x, x, x, x, x]\n" + "".join(
            f"b{i}: &b{i} [{', '.join(['*b' + str(i - 1)] * 8)}]\n" for i in range(1, 8))
    if kind == 6:
        return text + "\ndeep: " + "[" * 200 + "]" * 200 + "\n"
    if kind == 7:
        return text + "\n---\nsecond: document\n"
    if kind == 8:
        return text.replace(":", "", 1)
    return "".join(rng.choice([line, line.upper()]) for line in lines)


# ---------------------------------------------------------------------------------------------
# configs

NATIVE = ["configs/appendix-c/example1.yaml", "configs/appendix-c/example2.yaml", "configs/appendix-c/example3.yaml",
          "configs/sherpa-arm.yaml"]
ROSPARAM = ["configs/seed-d1.yaml"]
# cases per file: (NaN/Inf at a number, hostile scalar at a number, hostile scalar anywhere, text damage);
# the whole arm's config costs ten times an example's, so it gets a few
PER_FILE = {"configs/sherpa-arm.yaml": (4, 4, 3, 3)}
PER_FILE_DEFAULT = (12, 20, 12, 10)


def _config_consistent(cfg: Any) -> str | None:
    """None when `config check` and the later steps agree about this config, else the disagreement."""
    from sherpa_cli.config import dump_native, load_config_text
    from sherpa_cli.elmo import codec
    from sherpa_cli.elmo.commands import parse_param_key
    from sherpa_cli.joints.limits import config_findings, derive_checked

    errors = [f for f in config_findings(cfg) if f.level == "error"]
    again = load_config_text(dump_native(cfg), "roundtrip.yaml")  # must not raise either
    assert again is not None
    if errors:
        return None  # `config check` fails: nothing later has to accept it
    sets, _ = derive_checked(cfg)  # must not raise: the check passed
    for dp in sets:
        for key, value in dp.params.items():
            letters, index = parse_param_key(key)
            codec.encode_set(letters, index, value)  # must not raise
    return None


def config_cases(rng: random.Random, tally: Tally) -> None:
    from sherpa_cli.config import load_config_text

    for rel in NATIVE + ROSPARAM:
        text = (ROOT / rel).read_text()
        data = yaml.safe_load(text)
        leaves = numeric_leaves(data)
        every = all_leaves(data)
        native = rel in NATIVE
        n_nan, n_number, n_any, n_text = PER_FILE.get(rel, PER_FILE_DEFAULT)
        plans: list[tuple[str, str, bool]] = []
        for _ in range(n_nan):  # NaN / Inf at a random number: always refused by a native config
            path = rng.choice(leaves)
            raw = rng.choice(NAN_TEXT)
            plans.append((f"{rel} {'.'.join(map(str, path))}={raw}", with_value(data, path, raw), native))
        for _ in range(n_number):  # any hostile scalar at any number
            path = rng.choice(leaves)
            raw = rng.choice(HOSTILE_SCALARS)
            plans.append((f"{rel} {'.'.join(map(str, path))}={raw[:30]}", with_value(data, path, raw), False))
        for _ in range(n_any):  # any hostile scalar anywhere
            path = rng.choice(every)
            raw = rng.choice(HOSTILE_SCALARS)
            plans.append((f"{rel} {'.'.join(map(str, path))}={raw[:30]}", with_value(data, path, raw), False))
        for _ in range(n_text):  # text damage
            plans.append((f"{rel} text mutation", text_mutation(rng, text), False))
        for what, body, must_fail in plans:
            judge(tally, "config", what, lambda body=body: load_config_text(body, "fuzz.yaml"), must_fail=must_fail,
                  after=_config_consistent)


# ---------------------------------------------------------------------------------------------
# recipes and dumps

def recipe_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    from sherpa_cli.recipes import load_recipe

    cases: list[tuple[str, str, bool]] = []
    for rel in ("recipes/commission-arm.yaml", "recipes/backup.yaml"):
        text = (ROOT / rel).read_text()
        data = yaml.safe_load(text)
        every = all_leaves(data)
        for _ in range(25):
            path = rng.choice(every)
            raw = rng.choice(HOSTILE_SCALARS)
            cases.append((f"{rel} {'.'.join(map(str, path))}={raw[:30]}", with_value(data, path, raw), False))
        for _ in range(15):
            cases.append((f"{rel} text mutation", text_mutation(rng, text), False))
    clearly_bad = [
        "steps:\n  - name: a\n    run: frobnicate\n",
        "steps:\n  - name: a\n    run: scan --no-such-option\n",
        "steps:\n  - name: a\n    kind: scan\n",
        "steps:\n  - name: a\n    run: sherpa recipe run x.yaml\n",
        "steps:\n  - run: monitor --interval soon\n",
        "steps:\n  - run: params\n",
        "steps:\n  - run: cmd\n",
        "steps:\n  - run: '--sim scan'\n",
        "steps: []\n",
        "steps:\n  - run: scan\n    expect: {exit: 999}\n",
        "steps:\n  - run: '{undefined} scan'\n",
        "name: x\nsteps:\n  - run: \"scan 'unclosed\"\n",
        "steps:\n  - {name: a, run: scan}\n  - {name: a, run: scan}\n",
        "steps:\n  - run: scan\n    on_failure: explode\n",
    ]
    for body in clearly_bad:
        cases.append((f"clearly bad recipe {body!r}", body, True))
    for i, (what, body, must_fail) in enumerate(cases):
        path = tmp / f"recipe-{i}.yaml"
        path.write_text(body, encoding="utf-8", errors="surrogateescape")
        if must_fail:
            tally.case("recipe")
            check_cli(tally, "recipe", ["recipe", "check", str(path)], must_fail=True)
            continue

        judge(tally, "recipe", what, lambda path=path: load_recipe(path))


def dump_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    from sherpa_cli.ops.params_file import dump_from_text

    good = tmp / "good-dump.yaml"
    code, _, err, exc, _ = run_cli([*EX3, "--sim", "dump-params", "-o", str(good)])
    assert code == 0 and exc is None, err
    DUMP = good.read_text()
    dump_from_text(DUMP, str(good))
    data = yaml.safe_load(DUMP)
    every = all_leaves(data)
    cases = []
    for _ in range(70):
        path = rng.choice(every)
        raw = rng.choice(HOSTILE_SCALARS)
        cases.append((f"dump {'.'.join(map(str, path))}={raw[:30]}", with_value(data, path, raw)))
    for _ in range(30):
        cases.append(("dump text mutation", text_mutation(rng, DUMP)))
    for what, body in cases:
        judge(tally, "dump", what, lambda body=body: dump_from_text(body, "fuzz-dump.yaml"))


# ---------------------------------------------------------------------------------------------
# command lines

def run_cli(argv: list[str]) -> tuple[int | None, str, str, BaseException | None, bool]:
    from sherpa_cli.cli.app import run

    def go() -> tuple[int, str, str]:
        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            code = run(argv)
        return int(code), out.getvalue(), err.getvalue()

    result, exc, hung = bounded(go)
    if result is None:
        return None, "", "", exc, hung
    return result[0], result[1], result[2], None, False


def check_cli(tally: Tally, kind: str, argv: list[str], *, must_fail: bool, names: str | None = None,
              exits: set[int] | None = None) -> None:
    """One command line; ``names``: a refusal must name this (the option whose value is bad);
    ``exits``: the exit codes a refusal may have (default: any documented one)."""
    code, out, err, exc, hung = run_cli(argv)
    what = "sherpa " + shlex.join(argv)
    if hung:
        tally.fail(kind, what, "hang")
    elif exc is not None:
        tally.fail(kind, what, exc.__dict__.get("_tb_text", repr(exc)))
    elif "Traceback" in err or "Traceback" in out:
        tally.fail(kind, what, "traceback in the output:\n" + err[-1500:])
    elif must_fail and code == 0:
        tally.fail(kind, what, "exit 0 on clearly bad input:\n" + out[-500:] + err[-500:])
    elif must_fail and code not in (exits or DOCUMENTED_EXITS):
        tally.fail(kind, what, f"exit {code}, not a documented exit code:\n" + err[-500:])
    elif names is not None and names not in err:
        tally.fail(kind, what, f"the refusal does not name {names}:\n" + err[-500:])


EX1 = ["--config", "configs/appendix-c/example1.yaml"]
DOCUMENTED_EXITS = {1, 2, 3, 4, 5, 6, 129, 130, 143}  # docs/exit-codes.md
EX3 = ["--config", "configs/appendix-c/example3.yaml"]
BAD_WORDS = ["", " ", "-", "--", "nosuch", "joint1x", "can0:0", "can0:128", "can9:1", "can0:", ":1", "a" * 300,
             "\u0394", "--bogus", "-x", "1e400", "nan", "-1", "0", "99999999999999999999999", "../../etc/passwd",
             "joint1:1", "=", "PX[", "AC==1", "[3]"]
BAD_EXPR = ["QQ", "px", "PX[", "LL[99999]", "LL[-1]", "AC=1e40", "AC=nan", "CL[1]=inf", "AC=" + "9" * 5000,
            "AC=0x", "LL[" + "9" * 5000 + "]", "MO=2=3", "LL", "BG=1", "SR=5", "AC= ", "AC=1.5", "UM=abc", "\u00c4C=1", "AC\x00", "LL[3.0]"]
BAD_FILES = ["/nonexistent/x.yaml", "/dev/null", "/dev/zero", "/", "configs", "README.md", "recipes/backup.yaml"]


def cli_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    cases: list[tuple[list[str], bool]] = []
    # global options
    for word in BAD_WORDS[:12]:
        cases.append((["--config", word or "''", "limits", "show"], True))
        cases.append((["--bus-map", word, *EX1, "--sim", "scan"], word.strip() not in ("", "-", "--")))
    for f in BAD_FILES:
        cases.append((["--config", f, "config", "check"], True))
        cases.append((["config", "check", f], True))
        cases.append((["config", "convert", f], True))
        cases.append((["recipe", "check", f], not f.startswith("recipes/")))
        cases.append(([*EX1, "params", "diff", f, "config"], True))
        cases.append(([*EX1, "--sim", "params", "restore", f], True))
    # every command with a bad target or option
    for word in rng.sample(BAD_WORDS, 8):
        if word == "--":  # the end-of-options marker: no target at all is valid (every drive)
            word = "--x"
        cases += [
            ([*EX1, "limits", "show", word], True),
            ([*EX1, "--sim", "program-limits", word], True),
            ([*EX1, "--sim", "identify", word], True),
            ([*EX1, "--sim", "monitor", "--once", word], True),
            ([*EX1, "--sim", "dump-params", word], True),
            ([*EX3, "diffdrive", "limits", word], True),
            ([*EX3, "diffdrive", "convert", word, "--sigma", "0", "--delta", "0"], True),
            ([*EX1, "--sim", "cmd", word, "PX"], True),
            ([*EX1, "--sim", "params", "diff", "config", "live", "--target", word], True),
            ([*EX1, "--sim", "scan", "--bus", word], True),
            ([*EX1, "--sim", "bus", "status", word, "--window", "0"], True),
            ([*EX1, "--sim", "bus", "watch", word, "--for", "0.1"], True),
            ([*EX1, "--sim", "bus", "up", word], True),
            ([*EX1, "--sim", "bus", "down", word], True),
            ([*EX1, "--sim", "move", word], True),
            ([*EX3, "--sim", "move", word, "--joints", word], True),
        ]
    for i, expr in enumerate(BAD_EXPR):
        cases.append(([*EX1, "--sim", "cmd", "joint1", expr, *(["--apply"] if i % 2 else [])], True))
    numbers = ["nan", "inf", "-inf", "1e400", "-1", "0", "abc", "", "9" * 5000, "70000", "65536", "1e-9"]
    for n in numbers:
        cases += [
            ([*EX1, "--sim", "monitor", "--once", "--interval", n], n in ("nan", "inf", "-inf", "1e400", "-1", "0",
                                                                        "abc", "", "9" * 5000)),
            ([*EX1, "--sim", "monitor", "--once", "--heartbeat", n], n in ("nan", "inf", "-inf", "1e400", "-1",
                                                                         "abc", "", "9" * 5000, "70000", "65536",
                                                                         "1e-9")),
            ([*EX3, "diffdrive", "convert", "pair1", "--sigma", n, "--delta", "0"], n in ("nan", "inf", "-inf",
                                                                                          "1e400", "abc", "",
                                                                                          "9" * 5000)),
            ([*EX3, "diffdrive", "convert", "pair1", "--motor-a", n, "--motor-b", n], n in ("nan", "inf", "-inf",
                                                                                           "1e400", "abc", "",
                                                                                           "9" * 5000)),
            ([*EX1, "sim", "--duration", n], True),
            ([*EX1, "--sim", "bus", "status", "--window", n], n not in ("0", "1e-9")),
            ([*EX1, "--sim", "doctor", "--window", n], n not in ("0", "1e-9")),
            ([*EX1, "--sim", "bus", "up", "--bitrate", n], n not in ("70000", "65536")),
            ([*EX1, "--sim", "bus", "up", "--restart-ms", n], n in ("nan", "inf", "-inf", "1e400", "-1", "abc", "",
                                                                   "9" * 5000, "70000", "65536", "1e-9")),
        ]
        if n not in ("70000", "65536"):  # a valid duration: the watch would run that long
            cases.append(([*EX1, "--sim", "bus", "watch", "--for", n], n not in ("1e-9",)))
        if n != "0":  # port 0 is valid: it would serve the arm until Ctrl-C
            cases.append(([*EX1, "sim", "--serve", f"127.0.0.1:{n}"], True))
    for mode in ("counts", "rad", "deg", "", "RAD"):
        cases.append(([*EX3, "diffdrive", "convert", "pair1", "--sigma", "1", "--delta", "1", "--unit", mode],
                      mode not in ("counts", "rad")))
    odd = [
        [*EX1, "--sim", "sim"], [*EX1, "sim", "--serve", "0.0.0.0:1"], [*EX1, "sim", "--serve", "nohost"],
        [*EX1, "sim", "--serve", ":"],
        ["--bogus"], ["scan", "--bogus"], ["params"], ["params", "bogus"], ["limits", "bogus"], ["recipe", "run"],
        [*EX1, "--sim", "program-limits", "--save"], [*EX1, "--sim", "params", "diff", "bogus", "live"],
        [*EX1, "--sim", "commission", "--from", "nosuchstep"], [*EX1, "--sim", "commission", "--set", "x"],
        [*EX1, "--sim", "commission", "--set", "nosuch=1"], [*EX1, "--sim", "recipe", "run", "recipes/backup.yaml",
                                                             "--from", "99"],
        [*EX1, "--sim", "cmd", "joint1"], [*EX1, "--sim", "cmd"], [*EX3, "diffdrive", "convert", "pair1"],
        [*EX3, "diffdrive", "convert", "pair1", "--sigma", "1"],
        [*EX3, "diffdrive", "convert", "pair1", "--sigma", "1", "--delta", "1", "--motor-a", "1", "--motor-b", "1"],
        [*EX1, "--sim", "dump-params", "-o", "/dev/null/x.yaml"],
        [*EX1, "--sim", "commission", "--report", "/dev/null/r.json"],
        [*EX1, "--sim", "commission", "--junit", "/"],
    ]
    cases += [(argv, True) for argv in odd]
    # hostile config files through the CLI
    for i in range(25):
        text = text_mutation(rng, (ROOT / rng.choice(NATIVE)).read_text())
        path = tmp / f"cli-config-{i}.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogateescape")
        cases.append((["--config", str(path), rng.choice(["config", "limits"]), "check" if i % 2 else "show"],
                      False))
    for argv, must_fail in cases:
        tally.case("cli")
        check_cli(tally, "cli", argv, must_fail=must_fail)


# ---------------------------------------------------------------------------------------------
# wrong types in every section of a config

TYPED = ["configs/appendix-c/example1.yaml", "configs/appendix-c/example3.yaml", "tests/data/jog-fast-arm.yaml",
         "tests/data/home-arm.yaml", "tests/data/step-arm.yaml", "tests/data/joystick-arm.yaml"]
TYPED_PER_SECTION = 4  # leaves per top-level section and file (a config load costs ~50-70 ms)
# (YAML text, what it is): a value of the wrong type for the leaf it replaces
NOT_A_NUMBER = [("abc", "a word"), ("[1, 2]", "a list"), ("{a: 1}", "a mapping"), ("'12'", "a quoted number"),
                ("2021-01-01", "a date")]
NOT_A_STRING = [("[a, b]", "a list"), ("{a: 1}", "a mapping")]
NOT_A_CONTAINER = [("7", "a number"), ("word", "a word"), ("[7, 8]", "a list"), ("true", "a boolean")]


def _node(data: Any, path: tuple) -> Any:
    for key in path:
        data = data[key]
    return data


def config_type_cases(rng: random.Random, tally: Tally) -> None:
    """Every leaf and every mapping of each config, in every section, given a value of the wrong
    type: refused (a mapping given a list is left out: some sections take either)."""
    from sherpa_cli.config import load_config_text

    for rel in TYPED:
        data = yaml.safe_load((ROOT / rel).read_text())
        by_section: dict[Any, list[tuple]] = {}
        for path in all_leaves(data):
            by_section.setdefault(path[0], []).append(path)
        chosen = [p for paths in by_section.values() for p in rng.sample(paths, min(TYPED_PER_SECTION, len(paths)))]
        for path in chosen:
            value = _node(data, path)
            if isinstance(value, bool):
                choices = [*NOT_A_STRING, ("abc", "a word")]
            elif isinstance(value, (int, float)):
                choices = NOT_A_NUMBER
            elif isinstance(value, str):
                choices = NOT_A_STRING
            elif isinstance(value, dict):
                choices = [c for c in NOT_A_CONTAINER if c[1] != "a list"]
            else:  # a list: a mapping or a word instead
                choices = [("{a: 1}", "a mapping"), ("word", "a word")]
            raw, kind = rng.choice(choices)
            if isinstance(value, str) and path[-1] in ("name", "description", "comment"):
                continue  # free text: any YAML scalar reads as text there
            what = f"{rel} {'.'.join(map(str, path))} = {kind}"
            body = with_value(data, path, raw)
            judge(tally, "config type", what, lambda body=body: load_config_text(body, "t.yaml"), must_fail=True)


# unsafe dead-man settings and other motion values that would make the dead-man meaningless
UNSAFE_MOTION = [
    "consumer_time_ms: 0", "consumer_time_ms: -1", "consumer_time_ms: 5001", "consumer_time_ms: 60000",
    "consumer_time_ms: 65535", "consumer_time_ms: 70000", "consumer_time_ms: 1.0e+9", "consumer_time_ms: .nan",
    "loss_action: 0", "loss_action: -1", "loss_action: 4", "loss_action: 0.5", "loss_action: '2'",
    "liveness_timeout: 0", "liveness_timeout: -1", "liveness_timeout: 11", "liveness_timeout: 1.0e+9",
    "liveness_timeout: .inf", "liveness_timeout: .nan", "heartbeat_period_ms: -1", "heartbeat_period_ms: 400",
    "heartbeat_period_ms: 1.0e+9", "comm_error_behaviour: 3", "comm_error_behaviour: -1",
    "deadman_check_interval: 0", "deadman_check_interval: 100", "deadman_check_interval: .nan",
    "host_node_id: 0", "host_node_id: 128", "host_id_pool: [0]", "host_id_pool: [124, 124]",
    "max_torque_for: 0", "max_torque_for: 61", "max_torque_for: .inf", "max_torque_for: 1.0e+9",
    "standstill_timeout: 0", "standstill_timeout: .nan", "stall_time: 31", "recovery_speed: 2",
]


def deadman_cases(rng: random.Random, tally: Tally) -> None:
    from sherpa_cli.config import load_config_text

    for rel in ("configs/appendix-c/example1.yaml", "tests/data/jog-fast-arm.yaml"):
        text = (ROOT / rel).read_text()
        data = yaml.safe_load(text)
        data.pop("motion", None)
        base = yaml.safe_dump(data, sort_keys=False, width=10_000)
        for setting in UNSAFE_MOTION:
            body = base + f"motion: {{{setting}}}\n"
            judge(tally, "unsafe motion", f"{rel} motion.{setting}", lambda body=body: load_config_text(body, "m.yaml"),
                  must_fail=True)


# ---------------------------------------------------------------------------------------------
# numeric options of every command: Unicode digits, NaN/Inf, numbers too big to be one

UNICODE_NUMBERS = ["\uff13", "\u0663", "\u0967", "\uff11.\uff15", "\u00bd", "\u2167", "1\u00b2", "\U0001d7d1"]
NOT_NUMBERS = ["nan", "inf", "-inf", "1e400", "-1e400", "9" * 400, "0x10", "1,5", "--", "1e", ".", "\u22121"]


def numeric_option_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    csv = tmp / "opt-rec.csv"
    csv.write_text(GOOD_RECORDING)
    log = tmp / "opt-cap.log"
    log.write_text(GOOD_CANDUMP)
    out = str(tmp / "opt-out.csv")
    png = str(tmp / "opt-out.png")
    # (command line without the option, the option, the number it takes)
    options: list[tuple[list[str], str]] = [
        ([*EX1, "--sim", "monitor", "--once"], "--interval"),
        ([*EX1, "--sim", "monitor", "--once"], "--heartbeat"),
        ([*EX1, "--sim", "monitor"], "--for"),
        (["--bus-map", "can0=virtual:fuzz-serve", *EX1, "sim"], "--duration"),
        ([*EX1, "--sim", "doctor"], "--window"),
        ([*EX3, "diffdrive", "convert", "pair1", "--delta", "0"], "--sigma"),
        ([*EX3, "diffdrive", "convert", "pair1", "--sigma", "0"], "--delta"),
        ([*EX3, "diffdrive", "convert", "pair1", "--motor-b", "0"], "--motor-a"),
        ([*EX1, "--sim", "bus", "status"], "--window"),
        ([*EX1, "--sim", "bus", "watch"], "--for"),
        ([*EX1, "--sim", "bus", "watch", "--for", "0.05"], "--interval"),
        ([*EX1, "--sim", "bus", "up"], "--bitrate"),
        ([*EX1, "--sim", "bus", "up"], "--restart-ms"),
        ([*EX1, "log", "decode", str(log)], "--node"),
        (["--bus-map", "can0=virtual:fuzz-capture", *EX1, "log", "capture", "-o", str(tmp / "opt-cap2.log")],
         "--for"),
        ([*EX1, "log", "plot", str(csv), "-o", png], "--step-at"),
        ([*EX1, "log", "plot", str(csv), "-o", png], "--target"),
        ([*EX1, "--sim", "log", "record", "joint1", "-o", out, "--for", "0.05"], "--rate"),
        ([*EX1, "--sim", "log", "record", "joint1", "-o", out], "--for"),
        ([*EX1, "--sim", "log", "step", "joint1", "-o", out, "--apply"], "--position"),
        ([*EX1, "--sim", "log", "step", "joint1", "-o", out, "--apply"], "--velocity"),
        ([*EX1, "--sim", "log", "step", "joint1", "-o", out, "--apply"], "--torque"),
        ([*EX1, "--sim", "log", "step", "joint1", "-o", out, "--torque", "0.1", "--apply"], "--for"),
        ([*EX1, "--sim", "log", "step", "joint1", "-o", out, "--position", "0.1", "--apply"], "--rate"),
        ([*EX1, "--sim", "jog", "joint1", "--uncalibrated", "--apply"], "--to"),
        ([*EX1, "--sim", "jog", "joint1", "--uncalibrated", "--apply"], "--by"),
        ([*EX1, "--sim", "jog", "joint1", "--for", "0.05", "--uncalibrated", "--apply"], "--velocity"),
        ([*EX1, "--sim", "jog", "joint1", "--for", "0.05", "--apply"], "--torque"),
        ([*EX1, "--sim", "jog", "joint1", "--velocity", "0.01", "--uncalibrated", "--apply"], "--for"),
        ([*EX1, "--sim", "jog", "joint1", "--torque", "0.1", "--apply"], "--for"),
        ([*EX3, "--sim", "diffdrive", "move", "pair1", "--delta", "0", "--uncalibrated", "--apply"], "--sigma"),
        ([*EX3, "--sim", "diffdrive", "move", "pair1", "--sigma", "0", "--uncalibrated", "--apply"], "--delta"),
        ([*EX3, "--sim", "diffdrive", "move", "pair1", "--sigma", "0", "--delta", "0", "--uncalibrated", "--apply"],
         "--velocity"),
        ([*EX1, "--sim", "move", "transport", "--uncalibrated", "--apply"], "--speed-scale"),
    ]
    cases: list[tuple[list[str], str]] = []
    for argv, option in options:
        for value in [rng.choice(UNICODE_NUMBERS), *rng.sample(NOT_NUMBERS, 2)]:
            cases.append(([*argv, f"{option}={value}"], option))
    # numbers inside other arguments: an interpreter expression, gains, a bus map's port
    # (0x10 is a number there: the interpreter's hex)
    for value in rng.sample(UNICODE_NUMBERS, 4) + rng.sample([n for n in NOT_NUMBERS if n != "0x10"], 4):
        cases.append(([*EX1, "--sim", "cmd", "joint1", f"AC={value}", "--apply"], "AC"))
        cases.append(([*EX1, "--sim", "tune", "set", "joint1", f"KP[2]={value}", "--apply"], "KP"))
        cases.append(([*EX1, "--sim", "cmd", "joint1", f"LL[{value}]"], "LL"))
    for argv, option in cases:
        tally.case("numeric option")
        check_cli(tally, "numeric option", argv, must_fail=True, names=option)


# ---------------------------------------------------------------------------------------------
# bus maps (without --sim, which excludes --bus-map: the map itself must be refused)

BAD_BUS_MAPS = [
    "can0", "can0=", "=socketcan:vcan0", "can0=socketcan", "can0=socketcan:", "can0=:vcan0", "can0==socketcan:x",
    " =virtual:x", "can9=virtual:x", "CAN0=virtual:x", "can0=nosuchiface:x",
    "can0=udp_multicast:239.0.0.1", "can0=remote:", "can0=remote:127.0.0.1:99999", "can0=remote:127.0.0.1:-1",
    "can0=remote:127.0.0.1:\uff15\uff14", "can0=remote:127.0.0.1:abc", "can0=remote:[::1",
    "can0=virtual:x,can0=virtual:y", "can0=virtual:x,can0=socketcan:vcan0", "\u0441an0=virtual:x",
    "can0=" + "a" * 300 + ":x", "can0=so cket:x", "can0=socket-can:x", "can0=\u0455ocketcan:x",
    "can0=remote:host:1e400", "can0=remote:127.0.0.1:0", "can0=remote:127.0.0.1:65536",
]


def bus_map_cases(rng: random.Random, tally: Tally) -> None:
    """Each through --bus-map and through SHERPA_BUS_MAP: refused as a usage error naming the map."""
    import os

    from sherpa_cli.bus.busmap import ENV_VAR

    for spec in BAD_BUS_MAPS:
        tally.case("bus map")
        check_cli(tally, "bus map", ["--bus-map", spec, *EX1, "scan"], must_fail=True, names="bus", exits={2})
    for spec in rng.sample(BAD_BUS_MAPS, 8):  # the other door, for a few
        tally.case("bus map")
        os.environ[ENV_VAR] = spec
        try:
            check_cli(tally, "bus map", [*EX1, "identify"], must_fail=True, names="bus", exits={2})
        finally:
            del os.environ[ENV_VAR]


# ---------------------------------------------------------------------------------------------
# recipe steps whose arguments are bad: `recipe check` refuses them before step 1

BAD_STEP_ARGS = [
    "jog joint1 --to \uff13 --apply", "jog joint1 --by nan --apply", "jog joint1 --to 1e400 --apply",
    "jog joint1 --velocity 0.1 --for 1e400 --apply", "jog joint1 --torque 0.1 --apply",
    "jog joint1 --torque \u0663 --for 1 --apply", "jog joint1 --to 0.1 --by 0.1 --apply", "jog nosuch --to 0",
    "jog joint1 --velocity inf --for 1", "jog joint1 --to", "home nosuch --yes", "home joint1 --bogus",
    "log record joint1 --rate \uff11\uff10\uff10 --for 1 -o x.csv", "log record joint1 --rate nan -o x.csv",
    "log record joint1 --rate 100 --for -1 -o x.csv", "log record nosuch -o x.csv", "log record joint1",
    "log step joint1 --position \u00bd -o x.csv --apply", "log step joint1 --torque 1 --for inf -o x.csv --apply",
    "log step joint1 -o x.csv", "log step joint1 --position 1 --velocity 1 -o x.csv",
    "diffdrive move pair1 --sigma \uff10 --delta 0 --apply", "diffdrive move nosuch --sigma 0 --delta 0",
    "diffdrive convert pair1 --sigma nan --delta 0", "monitor --interval \uff11", "monitor --heartbeat -1",
    "bus watch --for nan", "bus up --bitrate 1e400", "cmd joint1 AC=\uff11", "cmd joint1 LL[nan]",
    "tune set joint1 KP[2]=\uff11 --apply", "params restore /nonexistent.yaml", "scan --bus can9",
    "identify nosuch", "stop nosuch", "program-limits nosuch", "dump-params -o /dev/null/x.yaml",
    "log plot x.csv", "log decode", "sim --duration \uff11",
]


def recipe_step_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    for i, step in enumerate(BAD_STEP_ARGS):
        body = f"name: bad step {i}\nconfig: configs/appendix-c/example1.yaml\nsteps:\n" \
               f"  - name: fine\n    run: limits show\n  - name: bad\n    run: {json_quote(step)}\n"
        path = tmp / f"bad-step-{i}.yaml"
        path.write_text(body, encoding="utf-8")
        tally.case("recipe step")
        check_cli(tally, "recipe step", [*EX1, "recipe", "check", str(path)], must_fail=True)


def json_quote(text: str) -> str:
    import json

    return json.dumps(text, ensure_ascii=False)


# ---------------------------------------------------------------------------------------------
# recordings and captures handed to `log plot` / `log decode`, truncated or garbled

GOOD_RECORDING = "time_s,joint1.pos_rad,joint1.vel_rad_s,joint1.cur_a,drive1.px,drive1.vx,drive1.iq_a\n" + "".join(
    f"{k / 100:.6f},{0.01 * k:.5f},{0.5:g},{0.1:g},{k},{50},{0.1:g}\n" for k in range(40))
GOOD_CANDUMP = "".join(f"({1700000000 + k / 1000:.6f}) can0 {cob:03X}#{data}\n" for k, (cob, data) in enumerate(
    [(0x080, ""), (0x28A, "50580000E8030000"), (0x30A, "50580000"), (0x701, "05"), (0x60A, "4001140200000000"),
     (0x58A, "4F011402FF000000"), (0x08A, "1000010000000000"), (0x000, "010A")] * 5))


def file_mutation(rng: random.Random, data: bytes) -> tuple[bytes, str]:
    kind = rng.randrange(9)
    if kind == 0:
        cut = rng.randrange(1, max(2, len(data)))
        return data[:cut], f"truncated at {cut}"
    if kind == 1:
        b = bytearray(data)
        for _ in range(rng.randrange(1, 20)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b), "bytes garbled"
    if kind == 2:
        lines = data.splitlines(True)
        rng.shuffle(lines)
        return b"".join(lines), "lines shuffled"
    if kind == 3:
        return data.replace(b",", b";"), "another delimiter"
    if kind == 4:
        return b"\xef\xbb\xbf" + data.replace(b"\n", b"\r\n"), "BOM and CRLF"
    if kind == 5:
        lines = data.splitlines(True)
        i = rng.randrange(len(lines))
        return b"".join([*lines[:i], rng.choice([b"nan,nan,inf\n", b"," * 50 + b"\n", b"1e400," * 7 + b"\n",
                                                 b"x" * 100_000 + b"\n", b"\x00\x00\n"]), *lines[i:]]), "a bad line"
    if kind == 6:
        return data.split(b"\n", 1)[0] + b"\n", "header only"
    if kind == 7:
        return data[: len(data) // 2] + b"\x00" * 64 + data[len(data) // 2:], "NUL bytes inside"
    return data.replace(b".", b"\xd9\xab"), "Unicode decimal points"


def log_file_cases(rng: random.Random, tally: Tally, tmp: Path) -> None:
    recording = GOOD_RECORDING.encode()
    capture = GOOD_CANDUMP.encode()
    png = str(tmp / "fuzz-plot.png")
    junk = [(b"", "empty"), (bytes(rng.randrange(256) for _ in range(4096)), "random bytes"), (b"\x00" * 1000, "NULs"),
            (b"\x89MCAP0\r\n" + bytes(100), "an MCAP magic then nothing"), (b"PK\x03\x04" + bytes(60), "a zip")]
    cases: list[tuple[list[str], bytes, str, str, bool]] = []  # (argv before the file, body, suffix, what, must fail)
    for _ in range(40):
        body, what = file_mutation(rng, capture)
        cases.append(([*EX1, "log", "decode"], body, rng.choice([".log", ".txt"]), "capture " + what, False))
    for _ in range(22):
        body, what = file_mutation(rng, recording)
        cases.append(([*EX1, "log", "plot"], body, ".csv", "recording " + what, False))
    for _ in range(10):
        body, what = file_mutation(rng, recording)
        cases.append(([*EX1, "log", "decode"], body, ".csv", "recording as a capture " + what, False))
    for body, what in junk:  # an empty capture is a quiet bus's: decoded as no frames, exit 0
        for suffix in (".log", ".csv", ".mcap", ".asc", ".blf", ".trc"):
            cases.append(([*EX1, "log", "decode"], body, suffix, what, bool(body) or suffix in (".mcap", ".blf")))
        cases.append(([*EX1, "log", "plot"], body, rng.choice([".csv", ".mcap"]), what, True))
    for i, (argv, body, suffix, _what, must_fail) in enumerate(cases):
        path = tmp / f"fuzz-file-{i}{suffix}"
        path.write_bytes(body)
        full = [*argv, str(path), *(["-o", png] if "plot" in argv else [])]
        tally.case("log file")
        check_cli(tally, "log file", full, must_fail=must_fail)


# ---------------------------------------------------------------------------------------------
# hostile frames

def frame_cases(rng: random.Random, tally: Tally) -> None:
    from sherpa_cli.sim import ManualClock, SimSettings
    from sherpa_cli.sim.drive import SimDrive
    from sherpa_cli.sim.sdo import SdoServer

    node = 5
    clock = ManualClock()
    drive = SimDrive(node, clock=clock, settings=SimSettings(heartbeat_ms=50), serial=7)
    sdo = SdoServer(node, drive, lambda can_id, data: None)
    drive.receive(0x000, bytes([0x01, node]))
    interesting = [0x000, 0x300 + node, 0x600 + node, 0x700 + 100, 0x080 + node, 0x280 + node]
    for _ in range(260):
        tally.case("frame to the drive")
        can_id = rng.choice(interesting)
        n = rng.choice([0, 1, 2, 3, 4, 5, 7, 8, 8, 8, 9, 64])
        data = bytes(rng.randrange(256) for _ in range(n))
        if can_id == 0x300 + node and n >= 4 and rng.random() < 0.5:
            data = rng.choice([b"AC", b"LL", b"CL", b"SV", b"MO", b"QQ", b"il"]) + data[2:]
        if can_id == 0x000 and rng.random() < 0.7:
            data = bytes([rng.choice([0x01, 0x02, 0x80, 0x81, 0x82, 0x00, 0xFF]), rng.choice([0, node, 99])])
        if rng.random() < 0.03 and can_id == 0x300 + node:
            data = b"SV\x00\x00"  # a save in the middle: blackout, flash
        what = f"0x{can_id:03X} [{len(data)}] {data.hex(' ')}"
        try:
            if drive.receive(can_id, data) and 0x600 < can_id <= 0x67F:
                sdo.receive(can_id, data)
            clock.advance(rng.choice([0.0, 0.001, 0.01, 0.6]))
            drive.tick()
            drive.pop_frames()
        except BaseException:  # noqa: BLE001
            tally.fail("frame to the drive", what, traceback.format_exc())
            drive = SimDrive(node, clock=clock, settings=SimSettings(heartbeat_ms=50), serial=7)
            sdo = SdoServer(node, drive, lambda can_id, data: None)

    client_frame_cases(rng, tally)


class AnsweringTransport:
    """Answers every RPDO2 frame at once with a frame chosen by the test."""

    def __init__(self, answer: Callable[[bytes], list[bytes]]) -> None:
        self.answer = answer
        self.subs: dict[int, Callable] = {}

    def subscribe(self, can_id: int, callback: Callable) -> None:
        self.subs[can_id] = callback

    def send(self, can_id: int, data: bytes) -> None:
        for reply in self.answer(bytes(data)):
            callback = self.subs.get(0x280 + (can_id & 0x7F))
            if callback is not None:
                callback(0x280 + (can_id & 0x7F), reply, 0.0)


def client_frame_cases(rng: random.Random, tally: Tally) -> None:
    from sherpa_cli.elmo.client import DriveClient
    from sherpa_cli.errors import DriveTimeoutError, ProtocolError, SherpaError

    asks = [("get", "AC", 0), ("get", "CL", 1), ("get", "LL", 3), ("set", "AC", 0), ("set", "CL", 1), ("get", "PX", 0)]
    for _ in range(150):
        tally.case("frame to the client")
        op, letters, index = rng.choice(asks)
        header = letters.encode() + struct.pack("<H", index | (0x8000 if letters == "CL" else 0))
        # one of them is called at once, in this iteration: the loop variables are this round's
        bad = rng.choice([
            lambda: header,  # noqa: B023  DLC 4
            lambda: header[:rng.randrange(4)],  # noqa: B023
            lambda: header + bytes(rng.randrange(256) for _ in range(rng.choice([1, 2, 3, 5, 8]))),  # noqa: B023
            lambda: letters.encode() + struct.pack("<H", index | 0x8000) + struct.pack("<f", rng.choice(  # noqa: B023
                [math.nan, math.inf, -math.inf])),
            lambda: bytes([0xFF, 0x80]) + header[2:] + bytes(4),  # noqa: B023
            lambda: bytes(rng.randrange(256) for _ in range(rng.choice([1, 4, 8]))),
        ])()
        # a bad frame whose readable header names another command is someone else's: then silence
        ours = len(bad) < 4 or bad[:2] == letters.encode() or not bad[:2].isalpha() or not bad[:2].isupper()
        if len(bad) >= 4 and bad[:2] == letters.encode() and (bad[2] | bad[3] << 8) & 0x3FFF != index:
            ours = False
        if len(bad) == 8 and bad[:2] == letters.encode() and (bad[2] | bad[3] << 8) & 0x3FFF == index:
            from sherpa_cli.elmo.codec import decode_reply
            try:
                decode_reply(bad)
                ours = None  # a valid frame after all: any answer is fine
            except SherpaError:
                pass
        client = DriveClient(AnsweringTransport(lambda _f, bad=bad: [bad]), 10, name="fuzz", timeout=0.02,
                             retries=0)
        what = f"{op} {letters}[{index}] answered {bad.hex(' ')}"

        def attempt(client=client, op=op, letters=letters, index=index) -> Any:
            return client.get(letters, index) if op == "get" else client.set(letters, index, 1)

        _, exc, hung = bounded(attempt)
        if hung:
            tally.fail("frame to the client", what, "hang")
        elif exc is not None and not isinstance(exc, SherpaError):
            tally.fail("frame to the client", what, exc.__dict__.get("_tb_text", repr(exc)))
        elif ours and isinstance(exc, DriveTimeoutError) and op == "get":
            tally.fail("frame to the client", what, f"'no answer' for a drive that answered: {exc}")
        elif ours and op == "get" and exc is not None and not isinstance(exc, ProtocolError):
            tally.fail("frame to the client", what, f"expected a ProtocolError, got {exc!r}")
        elif isinstance(exc, ProtocolError) and ("fuzz (node 10)" not in str(exc) or "TPDO2 0x28A" not in str(exc)):
            tally.fail("frame to the client", what, f"the protocol error names no drive or frame: {exc}")


# ---------------------------------------------------------------------------------------------

def test_bad_input_generator(monkeypatch, tmp_path, request, capsys):
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("COLUMNS", "100")
    monkeypatch.setenv("NO_COLOR", "1")
    monkeypatch.setenv("TERM", "dumb")
    monkeypatch.delenv("SHERPA_CONFIG", raising=False)
    monkeypatch.delenv("SHERPA_BUS_MAP", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    rng = random.Random(SEED)
    tally = Tally()
    started = time.monotonic()
    config_cases(rng, tally)
    recipe_cases(rng, tally, tmp_path)
    dump_cases(rng, tally, tmp_path)
    cli_cases(rng, tally, tmp_path)
    config_type_cases(rng, tally)
    deadman_cases(rng, tally)
    numeric_option_cases(rng, tally, tmp_path)
    bus_map_cases(rng, tally)
    recipe_step_cases(rng, tally, tmp_path)
    log_file_cases(rng, tally, tmp_path)
    frame_cases(rng, tally)
    elapsed = time.monotonic() - started
    summary = (f"bad-input generator (seed {SEED}): {tally.count} inputs "
               f"({', '.join(f'{k} {v}' for k, v in tally.by_kind.items())}) in {elapsed:.1f} s: "
               f"{len(tally.failures)} tracebacks, hangs or accepted bad inputs")
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        with capsys.disabled():  # shown in the test run's output, captured or not
            reporter.write_line("")
            reporter.write_line(summary)
    request.node.user_properties.append(("bad_inputs", tally.count))
    assert not tally.failures, summary + "\n" + "\n\n".join(tally.failures[:15])
    assert tally.count >= MIN_CASES, summary
