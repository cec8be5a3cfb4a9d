"""HOST:PORT options of the servers the tool starts (`sim --serve`, `--foxglove-at`): parsed with
ASCII digits and range-checked where they are parsed, and kept on this machine unless asked."""

from __future__ import annotations

import ipaddress

from sherpa_cli.errors import UsageError


def parse_host_port(text: str, option: str, *, example: str, ports: int = 1, what: str = "") -> tuple[str, int]:
    """``HOST:PORT`` of ``option``; with ``ports`` > 1 the server uses PORT..PORT+ports-1 (``what``
    names them, e.g. "the 3 buses are served on"), and every one must be a TCP port (1..65535).
    Digits are ASCII (``str.isdigit`` takes any script's)."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host or not (port_text.isascii() and port_text.isdigit()):
        raise UsageError(f"{option}: '{text}' is not HOST:PORT", hint=f"e.g. {option} {example}")
    last = 65535 - max(ports, 1) + 1
    if len(port_text) > 5 or not 1 <= int(port_text) <= last:
        span = f"{what} PORT..PORT+{ports - 1}, " if ports > 1 else ""
        raise UsageError(f"{option} {text}: port {port_text[:12]} is out of range; {span}so PORT must be 1..{last}",
                         hint=f"e.g. {option} {example}")
    return host.strip("[]"), int(port_text)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_bind(host: str, allow_remote: bool, option: str, what: str) -> None:
    """Refuse a non-loopback address unless ``allow_remote`` (``--allow-remote``)."""
    if not is_loopback(host) and not allow_remote:
        raise UsageError(f"{option} {host}: refusing to {what} beyond this machine",
                         hint="bind to 127.0.0.1, or pass --allow-remote if other machines must connect")
