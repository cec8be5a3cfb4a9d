"""One wording for one thing across commands.

- IL values: `cmd DRIVE "IL[n]"` and `limits show` decode them with one decoder (elmo-protocol.md's
  IL table: 5 is "ignore, active high"; the config's il_codes name what the tool uses it for);
- output that is not a terminal is not wrapped (full names, every column); a terminal's narrow
  table drops columns but never splits a name;
- `identify` ends with one line per drive, its detail behind --verbose;
- a motion's normal end reads "stopped; motor off; settings put back", the objects behind --verbose;
- `home --check-wiring` of an absolute-encoder joint says there is nothing to check.
"""

from __future__ import annotations

import io
import json

from rich.console import Console

from sherpa_cli.cli.output import make_table
from sherpa_cli.elmo.faults import describe_il
from sherpa_cli.motion.report import DriveStop, GuardReport

EXAMPLE2 = "configs/appendix-c/example2.yaml"  # a home switch on input 1: IL[1] = il_codes.home = 5


def _row(stdout: str, key: str) -> str:
    line = next(line for line in stdout.splitlines() if line.strip().startswith(key))
    return line.split(None, 2)[2].strip()


def test_il_5_reads_the_same_in_cmd_and_limits_show(cli):
    shown = cli("--config", EXAMPLE2, "limits", "show")
    assert shown.exit_code == 0, shown.transcript()
    in_limits = _row(shown.stdout, "IL[1]")
    asked = cli("--config", EXAMPLE2, "--sim", "cmd", "drive1", "IL[1]=5", "IL[1]", "--apply")
    assert asked.exit_code == 0, asked.transcript()
    in_cmd = [line for line in asked.stdout.splitlines() if line.strip().startswith("IL[1] ")][-1]
    in_cmd = in_cmd.split(None, 2)[2].strip()
    # the drive's table (elmo-protocol.md: IL=5 = "ignore, active high"), with the config's use of it
    assert in_cmd == "ignore, active high (config: home switch)"
    assert in_limits == f"input: {in_cmd}"
    assert describe_il(5) == "ignore, active high" and describe_il(21, {21: "stop switch"}).endswith(
        "(config: stop switch)")


def test_piped_output_is_not_wrapped_and_keeps_every_column(cli, monkeypatch):
    monkeypatch.delenv("COLUMNS")  # the cli fixture's stdout is not a terminal: a pipe
    mon = cli("--sim", "monitor", "--once")
    assert mon.exit_code == 0, mon.transcript()
    assert "not shown" not in mon.stdout and " UM " in mon.stdout
    ident = cli("--sim", "identify")
    assert "shoulder_yaw_stiffness 0.0000 rad" in ident.stdout  # one line, one cell
    assert "Whistle 1.1.10.4 SIM" in ident.stdout and "not shown" not in ident.stdout
    limits = cli("limits", "show", "upper_arm_stiffness")
    assert "input: both stop (UNCONFIRMED), active high (config: stop switch)" in limits.stdout


def test_a_narrow_terminal_drops_columns_but_never_splits_a_name(cli, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    ident = cli("--sim", "identify", "elbow_1a", "shoulder_diff")
    assert ident.exit_code == 0, ident.transcript()
    assert "not shown: device, firmware" in ident.stdout
    for name in ("shoulder_pitch", "shoulder_roll", "elbow_pitch", "shoulder_2a"):
        assert name in ident.stdout, ident.stdout
    # the table alone, narrower still: rich would share the width out by ratio and fold a name
    rows = [["shoulder_1b", "can0:11", "shoulder_yaw_stiffness 0.0000 rad", "ok"],
            ["wrist_3b", "can2:71", "wrist_3_stiffness 0.0000 rad", "a much longer remark that wraps " * 2]]
    for width in (50, 60, 70):
        out = io.StringIO()
        Console(file=out, width=width, no_color=True).print(
            make_table("t", ["drive", "address", "joint", "check"], rows, width=width))
        assert "shoulder_yaw_stiffness" in out.getvalue() and "wrist_3_stiffness" in out.getvalue(), out.getvalue()
        assert max(len(line.rstrip()) for line in out.getvalue().splitlines()) <= width


def test_identify_ends_with_one_line_per_drive_and_the_detail_is_behind_verbose(cli):
    short = cli("--sim", "identify")
    assert short.exit_code == 0, short.transcript()
    lines = short.stdout.splitlines()
    assert lines[-1].startswith("14 of 14 drives identified")
    assert sum(1 for line in lines if line.split()[:1] and line.split()[0] in (
        "shoulder_1a", "shoulder_1b", "shoulder_2a", "shoulder_2b", "shoulder_3a", "shoulder_3b", "elbow_1a",
        "elbow_1b", "wrist_1a", "wrist_1b", "wrist_2a", "wrist_2b", "wrist_3a", "wrist_3b")) == 14
    assert "software version" not in short.stdout and len(lines) < 25
    for verbose in (["identify", "--verbose"], ["--verbose", "identify"]):
        full = cli("--sim", *verbose, "elbow_1a")
        assert full.exit_code == 0, full.transcript()
        assert "software version" in full.stdout and full.stdout.rstrip().endswith(
            "1 of 1 drive identified, no mismatch in model or firmware")


def test_a_normal_end_reads_stopped_motor_off_settings_put_back(cli):
    args = ("jog", "elbow_pitch", "--velocity", "0.2", "--for", "0.2", "--apply")
    plain = cli("--sim", *args)
    assert plain.exit_code == 0, plain.transcript()
    assert "stop: elbow_1a (can1:40): stopped; motor off; settings put back" in plain.stdout
    assert "0x1016" not in plain.stdout
    verbose = cli("--sim", "--verbose", *args)
    assert "stop: elbow_1a (can1:40): stopped by ST; motor off; restored 0x1016:1, 0x1029:1, 0x6007:0" \
        in verbose.stdout
    data = json.loads(cli("--sim", "--json", *args).stdout)
    assert data["stop"]["drives"][0]["restored"] == ["0x1016:1", "0x1029:1", "0x6007:0"]  # the data unchanged


def test_the_stop_line_shows_what_went_wrong_without_verbose():
    bad = DriveStop("d", "can0:1", stopped_by="not stopped", motor_off=False, kept=["0x1016:1 (stop failed)"],
                    problems=["stop: no answer"])
    assert bad.line() == "d (can0:1): NOT stopped; kept 0x1016:1 (stop failed) -- stop: no answer"
    off = DriveStop("d", "can0:1", stopped_by="motor was off", restored=["UM=2"])
    assert off.line() == "d (can0:1): motor was off; settings put back"
    assert off.line(verbose=True) == "d (can0:1): stopped by motor was off; restored UM=2"
    slow = DriveStop("d", "can0:1", stopped_by="JV=0 + BG", standstill=False, motor_off=True)
    assert slow.line() == "d (can0:1): stopped; NOT at standstill; motor off"
    report = GuardReport([bad, off], "SIGTERM")
    assert GuardReport.from_json(report.as_json()).lines(True) == report.lines(True)


def test_check_wiring_of_an_absolute_encoder_joint_says_there_is_nothing_to_check(cli):
    result = cli("--sim", "home", "--check-wiring", "upper_arm_twist")
    assert result.exit_code == 0, result.transcript()
    assert result.stdout.startswith("upper_arm_twist has an absolute encoder (drive:PY) and no switches: "
                                    "there is no wiring to check")
    js = json.loads(cli("--sim", "--json", "home", "--check-wiring", "shoulder_3a").stdout)
    assert js["abs_encoder"] is True and js["switches"] == 0 and js["findings"] == []
    no_switch = cli("--config", "configs/appendix-c/example3.yaml", "--sim", "home", "--check-wiring", "joint1")
    assert no_switch.exit_code in (0, 2)  # a joint with switches or none: the old answers stand


def test_a_log_step_dry_run_says_what_apply_would_refuse(cli, tmp_path):
    """The dry run used to say "would move" and --apply then refused the joint as not homed."""
    out = tmp_path / "step"
    dry = cli("--sim", "log", "step", "shoulder_yaw", "--position", "0.1", "-o", str(out))
    assert not out.exists()  # a dry run writes nothing
    real = cli("--sim", "log", "step", "shoulder_yaw", "--position", "0.1", "-o", str(out), "--apply")
    assert real.exit_code == 1 and "not homed" in real.stderr  # the real run refuses ...
    assert dry.exit_code == 1, dry.transcript()  # ... and its dry run says so, with the same reason
    assert dry.stdout.startswith("dry run: would be refused: shoulder_yaw: not homed since power-up")
    assert "--apply would refuse it too" in dry.stdout
    far = json.loads(cli("--sim", "--json", "log", "step", "upper_arm_twist", "--position", "9", "-o",
                         str(out)).stdout)
    assert far["checked"] is True and "outside the joint's normal range" in far["would_be_refused"][0]
    fine = cli("--sim", "log", "step", "shoulder_yaw", "--position", "0.1", "--uncalibrated", "-o", str(out))
    assert fine.exit_code == 0 and fine.stdout.startswith("dry run: would record shoulder_yaw")


def test_a_log_step_dry_run_names_a_drive_in_fault(cli, tmp_path, monkeypatch):
    from sherpa_cli.sim.arm import SimArm

    start = SimArm.start

    def faulted(self):
        start(self)
        with self.lock:
            self.drives["elbow_1a"]._shut_down(0x1000, "test: a latched motor fault")  # MF stays until MO=1
        return self

    monkeypatch.setattr(SimArm, "start", faulted)
    dry = cli("--sim", "log", "step", "elbow_pitch", "--velocity", "0.1", "-o", str(tmp_path / "s"))
    assert dry.exit_code == 1 and dry.stdout.startswith("dry run: would be refused: elbow_1a"), dry.transcript()
    assert "in fault" in dry.stdout


def test_a_diffdrive_move_dry_run_says_what_apply_would_refuse(cli):
    """`diffdrive move`'s dry run used to say "would move" where --apply refused an un-homed pair."""
    fast = ["--config", "tests/data/jog-fast-arm.yaml", "--sim"]
    dry = cli(*fast, "diffdrive", "move", "diff", "--sigma", "100counts")
    real = cli(*fast, "diffdrive", "move", "diff", "--sigma", "100counts", "--apply")
    assert real.exit_code == 1 and "joint pitch is not homed since power-up" in real.stderr
    assert dry.exit_code == 1, dry.transcript()
    assert dry.stdout.startswith("dry run: would be refused: diff: refusing a move: joint pitch is not homed")
    js = json.loads(cli(*fast, "--json", "diffdrive", "move", "diff", "--sigma", "100counts").stdout)
    assert js["applied"] is False and js["checked"] is True and "not homed" in js["would_be_refused"][0]
    ok = cli(*fast, "diffdrive", "move", "diff", "--sigma", "100counts", "--uncalibrated")
    assert ok.exit_code == 0 and ok.stdout.startswith("dry run: would move pair diff")
