"""Written paths (`dump-params -o`, `--report`, `--junit`): `-` is stdout, a FIFO or device is written in
place and never replaced by a regular file, a directory is refused, a symlink's target is replaced atomically."""

from __future__ import annotations

import json
import os
import re
import stat
import threading
from pathlib import Path

import pytest

from sherpa_cli.errors import UsageError
from sherpa_cli.output_files import check_output_path, write_output

DUMP = ["--sim", "dump-params", "elbow_1a"]
RECIPE = "steps:\n  - name: show\n    run: limits show elbow_pitch\n"


@pytest.fixture(autouse=True)
def fixed_date(monkeypatch):
    monkeypatch.setenv("SHERPA_DUMP_DATE", "2024-05-02T10:00:00Z")


def _read_fifo(path: Path) -> tuple[threading.Thread, list[str]]:
    got: list[str] = []

    def reader() -> None:
        with open(path, encoding="utf-8") as handle:
            got.append(handle.read())

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    return t, got


# --------------------------------------------------------------------------- the helper


def test_dash_is_stdout():
    seen: list[str] = []
    assert write_output("-", "hello\n", "-o", stdout=seen.append) == "stdout"
    assert seen == ["hello\n"]


def test_regular_file_is_replaced_atomically_and_keeps_its_mode(tmp_path):
    target = tmp_path / "out.yaml"
    target.write_text("old\n")
    target.chmod(0o640)
    before = target.stat().st_ino
    assert write_output(target, "new\n", "-o") == "atomically"
    assert target.read_text() == "new\n"
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert target.stat().st_ino != before, "renamed into place, not rewritten"
    assert [p.name for p in tmp_path.iterdir()] == ["out.yaml"], "no temporary file left"


def test_new_file_gets_the_usual_mode_not_0600(tmp_path):
    umask = os.umask(0o022)
    try:
        write_output(tmp_path / "sub" / "new.yaml", "x\n", "-o")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "sub" / "new.yaml").stat().st_mode) == 0o644


def test_symlink_is_followed_and_its_target_replaced(tmp_path):
    real = tmp_path / "real.yaml"
    real.write_text("old\n")
    link = tmp_path / "link.yaml"
    link.symlink_to(real)
    assert write_output(link, "new\n", "-o") == "atomically"
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text() == "new\n"
    dangling = tmp_path / "dangling.yaml"
    dangling.symlink_to(tmp_path / "made-by-write.yaml")
    write_output(dangling, "x\n", "-o")
    assert dangling.is_symlink() and (tmp_path / "made-by-write.yaml").read_text() == "x\n"


def test_dev_null_is_written_in_place():
    assert write_output("/dev/null", "nothing\n", "-o") == "in place"
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_fifo_is_written_in_place(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    t, got = _read_fifo(fifo)
    assert write_output(fifo, "through the pipe\n", "--report") == "in place"
    t.join(5)
    assert got == ["through the pipe\n"]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode), "still a FIFO, not replaced by a regular file"


def test_directory_and_symlink_to_directory_are_refused(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "to-d").symlink_to(tmp_path / "d")
    for path in (tmp_path / "d", tmp_path / "to-d"):
        with pytest.raises(UsageError, match="is a directory, expected a file name"):
            check_output_path(path, "--junit")
        with pytest.raises(UsageError, match=r"--junit .*: is a directory"):
            write_output(path, "x", "--junit")
    assert (tmp_path / "to-d").is_symlink()


# --------------------------------------------------------------------------- the commands


def test_dump_params_dash_is_stdout(cli):
    plain = cli(*DUMP)
    dash = cli(*DUMP, "-o", "-")
    assert dash.exit_code == 0 and dash.stdout == plain.stdout and "drives:" in dash.stdout


def test_dump_params_to_dev_null(cli):
    r = cli(*DUMP, "-o", "/dev/null")
    assert r.exit_code == 0, r.transcript()
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_dump_params_to_a_fifo(cli, tmp_path):
    fifo = tmp_path / "dump.fifo"
    os.mkfifo(fifo)
    t, got = _read_fifo(fifo)
    r = cli(*DUMP, "-o", str(fifo))
    t.join(5)
    assert r.exit_code == 0, r.transcript()
    assert got and got[0].startswith("# sherpa-cli parameter dump") and "elbow_1a:" in got[0]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_dump_params_into_a_directory_is_refused_before_reading(cli, tmp_path):
    r = cli(*DUMP, "-o", str(tmp_path))
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert r.stderr.startswith(f"error: --output {tmp_path}: is a directory, expected a file name")


def test_dump_params_through_a_symlink(cli, tmp_path):
    real = tmp_path / "real.yaml"
    real.write_text("old\n")
    link = tmp_path / "latest.yaml"
    link.symlink_to(real)
    r = cli(*DUMP, "-o", str(link))
    assert r.exit_code == 0, r.transcript()
    assert link.is_symlink() and real.read_text().startswith("# sherpa-cli parameter dump")


def test_recipe_reports_to_stdout_fifo_and_dev_null(cli, tmp_path):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(RECIPE)
    r = cli("recipe", "run", str(recipe), "--report", "-", "--junit", "/dev/null")
    assert r.exit_code == 0, r.transcript()
    start = r.stdout.index("{\n")
    body = json.loads(r.stdout[start:r.stdout.index("\n}\n", start) + 2])
    assert body["outcome"] == "passed"
    fifo = tmp_path / "junit.fifo"
    os.mkfifo(fifo)
    t, got = _read_fifo(fifo)
    r = cli("recipe", "run", str(recipe), "--junit", str(fifo))
    t.join(5)
    assert r.exit_code == 0 and got and got[0].startswith('<?xml version="1.0"')
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_both_reports_to_stdout_is_refused(cli, tmp_path):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(RECIPE)
    r = cli("recipe", "run", str(recipe), "--report", "-", "--junit", "-")
    assert r.exit_code == 2 and "only one report can go to stdout" in r.stderr
    assert "[1/1]" not in r.stdout


# -- where no file can go: refused before the work, not a traceback after it -----------------------

@pytest.mark.parametrize("bad", ["/dev/null/x.csv", "/proc/self/x.csv", "/proc/adv/sub/x.csv"])
def test_a_path_where_no_file_can_be_made_is_refused_up_front(bad):
    with pytest.raises(UsageError, match=r"^-o " + re.escape(bad) + ": "):
        check_output_path(bad, "-o", "the recording")


def test_check_output_dir_takes_a_new_directory_below_a_writable_one_and_refuses_a_file_on_the_way(tmp_path):
    from sherpa_cli.output_files import check_output_dir

    check_output_dir(tmp_path / "new" / "deeper", "-o")
    assert not (tmp_path / "new").exists() and list(tmp_path.iterdir()) == []  # the probe leaves nothing
    (tmp_path / "f").write_text("x")
    with pytest.raises(UsageError, match="is not a directory"):
        check_output_dir(tmp_path / "f" / "sub", "-o")
    with pytest.raises(UsageError, match="cannot write"):
        check_output_dir("/proc/adv", "-o", "the step's files")


@pytest.mark.parametrize("args", [
    ("log", "record", "elbow_pitch", "--for", "0.2", "-o", "/dev/null/x.csv"),
    ("log", "record", "elbow_pitch", "--for", "0.2", "-o", "/proc/self/x.csv"),
    ("log", "step", "elbow_pitch", "--velocity", "0.1", "--apply", "-o", "/proc/adv"),
    ("dump-params", "elbow_1a", "-o", "/proc/self/p.json"),
])
def test_commands_refuse_an_unwritable_output_with_one_line_and_no_traceback(cli, args):
    result = cli("--sim", *args)
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr and result.stderr.startswith("error: "), result.transcript()
    assert "cannot write" in result.stderr and "elbow_1a" not in result.stdout
