"""How many times this tool has saved (SV) each drive's flash, keyed by the drive's serial number.

A Whistle's flash endures about 100,000 saves (elmo-protocol.md 2.6). One commissioning
run saves once per drive; a script that saves in a loop would wear the flash out unseen,
so every save is counted per serial number (0x1018 sub 4, which follows the drive when it
moves to another node or arm) and a warning grows louder as the count rises.

The ledger is a small JSON file in the user's state directory; it holds counts only, no
times, so that two identical runs leave identical files.
"""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from sherpa_cli.errors import ConfigError, Location
from sherpa_cli.paths import STATE_DIR_HINT, file_lock, move_aside_hint, read_json, state_dir, write_atomic

T = TypeVar("T")

FORMAT = 1
FILE_NAME = "save-ledger.json"

FLASH_ENDURANCE = 100_000  # saves ([CR 3-138])
WARN_EVERY = 100  # a reminder at every hundredth save of a drive
WARN_ALWAYS_ABOVE = 1_000  # beyond this every save warns: commissioning never needs that many


def ledger_path() -> Path:
    return state_dir() / FILE_NAME


def save_warning(drive: str, serial: int, count: int) -> str | None:
    """The warning to show after a drive's ``count``-th save by this tool, or None."""
    if count > WARN_ALWAYS_ABOVE:
        return (f"{drive} (serial 0x{serial:08X}) has now been saved {count} times by this tool; "
                f"its flash endures about {FLASH_ENDURANCE:,} saves -- find out what saves it so often")
    if count % WARN_EVERY == 0:
        return (f"{drive} (serial 0x{serial:08X}) has now been saved {count} times by this tool "
                f"(flash endures about {FLASH_ENDURANCE:,} saves)")
    return None


@dataclass(frozen=True)
class SaveRecord:
    serial: int
    count: int  # saves by this tool, this one included
    warning: str | None


class SaveLedger:
    """The per-serial save counts; thread- and process-safe, each record is written to disk at once."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path or ledger_path()
        self._lock = threading.Lock()

    def count(self, serial: int) -> int:
        with self._lock:
            return int(self._load().get(_key(serial), {}).get("saves", 0))

    def check(self) -> None:
        """Raise ConfigError (path, what is wrong, how out) if the ledger file is damaged."""
        with self._lock:
            self._load()

    def record(self, serial: int, drive: str) -> SaveRecord:
        """Count one save of the drive with this serial (call it only after the drive accepted SV)."""
        def update(drives: dict[str, dict]) -> int:
            entry = drives.setdefault(_key(serial), {"saves": 0})
            entry["saves"] = int(entry.get("saves", 0)) + 1
            entry["last_name"] = drive
            entry.pop("unsaved", None)
            return int(entry["saves"])

        try:
            count, problem = self._update(update)
        except ConfigError as exc:
            # the save happened: report it, and leave the damaged file for a look
            return SaveRecord(serial, 1, f"save not counted: {exc}; {exc.hint}")
        if count is None:  # the ledger could not even be locked: count this save from what it held
            try:
                count = self.count(serial) + 1
            except ConfigError:
                count = 1
        warning = save_warning(drive, serial, count)
        if problem is not None:
            # the save happened; a ledger we cannot write must not hide that from the report
            warning = "; ".join(w for w in (warning, problem) if w)
        return SaveRecord(serial, count, warning)

    # A run with --apply but without --save leaves verified values in RAM only. A later
    # `--apply --save` then finds nothing to change, yet flash still holds the old values:
    # the ledger remembers such drives so that run saves them (one SV, never a loop).
    def mark_unsaved(self, serial: int, drive: str) -> str | None:
        """Remember the drive as written but not saved; a warning if the ledger cannot be written."""
        def update(drives: dict[str, dict]) -> None:
            entry = drives.setdefault(_key(serial), {"saves": 0})
            entry["unsaved"] = True
            entry["last_name"] = drive

        try:
            return self._update(update)[1]
        except ConfigError as exc:
            return f"{drive} not marked as unsaved: {exc}; {exc.hint}"

    def unsaved_drives(self) -> list[tuple[str, int]]:
        """(drive name, serial) of every drive marked written but not saved (`recover` lists them)."""
        with self._lock:
            drives = self._load()
        out = []
        for key, entry in drives.items():
            if isinstance(entry, dict) and entry.get("unsaved"):
                with contextlib.suppress(ValueError):
                    out.append((str(entry.get("last_name", "?")), int(key, 0)))
        return sorted(out)

    def unsaved(self, serial: int) -> bool:
        with self._lock:
            return bool(self._load().get(_key(serial), {}).get("unsaved", False))

    def _update(self, change: Callable[[dict[str, dict]], T]) -> tuple[T | None, str | None]:
        """Load, change and store the ledger under the thread lock and the file lock.

        Returns what ``change`` returned (None if the ledger could not be locked) and the warning
        to show if it was not written (the drives' work is already done).
        """
        with self._lock:
            try:
                with file_lock(self.path):
                    drives = self._load()
                    result = change(drives)
                    return result, self._store(drives)
            except OSError as exc:  # the directory cannot be made, or another command holds the lock
                return None, f"save ledger {self.path} not updated: {exc.strerror or exc}"

    def _store(self, drives: dict[str, dict]) -> str | None:
        """Write the ledger; on failure the warning to show (the drives' work is already done)."""
        body = {"format": FORMAT, "drives": dict(sorted(drives.items()))}
        try:
            write_atomic(self.path, json.dumps(body, indent=1, sort_keys=True) + "\n")
        except OSError as exc:
            return f"save ledger {self.path} not updated: {exc.strerror or exc}"
        return None

    def _load(self) -> dict[str, dict]:
        """The entries; a damaged file raises ConfigError naming it and the way out (never a
        silent restart from zero, which would hide the counts and the unsaved marks)."""
        try:
            data = read_json(self.path, {})
        except OSError as exc:
            raise ConfigError(f"save ledger cannot be read: {exc.strerror or exc}", Location(str(self.path)),
                              hint=STATE_DIR_HINT) from None
        except ValueError as exc:
            raise self._damaged(f"is not a valid ledger ({exc})") from None
        if data == {}:
            return {}
        if not isinstance(data, dict) or not isinstance(data.get("drives"), dict):
            raise self._damaged("is not a save ledger (expected {\"format\": 1, \"drives\": {...}})")
        if data.get("format") != FORMAT:
            raise self._damaged(f"has format {data.get('format')!r}; this version reads format {FORMAT}")
        drives = {}
        for key, entry in data["drives"].items():
            saves = entry.get("saves", 0) if isinstance(entry, dict) else None
            if isinstance(saves, bool) or not isinstance(saves, int) or saves < 0:
                raise self._damaged(f"entry {key!r} is damaged (expected {{\"saves\": count, ...}}, got "
                                    f"{json.dumps(entry)[:60]})")
            drives[key] = dict(entry)
        return drives

    def _damaged(self, problem: str) -> ConfigError:
        return ConfigError(f"save ledger {problem}", Location(str(self.path)),
                           hint=move_aside_hint(self.path, "the save counts then restart from zero"))


def _key(serial: int) -> str:
    return f"0x{serial & 0xFFFFFFFF:08X}"
