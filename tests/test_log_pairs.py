"""Differential pairs in `log record --poll` and `log step` (tests/data/step-arm.yaml: pair `diff`,
Σ `pitch`, Δ `roll`, motors `left`/`right`).

- `--poll` gives a pair the same joint columns as the TPDO recorder (Σ/Δ from both motors'
  readings of one poll round);
- `log step` of a Σ/Δ joint, a pair motor or the pair is refused with one message (a Σ or Δ step
  moves both motors: `diffdrive move`'s job), before the bus is opened.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from sherpa_cli.bus.session import ArmSession
from sherpa_cli.bus.targets import drive_refs
from sherpa_cli.config import load_config
from sherpa_cli.log.record import Poller
from sherpa_cli.log.recording import read_csv
from sherpa_cli.sim.arm import SimArm

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "tests/data/step-arm.yaml"
ARM = ["--config", "tests/data/step-arm.yaml", "--sim"]
PAIR_COLUMNS = {"pitch.pos_rad", "pitch.vel_rad_s", "roll.pos_rad", "roll.vel_rad_s"}


def _joint_columns(rec) -> set[str]:
    return {c for c in rec.columns if c.split(".")[1] in ("pos_rad", "vel_rad_s", "cur_a")}


def test_poll_gives_a_pair_its_sigma_and_delta_columns():
    cfg = load_config(CONFIG)
    refs = drive_refs(cfg, ["pitch"])
    assert sorted(r.name for r in refs) == ["left", "right"]
    with ArmSession.open(cfg, sim=SimArm.in_process(cfg), buses=["can0"]) as session:
        with session.sim.lock:  # the motors stand at known counts: a = 1000, b = 300
            session.sim.drives["left"].write_param("PX", 1000)
            session.sim.drives["right"].write_param("PX", 300)
        poller = Poller(session, refs)
        with poller:
            deadline = time.monotonic() + 10
            while min(poller.counts().values()) < 5 and time.monotonic() < deadline:
                time.sleep(0.01)
        rec = poller.recording(cfg)
    assert _joint_columns(rec) == PAIR_COLUMNS
    sigma = [v for v in rec.columns["pitch.pos_rad"] if v == v]
    delta = [v for v in rec.columns["roll.pos_rad"] if v == v]
    # one value per poll round (the round's second reading), from both motors of that round
    assert len(sigma) == len(delta) >= 4
    assert len(sigma) >= min(poller.counts().values()) - 1
    assert all(v == pytest.approx(1300 / 6000 * 2 * math.pi) for v in sigma)
    assert all(v == pytest.approx(700 / 6000 * 2 * math.pi) for v in delta)
    assert all(v == 0 for v in rec.columns["pitch.vel_rad_s"] if v == v)


def test_poll_pairs_readings_of_the_same_round():
    """The pair's rows alternate; a round's Σ never mixes in the other motor's reading of another round."""
    cfg = load_config(CONFIG)
    refs = drive_refs(cfg, ["left", "right", "arm"])
    p = Poller.__new__(Poller)
    p.refs, p.current, p.t0 = refs, False, 0.0
    # rounds of the bus thread read refs in order; values tell the round apart
    p.rows = [(0.000, "left", 10, 0, None), (0.001, "right", 1, 0, None), (0.002, "elbow", 5, 0, None),
              (0.010, "left", 20, 0, None), (0.011, "right", 2, 0, None), (0.012, "elbow", 5, 0, None),
              (0.020, "left", 30, 0, None)]  # the last round was cut off after its first reading
    rec = Poller.recording(p, cfg)
    counts = [None if v != v else round(v / (2 * math.pi) * 6000) for v in rec.columns["pitch.pos_rad"]]
    assert counts == [None, 11, None, None, 22, None, None]
    deltas = [None if v != v else round(v / (2 * math.pi) * 6000) for v in rec.columns["roll.pos_rad"]]
    assert deltas == [None, 9, None, None, 18, None, None]


def test_cli_poll_records_a_pair_with_joint_columns(cli, tmp_path):
    out = tmp_path / "pair.csv"
    result = cli(*ARM, "log", "record", "pitch", "--poll", "--for", "0.3", "-o", str(out))
    assert result.exit_code == 0, result.transcript()
    rec = read_csv(out)
    assert _joint_columns(rec) == PAIR_COLUMNS
    assert any(v == v for v in rec.columns["pitch.pos_rad"])


@pytest.mark.parametrize("name", ["pitch", "roll", "left", "diff"])
def test_log_step_refuses_a_pair(cli, tmp_path, name):
    out = tmp_path / "step"
    result = cli(*ARM, "log", "step", name, "--position", "0.1", "-o", str(out))
    assert result.exit_code == 2, result.transcript()
    assert "Traceback" not in result.stderr
    assert "differential pair" in result.stderr and "diffdrive move" in result.stderr
    assert result.stderr.count("error:") == 1
    assert not out.exists()  # refused before anything was written or opened


@pytest.mark.golden
def test_log_step_refuses_a_sigma_joint_golden(cli, golden, tmp_path):
    result = cli(*ARM, "log", "step", "pitch", "--position", "0.1", "-o", str(tmp_path / "step"))
    golden("log-step-refuse-pair.txt", result.transcript().replace(str(tmp_path), "TMP"))
