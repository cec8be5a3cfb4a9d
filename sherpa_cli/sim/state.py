"""What a simulated drive keeps across power cycles: its flash (what SV saved) and its save count.

Flash persists in one JSON file per arm under the user's state directory. Two simulators of the
same arm merge their saves under a file lock: neither loses the other's SV.

``--sim`` keeps the arm powered between commands: the in-process arm's RAM (positions, parameters,
calibration marks, PDO and dead-man objects, faults) lives beside the flash in ``<arm>.ram.json``,
loaded when a command's arm starts and saved when it stops, under a lock held meanwhile (two `--sim`
commands at once are serialised). While the command runs the file follows the drives (SimArm
``ram_save_s``), so a command killed with SIGKILL leaves what a real arm would hold: the next command's
power-on lets the heartbeat consumers that were watching act (motor off, MF latched), and the killed
command's temporary changes stay in RAM for `sherpa recover`. `sherpa sim --power-cycle` drops the RAM (positions stay, as the
joints do), `--reset-state` drops RAM and flash.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import filelock

from sherpa_cli.config.model import ArmConfig
from sherpa_cli.errors import ConfigError, ExitCode, Location, SherpaError
from sherpa_cli.paths import STATE_DIR_HINT, file_lock, move_aside_hint, read_json, state_dir, write_atomic

FORMAT = 1


@dataclass
class DriveFlash:
    serial: int
    flash: dict[str, int | float] = field(default_factory=dict)  # parameter key -> saved value
    save_count: int = 0


def arm_key(cfg: ArmConfig) -> str:
    """One state file per arm: its name plus the drives' addresses (a re-wired arm starts fresh)."""
    layout = sorted((d.name, d.bus, d.node) for d in cfg.drives.values())
    digest = hashlib.sha256(json.dumps(layout).encode()).hexdigest()[:10]
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in cfg.name)
    return f"{safe}-{digest}"


def state_path(cfg: ArmConfig) -> Path:
    return state_dir() / "sim" / f"{arm_key(cfg)}.json"


def default_serial(cfg: ArmConfig, drive: str) -> int:
    """A stable serial number per drive (unique within the arm), as 0x1018 sub 4 reports it."""
    names = sorted(cfg.drives)
    return 0x5A000000 + 0x100 * (names.index(drive) + 1) + cfg.drives[drive].node


def load(cfg: ArmConfig, path: Path | None = None) -> dict[str, DriveFlash]:
    """Flash per drive; drives not in the file start at factory state.

    A damaged file (not JSON, wrong shape, a value no drive could hold) raises ConfigError
    naming the file and the way out, before any simulated drive is built from it.
    """
    target = path or state_path(cfg)

    def damaged(problem: str) -> ConfigError:
        return ConfigError(f"simulator state {problem}", Location(str(target)),
                           hint=move_aside_hint(target, "or reset it with `sherpa sim --reset-state` "
                                                        "(the simulated drives then start with factory flash)"))

    try:
        data: object = read_json(target, {})
    except OSError as exc:
        raise SherpaError(f"{target}: cannot read the simulator state: {exc.strerror or exc}",
                          hint=STATE_DIR_HINT) from None
    except ValueError as exc:
        raise damaged(f"is damaged ({exc})") from None
    if not isinstance(data, dict) or (data and not isinstance(data.get("drives", {}), dict)):
        raise damaged("is not a simulator state file (expected {\"format\": 1, \"drives\": {...}})")
    drives = data.get("drives", {}) if data.get("format") == FORMAT else {}
    result = {}
    for name in cfg.drives:
        saved = drives.get(name, {})
        try:
            result[name] = _drive_flash(saved, default_serial(cfg, name))
        except (TypeError, ValueError) as exc:
            raise damaged(f"is damaged: drive {name}: {exc}") from None
    return result


def _drive_flash(saved: object, serial: int) -> DriveFlash:
    from sherpa_cli.sim.od import ODError, check_value
    from sherpa_cli.sim.params import parse_flash

    if not isinstance(saved, dict):
        raise ValueError(f"expected a mapping, got {json.dumps(saved)[:40]}")
    serial = saved.get("serial", serial)
    count = saved.get("save_count", 0)
    flash = saved.get("flash", {})
    for key, value, hi in (("serial", serial, 0xFFFFFFFF), ("save_count", count, 10**9)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= hi:
            raise ValueError(f"{key} {json.dumps(value)[:40]} is not an integer 0..{hi}")
    if not isinstance(flash, dict):
        raise ValueError("flash is not a mapping")
    parse_flash(flash)  # interpreter keys: ValueError naming the key
    for key, value in flash.items():
        if isinstance(key, str) and key.startswith("0x"):
            try:
                index, sub = (int(part, 16) if i == 0 else int(part) for i, part in enumerate(key.split(":")))
                check_value(index, sub, value)
            except (ValueError, ODError) as exc:
                raise ValueError(f"flash key {key!r}: {exc}") from None
    return DriveFlash(serial=serial, flash=dict(flash), save_count=count)


def save(cfg: ArmConfig, drives: dict[str, DriveFlash], path: Path | None = None) -> Path:
    """Write the arm's flash atomically; SherpaError (one message) if the state directory is unwritable."""
    target = path or state_path(cfg)
    body = {"format": FORMAT, "arm": cfg.name,
            "drives": {name: {"serial": d.serial, "save_count": d.save_count, "flash": d.flash}
                       for name, d in sorted(drives.items())}}
    try:
        write_atomic(target, json.dumps(body, indent=1, sort_keys=True) + "\n")
    except OSError as exc:
        raise SherpaError(f"{target}: cannot save the simulated drives' flash: {exc.strerror or exc}",
                          hint=f"the file is unchanged; {STATE_DIR_HINT}") from None
    return target


def save_changes(cfg: ArmConfig, before: dict[str, DriveFlash], after: dict[str, DriveFlash],
                 path: Path | None = None) -> Path:
    """Store what changed between ``before`` (as loaded) and ``after``, merged with the file as it
    is now: another simulator of this arm may have saved meanwhile. A drive this one saved gets
    its flash and the other's saves added to its count; the others keep what the file holds."""
    target = path or state_path(cfg)
    with file_lock(target):
        current = load(cfg, target)
        for name, now in after.items():
            then = before.get(name)
            if then is not None and now.flash == then.flash and now.save_count == then.save_count:
                continue
            added = now.save_count - (then.save_count if then is not None else 0)
            base = current.get(name)
            count = (base.save_count if base is not None else 0) + max(added, 0)
            current[name] = DriveFlash(serial=now.serial, flash=dict(now.flash), save_count=count)
        return save(cfg, current, target)


def reset(cfg: ArmConfig, path: Path | None = None) -> bool:
    """Factory state for the arm: removes its state file; True if there was one."""
    target = path or state_path(cfg)
    with file_lock(target):
        try:
            target.unlink()
            return True
        except FileNotFoundError:
            return False


# -- RAM: the arm stays powered between `--sim` commands ------------------------------------------------

RAM_FORMAT = 1


class SimArmBusyError(SherpaError):
    """Another `--sim` command holds the simulated arm (its RAM state) for longer than we waited (exit 5)."""

    exit_code = ExitCode.BUSY


def ram_path(cfg: ArmConfig) -> Path:
    """The powered arm's RAM (positions, parameters, PDO and dead-man objects, faults), beside its flash."""
    return state_dir() / "sim" / f"{arm_key(cfg)}.ram.json"


SECOND_TERMINAL_HINT = ("an in-process `--sim` arm lives in the process of the command that opened it; for "
                        "commands from a second terminal run `sherpa sim --serve` once and give every command its "
                        "--bus-map (docs/simulator.md)")


def ram_holder(cfg: ArmConfig) -> int | None:
    """The pid of the `--sim` command holding the arm, if it wrote one and still runs."""
    try:
        pid = int(ram_path(cfg).with_suffix(".pid").read_text(encoding="ascii").split()[0])
    except (OSError, ValueError, IndexError):
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except OSError:
        pass  # another user's process: it runs
    return pid


def ram_lock(cfg: ArmConfig, timeout: float,
             on_wait: Callable[[str], None] | None = None) -> filelock.BaseFileLock:
    """Held by an in-process `--sim` arm from loading its RAM to saving it: two commands are serialised.
    A second command says at once who holds the arm (``on_wait``) and waits up to ``timeout`` s, then
    :class:`SimArmBusyError`; with ``timeout`` 0 (`sherpa stop`: it cannot reach a motor moved in
    another process) it is refused at once."""
    target = ram_path(cfg)
    lock = file_lock(target, timeout=timeout)
    try:
        try:
            lock.acquire(timeout=0)
        except filelock.Timeout:
            holder = ram_holder(cfg)
            busy = (f"simulated arm '{cfg.name}': another `--sim` command" + (f" (pid {holder})" if holder else "")
                    + " is using it")
            if timeout <= 0:
                raise SimArmBusyError(busy + ": this command cannot reach a motor that process moves",
                                      hint=SECOND_TERMINAL_HINT) from None
            if on_wait is not None:
                on_wait(f"{busy}; waiting up to {timeout:g} s for it to end ({SECOND_TERMINAL_HINT})")
            lock.acquire()
    except filelock.Timeout:
        raise SimArmBusyError(f"simulated arm '{cfg.name}': another `--sim` command is using it (waited {timeout:g} s)",
                              hint=SECOND_TERMINAL_HINT) from None
    except OSError as exc:
        raise SherpaError(f"{target}: cannot lock the simulated arm's state: {exc.strerror or exc}",
                          hint=STATE_DIR_HINT) from None
    with contextlib.suppress(OSError):  # the pid is only for the other command's message
        target.with_suffix(".pid").write_text(f"{os.getpid()}\n", encoding="ascii")
    return lock


def release_ram_lock(cfg: ArmConfig, lock: filelock.BaseFileLock) -> None:
    with contextlib.suppress(OSError):
        ram_path(cfg).with_suffix(".pid").unlink()
    lock.release()


def load_ram(cfg: ArmConfig, path: Path | None = None) -> dict[str, Any] | None:
    """The powered arm's RAM as saved, or None (never powered, or reset). A damaged file raises ConfigError."""
    target = path or ram_path(cfg)
    try:
        data: object = read_json(target, None)
    except OSError as exc:
        raise SherpaError(f"{target}: cannot read the simulated arm's RAM: {exc.strerror or exc}",
                          hint=STATE_DIR_HINT) from None
    except ValueError as exc:
        raise ram_damaged(target, str(exc)) from None
    if data is None:
        return None
    if not isinstance(data, dict) or data.get("format") != RAM_FORMAT or not isinstance(data.get("drives"), dict):
        raise ram_damaged(target, "not a simulated arm's RAM file")
    return data


def ram_damaged(target: Path, problem: str) -> ConfigError:
    return ConfigError(f"simulated arm RAM state is damaged ({problem})", Location(str(target)),
                       hint=move_aside_hint(target, "or power the simulated arm off and on with `sherpa sim --power-cycle`"))


def save_ram(cfg: ArmConfig, drives: dict[str, Any], powered: bool = True, path: Path | None = None,
             durable: bool = True) -> Path:
    """Write the arm's RAM atomically (``powered`` False: only positions survive, a power cycle;
    ``durable`` False: no fsync, for the copies a running command keeps, paths.write_atomic)."""
    target = path or ram_path(cfg)
    body = {"format": RAM_FORMAT, "arm": cfg.name, "powered": powered, "drives": drives}
    try:
        write_atomic(target, json.dumps(body, indent=1, sort_keys=True) + "\n", durable=durable)
    except OSError as exc:
        raise SherpaError(f"{target}: cannot save the simulated arm's RAM: {exc.strerror or exc}",
                          hint=STATE_DIR_HINT) from None
    return target


def power_cycle(cfg: ArmConfig, timeout: float = 10.0) -> bool:
    """`sherpa sim --power-cycle`: RAM is lost, the joints stay where they are (PX reads 0 there at the
    next power-up). True if the arm was powered."""
    lock = ram_lock(cfg, timeout)
    try:
        saved = load_ram(cfg)
        if saved is None:
            return False
        positions = {name: {"position": d.get("position")} for name, d in saved["drives"].items()
                     if isinstance(d, dict) and "position" in d}
        save_ram(cfg, positions, powered=False)
        return bool(saved.get("powered", True))
    finally:
        lock.release()


def reset_ram(cfg: ArmConfig, timeout: float = 10.0) -> bool:
    """Forget RAM and positions (the arm as delivered); True if there was a RAM file."""
    lock = ram_lock(cfg, timeout)
    try:
        ram_path(cfg).unlink()
        return True
    except FileNotFoundError:
        return False
    finally:
        lock.release()
