"""`sherpa jog --interactive [JOINT...]`, `sherpa jog --joystick`, `sherpa jog --list-joysticks`
(docs/jog.md): parse, open the session, render. The motion is ops/live_jog.py (one motion guard,
the limits of `jog`), the joystick loop ops/joystick.py, the view cli/jog_view.py."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import typer

from sherpa_cli.errors import UsageError

if TYPE_CHECKING:
    from sherpa_cli.cli.context import AppState
    from sherpa_cli.config.model import ArmConfig
    from sherpa_cli.motion.axis import Axis
    from sherpa_cli.motion.report import GuardReport


def list_joysticks(st: AppState) -> None:
    from sherpa_cli.ops import joystick

    found = joystick.list_joysticks()
    if st.json_mode:
        st.out.json([{"path": j.path, "name": j.name, "axes": list(j.axes), "buttons": list(j.buttons)}
                     for j in found])
        return
    if not found:
        st.out.line("no joystick found (no input device with axes under /dev/input)")
        return
    for j in found:
        st.out.line(f"{j.path}: {j.name}")
        st.out.line(f"  axes: {', '.join(j.axes) or '-'}")
        st.out.line(f"  buttons: {', '.join(j.buttons) or '-'}")


def have_terminal() -> bool:
    """The view needs a terminal on both ends (the tests replace this to run it headless)."""
    return sys.stdin.isatty() and sys.stdout.isatty()


def _buses(cfg: ArmConfig, axes: Sequence[Axis]) -> list[str]:
    return sorted({cfg.drives[d].bus for a in axes for d in a.drives})


def _stop_lines(st: AppState, report: GuardReport) -> None:
    for line in report.lines(st.verbose):
        st.out.line(f"stop: {line}")


def interactive(st: AppState, names: Sequence[str], *, apply: bool, uncalibrated: bool) -> None:
    from sherpa_cli.ops.live_jog import resolve_axes

    cfg = st.load_config()
    axes = resolve_axes(cfg, names)
    if st.json_mode:
        raise UsageError("--interactive is a full-screen view; --json does not apply")
    if not apply:
        st.out.line(f"dry run: would open the interactive view on {', '.join(a.name for a in axes)} "
                    f"(drives {', '.join(sorted({d for a in axes for d in a.drives}))}) inside the motion guard")
        st.out.line("nothing sent; add --apply to move")
        return
    if not have_terminal():
        raise UsageError("--interactive needs a terminal (stdin and stdout)",
                         hint="run it in an interactive shell (ssh -t for a remote one)")
    from sherpa_cli.api import Arm
    from sherpa_cli.cli.jog_view import JogView

    with st.session(buses=_buses(cfg, axes)) as session:
        live = Arm(session).live_jog(names, uncalibrated=uncalibrated)
        try:
            with live:
                app = JogView(live)
                try:
                    app.run()
                finally:
                    for text in app.home_log:  # what the calibrate key did, for the terminal's record
                        st.out.info(text)
                if app.error is None:  # a SIGTERM/SIGHUP that textual caught itself: still exit 130
                    live.guard.check()
                if app.error is not None:
                    raise app.error
        except BaseException as exc:
            report = getattr(live, "guard", None) and live.guard.report
            if report is not None and report.drives:
                for line in report.lines(st.verbose):
                    st.out.info(f"stop: {line}")
            raise exc
    _stop_lines(st, live.report)
    for text in live.messages:
        st.out.line(text)


def joystick(st: AppState, device: str | None, *, apply: bool) -> None:
    from sherpa_cli.ops import joystick as joy
    from sherpa_cli.ops.live_jog import resolve_axes

    cfg = st.load_config()
    jcfg = cfg.joystick
    if not jcfg.axes:
        raise UsageError("the config maps no joystick axes: add a `joystick:` section with `axes:`",
                         hint="docs/config.md, section joystick")
    axes = resolve_axes(cfg, joy.joints_of(cfg, jcfg))
    path = device or jcfg.device
    if not apply:
        maps = "; ".join(f"{m.axis} -> {m.joint} ({m.mode})" if m.joint else
                         f"{m.x}/{m.y} -> pair {m.pair} ({m.mix}, {m.mode})" for m in jcfg.axes)
        st.out.line(f"dry run: would read {path or 'the first joystick found'} at {jcfg.rate_hz:g} Hz while "
                    f"{jcfg.deadman} is held: {maps}")
        st.out.line("nothing sent; add --apply to move")
        return
    where = f"{cfg.source}: joystick.deadman" if cfg.source else "joystick.deadman"
    # a clear message if evdev or the device is missing, or the dead-man is not one of its buttons
    source = joy.EvdevSource(path, jcfg.deadman, where=where)
    keepalive = max(0.25, 5.0 / jcfg.rate_hz)
    from sherpa_cli.api import Arm

    with st.session(buses=_buses(cfg, axes)) as session:
        arm = Arm(session)
        live = arm.live_jog(arm.joystick_joints(jcfg), keepalive=keepalive, tick_period=1.0 / jcfg.rate_hz)
        try:
            with live:
                st.out.info(f"joystick {source.path}: hold {jcfg.deadman} to move; release stops; Ctrl-C ends")
                st.out.info(live.deadman)
                run = arm.joystick(live, source, mapping=jcfg, on_status=st.out.info)
        except KeyboardInterrupt:
            run = None
        finally:
            source.close()
    _stop_lines(st, live.report)
    if run is not None:
        for text in run.messages:
            st.out.line(text)
        if run.ended_by == "the joystick is gone":
            st.out.line("the joystick disappeared: every joint stopped")
            raise typer.Exit(1)
