"""Set one entry of a top-level section in a YAML document's text, leaving every other byte alone.

`pose save` writes into the user's own config: a load and dump would drop its comments, blank
lines and key order. PyYAML's composed nodes carry the character span of every value, so only the
one entry's span is replaced (or text appended where it is new). Comments inside the replaced
entry go with it; everything outside it survives as written.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

__all__ = ["YamlEditError", "format_scalar", "set_entry"]

# words a YAML reader may take for a bool or null (YAML 1.1 also has y/n)
_SPECIAL = frozenset({"y", "yes", "n", "no", "true", "false", "on", "off", "null", "~"})


class YamlEditError(ValueError):
    """The document cannot take the entry where it belongs (the section is not a mapping, the
    text is not YAML, a value is not a finite number)."""


def format_scalar(value: float | str) -> str:
    """``value`` as YAML writes it plainly: a float to 9 significant digits (far below a count of any
    configured joint), a unit string as given."""
    if isinstance(value, bool):
        raise YamlEditError(f"{value!r} is not a number")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise YamlEditError(f"{value!r} is not a finite number")
        mantissa, e, exponent = f"{value:.9g}".partition("e")
        # YAML 1.1 (PyYAML) reads a number as a float only with a dot: 1e-05 would be a string
        return (mantissa if "." in mantissa else f"{mantissa}.0") + e + exponent
    return _text(value)


def _text(word: str) -> str:
    """A key or a unit string: plain where YAML reads it back as that string, else double-quoted
    (a JSON string is a YAML double-quoted scalar)."""
    if not word:
        raise YamlEditError("an empty name cannot be written")
    if word.lower() not in _SPECIAL and "#" not in word and word == word.strip():
        try:
            if yaml.safe_load(f"{word}: {word}") == {word: word}:
                return word
        except yaml.YAMLError:
            pass
    return json.dumps(word, ensure_ascii=False)


def _root(text: str) -> MappingNode | None:
    try:
        # the pure loader: its marks count characters (libyaml's may count bytes)
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise YamlEditError(f"not YAML: {exc}") from None
    if node is None:
        return None
    if not isinstance(node, MappingNode):
        raise YamlEditError("the document is not a mapping")
    return node


def _find(mapping: MappingNode, key: str) -> tuple[ScalarNode, Node] | None:
    for k, v in mapping.value:
        if isinstance(k, ScalarNode) and k.value == key:
            return k, v
    return None


def _content_end(node: Node) -> int:
    """Where ``node``'s own text ends: a block collection's end mark lies past the comments and
    blank lines that follow it, so it ends where its last value does."""
    if isinstance(node, MappingNode) and not node.flow_style and node.value:
        return _content_end(node.value[-1][1])
    if isinstance(node, SequenceNode) and not node.flow_style and node.value:
        return _content_end(node.value[-1])
    return node.end_mark.index


def _block(entries: Mapping[str, float | str], indent: int) -> str:
    pad = " " * indent
    return "\n".join(f"{pad}{_text(k)}: {format_scalar(v)}" for k, v in entries.items())


def set_entry(text: str, section: str, key: str, entries: Mapping[str, float | str], *, indent: int = 2) -> str:
    """``text`` with ``section: {key: entries}`` set: a new key is appended to the section (the
    section to the document), an existing key's value is replaced. Written in block style at the
    document's own indentation where it has one."""
    if not entries:
        raise YamlEditError(f"{section}.{key}: nothing to write")
    root = _root(text)
    found = _find(root, section) if root is not None else None
    if found is None:
        body = f"{_text(section)}:\n{' ' * indent}{_text(key)}:\n{_block(entries, 2 * indent)}\n"
        return text + ("" if not text or text.endswith("\n") else "\n") + body
    section_key, section_node = found
    if isinstance(section_node, ScalarNode) and section_node.value in ("", "~", "null"):
        section_node = MappingNode("tag:yaml.org,2002:map", [], section_node.start_mark, section_node.end_mark,
                                   flow_style=True)
    if not isinstance(section_node, MappingNode):
        raise YamlEditError(f"{section}: is not a mapping (line {section_key.start_mark.line + 1})")
    item = _find(section_node, key)
    col = section_key.start_mark.column
    if item is None:
        if section_node.flow_style or not section_node.value:
            # `poses: {}` or an empty `poses:`: the section's value becomes a block mapping
            start, end = section_key.end_mark.index, _content_end(section_node)
            inner = col + indent
            new = f":\n{' ' * inner}{_text(key)}:\n{_block(entries, inner + indent)}"
            return text[:start] + new + text[end:]
        inner = section_node.value[0][0].start_mark.column
        at = _content_end(section_node)
        return text[:at] + f"\n{' ' * inner}{_text(key)}:\n{_block(entries, inner + indent)}" + text[at:]
    key_node, value_node = item
    inner = key_node.start_mark.column
    if isinstance(value_node, MappingNode) and not value_node.flow_style and value_node.value:
        # keep the entry's block layout: its first key's column, the key line's comment
        column = value_node.value[0][0].start_mark.column
        start = value_node.start_mark.index
        return text[:start] + _block(entries, column)[column:] + text[_content_end(value_node):]
    start, end = key_node.end_mark.index, _content_end(value_node)
    return text[:start] + f":\n{_block(entries, inner + indent)}" + text[end:]
