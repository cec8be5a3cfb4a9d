"""Generated bad inputs: 0 tracebacks and 0 hangs (issue 11 item 8).

A seeded generator builds well over 900 bad inputs -- configs (native and rosparam), recipes,
parameter dumps, command lines of every command, and hostile CAN frames for both ends of the
bus (the simulated drive and the tool's drive client) -- and feeds them through the same doors
a user's input takes: ``load_config_text`` / ``load_recipe`` / ``dump_from_text``, the CLI's
``run(argv)`` in this process (as the ``cli`` fixture does), ``SimDrive.receive`` with its SDO
server, and ``DriveClient`` over a transport that answers at once.

What counts as a failure:

- a traceback: an exception that is not a SherpaError (or, for the simulated drive, any
  exception at all), or "Traceback" on stderr;
- a hang: one case taking longer than HANG_S;
- exit 0 (or no error) for input that is clearly bad (a must-fail case);
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
MIN_CASES = 900


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


def check_cli(tally: Tally, kind: str, argv: list[str], *, must_fail: bool) -> None:
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


EX1 = ["--config", "configs/appendix-c/example1.yaml"]
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
