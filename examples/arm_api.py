"""Program one joint's limits and stop the arm, from Python (docs/api.md).

CI checks this file with `mypy --strict` (the lint stage), so the API's types are what a user's
own script sees. Run it on the simulated arm: `python examples/arm_api.py`.
"""

from __future__ import annotations

from collections.abc import Sequence

from sherpa_cli import Arm
from sherpa_cli.api import ProgramReport, StopReport


def say_yes(drives: Sequence[str], proof: bool) -> bool:
    print(f"saving {', '.join(drives)}{' after a flash proof' if proof else ''}")
    return True


def commission(joint: str) -> tuple[ProgramReport, StopReport]:
    with Arm.open("configs/sherpa-arm.yaml", sim=True) as arm:
        plan = arm.program_limits([joint])
        print(f"{plan.changes} change(s) planned for {joint}")
        done = arm.program_limits([joint], apply=True, save=plan.changes > 0, confirm_save=say_yes)
        stopped = arm.stop()
        return done, stopped


if __name__ == "__main__":
    done, stopped = commission("elbow_pitch")
    print("programmed" if done.ok else f"problem: {done.problem}", "/",
          f"{sum(r.motor_off for r in stopped.drives)} drive(s) switched off")
