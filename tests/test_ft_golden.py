"""`sherpa ft show` and `sherpa ft bias` on the simulated arm of tests/data/ft-arm.yaml (a 1 kg
payload on the wrist, seeded noise, no drift): whole output against tests/golden/ft/, and the
errors a technician can make. The pause between samples is stubbed: no test waits on wall time."""

from __future__ import annotations

from pathlib import Path

import pytest

from sherpa_cli.cli import ft_cmd

ROOT = Path(__file__).resolve().parent.parent
ARM = "tests/data/ft-arm.yaml"


@pytest.fixture(autouse=True)
def no_pause(monkeypatch):
    pauses: list[float] = []
    monkeypatch.setattr(ft_cmd, "sleep", pauses.append)
    return pauses


def test_show_streams_fixed_width_lines(cli, golden, no_pause):
    result = cli("--config", ARM, "--sim", "ft", "show", "--for", "0.5", "--rate", "10")
    assert result.exit_code == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 2 + 5 and no_pause == [0.1] * 4  # 0.5 s at 10 Hz: 5 samples, 4 pauses
    assert len({len(line) for line in lines[2:]}) == 1  # fixed width
    assert all(-9.9 < float(line.split()[2]) < -9.7 for line in lines[2:])  # the payload's weight along -z
    golden("ft/show.txt", result.transcript())


def test_show_json(cli, golden):
    result = cli("--config", ARM, "--sim", "--json", "ft", "show", "wrist_ft", "--for", "0.2", "--rate", "10")
    assert result.exit_code == 0, result.stderr
    golden("ft/show-json.txt", result.transcript())


def test_bias_is_a_dry_run_without_apply_and_zeroes_with_it(cli, golden):
    dry = cli("--config", ARM, "--sim", "ft", "bias")
    assert dry.exit_code == 0 and "dry run: bias frame 010#04 not sent" in dry.stdout
    golden("ft/bias-dry-run.txt", dry.transcript())
    after_dry = cli("--config", ARM, "--sim", "ft", "show", "--for", "0.1")
    assert float(after_dry.stdout.splitlines()[2].split()[2]) < -9.7  # nothing was zeroed
    applied = cli("--config", ARM, "--sim", "ft", "bias", "--apply")
    assert applied.exit_code == 0, applied.stderr
    golden("ft/bias-apply.txt", applied.transcript())
    later = cli("--config", ARM, "--sim", "ft", "show", "--for", "0.3")  # the next command: still zeroed
    assert all(abs(float(v)) < 0.1 for line in later.stdout.splitlines()[2:] for v in line.split()[:6])
    golden("ft/show-after-bias.txt", later.transcript())


@pytest.mark.parametrize(("args", "said"), [
    (["ft", "show", "--rate", "0"], "--rate 0.0: expected samples per second > 0 and <= 200"),
    (["ft", "show", "--for", "-1"], "--for -1.0: expected seconds > 0"),
    (["ft", "show", "elbow_drive"], "'elbow_drive' is no F/T sensor; F/T sensors: wrist_ft"),
    (["--json", "ft", "show"], "--json needs --for"),
])
def test_bad_arguments_are_one_line(cli, args, said):
    result = cli("--config", ARM, "--sim", *args)
    assert result.exit_code == 2 and said in result.stderr and "Traceback" not in result.stderr, result.stderr


def test_an_arm_without_a_sensor_says_so(cli):
    result = cli("--sim", "ft", "show", "--for", "0.1")
    assert result.exit_code == 2 and "this arm has no F/T sensor" in result.stderr, result.stderr


def test_a_silent_sensor_is_a_bus_error_not_a_traceback(cli, tmp_path):
    text = (ROOT / ARM).read_text(encoding="utf-8").replace("      seed: 7\n", "      seed: 7\n      silent_at: 0\n")
    text = text.replace("sim:\n", "sim:\n  reply_timeout: 0.2\n")  # --sim waits this long, not reply_ms
    path = tmp_path / "silent.yaml"
    path.write_text(text, encoding="utf-8")
    result = cli("--config", str(path), "--sim", "ft", "show", "--for", "0.1")
    assert result.exit_code == 3, result.stderr
    assert "F/T sensor wrist_ft (base 0x010): no reply within 200 ms" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize(("name", "args", "code"), [
    ("monitor-once", ["monitor", "--once"], 0),
    ("monitor-once-json", ["--json", "monitor", "--once"], 0),
    ("identify-sensor", ["identify", "wrist_ft"], 0),
    ("identify-sensor-json", ["--json", "identify", "wrist_ft"], 0),
    ("config-check", ["config", "check"], 0),
])
def test_status_views_show_the_sensor(cli, golden, name, args, code):
    result = cli("--config", ARM, *(["--sim"] if args[0] != "config" else []), *args)
    assert result.exit_code == code, result.stderr
    assert "wrist_ft" in result.stdout
    golden(f"ft/{name}.txt", result.transcript())


def test_monitor_once_names_a_silent_sensor_and_exits_1(cli, tmp_path):
    text = (ROOT / ARM).read_text(encoding="utf-8").replace("      seed: 7\n", "      seed: 7\n      silent_at: 0\n")
    text = text.replace("sim:\n", "sim:\n  reply_timeout: 0.2\n")
    path = tmp_path / "silent.yaml"
    path.write_text(text, encoding="utf-8")
    result = cli("--config", str(path), "--sim", "monitor", "--once")
    assert result.exit_code == 1, result.stderr
    assert "wrist_ft (can0 base 0x010): F/T sensor wrist_ft (base 0x010): no reply within 200 ms" in result.stdout
    assert "no answer" in result.stdout


def test_monitor_once_exits_1_when_a_sensor_reports_a_fault_in_its_status_word(cli, tmp_path):
    text = (ROOT / ARM).read_text(encoding="utf-8").replace("      seed: 7\n", "      seed: 7\n      status: 0x8001\n")
    path = tmp_path / "status.yaml"
    path.write_text(text, encoding="utf-8")
    result = cli("--config", str(path), "--sim", "monitor", "--once")
    assert result.exit_code == 1, result.transcript()
    assert "0x8001" in result.stdout, result.stdout
    ok = cli("--config", str(ROOT / ARM), "--sim", "monitor", "--once")
    assert ok.exit_code == 0, ok.transcript()
