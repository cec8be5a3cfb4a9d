"""Counts in words: "1 drive", "2 drives" -- never "1 drives" nor "drive(s)"."""

from __future__ import annotations


def plural(count: int, noun: str, nouns: str | None = None) -> str:
    """``count`` and the noun in the number it takes; ``nouns`` where the plural is not noun + "s"."""
    return f"{count} {noun if count == 1 else nouns or noun + 's'}"
