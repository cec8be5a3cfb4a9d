"""Program one joint's limits, home it, step it and stop the arm, from Python (docs/api.md).

CI checks this file with `mypy --strict` (the lint stage), so the API's types are what a user's
own script sees. Run it on the simulated arm: `python examples/arm_api.py`.
"""

from __future__ import annotations

from collections.abc import Sequence

from sherpa_cli import Arm
from sherpa_cli.api import ProgramReport, StopReport
from sherpa_cli.ops.step import StepResult


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


def home_and_step(joint: str, speed: float) -> StepResult:
    """Calibrate ``joint``, then a velocity step of ``speed`` rad/s: `sherpa home` and `log step`."""
    with Arm.open("configs/sherpa-arm.yaml", sim=True) as arm:
        homed = arm.home([joint])
        print(", ".join(f"{u.name} homed ({u.kind})" for u in homed.units))
        return arm.log_step(joint, "velocity", speed, duration=0.3, rate=200)


if __name__ == "__main__":
    done, stopped = commission("elbow_pitch")
    print("programmed" if done.ok else f"problem: {done.problem}", "/",
          f"{sum(r.motor_off for r in stopped.drives)} drive(s) switched off")
    step = home_and_step("elbow_pitch", 0.1)
    rise = step.metrics.rise_time
    print(f"{step.command}: {step.ended_by}" + (f", rise time {rise:.3f} s" if rise is not None else ""))
