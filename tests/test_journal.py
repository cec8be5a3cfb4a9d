"""The journal of temporary drive changes (sherpa_cli/bus/journal.py) and `sherpa recover` in process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from sherpa_cli.bus import journal
from sherpa_cli.bus.targets import DriveRef


def ref(node: int = 40) -> DriveRef:
    return DriveRef("elbow_1a", "can1", node, None)  # type: ignore[arg-type]


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_note_then_forget_leaves_no_file_and_steps_keep_their_order():
    r = ref()
    journal.note(r, journal.interp("motion command", "UM", 0, 5), journal.sdo("motion command", 0x1016, 1, 4, 0))
    journal.note(r, journal.sdo("log record", 0x1800, 1, 4, 0x1C0))
    data = json.loads(journal.path_for("can1", 40).read_text())
    assert [s["name"] for s in data["steps"]] == ["UM", "0x1016:1", "0x1800:1"]
    assert journal.leftover(r) == []  # this process is alive: not a leftover
    journal.forget(r, "motion command", {"UM"})
    assert [s["name"] for s in json.loads(journal.path_for("can1", 40).read_text())["steps"]] == ["0x1016:1",
                                                                                                   "0x1800:1"]
    journal.forget(r, "motion command")
    journal.forget(r, "log record")
    assert not journal.path_for("can1", 40).exists()


def test_a_dead_process_leaves_a_leftover_named_in_the_text():
    r = ref()
    pid = dead_pid()
    steps = [journal.Step("motion command", "interp", "UM", 5, "UM", pid=pid),
             journal.Step("motion command", "sdo", "0x1016:1", 0, index=0x1016, sub=1, size=4, pid=pid)]
    journal.path_for("can1", 40).parent.mkdir(parents=True, exist_ok=True)
    journal.path_for("can1", 40).write_text(json.dumps({"steps": [s.as_json() for s in steps]}))
    left = journal.leftover(r)
    assert [s.name for s in left] == ["UM", "0x1016:1"]
    text = journal.leftover_text(r, left)
    assert text == ("elbow_1a (can1:40): a motion command that did not finish (killed?) left temporary changes; "
                    "to put back: 0x1016:1=0x0, UM=5")
    assert pid != os.getpid()


def test_a_damaged_journal_is_no_traceback(tmp_path):
    journal.path_for("can1", 41).parent.mkdir(parents=True, exist_ok=True)
    journal.path_for("can1", 41).write_text("{not json")
    assert journal.leftover(ref(41)) == []


def test_recover_with_nothing_left_says_so(cli):
    result = cli("--sim", "recover")
    assert result.exit_code == 0
    assert "nothing to recover" in result.stdout
    # a dead-man that tripped under a command that ended normally leaves no journal note: the line
    # says where that is found and cleared (a newcomer took "nothing to recover" for all clear)
    assert "--check-drives --apply" in " ".join(result.stdout.split()) and "dead-man" in result.stdout


def test_recover_of_an_unknown_target_is_a_usage_error(cli):
    result = cli("--sim", "recover", "no_such_joint")
    assert result.exit_code == 2 and "Traceback" not in result.stderr


@pytest.mark.parametrize("args", [("jog", "elbow_pitch", "--by", "0.05", "--apply"),
                                  ("log", "record", "elbow_pitch", "--for", "0.2", "-o", "{tmp}/r.csv")])
def test_a_journal_that_cannot_be_written_refuses_the_change_with_one_line(cli, tmp_path, args):
    """The journal's directory taken by a file (or not writable): the command went to a traceback
    (FileExistsError) mid-way; now the change is not made and one line says where and why."""
    journal_path = tmp_path / "state" / "sherpa-cli" / "journal"
    journal_path.parent.mkdir(parents=True)
    journal_path.write_text("not a directory")
    result = cli("--sim", *(a.format(tmp=tmp_path) for a in args))
    assert result.exit_code == 1, result.transcript()
    assert "Traceback" not in result.stderr
    assert f"elbow_1a: cannot write the journal {journal_path}/can1-node40.json" in result.stderr
    assert "was not made" in result.stderr and f"hint: make {journal_path} a directory" in result.stderr


def _leave(drive: str, bus: str, node: int, steps: list[journal.Step]) -> None:
    pid = dead_pid()
    path = journal.path_for(bus, node)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"drive": drive, "bus": bus, "node": node,
                                "steps": [{**s.as_json(), "pid": pid} for s in steps]}))


def test_notes_of_values_the_drive_already_holds_are_dropped_not_refused(cli):
    """A drive reset since the note holds every noted value again (RAM at flash
    values): `recover` says so, and a jog goes on instead of refusing."""
    _leave("elbow_1a", "can1", 40, [journal.interp("motion command", "UM", 0, 5),
                                    journal.sdo("motion command", 0x1016, 1, 4, 0),
                                    journal.sdo("motion command", 0x6007, 0, 2, 1)])
    dry = cli("--sim", "recover", "elbow_1a")
    assert dry.exit_code == 0 and "already holds every value" in dry.stdout and "--apply drops" in dry.stdout, \
        dry.transcript()
    assert journal.path_for("can1", 40).exists()  # a dry run drops nothing
    jog = cli("--sim", "jog", "elbow_pitch", "--by", "0.01", "--uncalibrated", "--apply")
    assert jog.exit_code == 0, jog.transcript()
    assert not journal.path_for("can1", 40).exists()


def test_notes_of_values_the_drive_does_not_hold_still_refuse(cli):
    _leave("elbow_1a", "can1", 40, [journal.interp("motion command", "UM", 0, 2)])  # the drive holds UM=5
    jog = cli("--sim", "jog", "elbow_pitch", "--by", "0.01", "--uncalibrated", "--apply")
    assert jog.exit_code == 1 and "UM=2" in jog.stderr and "refusing to move it" in jog.stderr, jog.transcript()
    assert journal.path_for("can1", 40).exists()


def test_a_note_whose_pid_a_later_process_reuses_is_still_a_leftover():
    """The note keeps the process's identity (boot id, start time): a live process that
    got the same pid later (or this process, for a note of another boot) does not hide the leftover."""
    r = ref()
    me = journal.process_identity(os.getpid())
    if me is None:
        pytest.skip("no /proc here: the identity cannot be read")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        step = journal.Step("motion command", "interp", "UM", 5, "UM", pid=live.pid, proc="0-other-boot:12345")
        path = journal.path_for("can1", 40)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"steps": [step.as_json()]}))
        assert [s.name for s in journal.leftover(r)] == ["UM"]  # the pid lives, but it is another process
        same = journal.Step("motion command", "interp", "UM", 5, "UM", pid=live.pid,
                            proc=journal.process_identity(live.pid) or "")
        path.write_text(json.dumps({"steps": [same.as_json()]}))
        assert journal.leftover(r) == []  # that very process still runs: its change, not a leftover
    finally:
        live.kill()
        live.wait()
    journal.note(r, journal.interp("motion command", "UM", 0, 5))
    assert json.loads(path.read_text())["steps"][-1]["proc"] == me


@pytest.mark.parametrize("content", ['{"steps": [{"owner": "motion command", "kind": "sd', "garbage \x00\x01",
                                     '{"steps": [{"owner": "motion command"}]}', '[1, 2]'],
                         ids=["truncated", "garbage", "damaged-step", "not-a-journal"])
def test_a_damaged_journal_is_refused_and_recover_resets_the_drive_from_flash(cli, content):
    """A damaged journal used to read as "nothing to recover" while the drive kept what a
    killed command changed. Now the next motion command refuses, `recover` says the journal is
    damaged and what the drive shows, and `--apply` (motor off) resets the drive (RAM from flash)
    and moves the journal aside."""
    path = journal.path_for("can1", 40)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content)
    jog = cli("--sim", "jog", "elbow_pitch", "--by", "0.01", "--uncalibrated", "--apply")
    assert jog.exit_code == 1 and "is damaged" in jog.stderr and "refusing to move it" in jog.stderr, jog.transcript()
    dry = cli("--sim", "recover", "elbow_pitch")
    assert dry.exit_code == 0 and "journal damaged" in dry.stdout and "0x1016:1=0x" in dry.stdout, dry.transcript()
    assert path.exists()
    fix = cli("--sim", "recover", "elbow_pitch", "--apply")
    assert fix.exit_code == 0 and "NMT reset node: RAM reloaded from flash" in fix.stdout, fix.transcript()
    assert not path.exists() and path.with_name(path.name + ".damaged").read_text() == content
    again = cli("--sim", "jog", "elbow_pitch", "--by", "0.01", "--uncalibrated", "--apply")
    assert again.exit_code == 0, again.transcript()
