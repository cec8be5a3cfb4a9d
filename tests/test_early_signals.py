"""Signals from the first instruction: before a motion guard exists there is nothing
to stop, so SIGINT, SIGTERM and SIGHUP end `sherpa` with one line and 130 / 143 / 129, no traceback
(docs/exit-codes.md). The CLI in its own process, as a user or a service manager starts it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = pytest.mark.crossprocess

EXPECTED = {signal.SIGINT: (130, "error: interrupted"), signal.SIGTERM: (143, "error: interrupted by SIGTERM"),
            signal.SIGHUP: (129, "error: interrupted by SIGHUP")}
COMMAND = ["--sim", "--config", "configs/sherpa-arm.yaml", "scan"]  # about a second on the simulated arm


def _env(tmp_path: Path) -> dict[str, str]:
    env = dict(os.environ, XDG_STATE_HOME=str(tmp_path / "state"), XDG_CONFIG_HOME=str(tmp_path / "config"),
               NO_COLOR="1", COLUMNS="100")
    for name in ("SHERPA_BUS_MAP", "SHERPA_CONFIG"):
        env.pop(name, None)
    return env


def _caught(pid: int) -> set[int]:
    """The signals the process has a handler for (Linux: SigCgt in /proc/PID/status)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            mask = int(line.split()[1], 16)
            return {n for n in range(1, 65) if mask >> (n - 1) & 1}
    return set()


@pytest.fixture(scope="module", autouse=True)
def _warm(tmp_path_factory):
    """One run first, so compiling the package's bytecode does not count against the first 0.05 s."""
    tmp = tmp_path_factory.mktemp("warm")
    subprocess.run([sys.executable, "-m", "sherpa_cli", "--help"], cwd=ROOT, env=_env(tmp),
                   capture_output=True, timeout=120, check=False)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads SigCgt from /proc")
@pytest.mark.parametrize("at", [0.05, 0.2], ids=["at 0.05 s", "at 0.2 s"])
@pytest.mark.parametrize("signum", list(EXPECTED), ids=lambda s: signal.Signals(s).name)
def test_a_signal_before_any_motion_ends_with_one_line_and_its_exit_code(tmp_path, signum, at):
    start = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "sherpa_cli", *COMMAND], cwd=ROOT, env=_env(tmp_path),
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Python's own start-up (before sherpa's first instruction) is not ours to handle: wait for the
        # entry's handlers if a loaded machine takes longer than `at` to get there (SIGTERM is caught
        # by nothing but sherpa's handler)
        while signal.SIGTERM not in _caught(proc.pid) and time.monotonic() - start < 10:
            time.sleep(0.002)
        installed = time.monotonic() - start
        assert signal.SIGTERM in _caught(proc.pid), "the entry did not install its handlers within 10 s"
        time.sleep(max(0.0, at - (time.monotonic() - start)))
        assert proc.poll() is None, "the command ended before the signal; this test needs a longer one"
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    code, line = EXPECTED[signum]
    why = f"handlers after {installed:.3f} s; exit {proc.returncode}\n--- stdout\n{out}--- stderr\n{err}"
    assert proc.returncode == code, why
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, why
    assert [ln for ln in err.splitlines() if ln.strip()] == [line], why


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads SigCgt from /proc")
def test_the_entry_installs_its_handlers_before_the_cli_is_imported(tmp_path):
    """What the first 0.05 s rely on: the handlers are there before typer and the commands load."""
    code = ("import signal, sys\n"
            "import sherpa_cli.cli.entry as entry\n"
            "entry.install_at_once()\n"
            "print(sorted(m for m in ('typer', 'sherpa_cli.cli.app', 'can', 'rich', 'yaml', 'typing') if m in sys.modules))\n"
            "print(signal.getsignal(signal.SIGTERM) is entry._at_once)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(tmp_path), capture_output=True, text=True,
                         timeout=60, check=True)
    assert out.stdout.split("\n")[:2] == ["[]", "True"], out.stdout + out.stderr


def test_a_signal_whose_exception_was_lost_still_ends_the_command_with_its_code(tmp_path):
    """CPython can drop a signal handler's exception (a SIGHUP while a module being imported was
    compiled: `sherpa --sim scan` ran to the end and exited 0). The entry keeps the signal and ends
    the command with its code and line even when its Terminated never arrived."""
    code = ("import os, signal\n"
            "import sherpa_cli.cli.app as app\n"
            "from sherpa_cli.cli import entry\n"
            "def run(args):\n"
            "    try:\n"
            "        os.kill(os.getpid(), signal.SIGHUP)\n"
            "        for _ in range(100000): pass\n"
            "    except BaseException:\n"
            "        pass  # as the C code did: the handler's exception is gone\n"
            "    print('ran to the end')\n"
            "    return 0\n"
            "app.run = run\n"
            "entry.main([])\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(tmp_path), capture_output=True, text=True,
                         timeout=60, check=False)
    assert out.stdout == "ran to the end\n", out.stdout + out.stderr
    assert out.returncode == 129, out.stdout + out.stderr
    assert out.stderr == "error: interrupted by SIGHUP\n"


def test_a_ctrl_c_wrapped_by_a_dataclass_built_during_a_lazy_import_is_still_an_interrupt(monkeypatch, capsys):
    """Ctrl-C landing while a lazily imported module builds a dataclass: Python 3.11 wraps the
    KeyboardInterrupt raised in __set_name__ in a RuntimeError (a loaded CI run caught it as a
    traceback, exit 1). It is the user's Ctrl-C: one line, exit 130."""
    from sherpa_cli.cli import boundary

    def interrupted_import(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise RuntimeError("Error calling __set_name__ on 'Field' instance 'where' in 'PairConfig'") from exc

    monkeypatch.setattr(boundary, "root_command", interrupted_import)
    assert boundary.run(["scan"]) == 130
    err = capsys.readouterr().err
    assert err.strip() == "error: interrupted" and "Traceback" not in err


def test_a_sigterm_wrapped_by_a_dataclass_built_during_a_lazy_import_is_still_that_signal(monkeypatch):
    """The same for SIGTERM (a loaded CI run: `diffdrive move` terminated while it imported
    motion/limit_watch.py printed a traceback): the boundary hands the signal on, unwrapped, to the
    entry, which ends it with its own line and exit code."""
    from sherpa_cli import errors
    from sherpa_cli.cli import boundary

    def terminated_import(*args, **kwargs):
        try:
            raise errors.Terminated(15)
        except errors.Terminated as exc:
            raise RuntimeError("Error calling __set_name__ on 'Field' instance 'joints' in 'WatchResult'") from exc

    monkeypatch.setattr(boundary, "root_command", terminated_import)
    with pytest.raises(errors.Terminated):
        boundary.run(["scan"])


def test_a_background_threads_exception_is_one_line_and_nothing_after_a_signal(capfd, monkeypatch):
    """A library's receive thread that meets a bus closed under it (the command unwinding after a
    Ctrl-C) printed a traceback. The entry's thread hook says it in one line, and nothing at all
    once a signal ends the command (its own line says why)."""
    import threading

    from sherpa_cli import errors
    from sherpa_cli.cli import entry

    monkeypatch.setattr(threading, "excepthook", entry._thread_ended)

    def fail() -> None:
        raise OSError(9, "Bad file descriptor")

    errors.note_signal(None)
    t = threading.Thread(target=fail, name="can.notifier")
    t.start()
    t.join()
    err = capfd.readouterr().err
    assert err == "warning: background thread can.notifier ended: OSError: [Errno 9] Bad file descriptor\n"
    errors.note_signal(signal.SIGINT)
    try:
        t = threading.Thread(target=fail, name="can.notifier")
        t.start()
        t.join()
    finally:
        errors.note_signal(None)
    assert capfd.readouterr().err == ""
