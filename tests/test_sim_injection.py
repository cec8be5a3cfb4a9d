"""The simulated arm is injected into the session by the CLI; ops never import the simulator."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT

from sherpa_cli.bus.session import ArmSession, resolve_target
from sherpa_cli.config import load_config
from sherpa_cli.sim.arm import SimArm


def test_no_ops_module_names_the_simulator_package():
    offenders = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "sherpa_cli/ops").glob("*.py"))
                 if "sherpa_cli.sim" in p.read_text(encoding="utf-8")]
    assert offenders == []


def test_importing_every_ops_module_loads_no_simulator_module():
    code = ("import importlib, pkgutil, sys, sherpa_cli.ops as ops\n"
            "for m in pkgutil.iter_modules(ops.__path__):\n"
            "    importlib.import_module('sherpa_cli.ops.' + m.name)\n"
            "print(sorted(n for n in sys.modules if n.startswith('sherpa_cli.sim')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_the_session_wires_starts_and_stops_the_arm_it_is_given():
    cfg = load_config(ROOT / "configs/appendix-c/example3.yaml")
    arm = SimArm.in_process(cfg)
    arm.persist = False  # nothing to the state directory
    with ArmSession.open(cfg, sim=arm) as session:
        assert session.sim is arm
        for name, link in session.links.items():
            assert (link.config.interface, link.config.channel) == ("virtual", arm.endpoints[name]["channel"])
        client = session.client(resolve_target(cfg, next(iter(cfg.drives))))
        client.nmt_start()
        assert client.get("PX") == 0, "the arm answers on the wired buses"
        assert arm._threads, "started"
    assert not arm._threads, "stopped when the session closed"


def test_a_flag_instead_of_an_arm_is_refused_by_name():
    cfg = load_config(ROOT / "configs/appendix-c/example3.yaml")
    with pytest.raises(TypeError, match="takes the simulated arm itself"), ArmSession.open(cfg, sim=True):
        pass


def test_a_factory_builds_the_arm_on_fresh_channels():
    cfg = load_config(ROOT / "configs/appendix-c/example3.yaml")
    seen = []

    def factory(cfg, channels):
        seen.append(dict(channels))
        return SimArm(cfg, {bus: {"interface": "virtual", "channel": ch} for bus, ch in channels.items()})

    first, _second = SimArm.in_process(cfg, factory), SimArm.in_process(cfg, factory)
    assert isinstance(first, SimArm) and list(seen[0]) == list(cfg.buses)
    assert seen[0] != seen[1], "every arm gets channels of its own"
