"""joints/jointmap.py: a joint read from its motors -- a plain joint is its drive, a Σ/Δ joint is
a ± b (position, velocity) and (a ± b)/2 (current), the same maths as joints/diffpair.py."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sherpa_cli.config import load_config
from sherpa_cli.joints.diffpair import joint_currents, to_joints
from sherpa_cli.joints.jointmap import JointMap, joint_map, joint_maps

SHIPPED = "configs/sherpa-arm.yaml"
counts = st.integers(min_value=-2**31, max_value=2**31 - 1)
amps = st.floats(min_value=-100, max_value=100, allow_nan=False)


def test_the_shipped_arm_maps_every_joint_to_its_drives():
    cfg = load_config(SHIPPED)
    maps = {m.joint: m for m in joint_maps(cfg)}
    assert set(maps) == {j.name for j in cfg.joints.values() if j.drive is not None or j.pair is not None}
    pair = cfg.pairs["shoulder_diff"]
    sigma, delta = maps[pair.sigma], maps[pair.delta]
    assert (sigma.a, sigma.b, sigma.sign) == (pair.drive_a, pair.drive_b, 1)
    assert (delta.a, delta.b, delta.sign) == (pair.drive_a, pair.drive_b, -1)
    plain = maps["elbow_pitch"]
    assert plain.b is None and plain.drives == (cfg.joints["elbow_pitch"].drive,)
    assert joint_map(cfg, cfg.joints["elbow_pitch"]) == plain


def test_exact_values():
    sigma, delta = JointMap("s", 1000, "a", "b", 1), JointMap("d", 1000, "a", "b", -1)
    assert (sigma.value(300, -100), delta.value(300, -100)) == (200, 400)
    assert (sigma.current(1.0, 0.5), delta.current(1.0, 0.5)) == (0.75, 0.25)
    assert JointMap("p", 1000, "a").value(7) == 7 and JointMap("p", 1000, "a").current(1.5) == 1.5
    with pytest.raises(ValueError, match="needs both motors"):
        sigma.value(1)


@given(counts, counts)
def test_a_pair_joint_is_diffpairs_transform(a, b):
    assert (JointMap("s", 1, "a", "b", 1).value(a, b), JointMap("d", 1, "a", "b", -1).value(a, b)) == to_joints(a, b)


@given(amps, amps)
def test_a_pair_joints_current_is_diffpairs(a, b):
    assert (JointMap("s", 1, "a", "b", 1).current(a, b), JointMap("d", 1, "a", "b", -1).current(a, b)) == \
        pytest.approx(joint_currents(a, b))
