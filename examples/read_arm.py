"""Read the simulated arm from Python: every joint's position, who the drives are, their parameters.

Run it from the checkout (`python examples/read_arm.py [DUMP.yaml]`); CI checks it with `mypy --strict`.
"""

from __future__ import annotations

import sys

from sherpa_cli import Arm

with Arm.open("configs/sherpa-arm.yaml", sim=True) as arm:
    state = arm.state()
    for joint in state.joints:
        mark = "" if joint.calibrated else "  (not calibrated)"
        print(f"{joint.name:24} {joint.position:+.4f} rad{mark}")
    report = arm.identify()
    for drive in report.drives:
        print(f"{drive.drive:12} {drive.identity.get('device_name')} firmware {drive.identity.get('software_version')}")
    dump = arm.dump_params(sys.argv[1] if len(sys.argv) > 1 else None)
    print(f"{len(report.drives)} drives identified, {len(report.findings)} finding(s);",
          f"{sum(len(d.params) for d in dump.drives.values())} parameters read")
