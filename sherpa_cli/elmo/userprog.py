"""User programs on an Elmo drive (PS): what the value means, and the refusals it causes.

An Elmo drive can run a user program (labels ``##NAME``, started with ``XQ##label``) that fights the
tool's commands, and SV is not allowed while one runs ([CR 3-138]; the drive answers EC 82 "program
is running"). ``PS`` reports it: -1 idle, -2 unavailable (no program), 1 running
(../shared/docs/real-arm.md section 4; one public source: other values are shown as unknown, never
guessed). Pure, except :func:`read_ps`, which asks a drive client.
"""

from __future__ import annotations

from typing import Protocol

from sherpa_cli.errors import DriveRefusedError, SafetyError

PS_IDLE = -1
PS_UNAVAILABLE = -2
PS_RUNNING = 1
PS_TEXT = {PS_IDLE: "idle (no program running)", PS_UNAVAILABLE: "no user program available",
           PS_RUNNING: "a user program is running"}
ALLOW_OPTION = "--allow-user-program"


class PsClient(Protocol):
    """What these checks use of a drive client (elmo/client.py's ``DriveClient``)."""

    @property
    def label(self) -> str: ...

    def get(self, letters: str, index: int = 0) -> int | float: ...


class UserProgramError(SafetyError):
    """A drive runs a user program and the operation would fight it (exit 1)."""


def describe_ps(value: int | None) -> str:
    if value is None:
        return "not reported by this drive"
    return PS_TEXT.get(value, f"PS={value} (meaning unknown)")


def program_running(value: int | None) -> bool | None:
    """True: a program runs; False: none runs; None: PS is unknown (unreadable or a value the sources
    do not name)."""
    if value is None:
        return None
    if value == PS_RUNNING:
        return True
    if value in (PS_IDLE, PS_UNAVAILABLE):
        return False
    return None


def read_ps(client: PsClient) -> int | None:
    """PS of one drive; None when the drive refuses the command (a firmware without user programs)."""
    try:
        return int(client.get("PS"))
    except DriveRefusedError:
        return None


def refuse_save_while_running(client: PsClient) -> None:
    """Before SV: a drive that runs a user program cannot save (it would answer EC 82); say why first."""
    ps = read_ps(client)
    if program_running(ps):
        raise UserProgramError(
            f"{client.label}: SV refused: a user program is running on the drive (PS={ps}); "
            "the drive does not save while a program runs",
            hint="stop the user program first (e.g. in Elmo Composer), then save again")


def refuse_motion_while_running(client: PsClient, *, allow: bool) -> int | None:
    """Before motion: refuse a drive whose user program runs (or whose PS is unknown) unless ``allow``."""
    ps = read_ps(client)
    running = program_running(ps)
    if allow or running is False or ps is None:
        return ps
    what = "a user program is running on it" if running else f"its program state is unknown (PS={ps})"
    raise UserProgramError(f"{client.label}: refusing to move it: {what}; the program could fight the motion",
                           hint=f"stop the user program first, or give {ALLOW_OPTION} before the command "
                           f"(`sherpa {ALLOW_OPTION} jog ...`) if it is meant to run alongside")
