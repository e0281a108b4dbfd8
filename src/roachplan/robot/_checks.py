"""Validators of the robot's own settings (addresses, ports, devices), made as
roachplan/_settings.py makes every other: None when a value is accepted, else what would be."""

from __future__ import annotations

from typing import Any

from roachplan._settings import Check, integer


def port(*, free: bool = False) -> Check:
    """A UDP port: 1 to 65535 (free: 0 too, a free one picked)."""
    return integer(0 if free else 1, 65535, noun="a port number")


def host() -> Check:
    """An address or host name (what a socket is given)."""
    expected = "expected an IP address or host name, e.g. 127.0.0.1"

    def check(v: Any) -> str | None:
        ok = isinstance(v, str) and 0 < len(v) <= 253 and not any(c.isspace() for c in v)
        return None if ok and "\0" not in v else expected

    return check


def device() -> Check:
    """A serial device's path (or a pseudo-terminal's)."""
    expected = "expected a serial device, e.g. /dev/ttyUSB0 or COM3"
    return lambda v: None if isinstance(v, str) and v and "\0" not in v else expected


def rigid_body() -> Check:
    """A rigid body's streaming id (a positive integer) or its name in Motive."""
    expected = "expected a rigid body's streaming id (1 or more) or its name"

    def check(v: Any) -> str | None:
        if isinstance(v, bool):
            return expected
        if isinstance(v, int):
            return None if v >= 1 else expected
        return None if isinstance(v, str) and v.strip() else expected

    return check


def parse_address(text: str, *, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """'HOST:PORT' (or 'PORT') -> (host, port); ValueError saying what is accepted."""
    h, sep, p = text.strip().rpartition(":")
    h = h if sep else default_host
    try:
        number = int(p)
    except ValueError:
        raise ValueError("expected HOST:PORT (or PORT), e.g. 127.0.0.1:9870") from None
    for check, value in ((host(), h), (port(), number)):
        if (expected := check(value)) is not None:
            raise ValueError(expected)
    return h, number
