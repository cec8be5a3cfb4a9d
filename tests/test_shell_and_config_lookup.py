"""Shell completion, and the default config found outside the repository."""

from __future__ import annotations

import shutil

from tests.conftest import ROOT


def test_show_completion_prints_a_bash_script(cli):
    r = cli("--show-completion", "bash")
    assert r.exit_code == 0, r.stderr
    assert "_sherpa_completion" in r.stdout and "complete " in r.stdout and "_SHERPA_COMPLETE" in r.stdout


def test_completion_completes_commands(cli, monkeypatch):
    monkeypatch.setenv("_SHERPA_COMPLETE", "complete_bash")
    monkeypatch.setenv("COMP_WORDS", "sherpa progr")
    monkeypatch.setenv("COMP_CWORD", "1")
    r = cli()
    assert r.stdout.split() == ["program-limits"], r.stdout + r.stderr


def test_help_lists_the_completion_options(cli):
    r = cli("--help")
    assert "--install-completion" in r.stdout and "--show-completion" in r.stdout


def test_default_config_from_the_user_config_directory(cli, tmp_path, monkeypatch):
    # outside the repository: the user config directory's sherpa-arm.yaml is the default
    user_dir = tmp_path / "xdg" / "sherpa-cli"
    user_dir.mkdir(parents=True)
    shutil.copy(ROOT / "configs/appendix-c/example3.yaml", user_dir / "sherpa-arm.yaml")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    cli("--version")  # the fixture's environment first (it sets XDG_CONFIG_HOME too): set ours after it
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(elsewhere)
    r = cli("--json", "config", "check")
    assert r.exit_code == 0, r.stderr
    assert str(user_dir / "sherpa-arm.yaml") in r.stdout
    # ... and in the repository too it wins over ./configs/sherpa-arm.yaml
    monkeypatch.chdir(ROOT)
    r = cli("--json", "config", "check")
    assert str(user_dir / "sherpa-arm.yaml") in r.stdout
    # $SHERPA_CONFIG wins over both
    monkeypatch.setenv("SHERPA_CONFIG", str(ROOT / "configs/seed-d1.yaml"))
    r = cli("--json", "config", "check")
    assert "seed-d1.yaml" in r.stdout


def test_no_config_anywhere_says_where_it_looked(cli, tmp_path, monkeypatch):
    cli("--version")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "empty"))
    monkeypatch.chdir(tmp_path)
    r = cli("--sim", "scan")
    assert r.exit_code == 2 and "Traceback" not in r.stderr
    assert "no arm config found; looked at" in r.stderr
    assert f"{tmp_path / 'empty' / 'sherpa-cli' / 'sherpa-arm.yaml'} (the user config directory)" in r.stderr
    assert "configs/sherpa-arm.yaml (the working directory)" in r.stderr
    monkeypatch.setenv("SHERPA_CONFIG", str(tmp_path / "missing.yaml"))
    r = cli("limits", "show")
    assert r.exit_code == 2
    assert f"looked at {tmp_path / 'missing.yaml'} ($SHERPA_CONFIG)" in r.stderr
