"""YAML parsing that keeps a line and a key path on every value, and typed readers over it.

PyYAML's ``safe_load`` forgets where values came from; ``yaml.compose`` keeps a mark on
every node. We turn the composed tree into :class:`YNode` objects so every error can say
``file:line: key.path: what is wrong``. Only the safe tag set is resolved.

Composing uses libyaml (``yaml.CSafeLoader``) where PyYAML was built with it: its nodes carry
the same line marks. Its error texts are libyaml's, though, so a document it refuses is
composed again by the pure ``yaml.SafeLoader``, whose messages (and marks) are the ones we
report; the event replay that names the key at a syntax error uses the pure loader too.
"""

from __future__ import annotations

import builtins
import difflib
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar, overload

import yaml
from yaml.constructor import SafeConstructor
from yaml.events import (
    AliasEvent,
    MappingEndEvent,
    MappingStartEvent,
    ScalarEvent,
    SequenceEndEvent,
    SequenceStartEvent,
)
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from sherpa_cli.errors import ConfigError, Location

if TYPE_CHECKING:
    from typing import TypeAlias

    #: a loader class :func:`compose` and :func:`check_limits` may use
    Loader: TypeAlias = type[yaml.SafeLoader] | type[yaml.CSafeLoader]

_D = TypeVar("_D")

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


def join_path(parent: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{parent}[{key}]"
    return f"{parent}.{key}" if parent else str(key)


@dataclass
class YNode:
    """One YAML value: a scalar, ``list[YNode]`` or ``dict[str, YNode]`` (in file order)."""

    value: Any
    kind: str  # "map" | "seq" | "scalar"
    line: int  # 1-based line where the value starts
    path: str  # key path from the document root, "" for the root
    file: str
    key_line: int | None = None  # line of the mapping key holding this value

    @property
    def loc(self) -> Location:
        # The key's line is what a technician looks for; a list item has only its own line.
        return Location(self.file, self.key_line if self.key_line is not None else self.line, self.path or None)

    def child_loc(self, key: str) -> Location:
        """Where a key of this mapping would be (used for missing keys)."""
        return Location(self.file, self.loc.line, join_path(self.path, key))

    @property
    def is_null(self) -> bool:
        return self.kind == "scalar" and self.value is None

    def error(self, message: str, *, hint: str | None = None) -> ConfigError:
        return ConfigError(message, self.loc, hint=hint)


def describe(node: YNode) -> str:
    """A value as the user wrote it, for 'expected X, got Y' messages."""
    v = node.value
    if node.kind == "map":
        return "a mapping"
    if node.kind == "seq":
        return "a list"
    if v is None:
        return "nothing (null)"
    if isinstance(v, bool):
        return f"the boolean {str(v).lower()}"
    if isinstance(v, (int, float)):
        return f"the number {v!r}"
    if isinstance(v, str):
        return f"the string {v!r}"
    return f"{type(v).__name__} {v!r}"


# --- parsing ---------------------------------------------------------------------------------


#: libyaml's safe loader where PyYAML has it (about 10x faster composing), else None
FAST_LOADER: type[yaml.CSafeLoader] | None = getattr(yaml, "CSafeLoader", None)


def compose(text: str) -> yaml.Node | None:
    """``yaml.compose`` with the fast loader; what it refuses, the pure loader composes (or refuses in its words)."""
    if FAST_LOADER is not None:
        try:
            return yaml.compose(text, Loader=FAST_LOADER)
        except Exception:  # noqa: BLE001 - any refusal (libyaml also raises UnicodeEncodeError) is re-judged below
            pass
    return yaml.compose(text, Loader=yaml.SafeLoader)


# Limits of every YAML input (configs, recipes, parameter dumps), so a hostile or broken file
# gets one message instead of a memory blow-up, a RecursionError or a minute of parsing.
MAX_INPUT_BYTES = 1024 * 1024  # the whole arm's config is ~5 KB, a 14-drive dump ~20 KB
MAX_DEPTH = 32  # nesting of mappings and lists; the native schema needs 6
MAX_NODES = 50_000  # values after expanding aliases (&a / *a, merge keys): no "billion laughs"
MAX_NUMBER_CHARS = 40  # int32 needs 11 characters; Python refuses int('9' * 5000) with ValueError

_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")


def read_input(path: str | Path, limit: int = MAX_INPUT_BYTES) -> str:
    """A text input file read as UTF-8, at most ``limit`` bytes (ConfigError beyond).

    Raises what ``Path.read_text`` raises (FileNotFoundError, IsADirectoryError, other OSError,
    UnicodeDecodeError), so callers keep their own wording for those; a device such as
    /dev/zero is cut off at the limit instead of read for ever.
    """
    with open(path, "rb") as handle:
        data = handle.read(limit + 1)
    if len(data) > limit:
        raise ConfigError(f"file is larger than {limit // 1024} KiB, the limit for an input file",
                          Location(str(path)), hint="is this the file you meant?")
    return data.decode("utf-8")


def check_limits(text: str, filename: str) -> None:
    """Refuse too large, too deep or too widely expanding YAML before it is composed.

    One pass over the parser's events (the parser is iterative; PyYAML's composer recurses and
    would hit Python's recursion limit on deep nesting): the depth of open collections, the
    expanded size of every anchor, and the expanded size of the whole document.

    The pass runs with every parser that :func:`compose` may use. libyaml refuses deep flow
    nesting while scanning ahead (PyYAML 6.0.4: "exceeded maximum nesting depth"), before it
    yields the events this check counts; ``compose`` then falls back to the pure loader, whose
    composer recurses. So when libyaml refuses a document, the pure (iterative) parser's events
    are checked too: the limits hold whatever the installed PyYAML and libyaml refuse first.
    """
    if len(text) > MAX_INPUT_BYTES:
        raise ConfigError(f"text is larger than {MAX_INPUT_BYTES // 1024} KiB, the limit for an input file",
                          Location(filename))
    loaders: list[Loader] = [FAST_LOADER, yaml.SafeLoader] if FAST_LOADER is not None else [yaml.SafeLoader]
    for loader in loaders:
        if _check_events(text, filename, loader):
            return  # this parser reads the whole document: compose() uses it and nothing else


def _check_events(text: str, filename: str, loader: Loader) -> bool:
    """The limits over ``loader``'s events; False when the parser refused the text (a syntax error)."""
    stack: list[list[Any]] = []  # [expanded size so far, anchor]
    anchors: dict[str, int] = {}
    total = 0

    def add(size: int, line: int) -> None:
        nonlocal total
        if stack:
            stack[-1][0] += size
        else:
            total += size
        if total + sum(s for s, _ in stack) > MAX_NODES:
            raise ConfigError(f"the document expands to more than {MAX_NODES:,} values (aliases?)",
                              Location(filename, line), hint="write the values out instead of repeating aliases")

    try:
        for ev in yaml.parse(text, Loader=loader):
            line = ev.start_mark.line + 1 if ev.start_mark is not None else None
            if isinstance(ev, (MappingStartEvent, SequenceStartEvent)):
                if len(stack) >= MAX_DEPTH:
                    raise ConfigError(f"nesting deeper than {MAX_DEPTH} levels", Location(filename, line),
                                      hint="a configuration, recipe or dump is a few levels deep")
                stack.append([1, ev.anchor])
            elif isinstance(ev, (MappingEndEvent, SequenceEndEvent)):
                size, anchor = stack.pop()
                if anchor is not None:
                    anchors[anchor] = size
                add(size, line or 0)
            elif isinstance(ev, ScalarEvent):
                if ev.anchor is not None:
                    anchors[ev.anchor] = 1
                add(1, line or 0)
            elif isinstance(ev, AliasEvent):
                if ev.anchor not in anchors:
                    if any(a == ev.anchor for _, a in stack):
                        raise ConfigError(f"alias *{ev.anchor} refers to a value that contains it (recursive alias)",
                                          Location(filename, line))
                    continue  # an undefined alias: the composer reports it with its position
                add(anchors[ev.anchor], line or 0)
    except ConfigError:
        raise
    except Exception:  # noqa: BLE001 - syntax errors (libyaml's included) are reported by parse_yaml
        return False
    return True


def parse_yaml(text: str, filename: str) -> YNode:
    """Parse one YAML document; syntax errors become ConfigError with line and enclosing key path."""
    check_limits(text, filename)
    try:
        root = compose(text)
    except RecursionError:
        # check_limits counts the levels of the parsers compose() uses; this is the net under it
        # for a PyYAML whose parsers disagree about a document's nesting
        raise ConfigError(f"nesting deeper than {MAX_DEPTH} levels", Location(filename),
                          hint="a configuration, recipe or dump is a few levels deep") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        problem = exc.problem or "invalid YAML"
        if exc.context:
            problem = f"{problem} ({exc.context}"
            if exc.context_mark is not None and exc.problem_mark is not None and \
                    exc.context_mark.line != exc.problem_mark.line:
                problem += f" at line {exc.context_mark.line + 1}"
            problem += ")"
        path = _path_at_error(text)
        raise ConfigError(f"YAML syntax error: {problem}", Location(filename, line, path or None),
                          hint="check indentation, colons and brackets around this line") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"YAML syntax error: {exc}", Location(filename, None, None)) from None
    if root is None:
        raise ConfigError("the file is empty; expected a mapping of configuration keys",
                          Location(filename, 1, None))
    return _convert(root, "", filename, None, SafeConstructor())


def _convert(node: yaml.Node, path: str, filename: str, key_line: int | None,
             ctor: SafeConstructor, depth: int = 0) -> YNode:
    line = node.start_mark.line + 1
    if depth > 64:
        # Only a recursive alias (&a [*a]) nests this deep; configs are a few levels at most.
        raise ConfigError("nesting too deep (recursive alias?)", Location(filename, line, path or None))
    if isinstance(node, MappingNode):
        # Merge keys ("<<: *defaults") are a normal way to share blocks; resolve them like safe_load.
        try:
            ctor.flatten_mapping(node)
        except yaml.YAMLError as exc:
            raise ConfigError(f"invalid merge key: {getattr(exc, 'problem', exc)}",
                              Location(filename, line, path or None)) from None
        items: dict[str, YNode] = {}
        key_lines: dict[str, int] = {}
        for knode, vnode in node.value:
            kline = knode.start_mark.line + 1
            if not isinstance(knode, ScalarNode):
                raise ConfigError("a mapping key must be a plain name, not a list or mapping",
                                  Location(filename, kline, path or None))
            if knode.tag in _NUMBER_TAGS and not knode.value.isascii():
                raise ConfigError(f"key {knode.value[:40]!r} is not written with the ASCII digits 0-9",
                                  Location(filename, kline, path or None))
            if knode.tag in _NUMBER_TAGS and len(knode.value) > MAX_NUMBER_CHARS:
                raise ConfigError(f"key {knode.value[:20]}... is a number of {len(knode.value)} characters",
                                  Location(filename, kline, path or None))
            try:
                key = ctor.construct_object(knode, deep=True)
            except (ValueError, OverflowError, yaml.YAMLError) as exc:
                raise ConfigError(f"invalid key {knode.value[:40]!r}: {getattr(exc, 'problem', None) or exc}",
                                  Location(filename, kline, path or None)) from None
            if key is None or isinstance(key, (bool, float)):
                raise ConfigError(f"invalid key {knode.value!r}; keys must be names or numbers",
                                  Location(filename, kline, path or None),
                                  hint="quote the key if it is meant literally")
            skey = str(key)
            if skey in items:
                raise ConfigError(f"duplicate key '{skey}' (first given at line {key_lines[skey]})",
                                  Location(filename, kline, join_path(path, skey)))
            key_lines[skey] = kline
            items[skey] = _convert(vnode, join_path(path, skey), filename, kline, ctor, depth + 1)
        return YNode(items, "map", line, path, filename, key_line)
    if isinstance(node, SequenceNode):
        seq = [_convert(v, join_path(path, i), filename, None, ctor, depth + 1) for i, v in enumerate(node.value)]
        return YNode(seq, "seq", line, path, filename, key_line)
    if node.tag in _NUMBER_TAGS and not node.value.isascii():
        # only an explicit !!int / !!float gets here (the resolver's patterns are ASCII); int() and
        # float() would read other scripts' digits (U+FF13 -> 3)
        raise ConfigError(f"number {node.value[:40]!r} is not written with the ASCII digits 0-9",
                          Location(filename, key_line or line, path or None))
    if node.tag in _NUMBER_TAGS and len(node.value) > MAX_NUMBER_CHARS:
        raise ConfigError(f"number {node.value[:20]}... has {len(node.value)} characters; a number here has at "
                          f"most {MAX_NUMBER_CHARS}", Location(filename, key_line or line, path or None))
    try:
        value = ctor.construct_object(node, deep=True)
    except (ValueError, OverflowError) as exc:
        raise ConfigError(f"invalid value {node.value[:40]!r}: {exc}",
                          Location(filename, key_line or line, path or None)) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"invalid value {node.value!r}: {getattr(exc, 'problem', exc)}",
                          Location(filename, key_line or line, path or None)) from None
    return YNode(value, "scalar", line, path, filename, key_line)


def _path_at_error(text: str) -> str:
    """Replay parser events up to a syntax error to name the key being read when it failed."""
    stack: list[list[Any]] = []  # [kind, key or index, expecting a key?]

    def value_done() -> None:
        if stack:
            top = stack[-1]
            if top[0] == "map":
                top[2] = True
            else:
                top[1] += 1

    try:
        for ev in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(ev, (ScalarEvent, AliasEvent)):
                if stack and stack[-1][0] == "map" and stack[-1][2]:
                    stack[-1][1] = getattr(ev, "value", "*")
                    stack[-1][2] = False
                else:
                    value_done()
            elif isinstance(ev, MappingStartEvent):
                stack.append(["map", None, True])
            elif isinstance(ev, SequenceStartEvent):
                stack.append(["seq", 0, False])
            elif isinstance(ev, (MappingEndEvent, SequenceEndEvent)):
                if stack:
                    stack.pop()
                value_done()
    except yaml.YAMLError:
        pass
    path = ""
    for kind, key, expecting_key in stack:
        if kind == "map":
            if expecting_key or key is None:
                break
            path = join_path(path, str(key))
        else:
            path = join_path(path, int(key))
    return path


# --- typed readers ---------------------------------------------------------------------------


def suggest(word: str, choices: Iterable[str]) -> str | None:
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return found[0] if found else None


def where_text(path: str) -> str:
    return path if path else "the top level"


class Section:
    """A mapping with a fixed set of allowed keys; reads typed values with located errors.

    Unknown keys are rejected on construction, before any required key is looked up, so a
    typo of a required key is reported as the typo (with a suggestion) rather than as missing.
    """

    def __init__(self, node: YNode, allowed: Iterable[str], *, what: str = "a mapping",
                 null_ok: bool = False, aliases: dict[str, str] | None = None) -> None:
        if null_ok and node.is_null:
            node = YNode({}, "map", node.line, node.path, node.file, node.key_line)
        if node.kind != "map":
            raise node.error(f"expected {what}, got {describe(node)}")
        self.node = node
        self.allowed = list(allowed)
        aliases = aliases or {}
        for key, child in node.value.items():
            if key not in self.allowed:
                # Aliases are other spellings people bring along (the seed's pos_min for min);
                # a typo of an alias still leads to the valid key.
                close = suggest(key, [*self.allowed, *aliases])
                close = aliases.get(close, close) if close else None
                msg = f"unknown key '{key}' in {where_text(node.path)}"
                if close:
                    msg += f"; did you mean '{close}'?"
                    hint = None
                else:
                    hint = "valid keys here: " + ", ".join(self.allowed)
                raise ConfigError(msg, Location(node.file, child.key_line, child.path), hint=hint)

    @property
    def path(self) -> str:
        return self.node.path

    def __contains__(self, key: str) -> bool:
        child = self.node.value.get(key)
        return child is not None and not child.is_null

    def get(self, key: str) -> YNode | None:
        """The value node, or None when absent or null (null means 'use the default')."""
        child = self.node.value.get(key)
        if child is None or child.is_null:
            return None
        return child

    def req(self, key: str) -> YNode:
        child = self.node.value.get(key)
        if child is None:
            raise ConfigError(f"missing required key '{key}' in {where_text(self.path)}",
                              self.node.child_loc(key))
        if child.is_null:
            raise child.error(f"'{key}' needs a value, got nothing (null)")
        return child

    def loc(self, key: str) -> Location:
        child = self.node.value.get(key)
        return child.loc if child is not None else self.node.child_loc(key)

    # typed accessors: required when default is REQUIRED
    @overload
    def int(self, key: str, default: None = None, *, required: Literal[True]) -> builtins.int: ...
    @overload
    def int(self, key: str, default: None = None, *, required: bool = False) -> builtins.int | None: ...
    @overload
    def int(self, key: str, default: _D, *, required: bool = False) -> builtins.int | _D: ...

    def int(self, key: str, default: object = None, *, required: bool = False) -> object:
        node = self.req(key) if required else self.get(key)
        return default if node is None else as_int(node)

    @overload
    def num(self, key: str, default: None = None, *, required: Literal[True]) -> float: ...
    @overload
    def num(self, key: str, default: None = None, *, required: bool = False) -> float | None: ...
    @overload
    def num(self, key: str, default: _D, *, required: bool = False) -> float | _D: ...

    def num(self, key: str, default: object = None, *, required: bool = False) -> object:
        node = self.req(key) if required else self.get(key)
        return default if node is None else as_num(node)

    @overload
    def bool(self, key: str, default: None = None) -> builtins.bool | None: ...
    @overload
    def bool(self, key: str, default: _D) -> builtins.bool | _D: ...

    def bool(self, key: str, default: object = None) -> object:
        node = self.get(key)
        return default if node is None else as_bool(node)

    # past here `str` and `bool` name the accessors above: annotations spell out builtins
    @overload
    def str(self, key: builtins.str, default: None = None, *, required: Literal[True]) -> builtins.str: ...
    @overload
    def str(self, key: builtins.str, default: None = None, *,
            required: builtins.bool = False) -> builtins.str | None: ...
    @overload
    def str(self, key: builtins.str, default: _D, *, required: builtins.bool = False) -> builtins.str | _D: ...

    def str(self, key: builtins.str, default: object = None, *, required: builtins.bool = False) -> object:
        node = self.req(key) if required else self.get(key)
        return default if node is None else as_str(node)

    def section(self, key: builtins.str, allowed: Iterable[builtins.str], *, required: builtins.bool = False,
                what: builtins.str = "a mapping",
                aliases: dict[builtins.str, builtins.str] | None = None) -> Section | None:
        node = self.req(key) if required else self.get(key)
        return None if node is None else Section(node, allowed, what=what, aliases=aliases)


def as_int(node: YNode) -> int:
    v = node.value
    if node.kind != "scalar" or isinstance(v, bool) or not isinstance(v, int):
        raise node.error(f"expected an integer, got {describe(node)}")
    return v


def as_bool(node: YNode) -> bool:
    if node.kind != "scalar" or not isinstance(node.value, bool):
        raise node.error(f"expected true or false, got {describe(node)}")
    return node.value


def as_num(node: YNode) -> float:
    v = node.value
    if node.kind != "scalar" or isinstance(v, bool) or not isinstance(v, (int, float)):
        raise node.error(f"expected a number, got {describe(node)}")
    return float(v)


def as_str(node: YNode) -> str:
    v = node.value
    if node.kind != "scalar" or not isinstance(v, str):
        raise node.error(f"expected a string, got {describe(node)}")
    if not v.strip():
        raise node.error("expected a non-empty string")
    return v


def as_name(node: YNode, what: str) -> str:
    name = as_str(node)
    if not NAME_RE.match(name):
        raise node.error(f"invalid {what} name {name!r}; use letters, digits, '_', '-' or '.', "
                         "starting with a letter or '_'")
    return name


def as_seq(node: YNode, what: str = "a list") -> list[YNode]:
    if node.kind != "seq":
        raise node.error(f"expected {what}, got {describe(node)}")
    return node.value


def as_map(node: YNode, what: str = "a mapping", *, null_ok: bool = False) -> dict[str, YNode]:
    if null_ok and node.is_null:
        return {}
    if node.kind != "map":
        raise node.error(f"expected {what}, got {describe(node)}")
    return node.value


def named_items(node: YNode, what: str) -> Iterator[tuple[str, YNode]]:
    """The entries of a ``name: {...}`` mapping, names checked for use as CLI targets."""
    for key, child in as_map(node, f"a mapping of {what} names", null_ok=True).items():
        if not NAME_RE.match(key):
            raise ConfigError(f"invalid {what} name {key!r}; use letters, digits, '_', '-' or '.', "
                              "starting with a letter or '_'", Location(child.file, child.key_line, child.path))
        yield key, child


def plain(node: YNode) -> Any:
    """Back to plain Python data (for free-form blocks such as bus options)."""
    if node.kind == "map":
        return {k: plain(v) for k, v in node.value.items()}
    if node.kind == "seq":
        return [plain(v) for v in node.value]
    return node.value


@dataclass
class Locs:
    """Locations of model fields, keyed by a tuple like ("joint", "elbow", "range", "min").

    Lookups fall back to shorter keys, so a check can always point somewhere sensible.
    """

    file: str
    table: dict[tuple[str, ...], Location] = field(default_factory=dict)

    def put(self, key: tuple[str, ...], loc: Location) -> None:
        self.table[key] = loc

    def get(self, *key: str) -> Location:
        k = tuple(key)
        while k:
            if k in self.table:
                return self.table[k]
            k = k[:-1]
        return Location(self.file, None, None)
