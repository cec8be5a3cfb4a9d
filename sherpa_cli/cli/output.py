"""The one output sink: results to stdout, progress/warnings/errors to stderr, ``--json`` for machines.

Consoles are created per invocation (not at import) so tests that swap sys.stdout see
everything, and so ``sherpa --help`` never imports rich.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sherpa_cli.errors import SafetyError, UsageError

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table


def _color_allowed(no_color_flag: bool) -> bool:
    # https://no-color.org: any non-empty NO_COLOR disables colour
    return not no_color_flag and not os.environ.get("NO_COLOR")


@dataclass
class Output:
    json_mode: bool = False
    color: bool = True
    assume_yes: bool = False
    _out: Console | None = field(default=None, repr=False)
    _err: Console | None = field(default=None, repr=False)

    @classmethod
    def create(cls, *, json_mode: bool = False, no_color: bool = False) -> Output:
        return cls(json_mode=json_mode, color=_color_allowed(no_color))

    def _console(self, stderr: bool) -> Console:
        from rich.console import Console

        attr = "_err" if stderr else "_out"
        console = getattr(self, attr)
        if console is None:
            console = Console(
                file=sys.stderr if stderr else sys.stdout,
                no_color=not self.color,
                color_system="auto" if self.color else None,
                highlight=False,
                soft_wrap=False,
                emoji=False,
            )
            setattr(self, attr, console)
        return console

    @property
    def console(self) -> Console:
        return self._console(stderr=False)

    # results (stdout)
    def result(self, renderable: Any) -> None:
        self._console(stderr=False).print(renderable)

    def line(self, text: str = "") -> None:
        # soft_wrap: a long line stays one line (the terminal wraps it), so it greps and diffs well
        self._console(stderr=False).print(text, markup=False, soft_wrap=True)

    def raw(self, text: str) -> None:
        """Text that must reach stdout byte for byte (YAML, frames): no wrapping, no styling."""
        sys.stdout.write(text)
        sys.stdout.flush()

    def json(self, obj: Any) -> None:
        sys.stdout.write(json.dumps(obj, indent=2, ensure_ascii=False) + "\n")
        sys.stdout.flush()

    def table(self, title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]],
              *, right: Iterable[int] = (), drop: Sequence[int] | None = None) -> None:
        self.result(make_table(title, columns, rows, right=right, drop=drop,
                               width=self._console(stderr=False).width))

    # diagnostics (stderr)
    def info(self, text: str) -> None:
        self._console(stderr=True).print(text, markup=False, soft_wrap=True)

    def progress(self, text: str | None) -> None:
        """A live status line on stderr, rewritten in place; only on a terminal and never with --json.
        ``None`` ends it (clears the line)."""
        if self.json_mode or not sys.stderr.isatty():
            return
        sys.stderr.write("\r\x1b[2K" + (text or ""))
        if text is None:
            sys.stderr.write("\r")
        sys.stderr.flush()

    def warn(self, text: str) -> None:
        self._console(stderr=True).print(f"warning: {text}", style="yellow", markup=False, soft_wrap=True)

    def error(self, text: str, hint: str | None = None) -> None:
        err = self._console(stderr=True)
        err.print(f"error: {text}", style="bold red", markup=False, soft_wrap=True)
        if hint:
            err.print(f"hint: {hint}", markup=False, soft_wrap=True)

    def confirm(self, question: str, *, refusal: str | None = None,
                hint: str = "pass --yes to confirm in scripts") -> bool:
        """Ask yes/no on the terminal; refuse (never hang) when nobody can answer.

        ``refusal``/``hint``: the error then raised, for a caller that can say what was not done.
        """
        if self.assume_yes:
            return True
        if self.json_mode or not sys.stdin.isatty():
            raise SafetyError(refusal or f"{question} -- refusing: not an interactive terminal", hint=hint)
        # the question goes to the terminal (stderr), so `sherpa ... | tee log` still shows it
        err = self._console(stderr=True)
        err.print(f"{question} [y/N] ", markup=False, end="", soft_wrap=True)
        err.file.flush()
        answer = sys.stdin.readline().strip().lower()
        return answer in ("y", "yes")


def make_table(title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]],
               *, right: Iterable[int] = (), drop: Sequence[int] | None = None, width: int | None = None) -> Table:
    """A table that stays readable at ``width`` columns (default: the terminal's).

    No word is broken mid-name: cells wrap only between words, and when even that does not fit,
    whole columns are left out in ``drop`` order (default: from the last column; never the
    first), and the title says which.
    """
    from rich import box
    from rich.table import Table

    texts = [["" if v is None else str(v) for v in row] for row in rows]
    if width is None:
        from rich.console import Console

        width = Console().width
    keep = fit_columns(columns, texts, width, drop)
    left_out = [columns[i] for i in range(len(columns)) if i not in keep]
    if left_out and title is not None:
        title = f"{title} (not shown: {', '.join(left_out)}; wider terminal or --json)"
    table = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left", pad_edge=False)
    right_cols = set(right)
    for i in keep:
        # a technician must see the whole name or number:
        # fold, never truncate; the first column (the name) stays on one line
        table.add_column(columns[i], justify="right" if i in right_cols else "left", overflow="fold",
                         no_wrap=(i == 0))
    for row in texts:
        table.add_row(*(row[i] for i in keep))
    return table


def fit_columns(columns: Sequence[str], rows: Sequence[Sequence[str]], width: int,
                drop: Sequence[int] | None = None) -> list[int]:
    """The columns to show so that no word (header or cell) must be broken to fit ``width``."""

    def longest_word(i: int) -> int:
        cells = [columns[i], *(row[i] for row in rows)]
        return max((len(w) for c in cells for w in c.split()), default=0)

    minimum = {i: (max([len(columns[i]), *(len(row[i]) for row in rows)]) if i == 0 else longest_word(i))
               for i in range(len(columns))}
    keep = list(range(len(columns)))
    order = [i for i in (drop if drop is not None else reversed(range(1, len(columns)))) if i != 0]
    for i in [*order, *(j for j in reversed(range(1, len(columns))) if j not in order)]:
        # padding, divider, padding between columns and one edge each side (box.SIMPLE_HEAD, pad_edge=False)
        if sum(minimum[k] for k in keep) + 3 * (len(keep) - 1) + 2 <= width or len(keep) == 1:
            break
        keep.remove(i)
    return keep


def fmt_value(value: object) -> str:
    """Parameters as a technician types them (the ops layer words its messages the same way)."""
    from sherpa_cli.elmo.commands import format_value

    return format_value(value)


def require(condition: bool, message: str) -> None:
    if not condition:
        raise UsageError(message)
