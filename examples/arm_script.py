"""A controls developer's first script: read every joint, move two joints together in one motion
session, record 1 s at 200 Hz into memory, identify the drives and dump their parameters.

Run it from the checkout (`python examples/arm_script.py`); CI runs it and checks it with `mypy --strict`.
"""

from __future__ import annotations

from sherpa_cli import Arm

with Arm.open("configs/sherpa-arm.yaml", sim=True) as arm:
    known = {j.name: j.position for j in arm.state() if j.calibrated}  # rad; a joint not homed has none
    print("calibrated joints:", ", ".join(f"{name} {rad:+.3f}" for name, rad in known.items()))
    with arm.motion(["elbow_pitch", "wrist_1"]) as m:  # one guard, one dead-man for every move below
        moved = m.move_to({"elbow_pitch": known["elbow_pitch"] + 0.1, "wrist_1": known["wrist_1"] - 0.05})
        back = m.move_to({"elbow_pitch": known["elbow_pitch"], "wrist_1": known["wrist_1"]})
    print(f"moved together: {moved.ok}, back: {back.ok}")
    recording = arm.record(["elbow_pitch", "wrist_1"], rate=200, duration=1.0).recording
    print(f"{len(recording.times)} samples over {recording.times[-1]:.2f} s")
    report = arm.identify()
    dump = arm.dump_params()
    print(f"{len(report.drives)} drives identified, {sum(len(d.params) for d in dump.drives.values())} parameters read")
