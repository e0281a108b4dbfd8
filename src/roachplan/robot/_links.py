"""Command links: how the motor command frames (_frames.py) reach a robot, and how a robot
(the twin) receives them. A link is anything with send() and close() (CommandLink); links are
made by name from LINKS (register_link adds one for another robot)."""

from __future__ import annotations

import os
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from roachplan._settings import SettingError, check_settings, integer
from roachplan._settings import setting as s

from . import _checks
from ._errors import RobotError
from ._frames import FRAME_SIZE, CommandFrame, FrameReader, decode_command, encode_command


class CommandLink(Protocol):
    """Sends motor commands to one robot."""

    def send(self, left: float, right: float, *, stop: bool = False) -> CommandFrame:
        """Send (left, right) motor speeds [rad/s] (stop: a stop frame, speeds 0) now; the
        frame as sent."""
        ...

    def close(self) -> None: ...


class _Sequencer:
    """Numbers and stamps the frames of one sender."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.seq = 0
        self.clock = clock

    def frame(self, left: float, right: float, stop: bool) -> CommandFrame:
        frame = CommandFrame(
            seq=self.seq,
            t_us=int(self.clock() * 1e6),
            left=0.0 if stop else float(left),
            right=0.0 if stop else float(right),
            stop=stop,
        )
        self.seq = (self.seq + 1) % 2**32
        return frame


@dataclass(frozen=True, kw_only=True)
class UdpLinkSettings:
    """Commands as UDP datagrams, one frame each."""

    host: str = s("127.0.0.1", _checks.host())
    """The robot's (or its bridge's) address."""
    port: int = s(9870, _checks.port())
    """Its UDP port."""

    def __post_init__(self) -> None:
        check_settings(self)


class UdpCommandLink:
    """Sends each frame as one UDP datagram."""

    def __init__(self, settings: UdpLinkSettings) -> None:
        self.settings = settings
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._seq = _Sequencer()

    def send(self, left: float, right: float, *, stop: bool = False) -> CommandFrame:
        frame = self._seq.frame(left, right, stop)
        try:
            self._sock.sendto(encode_command(frame), (self.settings.host, self.settings.port))
        except OSError as exc:  # a robot gone (ECONNREFUSED from an earlier datagram): go on
            if exc.errno is None:
                raise
        return frame

    def close(self) -> None:
        self._sock.close()


@dataclass(frozen=True, kw_only=True)
class SerialLinkSettings:
    """Commands over a serial line (the VelociRoACH's radio bridge is one), frames back to
    back."""

    port: str = s(check=_checks.device())
    """The device: /dev/ttyUSB0, /dev/ttyACM0, COM3, a pseudo-terminal."""
    baudrate: int = s(115200, integer(300, 4_000_000, noun="a line speed [bit/s]"))
    """Line speed [bit/s]: a 28-byte frame takes 2.4 ms at 115200, well inside 20 ms."""

    def __post_init__(self) -> None:
        check_settings(self)


class SerialCommandLink:
    """Writes each frame to a serial line (pyserial)."""

    def __init__(self, settings: SerialLinkSettings) -> None:
        import serial  # pyserial: only a serial link loads it

        try:
            self._port = serial.Serial(
                settings.port, settings.baudrate, timeout=0, write_timeout=0.01
            )
        except (serial.SerialException, ValueError) as exc:
            raise RobotError(
                f"command link serial: cannot open {settings.port!r} at {settings.baudrate} "
                f"bit/s: {exc}; give the bridge's device (e.g. /dev/ttyUSB0)"
            ) from None
        self._seq = _Sequencer()

    def send(self, left: float, right: float, *, stop: bool = False) -> CommandFrame:
        import serial

        frame = self._seq.frame(left, right, stop)
        try:
            self._port.write(encode_command(frame))
        except serial.SerialTimeoutException:  # a full line: this frame is lost, the next goes
            pass
        return frame

    def close(self) -> None:
        self._port.close()


LINKS: dict[str, Callable[..., CommandLink]] = {
    "udp": lambda **kw: UdpCommandLink(UdpLinkSettings(**kw)),
    "serial": lambda **kw: SerialCommandLink(SerialLinkSettings(**kw)),
}
"""Command links by name: name -> factory taking the link's settings as keywords."""


def register_link(name: str, factory: Callable[..., CommandLink]) -> None:
    """Make another robot's link available by name (open_link(name, ...))."""
    LINKS[name] = factory


def open_link(name: str, **settings) -> CommandLink:
    """The command link `name` ("udp", "serial", or one registered) with its settings;
    RobotError naming the link and what is accepted."""
    if name not in LINKS:
        raise RobotError(f"command link {name!r}: choose from {', '.join(sorted(LINKS))}")
    try:
        return LINKS[name](**settings)
    except (TypeError, SettingError) as exc:
        raise RobotError(f"command link {name!r}: {exc}") from None


# -- the receiving side (a robot's firmware does this; here, the twin) -----------------------


class UdpCommandReceiver:
    """Receives command frames on a UDP port (bound to host:port; port 0 picks a free one)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, port))
        self._sock.setblocking(False)
        self.port = self._sock.getsockname()[1]
        self.bad = 0
        """Datagrams that were no valid frame."""

    def fileno(self) -> int:
        return self._sock.fileno()

    def poll(self) -> list[CommandFrame]:
        """Every frame that has arrived (none waits)."""
        frames = []
        while True:
            try:
                data = self._sock.recv(4096)
            except BlockingIOError:
                return frames
            if len(data) != FRAME_SIZE:
                self.bad += 1
                continue
            try:
                frames.append(decode_command(data))
            except RobotError:
                self.bad += 1

    def close(self) -> None:
        self._sock.close()


class FdCommandReceiver:
    """Receives command frames from a file descriptor of a byte stream: a serial device or a
    pseudo-terminal's master side (the twin's serial line)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        os.set_blocking(fd, False)
        self._reader = FrameReader()

    @property
    def bad(self) -> int:
        return self._reader.skipped

    def fileno(self) -> int:
        return self.fd

    def poll(self) -> list[CommandFrame]:
        frames = []
        while select.select([self.fd], [], [], 0)[0]:
            try:
                data = os.read(self.fd, 4096)
            except (BlockingIOError, OSError):  # EIO: the other side of a pty closed
                break
            if not data:
                break
            frames += self._reader.feed(data)
        return frames

    def close(self) -> None:
        os.close(self.fd)
