"""The one output sink: results to stdout, progress/warnings/errors to stderr, ``--json`` for machines.

Consoles are created per invocation (not at import) so tests that swap sys.stdout see
everything, and so ``sherpa --help`` never imports rich.
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Iterable, Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TextIO

from sherpa_cli.errors import SafetyError, UsageError

if TYPE_CHECKING:
    from rich.console import Console, ConsoleOptions, RenderableType
    from rich.segment import Segment
    from rich.table import Table
    from rich.text import Text

# The width of output that is not a terminal (a pipe, a file, a report): wide enough that nothing is
# wrapped and no column dropped. Tables never grow to it (they take their natural width).
UNWRAPPED = 10_000


def output_width(stream: TextIO) -> int | None:
    """The width to lay out for on ``stream``: None (the terminal's, or COLUMNS) on a terminal or when
    COLUMNS is set; otherwise UNWRAPPED, so piped output keeps full names and every column."""
    if os.environ.get("COLUMNS", "").strip().isdigit():
        return None  # asked for a width: lay out as a terminal of that width (the goldens' 80/100)
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    return None if tty else UNWRAPPED


#: Set while a command runs whose results nobody will see or read (a recipe step without --verbose,
#: a report or an expectation on its stdout, cli/recipe_cmd.py): the Output created for it then
#: renders no results (else commission draws 46 rich tables per run for output shown
#: only with --verbose). Diagnostics on stderr are kept: warnings and errors are shown.
DISCARD_RESULTS: ContextVar[bool] = ContextVar("sherpa_discard_results", default=False)


def _color_allowed(no_color_flag: bool) -> bool:
    # https://no-color.org: any non-empty NO_COLOR disables colour
    return not no_color_flag and not os.environ.get("NO_COLOR")


@dataclass
class Output:
    json_mode: bool = False
    color: bool = True
    assume_yes: bool = False
    #: results (stdout) are neither rendered nor written (DISCARD_RESULTS); stderr is unchanged
    discard_results: bool = False
    _out: Console | None = field(default=None, repr=False)
    _err: Console | None = field(default=None, repr=False)

    @classmethod
    def create(cls, *, json_mode: bool = False, no_color: bool = False) -> Output:
        return cls(json_mode=json_mode, color=_color_allowed(no_color), discard_results=DISCARD_RESULTS.get())

    def _console(self, stderr: bool) -> Console:
        from rich.console import Console

        attr = "_err" if stderr else "_out"
        console = getattr(self, attr)
        if console is None:
            stream = sys.stderr if stderr else sys.stdout
            console = Console(
                file=stream,
                width=output_width(stream),
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
    def result(self, renderable: RenderableType) -> None:
        if self.discard_results:
            return
        self._console(stderr=False).print(renderable)

    def line(self, text: str = "") -> None:
        if self.discard_results:
            return
        # soft_wrap: a long line stays one line (the terminal wraps it), so it greps and diffs well
        self._console(stderr=False).print(text, markup=False, soft_wrap=True)

    def raw(self, text: str) -> None:
        """Text that must reach stdout byte for byte (YAML, frames): no wrapping, no styling."""
        if self.discard_results:
            return
        sys.stdout.write(text)
        sys.stdout.flush()

    def json(self, obj: object) -> None:
        if self.discard_results:
            return
        sys.stdout.write(json.dumps(obj, indent=2, ensure_ascii=False) + "\n")
        sys.stdout.flush()

    def table(self, title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]],
              *, right: Iterable[int] = (), drop: Sequence[int] | None = None, one_line: bool = False) -> None:
        if self.discard_results:
            return  # not even laid out: the table is what costs
        console = self._console(stderr=False)
        rows = list(rows)
        if title is None and console.color_system is None:
            text = plain_table(columns, rows, right=right, width=console.width)
            if text is not None:
                console.file.write(text)
                console.file.flush()
                return
        # not cropped to the terminal: a title wider than the terminal is folded by it, never cut off
        console.print(make_table(title, columns, rows, right=right, drop=drop, width=console.width,
                                 one_line=one_line), crop=False)

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


_MARKUP = re.compile(r"\[[a-z#/@]|\\")


def plain_table(columns: Sequence[str], rows: Iterable[Sequence[Any]], *, right: Iterable[int] = (),
                width: int) -> str | None:
    """The text rich prints for :func:`make_table` without a title, colour or anything to fold, at a
    fraction of its cost (`program-limits` draws a table per drive, a quarter of
    its time at 126 drives); None when rich must lay it out (a cell it would fold or parse as
    markup, wide or control characters). tests/test_output_plain_table.py holds it to rich's
    output."""
    texts = [["" if v is None else str(v) for v in row] for row in rows]
    cells = [*columns, *(c for row in texts for c in row)]
    if any(not c.isascii() or not c.isprintable() or _MARKUP.search(c) for c in cells):
        return None
    if any(len(row) != len(columns) for row in texts):
        return None
    widths = [max([len(columns[i]), *(len(row[i]) for row in texts)]) for i in range(len(columns))]
    inner = sum(widths) + 3 * (len(columns) - 1)
    if inner + 2 > width:
        return None
    right_cols = set(right)

    def line(row: Sequence[str]) -> str:
        return " " + "   ".join(c.rjust(w) if i in right_cols else c.ljust(w)
                                  for i, (c, w) in enumerate(zip(row, widths, strict=True))) + " \n"

    blank = " " * (inner + 2) + "\n"
    return "".join([blank, line(columns), " " + "\u2500" * inner + " \n", *map(line, texts), blank])


def make_table(title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]],
               *, right: Iterable[int] = (), drop: Sequence[int] | None = None, width: int | None = None,
               one_line: bool = False) -> Table:
    """A table that stays readable at ``width`` columns (default: the terminal's; output that is not a
    terminal is not wrapped, see :func:`output_width`).

    No word is broken mid-name: cells wrap only between words, and when even that does not fit,
    whole columns are left out in ``drop`` order (default: from the last column; never the
    first), and the title says which. ``one_line``: no cell wraps either (a summary of one line per
    row): columns are left out until every row fits on one line.
    """
    from rich import box
    from rich.table import Table

    texts = [["" if v is None else str(v) for v in row] for row in rows]
    if width is None:
        width = output_width(sys.stdout)
    if width is None:
        from rich.console import Console

        width = Console().width
    keep = fit_columns(columns, texts, width, drop, one_line=one_line)
    fixed = {} if one_line else shared_widths(columns, texts, keep, width)
    left_out = [columns[i] for i in range(len(columns)) if i not in keep]
    if left_out and title is not None:
        title = f"{title} (not shown: {', '.join(left_out)}; wider terminal or --json)"
    heading = None if title is None else _title(title)
    table = Table(title=heading, box=box.SIMPLE_HEAD, title_justify="left", pad_edge=False)
    right_cols = set(right)
    for i in keep:
        # a technician must see the whole name or number:
        # fold, never truncate; the first column (the name) stays on one line
        # widths shared out here, not by rich: rich narrows the widest columns first and would fold
        # a long name mid-word (`shoulder_pi` / `tch`) although the kept columns' words all fit
        table.add_column(columns[i], justify="right" if i in right_cols else "left", overflow="fold",
                         no_wrap=(i == 0 or one_line), width=fixed.get(i))
    for row in texts:
        table.add_row(*(row[i] for i in keep))
    return table


def _title(text: str) -> Text:
    """A table title on one line, whatever the table's width: rich wraps a title to the width of its
    table, so a narrow table read "(both" / "motors)". Padded to the table's width as rich pads it;
    longer, it runs past the table (and a terminal narrower than it folds it like any long line)."""
    from rich.text import Text

    class Title(Text):
        def __rich_console__(self, console: Console, options: ConsoleOptions) -> Iterator[Segment]:
            line = self.copy()
            line.no_wrap, line.overflow = True, "ignore"
            if line.cell_len < options.max_width:
                line.pad_right(options.max_width - line.cell_len)
            yield from console.render(line, options)

    return Title(text, style="table.title")


def fit_columns(columns: Sequence[str], rows: Sequence[Sequence[str]], width: int,
                drop: Sequence[int] | None = None, *, one_line: bool = False) -> list[int]:
    """The columns to show so that no word (header or cell) must be broken to fit ``width``
    (``one_line``: no cell at all)."""
    minimum = min_widths(columns, rows, one_line=one_line)
    keep = list(range(len(columns)))
    order = [i for i in (drop if drop is not None else reversed(range(1, len(columns)))) if i != 0]
    for i in [*order, *(j for j in reversed(range(1, len(columns))) if j not in order)]:
        # padding, divider, padding between columns and one edge each side (box.SIMPLE_HEAD, pad_edge=False)
        if sum(minimum[k] for k in keep) + 3 * (len(keep) - 1) + 2 <= width or len(keep) == 1:
            break
        keep.remove(i)
    return keep


def shared_widths(columns: Sequence[str], rows: Sequence[Sequence[str]], keep: Sequence[int],
                  width: int) -> dict[int, int]:
    """Fixed widths for the ``keep`` columns when their natural widths do not fit ``width``: as rich
    does, the widest columns are narrowed first down to one level, but none below its longest word.
    Empty when everything fits as it is (rich lays it out itself)."""
    minimum = min_widths(columns, rows)
    natural = {i: max(len(line) for c in [columns[i], *(row[i] for row in rows)] for line in c.split("\n"))
               for i in keep}
    avail = width - 3 * (len(keep) - 1) - 2
    if sum(natural.values()) <= avail or sum(minimum[i] for i in keep) > avail:
        return {}

    def at(level: int) -> dict[int, int]:
        return {i: min(natural[i], max(minimum[i], level)) for i in keep}

    level = max(natural.values())
    while level > 0 and sum(at(level).values()) > avail:
        level -= 1
    out = at(level)
    for i in sorted(keep, key=lambda k: natural[k], reverse=True):  # the rest to the widest, one each
        if sum(out.values()) < avail and out[i] < natural[i]:
            out[i] += 1
    return out


def min_widths(columns: Sequence[str], rows: Sequence[Sequence[str]], *, one_line: bool = False) -> dict[int, int]:
    """Per column the narrowest width that breaks no word: the whole cell for the first column (the
    name stays on one line; every column with ``one_line``), the longest word elsewhere."""

    def longest_word(i: int) -> int:
        cells = [columns[i], *(row[i] for row in rows)]
        return max((len(w) for c in cells for w in c.split()), default=0)

    return {i: (max([len(columns[i]), *(len(row[i]) for row in rows)]) if i == 0 or one_line else longest_word(i))
            for i in range(len(columns))}


def stop_lines(st: object, stop: dict[str, Any] | None, fallback: Sequence[str] = ()) -> list[str]:
    """A motion's stop lines from the guard's report kept as JSON (GuardReport.as_json): a normal end
    reads "stopped; motor off; settings put back", ``--verbose`` names the objects put back.
    ``fallback``: lines already rendered, for a result without the report."""
    if not stop:
        return list(fallback)
    from sherpa_cli.motion.report import GuardReport

    return GuardReport.from_json(stop).lines(bool(getattr(st, "verbose", False)))


def fmt_value(value: object) -> str:
    """Parameters as a technician types them (the ops layer words its messages the same way)."""
    from sherpa_cli.elmo.commands import format_value

    return format_value(value)


def require(condition: bool, message: str) -> None:
    if not condition:
        raise UsageError(message)
