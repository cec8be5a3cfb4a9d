"""`sherpa dump-params` and the `sherpa params` group (`diff`; `restore` joins it later).

Each subcommand of the group is a plain function registered on ``app`` below, so another
module can add one with ``params_cmd.app.command("restore")(restore)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from sherpa_cli.cli.context import AppState, state
from sherpa_cli.cli.options import Targets
from sherpa_cli.words import plural

if TYPE_CHECKING:
    from sherpa_cli.ops.params_diff import DiffReport

app = typer.Typer(no_args_is_help=True, help="Drive parameter sets: compare dumps, the drives and the config.")

def dump_params(
    ctx: typer.Context,
    targets: Targets = None,
    output: Path | None = typer.Option(None, "--output", "-o", metavar="FILE",
                                          help="Write the YAML dump to FILE (atomically; a symlink's target; a "
                                          "FIFO or device in place) instead of stdout; - is stdout."),
) -> None:
    """Read the parameters commissioning touches, plus identity, into YAML that diffs cleanly in git.

    Per drive: UM, every parameter Appendix C programs, IL[n] for each input of the model,
    CA[18], and the SDO identity. A header block holds tool version, config file, its
    SHA-256 and the date (UTC; $SHERPA_DUMP_DATE overrides it); two dumps of unchanged
    drives differ only there. If any drive fails, nothing is written (exit 3).

    \b
    Examples:
      sherpa dump-params -o arm-2024-05-02.yaml
      sherpa dump-params shoulder_diff
    """
    from sherpa_cli.api import Arm
    from sherpa_cli.bus.targets import drive_names
    from sherpa_cli.ops.params_file import drive_block, dump_to_text, write_dump
    from sherpa_cli.output_files import check_output_path, is_stdout

    st = state(ctx)
    cfg = st.load_config()
    drives = drive_names(cfg, targets, elmo_only="dump-params")
    if is_stdout(output):
        output = None  # `-o -` is the default: the YAML on stdout
    check_output_path(output, "--output", "the dump")  # a directory is refused before the drives are read
    buses = sorted({cfg.drives[d].bus for d in drives})
    with st.session(buses=buses) as session:
        dump = Arm(session).dump_params(None, drives)
    for d in dump.drives.values():
        for key, why in d.unreadable.items():
            st.out.warn(f"{d.name}: {key} unreadable ({why})")
    if output is not None:
        write_dump(output, dump, "--output")
    if st.json_mode:
        st.out.json({"file": str(output) if output is not None else None, "meta": dump.meta,
                     "drives": {name: drive_block(d) for name, d in dump.drives.items()}})
    elif output is not None:
        st.out.line(f"wrote {plural(len(dump.drives), 'drive')} to {output}")
    else:
        st.out.raw(dump_to_text(dump))


@app.command("diff")
def diff(
    ctx: typer.Context,
    a: str = typer.Argument(..., metavar="A", help="A dump file, 'live' (read the drives now) or 'config'."),
    b: str = typer.Argument("live", metavar="[B]", help="The same choices; default: live."),
    targets: list[str] | None = typer.Option(None, "--target", "-t", metavar="TARGET",
                                                help="Only these drives (drive, joint, pair or BUS:NODE; repeat)."),
    only_differences: bool = typer.Option(False, "--only-differences", help="Show only the rows that differ."),
) -> None:
    """Compare two parameter sets per drive and parameter; exit 1 when they differ.

    'config' is what `sherpa limits show` derives and covers only those parameters (UM,
    CA[18] and IL[n] without a switch are not compared against it). Floats compare within
    float32 precision. Drives default to those named in the dump file(s), else all.

    \b
    Examples:
      sherpa params diff config              # after commissioning: do the drives hold the config?
      sherpa params diff arm-a.yaml arm-b.yaml
    """
    from sherpa_cli.bus.targets import drive_names
    from sherpa_cli.errors import ExitCode
    from sherpa_cli.ops import params_diff as pd

    st = state(ctx)
    cfg = st.load_config()
    pd.check_pair(a, b)
    warnings: list[str] = []
    files: dict[str, pd.Side] = {}
    for spec in (a, b):
        if pd.side_kind(spec) == "file" and spec not in files:
            files[spec], w = pd.file_side(Path(spec), cfg)
            warnings.extend(w)
    if targets:
        drives = drive_names(cfg, targets, elmo_only="params diff")
    elif files:
        drives = pd.drives_of(list(files.values()), cfg)
    else:
        drives = list(cfg.drives)
    sides: dict[str, pd.Side] = dict(files)
    if pd.CONFIG in (a, b):
        sides[pd.CONFIG], w = pd.config_side(cfg, drives)
        warnings.extend(w)
    if pd.LIVE in (a, b):
        from sherpa_cli.api import Arm
        from sherpa_cli.ops.params_file import ParamDump

        if drives:  # none (a dump of no drives): nothing to read, and an empty list to the API means all
            with st.session(buses=sorted({cfg.drives[d].bus for d in drives})) as session:
                live = Arm(session).dump_params(None, drives).drives
        else:
            live = {}
        sides[pd.LIVE] = pd.dump_side(pd.LIVE, ParamDump(meta={}, drives=live), kind="live")
    report = pd.diff_sides(sides[a], sides[b], drives, warnings)
    for warning in report.warnings:
        st.out.warn(warning)
    if st.json_mode:
        st.out.json(report.as_json())
    else:
        _render(st, report, only_differences)
    if report.differences:
        raise typer.Exit(int(ExitCode.PROBLEM))


def _fmt(value: float | None, note: str | None) -> str:
    from sherpa_cli.elmo.commands import format_value

    # 7 digits: float32 noise (2.2999999523) reads as 2.3, a real float32 step still shows
    return note if note is not None else format_value(value, digits=7)


def _render(st: AppState, report: DiffReport, only_differences: bool) -> None:
    a, b = report.a.label, report.b.label
    # labels in a legend, not in the column headers: a long file path must not widen every table
    st.out.line(f"A: {a}")
    st.out.line(f"B: {b}")
    n, count = report.differences, len(report.drives)
    if not n:
        # the sets agree: a table of hundreds of equal rows would bury that; --json still has them
        compared = sum(len(d.rows) for d in report.drives)
        st.out.line(f"no difference: {plural(count, 'drive')}, {plural(compared, 'parameter')} compared")
        return
    for d in report.drives:
        if d.only_in:
            side = a if d.only_in == "A" else b
            st.out.line(f"{d.drive} ({d.bus}:{d.node}): only in {d.only_in} ({side})")
            continue
        rows = [[r.key, _fmt(r.a, r.a_note), _fmt(r.b, r.b_note), "" if r.status == "same" else r.status]
                for r in d.rows if not only_differences or r.status != "same"]
        if only_differences and not rows:
            continue
        title = f"{d.drive} ({d.bus}:{d.node}) - " + (plural(d.differences, "difference") if d.differences
                                                      else "same")
        st.out.table(title, ["param", "A", "B", ""], rows, right=(1, 2))
    st.out.line(f"{plural(n, 'difference')} in {report.drives_differing} of {plural(count, 'drive')}")


# `params restore` lives with program-limits: both run the same plan / apply / verify / save engine.
from sherpa_cli.cli.program_cmd import params_restore  # noqa: E402

app.command("restore")(params_restore)
